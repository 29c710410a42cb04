"""run_guarded: a stop signal cancels the flight once; later ones cannot cut its stop short."""

from __future__ import annotations

import asyncio
import os
import signal
import threading

import pytest

from gcs.flight.interrupts import run_guarded

WAIT_S = 10.0  # bound on waiting for an event, never a sleep


def test_returns_the_result_and_restores_the_signal_handlers() -> None:
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}

    async def flight() -> int:
        return 42

    assert run_guarded(flight()) == 42
    assert {sig: signal.getsignal(sig) for sig in before} == before


def test_first_signal_cancels_later_ones_are_reported_until_the_stop_ends() -> None:
    repeats: list[int] = []
    stopped: list[str] = []
    both = threading.Event()

    def on_repeat(count: int) -> None:
        repeats.append(count)
        if len(repeats) == 2:
            both.set()

    async def flight() -> None:
        try:
            os.kill(os.getpid(), signal.SIGINT)
            await asyncio.Event().wait()  # the trial, until the interrupt cancels it
        except asyncio.CancelledError:
            # the emergency stop: an impatient operator presses Ctrl-C, then kill follows
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGTERM)
            assert await asyncio.to_thread(both.wait, WAIT_S)
            stopped.append("landed and disarmed")
            raise

    with pytest.raises(KeyboardInterrupt):
        run_guarded(flight(), on_repeat)
    assert stopped == ["landed and disarmed"]
    assert repeats == [2, 3]


def test_an_error_of_the_flight_passes_through_unchanged() -> None:
    async def flight() -> None:
        raise RuntimeError("link lost")

    with pytest.raises(RuntimeError, match="link lost"):
        run_guarded(flight())


def test_outside_the_main_thread_it_runs_unguarded() -> None:
    async def flight() -> str:
        return "flown"

    result: list[str] = []
    worker = threading.Thread(target=lambda: result.append(run_guarded(flight())))
    worker.start()
    worker.join(WAIT_S)
    assert result == ["flown"]
