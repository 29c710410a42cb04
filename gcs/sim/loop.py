"""An asyncio event loop on virtual time: when every task waits, time jumps to the next timer.

:class:`VirtualTimeLoop` is asyncio's own selector loop with two changes:

- ``time()`` is a virtual clock that starts at 0 and advances only when the loop would
  otherwise sleep: the selector is polled without blocking and, if nothing is ready, the
  clock moves on by the timeout asyncio asked for (to its next timer). ``asyncio.sleep``,
  ``asyncio.timeout`` and ``call_later`` all count on it, so a flight of minutes runs in the
  time its computations take;
- while work handed to an executor (``asyncio.to_thread``, ``run_in_executor``) is running,
  virtual time stands still and the loop waits for real, in short slices: that work takes no
  virtual time, whatever it costs on the machine, so a run does not depend on the machine's
  load. A loop with no timer at all also waits for real (a signal, a thread, a socket).

:func:`virtual_time` makes ``asyncio.run`` (and so every command of gcs) use it.

The technique is the known one of driving asyncio's loop with a fake clock; this small one is
written here because it needs to know about executor work, which general ones do not.
"""

from __future__ import annotations

import asyncio
import contextlib
import selectors
import threading
from collections.abc import Callable, Iterator
from typing import Any

__all__ = ["VirtualTimeLoop", "VirtualTimePolicy", "virtual_time"]

REAL_SLICE_S = 0.01
"""Longest real wait of one loop iteration while executor work runs [s]."""


class _VirtualSelector:
    """The loop's selector: polls, and turns a would-be sleep into a jump of virtual time."""

    def __init__(self, selector: selectors.BaseSelector, loop: VirtualTimeLoop) -> None:
        self._selector = selector
        self._loop = loop

    def select(self, timeout: float | None = None) -> list[Any]:
        events = self._selector.select(0)
        if events or timeout == 0:
            return events
        loop = self._loop
        if loop.executor_jobs > 0:
            wait = REAL_SLICE_S if timeout is None else min(timeout, REAL_SLICE_S)
            return self._selector.select(wait)  # virtual time stands still meanwhile
        if timeout is None:
            return self._selector.select(None)  # nothing scheduled: only the outside can wake it
        loop.advance(timeout)
        return []

    def __getattr__(self, name: str) -> Any:
        return getattr(self._selector, name)


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """A selector event loop whose ``time()`` is virtual (see the module's docstring).

    ``start_s``: virtual time at creation [s].
    """

    def __init__(self, start_s: float = 0.0) -> None:
        super().__init__()
        self._virtual_s = float(start_s)
        self._jobs = 0
        self._jobs_lock = threading.Lock()
        self._selector = _VirtualSelector(self._selector, self)  # type: ignore[assignment]

    def time(self) -> float:
        """Virtual time [s]."""
        return self._virtual_s

    def advance(self, delay_s: float) -> None:
        """Move virtual time on by ``delay_s`` (called by the loop when all tasks wait).

        ``delay_s``: how far [s]; not negative.
        """
        if delay_s > 0:
            self._virtual_s += delay_s

    @property
    def executor_jobs(self) -> int:
        """Executor calls still running (virtual time stands still while one does)."""
        return self._jobs

    def run_in_executor(
        self, executor: Any, func: Callable[..., Any], *args: Any
    ) -> asyncio.Future[Any]:
        """asyncio's ``run_in_executor``, counted: virtual time waits for it."""
        future = super().run_in_executor(executor, func, *args)
        with self._jobs_lock:
            self._jobs += 1
        future.add_done_callback(self._job_done)
        return future

    def _job_done(self, _future: asyncio.Future[Any]) -> None:
        with self._jobs_lock:
            self._jobs -= 1


class VirtualTimePolicy(asyncio.DefaultEventLoopPolicy):
    """An event loop policy whose new loops are :class:`VirtualTimeLoop`."""

    def new_event_loop(self) -> asyncio.AbstractEventLoop:
        """A new :class:`VirtualTimeLoop`."""
        return VirtualTimeLoop()


@contextlib.contextmanager
def virtual_time() -> Iterator[None]:
    """Within the block, ``asyncio.run`` and new event loops run on virtual time."""
    previous = asyncio.get_event_loop_policy()
    asyncio.set_event_loop_policy(VirtualTimePolicy())
    try:
        yield
    finally:
        asyncio.set_event_loop_policy(previous)
