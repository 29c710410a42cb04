"""The import graph of gcs: layers import only downwards, and no two modules import each other.

Read with the standard library's :mod:`ast` (nothing is imported), counting every import: at
the top, inside functions and under ``TYPE_CHECKING`` (a type is a dependency too).

The layers, lowest first (a module may import its own layer's modules and any lower layer):

0. ``gcs.errors``: the exceptions every layer raises;
1. ``gcs.core``: pure numerics (no files, MAVSDK or terminal);
2. ``gcs`` itself: the public Python API, the face of the numerics;
3. ``gcs.io``: files and formats, parsed into frozen configuration and records;
4. ``gcs.api``: the public API's conveniences that read files (``Learner.from_profile``);
5. ``gcs.flight`` and ``gcs.mock``: the vehicle side and the mock drone, beside each other
   (neither imports the other: the mock is a separate program that talks MAVLink);
6. ``gcs.app``: one room per command beside its view; ``gcs.sim``: the mock drone in-process
   behind a simulated link on a virtual clock, for the tests (it joins the two sides of 5);
7. ``gcs.cli`` and ``gcs.__main__``: the command line, which only wires.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "gcs"

#: Layer of each top-level part of the package (see the module's docstring).
LAYERS = {
    "gcs.errors": 0,
    "gcs.core": 1,
    "gcs": 2,
    "gcs.io": 3,
    "gcs.api": 4,
    "gcs.flight": 5,
    "gcs.mock": 5,
    "gcs.app": 6,
    "gcs.sim": 6,
    "gcs.cli": 7,
    "gcs.__main__": 7,
}
#: Parts of the same layer that must not import each other.
SIBLINGS = {
    ("gcs.flight", "gcs.mock"),
    ("gcs.mock", "gcs.flight"),
    ("gcs.app", "gcs.sim"),
    ("gcs.sim", "gcs.app"),
}
#: Errors that name a file, a run directory or the vehicle: the numerics never raise them
#: (the caller that read the file or flew the vehicle names it).
NOT_FOR_CORE = {
    "ProfileError",
    "RunLogError",
    "PathError",
    "VehicleError",
    "TrialAborted",
    "MocapError",
}
#: Cycles allowed while another branch removes them, each with who removes it (the sorted
#: modules of the cycle -> why). Empty: there are none.
ALLOWED_CYCLES: dict[tuple[str, ...], str] = {}


def _modules() -> dict[str, Path]:
    out = {}
    for path in ROOT.rglob("*.py"):
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _owner(name: str) -> str:
    """The module of ``name`` (a module, or a name defined in one)."""
    while name not in MODULES and "." in name:
        name = name.rsplit(".", 1)[0]
    return name


def _imports(module: str) -> list[tuple[str, list[str]]]:
    """(imported module, names taken from it) for every import statement of ``module``."""
    path = MODULES[module]
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(alias.name, []) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                out.append((sub, []) if sub in MODULES else (target, [alias.name]))
    return [(_owner(t), names) for t, names in out if t.split(".")[0] == "gcs"]


GRAPH = {m: {t for t, _ in _imports(m) if t != m} for m in MODULES}


def _part(module: str) -> str:
    parts = module.split(".")
    return module if len(parts) == 1 else ".".join(parts[:2])


def _cycles(graph: dict[str, set[str]]) -> list[tuple[str, ...]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(tuple(sorted(comp)))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_every_module_has_a_layer():
    assert {_part(m) for m in MODULES} <= set(LAYERS), "a new top-level part needs a layer"


def test_no_upward_or_sideways_import():
    bad = []
    for module, targets in GRAPH.items():
        for target in targets:
            src, dst = _part(module), _part(target)
            if LAYERS[dst] > LAYERS[src] or (src, dst) in SIBLINGS:
                bad.append(f"{module} -> {target}")
    assert not bad, "imports against the layers:\n" + "\n".join(sorted(bad))


def test_core_raises_no_file_or_vehicle_errors():
    bad = []
    for module in MODULES:
        if _part(module) == "gcs.core":
            for target, names in _imports(module):
                if target == "gcs.errors":
                    bad += [f"{module}: {n}" for n in names if n in NOT_FOR_CORE]
    assert not bad, "the numerics raise their own errors; the caller names the file:\n" + (
        "\n".join(bad)
    )


def test_no_import_cycles():
    cycles = [c for c in _cycles(GRAPH) if c not in ALLOWED_CYCLES]
    assert not cycles, "modules that import each other:\n" + "\n".join(map(str, cycles))


def test_allowed_cycles_still_exist():
    """An allowed cycle that is gone leaves the allow-list (so it cannot come back unseen)."""
    gone = set(ALLOWED_CYCLES) - set(_cycles(GRAPH))
    assert not gone, f"remove from ALLOWED_CYCLES: {sorted(gone)}"


@pytest.mark.parametrize(
    ("graph", "expected"),
    [
        ({"a": {"b"}, "b": {"a"}}, [("a", "b")]),
        ({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}, [("a", "b", "c")]),
        ({"a": {"b"}, "b": set()}, []),
    ],
)
def test_cycle_finder(graph, expected):
    assert _cycles(graph) == expected
