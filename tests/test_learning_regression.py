"""The learning of ``gcs learn`` / ``gcs fly`` and ``gcs montecarlo``'s tables, bit for bit as
recorded (``tests/data/``) with the code before the public learning API existed.

The learning record holds every learned file of the cases of :mod:`learning_cases`: synthetic
runs (smoother, K-ILC, mocap measurement, learning with history: floor, noise from the data,
refresh, safeguard, robustness "auto", Table I noise) and two PX4 SITL runs learnt again trial by
trial. The Monte Carlo records are ``gcs montecarlo --json`` of the default study, of a smaller
one and of a small ``--adaptive`` comparison.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from learning_cases import RECORD, learned
from typer.testing import CliRunner

from gcs.cli import app

DATA = Path(__file__).resolve().parent / "data"


def test_learned_files_are_those_recorded_bit_for_bit() -> None:
    recorded = np.load(RECORD)
    now = learned()
    assert sorted(now) == sorted(recorded.files)
    differ = [k for k in recorded.files if not np.array_equal(now[k], recorded[k])]
    assert differ == []


def _without_seconds(doc: object) -> object:
    if isinstance(doc, dict):
        return {k: _without_seconds(v) for k, v in doc.items() if k != "seconds"}
    if isinstance(doc, list):
        return [_without_seconds(v) for v in doc]
    return doc


@pytest.mark.parametrize(
    ("record", "args"),
    [
        ("montecarlo-small.json", ["--plants", "20", "--repeats", "2"]),
        ("montecarlo-adaptive-small.json",
         ["--levels", "0.05,0.4", "--plants", "10", "--repeats", "2", "--adaptive"]),
    ],
)  # fmt: skip
def test_montecarlo_tables_are_those_recorded(tmp_path: Path, record: str, args: list) -> None:
    out = tmp_path / "mc.json"
    result = CliRunner().invoke(app, ["montecarlo", *args, "--json", str(out)])
    assert result.exit_code == 0, result.output
    now = _without_seconds(json.loads(out.read_text()))
    assert now == _without_seconds(json.loads((DATA / record).read_text()))
