"""End to end: ``gcs identify --mock`` on the mock-gps profile (a GPS-navigated vehicle)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from synthetic import CI_FLIGHT

from gcs.core.model import dc_gain
from gcs.io.config import load_profile
from gcs.io.rundir import RunDir

pytestmark = pytest.mark.e2e
ROOT = Path(__file__).resolve().parents[1]
TIMEOUT_S = 150


def test_identify_mock_gps_settles_on_the_measured_hover_and_writes_a_profile(
    tmp_path: Path,
) -> None:
    data = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    limits = {k: v for k, v in CI_FLIGHT.items() if k != "hover_measure_s"}  # GPS: measure 10 s
    data["flight"] = dict(data.get("flight") or {}, **limits)
    data["identification"]["duration_s"] = 15.0  # two 15 s experiments (the least: 11.5 s)
    profile_path = tmp_path / "short.yaml"
    profile_path.write_text(yaml.safe_dump(data))
    out, run_path = tmp_path / "identified.yaml", tmp_path / "ident"
    proc = subprocess.run(
        [sys.executable, "-m", "gcs", "identify", "--mock", "--profile", profile_path,
         "--mock-config", ROOT / "profiles" / "mock-gps.yaml", "--run", run_path, "--out", out],
        cwd=ROOT, capture_output=True, text=True, timeout=TIMEOUT_S,
        env={**os.environ, "COLUMNS": "200", "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0, text
    assert "navigation: GPS (EKF2_GPS_CTRL 7" in text and "landed and disarmed" in text
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1]
    (session,) = run.sessions()
    first = session["hovers"][0]
    assert first["verdict"]["ok"] and first["stats"]["duration_s"] > 9.5
    assert first["verdict"]["tolerance_m"] == pytest.approx(first["stats"]["distance_p50_m"])
    assert first["verdict"]["tolerance_m"] > 0.1
    # 15 s under decimetres of wander identify little (the 60 s default: docs/mock.md), but the
    # written profile loads (stable models) and each loop passes a step, not amplified twice
    for axis, model in enumerate(load_profile(out).models()):
        assert 0.0 < dc_gain(model) < 2.0, (axis, dc_gain(model))
