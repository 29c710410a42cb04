"""The examples of ``examples/`` run and show what they claim (docs/api.md)."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from px4_data import shared
from synthetic import make_adaptive_run, make_run

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def example(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_learner_on_the_users_own_simulator_brings_e_pos_down() -> None:
    errors = example("own_simulator").main(trials=8, seed=1)
    assert len(errors) == 8
    assert errors[1] < 0.3 * errors[0]
    assert max(errors[4:]) < 0.05 * errors[0]  # down to the noise (5 mm per axis)
    assert errors[-1] > 0.005  # and not below it: the noise is not repeatable


@pytest.mark.parametrize("kind", ["smoother", "adaptive"])
def test_replaying_a_recorded_run_gives_its_setpoints(tmp_path: Path, kind: str, capsys) -> None:
    run = make_run(tmp_path, trials=4) if kind == "smoother" else make_adaptive_run(tmp_path, 5)
    assert example("replay_run").replay(run.path) <= 1e-9
    out = capsys.readouterr().out
    assert out.count("largest difference") == (3 if kind == "smoother" else 5)


def test_replaying_a_px4_sitl_run_gives_its_setpoints(tmp_path: Path) -> None:
    src = shared() / "data" / "px4-sitl" / "vision-identified-learn"
    run = tmp_path / "run"
    shutil.copytree(src, run, copy_function=shutil.copyfile)  # writable files
    run.chmod(0o755)
    assert example("replay_run").replay(run) <= 1e-9
    # a learner given other measurements learns other setpoints: the comparison can fail
    trial = run / "trial-002.csv"
    lines = trial.read_text().splitlines()
    cols = lines[0].split(",")
    k = cols.index("pos_north_m")
    row = lines[40].split(",")
    row[k] = f"{float(row[k]) + 0.05:.9g}"
    lines[40] = ",".join(row)
    trial.write_text("\n".join(lines) + "\n")
    assert 1e-6 < example("replay_run").replay(run) < np.inf
