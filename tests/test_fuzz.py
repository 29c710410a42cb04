"""Property-based fuzzing of profiles, trajectories and run directories (hypothesis).

Whatever the damage (a field deleted, of another type, NaN, infinite, huge; a file truncated,
deleted, added, renamed onto another), every command either succeeds with a sensible result
(exit 0) or refuses with exit code 2 and one line; the files that existed before are
byte-identical afterwards, and nothing appears in the workspace except what a successful
command writes.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest
import yaml
from badinputs import UNREACHABLE, Templates, _cwd, snapshot
from cli_runner import invoke as gcs_invoke
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from synthetic import ROOT

# Modest: the suite has a time budget (docs/CONVENTIONS.md); each example runs a command.
FUZZ = settings(
    max_examples=int(os.environ.get("GCS_FUZZ_EXAMPLES", "40")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

PROFILE = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
TRAJECTORY = yaml.safe_load((ROOT / "trajectories" / "eight-short.yaml").read_text())

BAD_VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-(10**20), 10**20),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
    st.lists(st.floats(-10, 10), max_size=4), st.dictionaries(st.text(max_size=4), st.integers(),
                                                              max_size=2),
)  # fmt: skip


def _paths(data: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path of a nested dict (sections and leaves)."""
    out = []
    if isinstance(data, dict):
        for key, value in data.items():
            out.append((*prefix, key))
            out += _paths(value, (*prefix, key))
    return out


def _mutate(data: dict, path: tuple, action: str, value: Any) -> dict:
    data = json.loads(json.dumps(data))
    node = data
    for key in path[:-1]:
        node = node[key]
    if action == "delete":
        del node[path[-1]]
    elif action == "extra":
        if isinstance(node[path[-1]], dict):
            node[path[-1]]["unexpected_field"] = value
        else:
            node["unexpected_field"] = value
    else:
        node[path[-1]] = value
    return data


def _invoke(cwd: Path, argv: list[str]):
    with _cwd(cwd):
        return gcs_invoke(argv, env={"COLUMNS": "400"})


def _one_line_or_success(result, success: str) -> None:
    assert result.exit_code in (0, 2), (result.exit_code, result.output, result.exception)
    lines = [line for line in result.output.splitlines() if line.strip()]
    if result.exit_code == 2:
        assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    else:
        assert success in result.output, result.output


def _dump(data: Any) -> str:
    return yaml.safe_dump(data, allow_unicode=True)


@FUZZ
@given(
    path=st.sampled_from(_paths(PROFILE)),
    action=st.sampled_from(["delete", "set", "extra"]),
    value=BAD_VALUES,
)
def test_fuzzed_profiles_are_flown_checked_or_refused_in_one_line(path, action, value) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        ws = Path(tmp)
        (ws / "p.yaml").write_text(_dump(_mutate(PROFILE, path, action, value)))
        before = snapshot(ws)
        argv = ["fly", "--connect", UNREACHABLE, "--profile", "p.yaml", "--trajectory",
                "eight-short", "--check", "--offline"]  # fmt: skip
        _one_line_or_success(_invoke(ws, argv), "checked: profile")
        assert snapshot(ws) == before


@FUZZ
@given(
    path=st.sampled_from(_paths(TRAJECTORY)),
    action=st.sampled_from(["delete", "set", "extra"]),
    value=BAD_VALUES,
)
def test_fuzzed_trajectories_are_checked_or_refused_in_one_line(path, action, value) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        ws = Path(tmp)
        (ws / "t.yaml").write_text(_dump(_mutate(TRAJECTORY, path, action, value)))
        before = snapshot(ws)
        argv = ["fly", "--mock", "--trajectory", "t.yaml", "--check", "--offline"]
        _one_line_or_success(_invoke(ws, argv), "checked: profile")
        assert snapshot(ws) == before


@FUZZ
@given(
    kind=st.sampled_from(["profile", "trajectory"]),
    cut=st.floats(0.0, 1.0),
    junk=st.sampled_from(["", "\x00", ":", "[", "  - {", "\t"]),
)
def test_truncated_yaml_files_are_checked_or_refused_in_one_line(kind, cut, junk) -> None:
    source = ROOT / ("profiles/antx.yaml" if kind == "profile" else "trajectories/eight.yaml")
    text = source.read_text()
    with tempfile.TemporaryDirectory() as tmp:
        ws = Path(tmp)
        (ws / "f.yaml").write_text(text[: int(len(text) * cut)] + junk)
        before = snapshot(ws)
        argv = ["fly", "--mock", f"--{kind}", "f.yaml", "--check", "--offline"]
        _one_line_or_success(_invoke(ws, argv), "checked: profile")
        assert snapshot(ws) == before


# ---------------------------------------------------------------------------- run directories

RUN_FILES = [
    "manifest.json", "reference.csv", "setpoints-000.csv", "setpoints-001.csv",
    "setpoints-002.csv", "trial-000.csv", "trial-000.json", "trial-001.csv", "trial-001.json",
    "estimate-000.csv", "estimate-001.csv",
]  # fmt: skip
EXTRA_FILES = [
    ("trial-002.json", '{"trial": 2, "status": "complete"}'),
    ("trial-005.csv", "k,t_s\n0,0\n"), ("setpoints-009.csv", "garbage"),
    ("session-001.json", "[]"), ("notes.txt", "hello"), ("trial-1.json", "{}"),
    ("estimate-004.csv", "k\n"), ("aborted", None),
]  # fmt: skip

damage = st.one_of(
    st.tuples(st.just("truncate"), st.sampled_from(RUN_FILES), st.floats(0.0, 0.999)),
    st.tuples(st.just("delete"), st.sampled_from(RUN_FILES), st.none()),
    st.tuples(st.just("swap"), st.sampled_from(RUN_FILES), st.sampled_from(RUN_FILES)),
    st.tuples(st.just("extra"), st.sampled_from(EXTRA_FILES), st.none()),
    st.tuples(st.just("cell"), st.sampled_from([f for f in RUN_FILES if f.endswith(".csv")]),
              st.tuples(st.integers(0, 200), st.integers(0, 15),
                        st.sampled_from(["nan", "inf", "-1e300", "", "x", "1e-320", "7"]))),
    st.tuples(st.just("json"), st.sampled_from([f for f in RUN_FILES if f.endswith(".json")]),
              st.tuples(st.sampled_from(["trial", "status", "epos_m", "algorithm", "n_samples",
                                         "t_ilc_s", "profile", "extra", "reason"]), BAD_VALUES)),
)  # fmt: skip


def _damage(run: Path, action: tuple) -> None:
    kind, what, how = action
    if kind in ("truncate", "delete", "swap", "cell", "json") and not (run / what).is_file():
        return  # gone already (an earlier action deleted or swapped it away)
    if kind == "swap" and not (run / how).is_file():
        return
    if kind == "truncate":
        data = (run / what).read_bytes()
        (run / what).write_bytes(data[: int(len(data) * how)])
    elif kind == "delete":
        (run / what).unlink()
    elif kind == "swap" and what != how:
        (run / what).rename(run / ".swap")
        (run / how).rename(run / what)
        (run / ".swap").rename(run / how)
    elif kind == "extra":
        name, text = what
        if text is None:
            (run / name).mkdir(exist_ok=True)
        else:
            (run / name).write_text(text)
    elif kind == "cell":
        row, col, value = how
        lines = (run / what).read_text().splitlines()
        if len(lines) > 1:
            r = 1 + row % (len(lines) - 1)
            cells = lines[r].split(",")
            cells[col % len(cells)] = value
            lines[r] = ",".join(cells)
            (run / what).write_text("\n".join(lines) + "\n")
    elif kind == "json":
        key, value = how
        try:
            data = json.loads((run / what).read_text())
        except ValueError:
            return  # truncated already
        if not isinstance(data, dict):
            return
        if isinstance(value, float) and not math.isfinite(value):
            value = str(value)  # strict JSON has no NaN; a string is a wrong type too
        data[key] = value
        (run / what).write_text(json.dumps(data))


@pytest.fixture(scope="module")
def learning_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return Templates(tmp_path_factory.mktemp("fuzz")).get("learning")


def _unchanged_except_new(before: dict, after: dict, allowed: set[str]) -> None:
    for key, value in before.items():
        assert after.get(key) == value, f"{key} changed or vanished"
    new = set(after) - set(before)
    assert new <= allowed, new


@FUZZ
@given(actions=st.lists(damage, min_size=1, max_size=2))
# found by a run of make test-fast: learn wrote estimate-001.csv, then refused the damaged
# estimate-000.csv it read for the trial's prediction (now read before anything is written)
@example(
    actions=[("delete", "estimate-001.csv", None), ("cell", "estimate-000.csv", (0, 0, "nan"))]
)
def test_damaged_run_directories_are_reported_learned_resumed_or_refused(
    learning_run: Path, actions: list
) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        ws = Path(tmp)
        run = ws / "run"
        shutil.copytree(learning_run, run)
        for action in actions:
            _damage(run, action)
        before = snapshot(ws)
        result = _invoke(ws, ["report", "run", "--json"])
        _one_line_or_success(result, '"iteration": 0')
        assert snapshot(ws) == before
        argv = ["fly", "--connect", UNREACHABLE, "--resume", "run", "--check", "--offline"]
        result = _invoke(ws, argv)
        _one_line_or_success(result, "checked: profile")
        assert snapshot(ws) == before
        result = _invoke(ws, ["learn", "run"])
        _one_line_or_success(result, "learned from trial")
        # learning may add the next estimate and setpoints, never change what was there
        allowed = {f"run/{k}-{j:03d}.csv" for k in ("estimate", "setpoints") for j in range(9)}
        _unchanged_except_new(before, snapshot(ws), allowed if result.exit_code == 0 else set())
