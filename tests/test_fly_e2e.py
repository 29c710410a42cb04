"""End to end: ``gcs fly`` flies the mock drone through the real MAVSDK over UDP loopback."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from synthetic import CI_FLIGHT, SHORT, ci_profile

from gcs.io.rundir import RunDir
from gcs.mock.config import Faults
from gcs.mock.process import MockProcess

pytestmark = pytest.mark.e2e
ROOT = Path(__file__).resolve().parents[1]
FLIGHT_TIMEOUT_S = 180


def gcs(*args: object, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "gcs", *map(str, args)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "COLUMNS": "120", "PYTHONUNBUFFERED": "1"},
        **kwargs,
    )


def finish(proc: subprocess.Popen) -> tuple[int, str]:
    out, _ = proc.communicate(timeout=FLIGHT_TIMEOUT_S)
    return proc.returncode, out


def fly_two_trials(tmp: Path, trajectory: Path, run: Path, *vehicle: object) -> tuple[int, str]:
    """``gcs fly <vehicle> --iter 2`` on ``trajectory`` with the CI profile, run to the end."""
    return finish(
        gcs(
            "fly",
            *vehicle,
            "--iter",
            2,
            "--trajectory",
            trajectory,
            "--run",
            run,
            "--profile",
            ci_profile(tmp),
        )  # fmt: skip
    )


def wait_for_line(proc: subprocess.Popen, text: str) -> list[str]:
    """Read the process's output until a line contains ``text`` (the event we wait for)."""
    seen = []
    for line in proc.stdout:
        seen.append(line)
        if text in line:
            return seen
    raise AssertionError(f"'{text}' never printed; output:\n{''.join(seen)}")


def interrupted_flight(url: str, trajectory: Path, run: Path, iterations: int, at: str):
    """``gcs fly --connect url`` sent Ctrl-C once ``at`` is printed; the process, still running."""
    proc = gcs(
        "fly", "--connect", url, "--iter", iterations, "--trajectory", trajectory, "--run", run,
        "--profile", ci_profile(run.parent),
    )  # fmt: skip
    wait_for_line(proc, at)
    proc.send_signal(signal.SIGINT)
    return proc


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(SHORT))
    return path


def final_state(stats_path: Path) -> dict:
    stats = json.loads(stats_path.read_text())
    return stats["modes"][-1]


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


def test_fly_on_a_slow_simulator_streams_records_and_learns_on_the_vehicle_clock(
    tmp_path: Path, tiny: Path
) -> None:
    # the mock's clock at 0.9x wall time, like PX4 SITL in lockstep on a loaded machine
    run_path = tmp_path / "run"
    stats_path = tmp_path / "stats.json"
    with MockProcess(seed=0, faults=Faults(clock_rate=0.9), stats_path=stats_path) as mock:
        code, out = fly_two_trials(tmp_path, tiny, run_path, "--connect", mock.url)
    assert code == 0, out
    assert "landed and disarmed" in out
    # read from the mock over MAVLink's parameter protocol: PX4's defaults
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
    stats = json.loads(stats_path.read_text())
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
    code, out = finish(gcs("report", run_path, "--json"))
    assert code == 0, out
    rows = json.loads(out)["rows"]
    assert [r["iteration"] for r in rows] == [0, 1]
    assert rows[1]["epos_m"] < 0.6 * rows[0]["epos_m"], rows
    assert rows[1]["vehicle_time_rate"] == pytest.approx(0.9, abs=0.002)


def test_ctrl_c_mid_trial_lands_marks_incomplete_and_resume_continues(
    tmp_path: Path, tiny: Path
) -> None:
    run_path = tmp_path / "run"
    stats = tmp_path / "stats.json"
    with MockProcess(seed=1, stats_path=stats) as mock:
        proc = interrupted_flight(mock.url, tiny, run_path, 2, at="trial 1 started")
        code, out = finish(proc)
        assert code != 0, out
        assert "landed and disarmed" in out, out
        run = RunDir.open(run_path)
        assert run.complete_trials() == [0]
        status = run.read_status(1)
        assert not status.complete and "interrupt" in status.reason
        assert run.read_status(0).complete  # completed trial kept intact

        code, out = finish(
            gcs("fly", "--connect", mock.url, "--resume", run_path, "--iter", 1)
        )  # the resumed run flies with the profile recorded in it
        assert code == 0, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1]
    assert (run_path / "aborted" / "trial-001-attempt-1.json").exists()
    last = final_state(stats)
    assert last["armed"] is False


def test_more_ctrl_c_while_stopping_cannot_leave_the_vehicle_in_the_air(
    tmp_path: Path, tiny: Path
) -> None:
    # an operator who finds the landing slow presses Ctrl-C again, then sends SIGTERM
    run_path = tmp_path / "run"
    stats = tmp_path / "stats.json"
    with MockProcess(seed=3, stats_path=stats) as mock:
        proc = interrupted_flight(mock.url, tiny, run_path, 1, at="trial 0 started")
        wait_for_line(proc, "aborting")  # printed as the emergency stop begins
        proc.send_signal(signal.SIGINT)
        proc.send_signal(signal.SIGTERM)
        code, out = finish(proc)
    assert code == 130, out
    assert "interrupt 2 ignored" in out and "interrupt 3 ignored" in out, out
    assert "emergency stop: landed and disarmed" in out, out
    status = RunDir.open(run_path).read_status(0)  # the partial trial is still recorded
    assert not status.complete and "interrupt" in status.reason
    assert final_state(stats)["armed"] is False


def test_low_battery_before_a_trial_lands_and_keeps_the_run_resumable(
    tmp_path: Path, tiny: Path
) -> None:
    # a battery that drains 3 %/s armed: ~75 % when trial 0 starts, ~50 % before trial 1
    profile = yaml.safe_load(ci_profile(tmp_path).read_text())
    profile["flight"]["min_battery_pct"] = 60
    profile_path = tmp_path / "low-battery.yaml"
    profile_path.write_text(yaml.safe_dump(profile))
    mock_config = tmp_path / "mock.yaml"
    mock_config.write_text("px4:\n  battery_drain_pct_s: 3.0\n")
    run_path = tmp_path / "run"
    stats = tmp_path / "stats.json"
    with MockProcess(mock_config, seed=4, stats_path=stats) as mock:
        code, out = finish(
            gcs(
                "fly",
                "--connect",
                mock.url,
                "--iter",
                2,
                "--trajectory",
                tiny,
                "--run",
                run_path,
                "--profile",
                profile_path,
            )
        )
    assert code == 2, out
    assert "before trial 1, below flight.min_battery_pct (60 %)" in out, out
    assert "landed and disarmed" in out, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0]
    assert not (run_path / "trial-001.json").exists()  # never started: nothing to mark
    assert run.next_trial() == 1 and (run_path / "setpoints-001.csv").exists()
    assert final_state(stats)["armed"] is False


def test_link_loss_mid_trial_aborts_lands_and_keeps_logs(tmp_path: Path, tiny: Path) -> None:
    run_path = tmp_path / "run"
    stats = tmp_path / "stats.json"
    # the loss starts when gcs says trial 0 started (the mock's SIGUSR1): on a loaded machine
    # take-off and settling take longer than any fixed time after the first OFFBOARD
    faults = Faults(link_loss_duration_s=2.0)
    with MockProcess(seed=2, stats_path=stats, faults=faults) as mock:
        proc = gcs(
            "fly", "--connect", mock.url, "--iter", 2, "--trajectory", tiny, "--run", run_path,
            "--profile", ci_profile(tmp_path),
        )  # fmt: skip
        seen = []
        for line in proc.stdout:
            seen.append(line)
            if "trial 0 started" in line:
                mock.lose_link()
                break
        code, rest = finish(proc)
    out = "".join(seen) + rest
    assert code == 2, out
    assert "landed and disarmed" in out, out
    run = RunDir.open(run_path)
    status = run.read_status(0)
    assert not status.complete and status.reason
    assert run.complete_trials() == []
    assert final_state(stats)["armed"] is False
    assert stats_link_loss_started(stats)


def stats_link_loss_started(stats_path: Path) -> bool:
    """Whether the mock recorded a link loss begun after the first OFFBOARD (by the signal)."""
    faults = json.loads(stats_path.read_text())["faults"]
    return faults["link_loss_at_s"] is not None and faults["link_loss_at_s"] > 0.0


def test_out_of_arena_trajectory_is_refused_before_connecting(tmp_path: Path) -> None:
    wide = dict(SHORT, amplitude_north_m=2.9, period_s=8.0)  # leaves the 3 m arena with margin
    path = tmp_path / "wide.yaml"
    wide["center_ned_m"] = [1.0, 0.0, -1.5]
    path.write_text(yaml.safe_dump(wide))
    code, out = finish(gcs("fly", "--connect", "udpout://127.0.0.1:9", "--trajectory", path))
    assert code == 2
    assert "leaves the arena" in out and "t = " in out
    assert len(out.strip().splitlines()) == 1
    assert not (ROOT / "logs" / "latest").is_symlink() or "wide" not in os.readlink(
        ROOT / "logs" / "latest"
    )


def test_unreachable_vehicle_is_one_clear_line(tmp_path: Path, tiny: Path) -> None:
    code, out = finish(
        gcs(
            "fly",
            "--connect",
            "udpout://127.0.0.1:9",
            "--trajectory",
            tiny,
            "--run",
            tmp_path / "run",
        )  # fmt: skip
    )
    assert code == 2
    # the error names the link it waited on: not a traceback, not another failure's message
    assert "error:" in out and "no autopilot answered on udpout://127.0.0.1:9" in out, out
