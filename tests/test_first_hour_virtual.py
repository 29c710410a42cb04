"""A researcher's first hour on the virtual clock: the ``Continue with: ...`` line runs.

``gcs fly --mock`` with an adaptive profile is interrupted (Ctrl-C: SIGINT to this process)
during the repeat of trial 0; the line it prints is run as it stands through gcs's command
line and must finish the run. The resumed session's mock drone must not replay the first
session's gusts: its seed differs, and is recorded in its session file. ``--mock`` starts a
simulated drone of the same settings and seed (tests/virtual.py); a real SIGINT to a real
``gcs fly`` process over the wire, and MAVSDK's demoted "Unexpected component ID 0", are
tests/test_fly_e2e.py's.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import numpy as np
import pytest
from test_fly_adaptive_virtual import SHORT, adaptive_ci_profile
from virtual import ctrl_c, on_trial, run_gcs, sim_mock

from gcs.app.fly import mock_session_seed
from gcs.io.rundir import RunDir

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e


def test_the_printed_resume_command_runs_and_flies_new_gusts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run_path = tmp_path / "run"
    profile = adaptive_ci_profile(tmp_path)
    sim_mock(monkeypatch)
    on_trial(monkeypatch, 1, ctrl_c)  # trial 1 repeats trial 0
    code, out = run_gcs(
        "fly", "--mock", "--iter", 3, "--trajectory", SHORT, "--profile", profile,
        "--run", run_path,
    )  # fmt: skip
    assert code == 130, out
    (line,) = [ln for ln in out.splitlines() if "Continue with: " in ln]
    argv = shlex.split(line.split("Continue with: ", 1)[1])
    assert argv[:2] == ["gcs", "fly"] and "--mock" in argv, argv
    assert argv[argv.index("--iter") + 1] == "2", argv  # what was left of --iter 3

    monkeypatch.undo()  # no Ctrl-C this time
    mock = sim_mock(monkeypatch)
    code, out = run_gcs(*argv[1:])  # run as printed
    assert code == 0, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1, 2]
    seeds = [s["mock_seed"] for s in run.sessions()]
    assert seeds == [0, mock_session_seed(0, 2, {0})] and seeds[1] != 0, seeds
    assert f"mock seed {seeds[1]}: --seed 0 was flown by an earlier session" in out, out
    assert mock.last is not None and mock.last.seed == seeds[1]  # the drone flown had it
    # the repeat flew trial 0's setpoints on other gusts: not a replay of trial 0
    pos = [run.read_trial(j).pos_ned_m[:, :2] for j in (0, 1)]
    apart_m = float(np.sqrt(np.mean(np.sum((pos[1] - pos[0]) ** 2, axis=1))))
    floor = run.read_floor()
    print(f"repeat vs trial 0: {1e3 * apart_m:.1f} mm RMS apart; floor {floor}", file=sys.stderr)
    assert floor["trials"] == [0, 1]
