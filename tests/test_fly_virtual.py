"""``gcs fly`` on the virtual clock: the bookkeeping of tests/test_fly_e2e.py in seconds.

The same flights as the e2e tests (the CI profile, the tiny trajectory, the mock's faults),
run in-process against the simulated drone (tests/virtual.py); the wire itself (MAVSDK over
UDP to the mock process) keeps its own tests in tests/test_fly_e2e.py.
"""

from __future__ import annotations

import asyncio
import json
import signal

import numpy as np
import pytest
import yaml
from synthetic import CI_FLIGHT, SHORT, ci_profile
from virtual import ctrl_c, on_trial, run_gcs

from gcs.io.rundir import RunDir
from gcs.mock.config import Faults, load_mock_config
from gcs.sim.drone import SimulatedDrone

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e


def arrivals_on_the_vehicle_clock(stats: dict, setpoints: np.ndarray, t0_vehicle_s: float):
    """(k, vehicle time of the first arrival of setpoint k - t0) for every change of setpoint."""
    sp = stats["setpoints"]
    t = np.array(sp["t_rx_vehicle_s"])
    ne = np.column_stack([sp["north_m"], sp["east_m"]])
    ks, times = [], []
    i = int(np.searchsorted(t, t0_vehicle_s - 0.1))
    for k in range(1, len(setpoints)):
        if np.allclose(setpoints[k, :2], setpoints[k - 1, :2], atol=1e-6):
            continue  # the same value again: no arrival marks its start
        match = np.flatnonzero(np.all(np.abs(ne[i:] - setpoints[k, :2]) < 1e-5, axis=1))
        assert match.size, k
        i += int(match[0])
        ks.append(k)
        times.append(t[i] - t0_vehicle_s)
    return np.array(ks), np.array(times)


@pytest.fixture
def tiny(tmp_path):  # type: ignore[no-untyped-def]
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(SHORT))
    return path


def fly(drone: SimulatedDrone, tmp, trajectory, run, *extra: object) -> tuple[int, str]:  # type: ignore[no-untyped-def]
    return run_gcs(
        "fly", "--connect", drone.url, "--iter", 2, "--trajectory", trajectory, "--run", run,
        "--profile", ci_profile(tmp), *extra,
    )  # fmt: skip


def test_fly_on_a_slow_simulator_streams_records_and_learns_on_the_vehicle_clock(
    tmp_path, tiny
) -> None:
    run_path = tmp_path / "run"
    with SimulatedDrone(faults=Faults(clock_rate=0.9), seed=0) as drone:
        code, out = fly(drone, tmp_path, tiny, run_path)
    assert code == 0, out
    assert "landed and disarmed" in out
    assert "warning: NAV_DLL_ACT = 0 (disabled)" in out, out
    assert "navigation: GPS (EKF2_GPS_CTRL 7 (position, altitude, velocity)" in out, out
    assert "hover at the start point: " in out and "settle tolerances: " in out, out
    for j in (0, 1):
        assert f"trial {j} flown: vehicle clock 0.90" in out, out
        assert f"warning: trial {j}: the vehicle's clock ran at 0.900x wall time" in out, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1]
    (session,) = run.sessions()
    assert session["hovers"][0]["verdict"]["ok"] and session["navigation"]["source"] == "GPS"
    assert session["hovers"][0]["clock_rate"] == pytest.approx(0.9, abs=0.002)
    stats = drone.stats()
    assert stats["clock_rate"] == 0.9
    for j in (0, 1):
        extra = run.read_status(j).extra
        assert extra["vehicle_time_rate"] == pytest.approx(0.9, abs=0.002) and extra["session"] == 1
        assert 0.0 <= extra["max_sent_offset_s"] < CI_FLIGHT["max_setpoint_late_s"]
        # setpoint k reached the vehicle at t0 + k t_ilc_s on its own clock, not 0.9 t_ilc_s
        ks, arrived = arrivals_on_the_vehicle_clock(
            stats, run.read_setpoints(j), extra["t0_vehicle_s"]
        )
        assert ks.size > 50
        slope, intercept = np.polyfit(ks, arrived, 1)
        assert slope == pytest.approx(run.t_ilc_s, rel=0.005), slope
        assert abs(intercept) < 0.01 and np.median(np.abs(arrived - ks * run.t_ilc_s)) < 0.005
        record = run.read_trial(j)  # the recorded send times, on the same grid
        assert np.median(np.abs(record.sp_sent_s[:-1] - record.t_s[:-1])) < 0.005
    # learning used both trials
    assert (run_path / "setpoints-002.csv").exists() and (run_path / "estimate-001.csv").exists()
    code, out = run_gcs("report", run_path, "--json")
    assert code == 0, out
    rows = json.loads(out)["rows"]
    assert [r["iteration"] for r in rows] == [0, 1]
    assert rows[1]["epos_m"] < 0.6 * rows[0]["epos_m"], rows
    assert rows[1]["vehicle_time_rate"] == pytest.approx(0.9, abs=0.002)


def test_ctrl_c_mid_trial_lands_marks_incomplete_and_resume_continues(
    tmp_path, tiny, monkeypatch
) -> None:
    run_path = tmp_path / "run"
    with SimulatedDrone(seed=1) as drone:
        on_trial(monkeypatch, 1, ctrl_c)
        code, out = fly(drone, tmp_path, tiny, run_path)
        assert code == 130, out
        assert "landed and disarmed" in out, out
        run = RunDir.open(run_path)
        assert run.complete_trials() == [0]
        status = run.read_status(1)
        assert not status.complete and "interrupt" in status.reason
        assert run.read_status(0).complete  # completed trial kept intact
        monkeypatch.undo()
        # the resumed run flies with the profile recorded in it
        code, out = run_gcs("fly", "--connect", drone.url, "--resume", run_path, "--iter", 1)
        assert code == 0, out
        assert drone.connections == 2
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1]
    assert (run_path / "aborted" / "trial-001-attempt-1.json").exists()
    assert drone.stats()["modes"][-1]["armed"] is False


def test_a_second_flight_on_the_same_vehicle_arms_after_a_complete_one(tmp_path, tiny) -> None:
    """PX4 returns to the last mode it was put in that allows arming when it disarms: after a
    complete flight (offboard, land, disarm) the vehicle sits disarmed in OFFBOARD, where it
    cannot arm without a setpoint stream. The next command on it (here a ``--resume``; ``gcs
    fly`` after ``gcs identify`` alike) switches it to Hold first, and flies."""
    run_path = tmp_path / "run"
    with SimulatedDrone(seed=1) as drone:
        code, out = fly(drone, tmp_path, tiny, run_path)
        assert code == 0, out
        assert "switched to Hold" not in out  # a vehicle fresh from boot is in Hold already
        last = drone.stats()["modes"][-1]
        assert (last["mode"], last["armed"]) == ("OFFBOARD", False)  # PX4's mode after disarm
        drone.advance(drone.vehicle.t_s + 10.0)  # the operator types the next command
        code, out = run_gcs("fly", "--connect", drone.url, "--resume", run_path, "--iter", 1)
        assert code == 0, out
        assert "switched to Hold" in out
        modes = drone.stats()["modes"]
    assert RunDir.open(run_path).complete_trials() == [0, 1, 2]
    armings = [i for i in range(1, len(modes)) if modes[i]["armed"] and not modes[i - 1]["armed"]]
    assert len(armings) == 2, modes
    assert modes[armings[1] - 1]["mode"] == "HOLD", modes  # armed from Hold, not from OFFBOARD


def test_more_ctrl_c_while_stopping_cannot_leave_the_vehicle_in_the_air(
    tmp_path, tiny, monkeypatch
) -> None:

    # an operator who finds the landing slow presses Ctrl-C again, then sends SIGTERM
    from gcs.flight.vehicle import Vehicle

    stop = Vehicle.emergency_stop

    async def impatient(self, reason):  # type: ignore[no-untyped-def]
        ctrl_c()
        import os

        os.kill(os.getpid(), signal.SIGTERM)
        return await stop(self, reason)

    monkeypatch.setattr(Vehicle, "emergency_stop", impatient)
    run_path = tmp_path / "run"
    with SimulatedDrone(seed=3) as drone:
        on_trial(monkeypatch, 0, ctrl_c)
        code, out = run_gcs(
            "fly", "--connect", drone.url, "--iter", 1, "--trajectory", tiny, "--run", run_path,
            "--profile", ci_profile(tmp_path),
        )  # fmt: skip
    assert code == 130, out
    assert "interrupt 2 ignored" in out and "interrupt 3 ignored" in out, out
    assert "emergency stop: landed and disarmed" in out, out
    status = RunDir.open(run_path).read_status(0)  # the partial trial is still recorded
    assert not status.complete and "interrupt" in status.reason
    assert drone.stats()["modes"][-1]["armed"] is False


def test_low_battery_before_a_trial_lands_and_keeps_the_run_resumable(tmp_path, tiny) -> None:
    # a battery that drains 3 %/s armed: ~75 % when trial 0 starts, ~50 % before trial 1
    profile = yaml.safe_load(ci_profile(tmp_path).read_text())
    profile["flight"]["min_battery_pct"] = 60
    profile_path = tmp_path / "low-battery.yaml"
    profile_path.write_text(yaml.safe_dump(profile))
    mock_config = tmp_path / "mock.yaml"
    mock_config.write_text("px4:\n  battery_drain_pct_s: 3.0\n")
    run_path = tmp_path / "run"
    with SimulatedDrone(load_mock_config(mock_config), seed=4) as drone:
        code, out = run_gcs(
            "fly", "--connect", drone.url, "--iter", 2, "--trajectory", tiny, "--run", run_path,
            "--profile", profile_path,
        )  # fmt: skip
    assert code == 2, out
    assert "before trial 1, below flight.min_battery_pct (60 %)" in out, out
    assert "landed and disarmed" in out, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0]
    assert not (run_path / "trial-001.json").exists()  # never started: nothing to mark
    assert run.next_trial() == 1 and (run_path / "setpoints-001.csv").exists()
    assert drone.stats()["modes"][-1]["armed"] is False


def test_link_loss_mid_trial_aborts_lands_and_keeps_logs(tmp_path, tiny, monkeypatch) -> None:
    run_path = tmp_path / "run"
    with SimulatedDrone(faults=Faults(link_loss_duration_s=2.0), seed=2) as drone:
        on_trial(monkeypatch, 0, drone.lose_link, after_s=0.0)
        code, out = fly(drone, tmp_path, tiny, run_path)
    assert code == 2, out
    assert "landed and disarmed" in out, out
    run = RunDir.open(run_path)
    status = run.read_status(0)
    assert not status.complete and ("link" in status.reason or "telemetry" in status.reason)
    assert run.complete_trials() == []
    stats = drone.stats()
    assert stats["modes"][-1]["armed"] is False
    assert stats["faults"]["link_loss_at_s"] is not None and stats["faults"]["link_loss_at_s"] > 0


def test_a_trial_gcs_fell_behind_in_is_kept_flown_again_and_the_run_completes(
    tmp_path, tiny, monkeypatch
) -> None:
    run_path = tmp_path / "run"

    def machine_pause() -> None:  # the machine left gcs unscheduled for 0.6 s
        asyncio.get_running_loop().advance(0.6)  # type: ignore[attr-defined]

    with SimulatedDrone(seed=1) as drone:
        on_trial(monkeypatch, 1, machine_pause)
        code, out = fly(drone, tmp_path, tiny, run_path)
    assert code == 0, out
    limit_ms = CI_FLIGHT["max_setpoint_late_s"] * 1e3
    assert f"ms late (limit {limit_ms:.0f} ms): gcs fell behind its stream" in out, out
    assert "flying trial 1 again (1 of 2)" in out, out
    assert out.count("trial 1 started") == 2, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1]
    kept = json.loads((run_path / "aborted" / "trial-001-attempt-1.json").read_text())
    assert kept["status"] == "incomplete" and "late" in kept["reason"]
    assert drone.stats()["modes"][-1]["armed"] is False
    code, out = run_gcs("report", run_path, "--json")
    assert code == 0, out
    assert [row["trial"] for row in json.loads(out)["rows"]] == [0, 1]
