"""Docstrings where readers need them: the policy of docs/CONVENTIONS.md, enforced.

**Full numpydoc** where a reader needs parameters, shapes and units: the numerics
(``gcs.core``) and the public API (``gcs.api`` and every name ``gcs`` exports). There every
public function and method (a name in its module's ``__all__``, or a public method of such a
class) has a ``Parameters`` section that names each parameter of its signature and no other,
and a ``Returns`` (or ``Yields``) section unless it returns ``None`` (or takes no parameters and
its one-line docstring says what it returns); a parameter or result that is an array states
its shape. Units are in the names (``t_ilc_s``, ``pos_ned_m``) or in
the descriptions (``[m]``); that part is left to review.

**A sentence** everywhere else (files, flight, the mock drone, the simulator, the commands):
every public module, class, function and method has a docstring that is at least one sentence.
Numpydoc is not required there; where a docstring does have a ``Parameters`` section, the names
it documents are parameters of the signature (a renamed parameter leaves no stale entry).

"Public" is the module's ``__all__`` where it has one (names defined in that module; a name
re-exported is checked where it is defined), otherwise every top-level name without a leading
underscore; in a public class, every function, class or static method and property without one.
A method that overrides a documented one inherits its docstring (``inspect.getdoc``); a class
needs its own.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import pkgutil
import re
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

import gcs

SKIP_PARAMS = {"self", "cls"}
#: numpydoc sections that document parameters.
PARAM_SECTIONS = ("Parameters", "Other Parameters")
#: Where full numpydoc is required: the numerics and the public API.
NUMPYDOC_PREFIXES = ("gcs.core", "gcs.api")


def _module_names() -> list[str]:
    names = ["gcs"]
    for info in pkgutil.walk_packages(gcs.__path__, "gcs."):
        names.append(info.name)
    return sorted(names)


MODULES = _module_names()


def _needs_numpydoc(module_name: str) -> bool:
    return any(module_name == p or module_name.startswith(p + ".") for p in NUMPYDOC_PREFIXES)


def _sections(doc: str) -> dict[str, list[str]]:
    """The numpydoc sections of a cleaned docstring: title -> its lines."""
    lines = doc.splitlines()
    out: dict[str, list[str]] = {}
    current: list[str] | None = None
    i = 0
    while i < len(lines):
        title = lines[i]
        if (
            i + 1 < len(lines)
            and re.fullmatch(r"[A-Z][A-Za-z ]*", title)
            and re.fullmatch(r"-{3,}", lines[i + 1])
        ):
            current = out.setdefault(title, [])
            i += 2
            continue
        if current is not None:
            current.append(lines[i])
        i += 1
    return out


def _entries(lines: list[str]) -> dict[str, str]:
    """The entries of a numpydoc section: name -> its type and description, as one text.

    ``a, b : type`` documents both names; ``*args`` and ``**kwargs`` keep their stars.
    """
    entries: dict[str, str] = {}
    names: list[str] = []
    for line in lines:
        if not line.strip():
            continue
        if not line[0].isspace():
            head, _, typ = line.partition(" : ")
            names = [n.strip() for n in head.split(",") if n.strip()]
            for n in names:
                entries[n] = typ
        else:
            for n in names:
                entries[n] += " " + line.strip()
    return entries


def _public_members(cls: type) -> Iterator[tuple[str, Callable]]:
    for attr, member in vars(cls).items():
        if attr.startswith("_"):
            continue
        if isinstance(member, (classmethod, staticmethod)):
            member = member.__func__
        if inspect.isfunction(member) or isinstance(member, property):
            yield attr, member


def _public_objects(module_name: str) -> Iterator[tuple[str, object]]:
    """Public functions and classes defined in a module, and the public members of its classes."""
    module = importlib.import_module(module_name)
    if hasattr(module, "__all__"):
        names = list(module.__all__)
    else:
        names = [n for n in vars(module) if not n.startswith("_")]
    for name in names:
        obj = getattr(module, name)
        if not (inspect.isfunction(obj) or inspect.isclass(obj)):
            continue
        if obj.__module__ != module_name:
            continue  # a re-export: checked where it is defined
        yield f"{module_name}.{name}", obj
        if inspect.isclass(obj):
            for attr, member in _public_members(obj):
                yield f"{module_name}.{name}.{attr}", member


def _exported() -> Iterator[tuple[str, object]]:
    """The names ``gcs`` exports, wherever they are defined, with their public members."""
    for name in gcs.__all__:
        obj = getattr(gcs, name)
        yield f"gcs.{name}", obj
        if inspect.isclass(obj):
            for attr, member in _public_members(obj):
                yield f"gcs.{name}.{attr}", member


def _numpydoc_cases() -> list[tuple[str, Callable]]:
    cases: dict[str, Callable] = {}
    objects = [o for m in MODULES if _needs_numpydoc(m) for o in _public_objects(m)]
    for name, obj in [*objects, *_exported()]:
        if inspect.isfunction(obj):
            cases.setdefault(name, obj)
    return sorted(cases.items())


def _sentence_cases() -> list[tuple[str, object]]:
    return [o for m in MODULES if not m.endswith("__main__") for o in _public_objects(m)]


NUMPYDOC_CASES = _numpydoc_cases()
SENTENCE_CASES = _sentence_cases()


def _is_sentence(doc: str | None) -> bool:
    """At least one sentence: text whose first paragraph has a full stop, ``?`` or ``!`` (or
    ends with ``:``, introducing what follows)."""
    first = (doc or "").strip().split("\n\n", 1)[0]
    return re.search(r"\w.*?([.?!](\s|$)|:$)", first, re.DOTALL) is not None


def _params(func: Callable) -> list[inspect.Parameter]:
    return [
        p
        for p in inspect.signature(func).parameters.values()
        if p.name not in SKIP_PARAMS and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    ]


def _signature_names(func: Callable) -> set[str]:
    names = set()
    for p in inspect.signature(func).parameters.values():
        star = {p.VAR_POSITIONAL: "*", p.VAR_KEYWORD: "**"}.get(p.kind, "")
        names |= {p.name, star + p.name}
    return names


def _returns_nothing(func: Callable) -> bool:
    ann = inspect.signature(func).return_annotation
    return ann in (None, "None") or func.__name__ == "__init__"


def _is_array(annotation: object) -> bool:
    return "ndarray" in str(annotation)


# ------------------------------------------------------------------------ the numpydoc zone


def test_there_are_functions_to_check() -> None:
    assert len(NUMPYDOC_CASES) > 30
    assert len(SENTENCE_CASES) > 300


def test_the_public_api_is_in_the_numpydoc_zone() -> None:
    """Every name ``gcs`` exports is defined in gcs.core or gcs.api, where numpydoc is checked."""
    outside = [name for name in gcs.__all__ if not _needs_numpydoc(getattr(gcs, name).__module__)]
    assert not outside, f"exported from outside gcs.core and gcs.api: {outside}"


@pytest.mark.parametrize(("name", "func"), NUMPYDOC_CASES, ids=[c[0] for c in NUMPYDOC_CASES])
def test_numpydoc_documents_parameters_and_returns(name: str, func: Callable) -> None:
    doc = inspect.getdoc(func)
    assert doc, f"{name} has no docstring"
    sections = _sections(doc)
    documented: dict[str, str] = {}
    for title in PARAM_SECTIONS:
        documented.update(_entries(sections.get(title, [])))
    params = _params(func)
    missing = [p.name for p in params if p.name not in documented]
    assert not missing, f"{name}: parameters not documented: {missing}"
    stale = sorted(set(documented) - _signature_names(func))
    assert not stale, f"{name}: documents parameters it does not have: {stale}"
    no_shape = [
        p.name
        for p in params
        if _is_array(p.annotation) and "shape" not in documented[p.name].lower()
    ]
    assert not no_shape, f"{name}: array parameters without their shape: {no_shape}"
    if not _returns_nothing(func):
        results = sections.get("Returns") or sections.get("Yields")
        one_liner = not params and "\n" not in doc
        assert results or one_liner, f"{name}: no Returns (or Yields) section"
        if _is_array(inspect.signature(func).return_annotation):
            text = " ".join(results) if results else doc
            assert "shape" in text.lower(), f"{name}: returns an array, its shape not stated"


# ------------------------------------------------------------------------ everywhere


@pytest.mark.parametrize("module_name", MODULES)
def test_every_module_says_what_it_is(module_name: str) -> None:
    spec = importlib.util.find_spec(module_name)
    assert spec is not None and spec.origin is not None
    doc = ast.get_docstring(ast.parse(Path(spec.origin).read_text(encoding="utf-8")))
    assert _is_sentence(doc), f"{module_name}: no module docstring of at least one sentence"


@pytest.mark.parametrize(("name", "obj"), SENTENCE_CASES, ids=[c[0] for c in SENTENCE_CASES])
def test_public_names_have_a_sentence(name: str, obj: object) -> None:
    # a class's own docstring (not a base class's, nor the signature a dataclass writes)
    if inspect.isclass(obj):
        doc = inspect.cleandoc(vars(obj).get("__doc__") or "")
        if re.fullmatch(rf"{obj.__name__}\(.*\)", doc, re.DOTALL):
            doc = ""  # the signature a dataclass writes when there is no docstring
    else:
        doc = inspect.getdoc(obj)
    assert _is_sentence(doc), f"{name}: no docstring of at least one sentence"
    sections = _sections(doc)
    documented = set()
    for title in PARAM_SECTIONS:
        documented |= set(_entries(sections.get(title, [])))
    if documented:
        stale = sorted(documented - _signature_names(obj))
        assert not stale, f"{name}: documents parameters it does not have: {stale}"
