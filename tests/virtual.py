"""Helpers of the virtual-clock flights: gcs in-process against the simulated drone.

The flights of ``tests/test_*_virtual.py`` run the real commands (``gcs fly``, ``gcs
identify``) and the real campaign in this process, against :class:`gcs.sim.drone.SimulatedDrone`
(the mock's commander, physics and estimator) on :func:`gcs.sim.loop.virtual_time`: a flight of
a minute takes the time its computations take. What they do not cover, MAVSDK and MAVLink on
the wire, the ``tests/test_*_e2e.py`` flights do (docs/testing.md).
"""

from __future__ import annotations

import asyncio
import itertools
import os
import signal
from collections.abc import Callable
from pathlib import Path

import pytest
from cli_runner import invoke as gcs_invoke
from click.testing import Result

from gcs.flight import campaign
from gcs.mock.config import load_mock_config
from gcs.sim.drone import SimulatedDrone
from gcs.sim.loop import virtual_time

ROOT = Path(__file__).resolve().parents[1]


def run_gcs(*args: object, cwd: Path = ROOT) -> tuple[int, str]:
    """``gcs ARGS`` in this process on virtual time: (exit code, output)."""
    result = invoke_gcs(*args, cwd=cwd)
    return result.exit_code, result.output


def invoke_gcs(*args: object, cwd: Path = ROOT) -> Result:
    """``gcs ARGS`` in this process on virtual time, run in ``cwd``: click's result (its
    ``stdout`` alone is what a shell's ``> FILE`` would write)."""
    from gcs import cli

    before = os.getcwd()
    os.chdir(cwd)  # by default as the subprocesses of the e2e tests: logs/ of the checkout
    # wide enough that no temporary path (pytest-xdist's are longer) is wrapped; the command
    # line's consoles read COLUMNS once, when gcs.cli is first imported, so set them here
    widths = (cli.console.width, cli.err_console.width)
    cli.console.width = cli.err_console.width = 400
    try:
        with virtual_time():
            return gcs_invoke(
                [str(a) for a in args], env={"COLUMNS": "400"}, catch_exceptions=False
            )
    finally:
        cli.console.width, cli.err_console.width = widths
        os.chdir(before)


def fly_virtual(main) -> object:  # type: ignore[no-untyped-def]
    """``asyncio.run(main)`` on virtual time."""
    with virtual_time():
        return asyncio.run(main)


def on_trial(
    monkeypatch: pytest.MonkeyPatch, number: int, action: Callable[[], None], after_s: float = 1.0
) -> None:
    """Call ``action`` ``after_s`` (virtual) seconds into the ``number``-th trial flown (0-based)
    of this test: the event the e2e tests wait for on the printed "trial j started" line."""
    flown = itertools.count()

    class Hooked(campaign.TrialRun):
        async def fly(self):  # type: ignore[no-untyped-def]
            if next(flown) == number:
                asyncio.get_running_loop().call_later(after_s, action)
            return await super().fly()

    monkeypatch.setattr(campaign, "TrialRun", Hooked)


def ctrl_c() -> None:
    """What the operator's Ctrl-C does: SIGINT to this process."""
    os.kill(os.getpid(), signal.SIGINT)


class SimMockProcess:
    """Stands in for :class:`gcs.mock.process.MockProcess` inside ``gcs fly --mock`` and
    ``gcs identify --mock``: the same settings and seed, as a simulated drone (no arena)."""

    last: SimulatedDrone | None = None

    def __init__(self, config_path=None, seed: int = 0, arena=None, **_: object) -> None:  # type: ignore[no-untyped-def]
        if arena is not None:
            raise AssertionError("the simulated drone serves no motion capture: fly it on the wire")
        self.drone = SimulatedDrone(load_mock_config(config_path), seed=seed)
        self.mocap_url = ""

    @property
    def url(self) -> str:
        return self.drone.url

    def __enter__(self) -> SimMockProcess:
        self.drone.__enter__()
        SimMockProcess.last = self.drone
        return self

    def __exit__(self, *exc: object) -> None:
        self.drone.__exit__(*exc)


def sim_mock(monkeypatch: pytest.MonkeyPatch) -> type[SimMockProcess]:
    """Make ``--mock`` start a simulated drone (:class:`SimMockProcess`) in this test."""
    import gcs.mock.process

    monkeypatch.setattr(gcs.mock.process, "MockProcess", SimMockProcess)
    return SimMockProcess


def fly_two_trials(tmp: Path, trajectory: Path, run: Path, *vehicle: object) -> tuple[int, str]:
    """``gcs fly <vehicle> --iter 2`` on ``trajectory`` with the CI profile (in-process)."""
    from synthetic import ci_profile

    return run_gcs(
        "fly", *vehicle, "--iter", 2, "--trajectory", trajectory, "--run", run,
        "--profile", ci_profile(tmp),
    )  # fmt: skip
