"""``gcs identify`` on mock-gps on the virtual clock:
the flights of tests/test_mock_gps_identify_e2e.py in-process.

The same commands, settings and checks against the simulated drone (tests/virtual.py) instead
of the mock process over UDP; ``--mock`` starts a simulated drone of the same settings and seed.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from synthetic import CI_FLIGHT
from virtual import run_gcs, sim_mock

from gcs.core.model import dc_gain
from gcs.io.config import load_profile
from gcs.io.rundir import RunDir

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT_S = 150


def test_identify_mock_gps_settles_on_the_measured_hover_and_writes_a_profile(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:

    sim_mock(monkeypatch)
    data = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    limits = {k: v for k, v in CI_FLIGHT.items() if k != "hover_measure_s"}  # GPS: measure 10 s
    data["flight"] = dict(data.get("flight") or {}, **limits)
    data["identification"]["duration_s"] = 15.0  # two 15 s experiments (the least: 11.5 s)
    profile_path = tmp_path / "short.yaml"
    profile_path.write_text(yaml.safe_dump(data))
    out, run_path = tmp_path / "identified.yaml", tmp_path / "ident"
    code, text = run_gcs(
        "identify", "--mock", "--profile", profile_path,
         "--mock-config", ROOT / "profiles" / "mock-gps.yaml", "--run", run_path, "--out", out,
    )  # fmt: skip
    assert code == 0, text
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
