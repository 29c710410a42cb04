"""The trajectory sources on the virtual clock:
the flights of tests/test_trajectory_e2e.py in-process.

The same commands, settings and checks against the simulated drone (tests/virtual.py) instead
of the mock process over UDP; ``--mock`` starts a simulated drone of the same settings and seed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from synthetic import ci_profile
from virtual import fly_two_trials, run_gcs

from gcs.core.trajectory_sources import SamplesShape, sample_samples
from gcs.io.rundir import RunDir
from gcs.io.samples_file import read_samples
from gcs.mock.config import load_mock_config
from gcs.sim.drone import SimulatedDrone

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e

#: A short climbing triangle: 0.5 m of altitude gained on the way round (about 5 s of motion).
TRIANGLE = {
    "name": "triangle",
    "type": "waypoints",
    "points_ned_m": [[0.0, 0.0, -1.5], [1.0, 0.0, -1.5], [1.0, 1.0, -2.0], [0.0, 0.0, -1.5]],
    "speed_m_s": 1.0,
    "hover_s": 0.5,
}


def test_a_three_dimensional_waypoints_trajectory_learns_and_flies_down_as_the_reference(
    tmp_path: Path,
) -> None:

    trajectory = tmp_path / "triangle.yaml"
    trajectory.write_text(yaml.safe_dump(TRIANGLE))
    run_path = tmp_path / "run"
    with SimulatedDrone(load_mock_config(None), seed=0) as mock:
        code, out = fly_two_trials(tmp_path, trajectory, run_path, "--connect", mock.url)
    assert code == 0, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1]
    ref = run.reference()
    assert np.ptp(ref.pos_ned_m[:, 2]) > 0.45  # a 3-D reference (the spline passes -2.0 m)
    for j in (0, 1):
        record = run.read_trial(j)
        # down is flown as the reference: every down setpoint is the reference's
        np.testing.assert_allclose(record.sp_ned_m[:-1, 2], ref.pos_ned_m[:-1, 2], atol=1e-9)
        # and the vehicle followed it: it climbed and came back
        assert np.ptp(record.pos_ned_m[:, 2]) > 0.3
        assert abs(record.pos_ned_m[-1, 2] - ref.pos_ned_m[-1, 2]) < 0.15
    code, report = run_gcs(*("report", run_path, "--json"))
    assert code == 0, report
    rows = json.loads(report)["rows"]
    assert [r["iteration"] for r in rows] == [0, 1]
    assert rows[1]["epos_m"] < rows[0]["epos_m"], rows


def test_a_samples_csv_is_flown_as_the_file_resampled_to_the_grid(tmp_path: Path) -> None:
    # a planner's output at 40 Hz (not the 20 Hz ILC grid): out 0.8 m east and back, 1.5 m up,
    # turning to face east (90 deg) on the way out and back to north
    t = np.arange(161) / 40.0
    east = 0.4 * (1.0 - np.cos(2.0 * np.pi * t / 4.0))
    yaw = 45.0 * (1.0 - np.cos(2.0 * np.pi * t / 4.0))  # at most 71 deg/s
    lines = ["t_s,north_m,east_m,down_m,yaw_deg"]
    lines += [f"{a:.3f},0.0,{e:.6f},-1.5,{y:.4f}" for a, e, y in zip(t, east, yaw, strict=True)]
    (tmp_path / "planner.csv").write_text("\n".join(lines) + "\n")
    trajectory = tmp_path / "planner.yaml"
    trajectory.write_text(
        yaml.safe_dump({"name": "planner", "type": "samples", "file": "planner.csv"})
    )
    run_path = tmp_path / "run"
    with SimulatedDrone(load_mock_config(None), seed=0) as mock:
        code, out = run_gcs(
            *(
                "fly",
                "--connect",
                mock.url,
                "--iter",
                1,
                "--trajectory",
                trajectory,
                "--run",
                run_path,
                "--profile",
                ci_profile(tmp_path),
            )  # fmt: skip
        )
    assert code == 0, out
    run = RunDir.open(run_path)
    data = read_samples(tmp_path / "planner.csv")
    expected = sample_samples(
        SamplesShape(data.t_s, data.pos_ned_m, np.radians(data.yaw_deg)), run.t_ilc_s
    )
    record = run.read_trial(0)
    assert record.t_s.shape == expected.t_s.shape
    np.testing.assert_allclose(record.ref_ned_m, expected.pos_ned_m, atol=1e-3)
    np.testing.assert_allclose(record.sp_ned_m[:-1], expected.pos_ned_m[:-1], atol=1e-3)
    assert np.ptp(record.pos_ned_m[:, 1]) > 0.5  # the vehicle flew it
    # the yaw: recorded with the reference, and every setpoint reached the vehicle with its own
    np.testing.assert_allclose(run.reference().yaw_rad, expected.yaw_rad, atol=1e-6)
    sent = mock.stats()["setpoints"]
    got = np.column_stack([sent[k] for k in ("north_m", "east_m", "down_m", "yaw_rad")])
    for k in range(expected.n_samples):
        near = np.all(np.abs(got[:, :3] - record.sp_ned_m[k]) < 1e-4, axis=1)
        assert np.any(np.abs(got[near, 3] - expected.yaw_rad[k]) < 1e-4), k
    assert np.degrees(got[:, 3].max()) == pytest.approx(90.0, abs=0.5)
