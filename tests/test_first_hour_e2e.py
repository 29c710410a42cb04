"""End to end, a researcher's first hour: what ``gcs fly`` says when it stops.

``gcs fly --mock`` with an adaptive profile is interrupted during the repeat of trial 0; the
``Continue with: ...`` line it prints is run as it stands (``gcs`` being ``python -m gcs``) and
must finish the run. The resumed session's mock drone must not replay the first session's
gusts: its seed differs, and is recorded in its session file. No flight prints MAVSDK's
harmless "Unexpected component ID 0". A vehicle that is not there: the wait is said at once,
and the final line says what to check.
"""

from __future__ import annotations

import shlex
import signal
import sys

import numpy as np
import pytest
from test_fly_adaptive_virtual import SHORT, adaptive_ci_profile
from test_fly_e2e import finish, gcs, wait_for_line

from gcs.app.fly import mock_session_seed
from gcs.io.rundir import RunDir

pytestmark = pytest.mark.e2e


def test_the_printed_resume_command_runs_and_flies_new_gusts(tmp_path) -> None:
    run_path = tmp_path / "run"
    profile = adaptive_ci_profile(tmp_path)
    proc = gcs(
        "fly", "--mock", "--iter", 3, "--trajectory", SHORT, "--profile", profile,
        "--run", run_path,
    )  # fmt: skip
    seen = wait_for_line(proc, "trial 1 started")  # trial 1 repeats trial 0
    proc.send_signal(signal.SIGINT)
    code, out = finish(proc)
    out = "".join(seen) + out
    assert code == 130, out
    (line,) = [ln for ln in out.splitlines() if "Continue with: " in ln]
    argv = shlex.split(line.split("Continue with: ", 1)[1])
    assert argv[:2] == ["gcs", "fly"] and "--mock" in argv, argv
    assert argv[argv.index("--iter") + 1] == "2", argv  # what was left of --iter 3

    code, out = finish(gcs(*argv[1:]))  # run as printed
    assert code == 0, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1, 2]
    seeds = [s["mock_seed"] for s in run.sessions()]
    assert seeds == [0, mock_session_seed(0, 2, {0})] and seeds[1] != 0, seeds
    assert f"mock seed {seeds[1]}: --seed 0 was flown by an earlier session" in out, out
    assert "Unexpected component ID" not in out, out  # stderr is in out: MAVSDK's, demoted
    # the repeat flew trial 0's setpoints on other gusts: not a replay of trial 0
    pos = [run.read_trial(j).pos_ned_m[:, :2] for j in (0, 1)]
    apart_m = float(np.sqrt(np.mean(np.sum((pos[1] - pos[0]) ** 2, axis=1))))
    floor = run.read_floor()
    print(f"repeat vs trial 0: {1e3 * apart_m:.1f} mm RMS apart; floor {floor}", file=sys.stderr)
    assert floor["trials"] == [0, 1]


def test_no_vehicle_says_it_waits_at_once_and_what_to_check(tmp_path) -> None:
    import socket

    import yaml
    from synthetic import ci_profile

    data = yaml.safe_load(ci_profile(tmp_path).read_text())
    data["flight"]["connect_timeout_s"] = 1.0
    profile = tmp_path / "quick.yaml"
    profile.write_text(yaml.safe_dump(data))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:  # a port nobody sends to
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"udpin://127.0.0.1:{port}"
    proc = gcs(
        "fly", "--connect", url, "--iter", 1, "--trajectory", SHORT, "--profile", profile,
        "--run", tmp_path / "run",
    )  # fmt: skip
    seen = wait_for_line(proc, "waiting up to 1 s for a vehicle on")
    code, out = finish(proc)
    out = "".join(seen) + out
    assert code == 2, out
    assert not any("no autopilot" in line for line in seen), out  # said before the wait ends
    (last,) = [ln for ln in out.splitlines() if ln.startswith("error: ")]
    assert f"no autopilot answered on {url} within 1 s" in last, out
    assert f"nothing arrived on UDP port {port}: is PX4 SITL running" in last, out
    assert "no trial was flown; the run is set up in" in out, out
