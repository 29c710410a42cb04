"""Run a flight to its end: the first Ctrl-C stops the vehicle, later ones cannot cut that short.

``asyncio.run`` turns the first Ctrl-C into a cancellation of the main task, which is what a
flight needs (the campaign catches it, holds, lands and disarms). A *second* Ctrl-C, though, is
raised as ``KeyboardInterrupt`` at once, wherever the loop happens to be: in the middle of that
emergency stop. The process then exits with the vehicle armed and hovering in Hold, nobody
connected, and the interrupted trial unrecorded; a second press is exactly what an operator does
when a landing seems slow. :func:`run_guarded` takes over SIGINT and SIGTERM for the duration
of the flight: the first one cancels it, later ones are only reported until it has ended. The
stop it waits for is bounded by the flight settings' own timeouts (command, land, link regain).
"""

from __future__ import annotations

import asyncio
import signal
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

__all__ = ["STOP_SIGNALS", "run_guarded"]

T = TypeVar("T")

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""Signals that stop a flight: Ctrl-C, and a polite ``kill`` (a supervisor, a closed session)."""


def run_guarded(main: Coroutine[Any, Any, T], on_repeat: Callable[[int], None] | None = None) -> T:
    """Run ``main`` in a new event loop; a stop signal cancels it once, and only once.

    ``main`` is the flight: on cancellation it must stop the vehicle before it ends. Its result is
    returned when no stop signal arrived; when one did and ``main`` ended because of the
    cancellation (after it stopped the vehicle), ``KeyboardInterrupt`` is raised. Each later
    signal, while ``main`` is still stopping, calls ``on_repeat`` on the event loop with the
    number of stop signals so far (2, 3, ...); it must return quickly. Where the event loop
    cannot take signal handlers (not the main thread, or a platform without
    ``loop.add_signal_handler``), ``main`` runs under plain ``asyncio.run`` rules.
    """
    return asyncio.run(_guarded(main, on_repeat))


async def _guarded(main: Coroutine[Any, Any, T], on_repeat: Callable[[int], None] | None) -> T:
    loop = asyncio.get_running_loop()
    task = asyncio.ensure_future(main)
    count = 0

    def on_signal() -> None:
        nonlocal count
        count += 1
        if count == 1:
            task.cancel()
        elif on_repeat is not None and not task.done():
            on_repeat(count)

    previous: dict[signal.Signals, Any] = {}
    for sig in STOP_SIGNALS:
        handler = signal.getsignal(sig)
        try:
            loop.add_signal_handler(sig, on_signal)
        except (NotImplementedError, RuntimeError, ValueError):
            continue  # no signal handlers here: asyncio.run's own SIGINT handling applies
        previous[sig] = handler
    try:
        return await task
    except asyncio.CancelledError:
        if count == 0:
            raise
        raise KeyboardInterrupt from None
    finally:
        for sig, handler in previous.items():
            loop.remove_signal_handler(sig)
            signal.signal(sig, handler)  # not the default: asyncio.run restores its own
