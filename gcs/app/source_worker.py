"""A trial source in a process of its own, so that nothing it does can delay the flight.

Between trials a source writes the trial's files and learns the next setpoints: seconds of
numerics (a model refresh). In a thread of the flight process that work holds the GIL while
the same process must take every mocap frame and forward it to the vehicle, stream the
setpoints and watch the telemetry; a 120 Hz ticker beside it loses a third of its ticks. So the
source lives in a single long-lived worker process (:class:`WorkerSource`): it is built there
from picklable arguments (a module-level builder and its arguments), every call of the
:class:`gcs.flight.campaign.TrialSource` protocol goes to it with its arguments pickled (the
recordings as arrays) and its answer comes back; the flight process keeps only the streams and
waits for the answer without holding the GIL.

What the caller sees is as before: the answers, the same exception types and one-line messages
(raised in the worker, re-raised here), and the source's callbacks (a view's ``on_row``, ...)
called in this process, in order, before the call returns (the builder is handed a ``notify``
function that queues ``(kind, payload)`` for that). The calls run one at a time, in the order
they were made (one worker), so a session record asked for after an interrupt is written after
the trial file the worker was writing then.

Once it has built the source (its imports: seconds of CPU, before take-off), the worker runs
:data:`WORKER_NICE` steps nicer than the flight process, so that on a busy machine its seconds
of numerics do not take the CPU from the streams either (the hover between trials grows
instead). The worker ignores SIGINT and SIGTERM: a Ctrl-C (sent to the whole
process group by a terminal) must not kill it in the middle of writing a run file without the
campaign knowing; the flight process's interrupt guard
(:func:`gcs.flight.interrupts.run_guarded`) stays in charge and stops the vehicle, then
:meth:`WorkerSource.close` lets the worker finish what it was asked and shuts it down, on every
exit path (a ``with`` block). A worker that dies raises
:class:`WorkerDied` (a bug, not bad input) at the next call.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import threading
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import numpy as np

from gcs.flight.campaign import FlightSession
from gcs.flight.trial import TrialRecording
from gcs.io.scheduling import to_normal

__all__ = ["WorkerSource", "WorkerDied", "Notify", "WORKER_NICE"]

Notify = Callable[[str, Any], None]
"""``notify(kind, payload)``: queue a callback for the flight process (worker side)."""

_source: Any = None  # the trial source, in the worker
_notes: list[tuple[str, Any]] = []  # callbacks queued by the current call, in the worker


class WorkerDied(RuntimeError):
    """The trial source's worker process ended while the flight needed it."""


class WorkerSource:
    """A :class:`gcs.flight.campaign.TrialSource` that runs in a worker process.

    ``build``: a module-level function (pickled by name) that builds the source in the worker:
    ``build(*args, notify=notify)``; ``notify(kind, payload)`` has ``callbacks[kind]`` called with
    ``payload`` in this process before the current call returns. ``args``: its picklable arguments
    (a :class:`gcs.io.rundir.RunDir`, arrays, flags). ``callbacks``: the callbacks by kind, called
    in this process (in the thread that made the call).

    Use it as a context manager: the worker starts (building the source; its error comes at the
    first call) on entry and is shut down on exit, after the calls made so far have run.
    """

    def __init__(
        self,
        build: Callable[..., Any],
        args: tuple[Any, ...] = (),
        callbacks: dict[str, Callable[[Any], None]] | None = None,
    ) -> None:
        self.build, self.args = build, args
        self.callbacks = dict(callbacks or {})
        self._pool: ProcessPoolExecutor | None = None
        self._built: Future[None] | None = None
        self._lock = threading.Lock()  # one call at a time, in the order they were made

    def __enter__(self) -> WorkerSource:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        """Start the worker and wait until it has built the source (a failed build raises at
        the first call).

        The worker's start-up (its imports and the build: seconds of CPU) is over before the
        flight begins: overlapping the connection on a 2-core machine running PX4 SITL, it
        delayed the connection by 2-3 s, and on the vision-only lab firmware gcs then set
        PX4's global origin before EKF2 fused the first vision (the estimate 488 m down, the
        origin's altitude; arming refused by the fence check).
        """
        if self._pool is not None:
            return
        pool = ProcessPoolExecutor(
            max_workers=1,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
            initargs=(os.getpid(),),
        )
        with _interrupts_ignored():  # the child starts with them ignored, before its imports
            self._built = pool.submit(_build, self.build, self.args)
        self._pool = pool
        wait([self._built])

    def close(self) -> None:
        """Let the worker finish the calls made so far, then shut it down (idempotent)."""
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def _call(self, name: str, *args: Any) -> Any:
        """Run ``source.name(*args)`` in the worker; its callbacks here; its answer."""
        with self._lock:
            if self._pool is None or self._built is None:
                raise WorkerDied(f"{name}: the trial source's worker is not running")
            try:
                self._built.result()
                result, notes = self._pool.submit(_run, name, args).result()
            except BrokenProcessPool as exc:
                raise WorkerDied(
                    f"{name}: the trial source's worker process ended ({exc})"
                ) from None
        for kind, payload in notes:
            self.callbacks[kind](payload)
        return result

    def setpoints_for(self, j: int) -> np.ndarray:
        """Setpoints of trial ``j`` (see :class:`gcs.flight.campaign.TrialSource`).

        Returns: ndarray, shape (N, 3), absolute local NED setpoints [m].
        """
        return self._call("setpoints_for", j)

    def hover_point_for(self, j: int) -> np.ndarray:
        """Where the vehicle hovers before trial ``j``.

        Returns: ndarray, shape (3,), absolute local NED [m].
        """
        return self._call("hover_point_for", j)

    def record(self, j: int, recording: TrialRecording) -> str | None:
        """Hand the complete recording of trial ``j`` to the worker (files, learning).

        Returns: a reason to fly no further trial, or None.
        """
        return self._call("record", j, recording)

    def record_incomplete(self, j: int, recording: TrialRecording, reason: str) -> None:
        """Hand the partial recording of trial ``j`` to the worker."""
        self._call("record_incomplete", j, recording, reason)

    def record_session(self, session: FlightSession) -> None:
        """Hand the flight session's record to the worker.

        ``session``: what the campaign found out about the vehicle.
        """
        self._call("record_session", session)


class _interrupts_ignored:
    """Ignore SIGINT and SIGTERM in this process meanwhile (main thread only; else no-op)."""

    def __enter__(self) -> None:
        self.saved: dict[int, Any] = {}
        if threading.current_thread() is threading.main_thread():
            for sig in _SIGNALS:
                self.saved[sig] = signal.signal(sig, signal.SIG_IGN)

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self.saved.items():
            signal.signal(sig, handler)


_SIGNALS = (signal.SIGINT, signal.SIGTERM)

WORKER_NICE = 10
"""How much nicer than the flight process the worker runs (where the OS has ``os.nice``): on a
busy machine a learning step can wait, the next mocap frame cannot."""


def _init_worker(parent_pid: int) -> None:
    """Worker initializer: interrupts ignored (the flight process's guard is in charge), and
    the worker ends with the flight process (:func:`_on_parent_death`)."""
    for sig in _SIGNALS:
        signal.signal(sig, signal.SIG_IGN)
    signal.signal(_PARENT_DEATH_SIGNAL, _on_parent_death)
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, _PARENT_DEATH_SIGNAL)
    except (OSError, AttributeError):  # not Linux: the pool's own shutdown ends it
        pass
    if os.getppid() != parent_pid:  # the flight process ended before the prctl
        os._exit(0)
    # a flight process under a real-time policy (gcs.io.scheduling, chrt) hands it down: the
    # worker's seconds of numerics would then take a core from everything at normal priority
    to_normal()


#: Linux's prctl option, and the signal it sends the worker when the flight process ends.
_PR_SET_PDEATHSIG = 1
_PARENT_DEATH_SIGNAL = signal.SIGUSR1
_busy = False  # a call of the flight process is running (in the worker)
_orphaned = False  # the flight process has ended (in the worker)


def _on_parent_death(signum: int, frame: Any) -> None:
    """The flight process ended without shutting the worker down (killed, crashed): end too,
    at once when idle, else once the call in progress has written its files. Left alone the
    worker (and multiprocessing's resource tracker with it) lived on, holding the terminal's
    output open: a test reading gcs's output after a SIGKILL waited for ever."""
    global _orphaned
    _orphaned = True
    if not _busy:
        os._exit(0)


def _call(fn: Callable[[], Any]) -> Any:
    """Run ``fn`` as a call of the flight process: an orphaned worker ends after it."""
    global _busy
    _busy = True
    try:
        return fn()
    finally:
        _busy = False
        if _orphaned:
            os._exit(0)


def _build(build: Callable[..., Any], args: tuple[Any, ...]) -> None:
    """Build the worker's trial source (in the worker)."""

    def notify(kind: str, payload: Any) -> None:
        _notes.append((kind, payload))

    def make() -> None:
        global _source
        _source = build(*args, notify=notify)

    _call(make)
    if hasattr(os, "nice"):  # built (its imports done) at full speed, before the flight
        os.nice(WORKER_NICE)


def _run(name: str, args: tuple[Any, ...]) -> tuple[Any, list[tuple[str, Any]]]:
    """Call the worker's source; its answer and the callbacks it queued (in the worker)."""
    _notes.clear()
    try:
        return _call(lambda: getattr(_source, name)(*args)), list(_notes)
    finally:
        _notes.clear()
