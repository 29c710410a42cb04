"""End to end: ``gcs fly`` flies the mock drone through the real MAVSDK over UDP loopback.

Ctrl-C and resume, and a link loss, stay here on the wire (a real SIGINT to a real process,
the mock's SIGUSR1); they and the other flights of ``gcs fly`` (a slow simulator's clock,
repeated Ctrl-C, a low battery) fly on the virtual clock in tests/test_fly_virtual.py
(docs/testing.md).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from synthetic import SHORT, ci_profile

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


def wait_for_line(proc: subprocess.Popen, text: str) -> list[str]:
    """Read the process's output until a line contains ``text`` (the event we wait for)."""
    seen = []
    for line in proc.stdout:
        seen.append(line)
        if text in line:
            return seen
    raise AssertionError(f"'{text}' never printed; output:\n{''.join(seen)}")


def interrupted_flight(url: str, trajectory: Path, run: Path, iterations: int, at: str):
    """``gcs fly --connect url`` sent Ctrl-C once ``at`` is printed: the process, still
    running, and the lines it printed until then."""
    proc = gcs(
        "fly", "--connect", url, "--iter", iterations, "--trajectory", trajectory, "--run", run,
        "--profile", ci_profile(run.parent),
    )  # fmt: skip
    seen = wait_for_line(proc, at)
    proc.send_signal(signal.SIGINT)
    return proc, seen


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(SHORT))
    return path


def final_state(stats_path: Path) -> dict:
    stats = json.loads(stats_path.read_text())
    return stats["modes"][-1]


@pytest.mark.flight_s(71)
def test_ctrl_c_mid_trial_lands_marks_incomplete_and_resume_continues(
    tmp_path: Path, tiny: Path
) -> None:
    run_path = tmp_path / "run"
    stats = tmp_path / "stats.json"
    with MockProcess(seed=1, stats_path=stats) as mock:
        proc, seen = interrupted_flight(mock.url, tiny, run_path, 2, at="trial 1 started")
        code, out = finish(proc)
        out = "".join(seen) + out
        assert code != 0, out
        assert "landed and disarmed" in out, out
        run = RunDir.open(run_path)
        assert run.complete_trials() == [0]
        status = run.read_status(1)
        assert not status.complete and "interrupt" in status.reason
        assert run.read_status(0).complete  # completed trial kept intact
        assert "Unexpected component ID" not in out, out  # stderr is in out: MAVSDK's, demoted

        code, out = finish(
            gcs("fly", "--connect", mock.url, "--resume", run_path, "--iter", 1)
        )  # the resumed run flies with the profile recorded in it
        assert code == 0, out
        assert "Unexpected component ID" not in out, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1]
    assert (run_path / "aborted" / "trial-001-attempt-1.json").exists()
    last = final_state(stats)
    assert last["armed"] is False


@pytest.mark.flight_s(28)
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
    # the profile's connect timeout (antx's 10 s) is not what is tested: the line is
    data = yaml.safe_load(ci_profile(tmp_path).read_text())
    data["flight"]["connect_timeout_s"] = 1.0
    profile = tmp_path / "quick.yaml"
    profile.write_text(yaml.safe_dump(data))
    proc = gcs(
        "fly", "--connect", "udpout://127.0.0.1:9", "--trajectory", tiny,
        "--profile", profile, "--run", tmp_path / "run",
    )  # fmt: skip
    code, out = finish(proc)
    assert code == 2
    # the error names the link it waited on: not a traceback, not another failure's message
    assert "error:" in out and "no autopilot answered on udpout://127.0.0.1:9" in out, out
