"""Learning on recorded runs, as the command line does it: the cases of the regression record.

Each case builds a run directory (synthetic trials of :mod:`synthetic`, or a PX4 SITL run of
``shared/data/px4-sitl/`` replayed trial by trial) and learns between its trials with
``gcs learn``'s function; :func:`learned` returns every learned file's arrays. The record
``tests/data/learning-regression.npz`` holds them as computed by the code before the public
learning API existed; ``tests/test_learning_regression.py`` asserts that the code of today
computes them bit for bit. ``python tests/learning_cases.py`` writes the record again (only
ever from a version whose learning is known to be the reference). The cases of
profiles/antx-adaptive.yaml state their ``repeats`` (the record's trial plan), so that a change
of the profile's default does not change what they learn; ``adaptive``, ``auto`` and ``table1``
learn with the profile's refresh as recorded (:func:`_as_recorded`), and ``anchor`` with the
profile as shipped.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import yaml
from px4_data import shared
from synthetic import (
    SHORT,
    adaptive_profile,
    fly_synthetic,
    make_adaptive_run,
    make_run,
    profile,
)

from gcs.core.metrics import epos, max_error
from gcs.io.config import load_profile, profile_from_dict, trajectory_from_dict
from gcs.io.records import TrialStatus
from gcs.io.rundir import RunDir

ROOT = Path(__file__).resolve().parent
RECORD = ROOT / "data" / "learning-regression.npz"
PX4_RUNS = ("eq11-learn", "vision-identified-learn")


def _learn(run: RunDir) -> None:
    from gcs.app.learn import learn_run

    learn_run(run)


def _arrays(run: RunDir, prefix: str) -> dict[str, np.ndarray]:
    """Every learned file of ``run``: setpoints, estimates, decision records, models."""
    out: dict[str, np.ndarray] = {}
    for path in sorted(run.path.iterdir()):
        name = path.name
        if name.startswith("setpoints-") and name != "setpoints-000.csv":
            out[f"{prefix}/{name}"] = run.read_setpoints(int(name[10:13]))
        elif name.startswith("estimate-"):
            d_hat, p = run.read_estimate(int(name[9:12]))
            out[f"{prefix}/{name}"] = np.stack([d_hat, p])
        elif name.startswith(("learn-", "model-", "floor")):
            # the run's creation time is in a refreshed model's description
            text = path.read_text().replace(str(run.manifest["created_utc"]), "<created>")
            out[f"{prefix}/{name}"] = np.array(text)
    return out


def _as_recorded(data: dict) -> dict:
    """profiles/antx-adaptive.yaml's ``data`` with the refresh the record was learnt with:
    consecutive pairs (no ``refresh_anchor``) and the take-back on, as shipped until
    2026-12-07; the rest (and the text of a profile written from it) as shipped."""
    adaptive = data["learning"]["adaptive"]
    adaptive.pop("refresh_anchor", None)
    adaptive["refresh_takeback"] = True
    return data


def _profile_file(tmp: Path, base: Path, name: str, **adaptive: object) -> Path:
    data = _as_recorded(yaml.safe_load(base.read_text()))
    data["learning"]["adaptive"].update(adaptive)
    path = tmp / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _with_mocap(run: RunDir, j: int, offset_m: float) -> None:
    """Trial j flown (synthetic) and recorded with a mocap that sees it ``offset_m`` north."""
    record = fly_synthetic(run, j)
    (run.path / f"trial-{j:03d}.json").unlink()
    (run.path / f"trial-{j:03d}.csv").unlink()
    mocap = record.pos_ned_m + np.array([offset_m, 0.01 * j, 0.0])
    record = dataclasses.replace(record, mocap_ned_m=mocap)
    m = record.measured("mocap")
    ref, pos = m.ref_ned_m[1:, :2], m.pos_ned_m[1:, :2]
    run.write_trial(j, record, TrialStatus(j, True, epos_m=epos(ref, pos),
                                           max_err_m=max_error(ref, pos)))  # fmt: skip


def _px4_replay(tmp: Path, name: str) -> RunDir:
    """The PX4 run ``name`` learnt again trial by trial: its trials and nothing learned."""
    src = shared() / "data" / "px4-sitl" / name
    dst = tmp / name
    dst.mkdir()
    for f in ("manifest.json", "reference.csv", "setpoints-000.csv"):
        shutil.copy(src / f, dst / f)
    run = RunDir.open(dst)
    trials = sorted(int(p.name[6:9]) for p in src.glob("trial-*.json"))
    for j in trials:
        for f in (f"trial-{j:03d}.csv", f"trial-{j:03d}.json"):
            shutil.copy(src / f, dst / f)
        _learn(run)
        if j != trials[-1]:  # the next trial flew the setpoints the run recorded
            shutil.copy(src / f"setpoints-{j + 1:03d}.csv", dst / f"setpoints-{j + 1:03d}.csv")
    return run


def _fresh(tmp: Path, name: str) -> Path:
    path = tmp / name
    path.mkdir()
    return path


def _smoother(tmp: Path) -> dict[str, np.ndarray]:
    return _arrays(make_run(_fresh(tmp, "smoother"), "smoother", trials=5), "smoother")


def _kilc(tmp: Path) -> dict[str, np.ndarray]:
    return _arrays(make_run(_fresh(tmp, "kilc"), "kilc", trials=5), "kilc")


def _adaptive(tmp: Path) -> dict[str, np.ndarray]:
    data = _as_recorded(yaml.safe_load(ADAPTIVE.read_text()))
    data["learning"]["adaptive"]["repeats"] = 1
    prof = profile_from_dict(data, str(ADAPTIVE))
    run = make_adaptive_run(_fresh(tmp, "adaptive"), trials=6, gust_m=0.01, prof=prof)
    return _arrays(run, "adaptive")


def _anchor(tmp: Path) -> dict[str, np.ndarray]:
    """The ``adaptive`` case's trials with the profile as shipped (pairs against trial 0)."""
    run = make_adaptive_run(_fresh(tmp, "anchor"), trials=6, gust_m=0.01, repeats=1)
    return _arrays(run, "anchor")


def _auto(tmp: Path) -> dict[str, np.ndarray]:
    prof = load_profile(_profile_file(tmp, ADAPTIVE, "auto", robustness_cutoff_rad_s="auto",
                                      repeats=2))  # fmt: skip
    run = make_adaptive_run(_fresh(tmp, "auto"), 7, seed=3, gust_m=0.005, prof=prof)
    return _arrays(run, "auto")


def _table1(tmp: Path) -> dict[str, np.ndarray]:
    prof = load_profile(_profile_file(tmp, ADAPTIVE, "table1", noise="table1", refresh=False,
                                      repeats=1))  # fmt: skip
    return _arrays(make_adaptive_run(_fresh(tmp, "table1"), 5, seed=5, prof=prof), "table1")


def _mocap(tmp: Path) -> dict[str, np.ndarray]:
    run = RunDir.create(_fresh(tmp, "mocap"), profile(), trajectory_from_dict(SHORT), "smoother",
                        run_id="run")  # fmt: skip
    for j in range(4):
        _with_mocap(run, j, 0.02)
        _learn(run)
    return _arrays(run, "mocap")


def _px4(name: str) -> Callable[[Path], dict[str, np.ndarray]]:
    def build(tmp: Path) -> dict[str, np.ndarray]:
        return _arrays(_px4_replay(_fresh(tmp, f"px4-{name}"), name), f"px4-{name}")

    return build


ADAPTIVE = ROOT.parent / "profiles" / "antx-adaptive.yaml"
#: every case by the prefix of its arrays' keys; each builds its runs in a directory of its own
CASES: dict[str, Callable[[Path], dict[str, np.ndarray]]] = {
    "smoother": _smoother, "kilc": _kilc, "adaptive": _adaptive, "anchor": _anchor,
    "auto": _auto, "table1": _table1, "mocap": _mocap,
    **{f"px4-{name}": _px4(name) for name in PX4_RUNS},
}  # fmt: skip


def learned_case(name: str) -> dict[str, np.ndarray]:
    """The learned arrays of the case ``name`` (a key of ``CASES``), by ``case/file``."""
    with tempfile.TemporaryDirectory() as tmp_str:
        return CASES[name](Path(tmp_str))


def learned() -> dict[str, np.ndarray]:
    """Every case's learned arrays, by ``case/file``."""
    out: dict[str, np.ndarray] = {}
    for name in CASES:
        out |= learned_case(name)
    assert adaptive_profile().learning.adaptive is not None
    return out


def main() -> None:
    arrays = learned()
    RECORD.parent.mkdir(exist_ok=True)
    np.savez_compressed(RECORD, **arrays)
    print(json.dumps({"record": str(RECORD), "arrays": len(arrays),
                      "bytes": RECORD.stat().st_size}))  # fmt: skip


if __name__ == "__main__":
    main()
