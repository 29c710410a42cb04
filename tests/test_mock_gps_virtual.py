"""The mock-gps profile on the virtual clock: the flights of tests/test_mock_gps_e2e.py in-process.

The same commands, settings and checks against the simulated drone (tests/virtual.py) instead
of the mock process over UDP; ``--mock`` starts a simulated drone of the same settings and seed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from synthetic import CI_FLIGHT
from virtual import run_gcs

from gcs.io.rundir import RunDir
from gcs.io.settings import FlightSettings
from gcs.mock.config import load_mock_config
from gcs.sim.drone import SimulatedDrone

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e


ROOT = Path(__file__).resolve().parents[1]


def gps_ci_profile(tmp: Path) -> Path:
    """profiles/antx.yaml with the CI watchdog limits, but the default 10 s hover measurement:
    GPS wander has correlation times of seconds, which a 2 s measurement cannot see."""
    data = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    limits = {k: v for k, v in CI_FLIGHT.items() if k != "hover_measure_s"}
    data["flight"] = dict(data.get("flight") or {}, **limits)
    path = tmp / "antx-gps-ci.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_fly_mock_gps_settles_on_the_measured_hover_and_learns(tmp_path: Path) -> None:
    run_path = tmp_path / "run"
    mock_gps = ROOT / "profiles" / "mock-gps.yaml"
    with SimulatedDrone(load_mock_config(mock_gps), seed=1) as mock:
        short = ROOT / "trajectories" / "eight-short.yaml"
        options = ["--iter", 2, "--trajectory", short, "--profile", gps_ci_profile(tmp_path)]
        code, out = run_gcs(*("fly", "--connect", mock.url, "--run", run_path, *options))
    assert code == 0, out
    assert "landed and disarmed" in out
    assert "navigation: GPS (EKF2_GPS_CTRL 7 (position, altitude, velocity)" in out, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1]
    # learning used both trials and wrote the next trial's setpoints
    assert (run_path / "estimate-001.csv").exists() and (run_path / "setpoints-002.csv").exists()

    (session,) = run.sessions()
    assert session["navigation"]["source"] == "GPS"
    first = session["hovers"][0]
    assert first["why"] == "measurement" and first["verdict"]["ok"], first
    measured = first["stats"]
    assert measured["duration_s"] > 9.5
    # the tolerances came from the measured hover, decimetres wide, not the indoor 5 cm floor
    floor = FlightSettings().settle_tolerance_m
    assert first["verdict"]["tolerance_m"] == pytest.approx(measured["distance_p50_m"])
    assert session["tolerance_m"] >= first["verdict"]["tolerance_m"] > 2 * floor
    assert f"settle tolerances: {first['verdict']['tolerance_m']:.2f} m" in out, out

    # what gcs recorded is the estimate: the mock's truth plus its estimator error
    truth = mock.stats()["estimator"]
    t_truth = np.array(truth["t_vehicle_s"])
    for j in (0, 1):
        record = run.read_trial(j)
        t = run.read_status(j).extra["t0_vehicle_s"] + record.t_s

        def at_t(*keys: str, t: np.ndarray = t) -> np.ndarray:
            return np.column_stack([np.interp(t, t_truth, truth[k]) for k in keys])

        true, err = at_t("north_m", "east_m"), at_t("err_north_m", "err_east_m")
        reported = record.pos_ned_m[:, :2]
        assert np.sqrt(np.mean((reported - (true + err)) ** 2)) < 0.03, j
        assert np.sqrt(np.mean(np.sum((reported - true) ** 2, axis=1))) > 0.03, j
