"""Real-time scheduling for the threads that keep a flight's streams at rate.

On a busy machine the OS may leave a sleeping process unscheduled for a long time: on a
2-core machine with its test suite and two CPU-bound processes beside a mock flight, a thread
that only sleeps 5 ms at a time went up to 0.75 s without running, both cores busy in user
code, with no time stolen by the host, no I/O wait and no garbage collection in that process.
A mocap stream, the vision forwarded to the vehicle or the vehicle's telemetry that stops for
0.4 s is refused as stale, and the flight ends. PX4 SITL, started as root, runs its own
threads under ``SCHED_FIFO`` for this reason.

So the threads that carry a flight's streams ask for ``SCHED_RR`` at priority
:data:`FLIGHT_PRIORITY` (the lowest real-time priority: above every normal process, below
PX4's own threads and the kernel's): gcs's flight loop while it is linked to a vehicle, its
motion-capture reader and the thread that forwards the frames, and the mock drone's and mock
Motive's loops. Where the OS does not allow it (a normal user without ``CAP_SYS_NICE`` or an
``RLIMIT_RTPRIO``), nothing changes. A thread already under a real-time policy (``chrt``) keeps
it. Heavy work never runs there: the learning runs in a worker process at the normal policy
(:mod:`gcs.app.source_worker`), and a virtual clock never asks.

On Linux a policy belongs to a thread: threads and processes it starts afterwards inherit it.
Threads started *before* the flight keep the normal policy, and in one process that is a
danger through the GIL: a normal thread that holds it when the machine's load preempts it
stops every raised thread waiting for it, for as long as the OS leaves it unscheduled (a
priority inversion). gcs's flight process has such threads: those of the learning worker's
pool, started before take-off, which pickle each call's recordings and unpickle its answer
between trials. So a flight raises every Python thread its process has
(:func:`raise_python_threads`) and gives them their policy back after landing.

The other pause of a process is its own: a full garbage collection walks every object the
process holds, and holds the GIL meanwhile. The mock drone, with pymavlink's dialect and its
flight records, paused 81 ms in one (its vehicle's served pose then jumped 0.10 m in one frame
and the flight was aborted); gcs's flight process, with MAVSDK, numpy, scipy and rich, 0.17 s.
So these processes collect once and freeze what they hold before the flight
(:func:`freeze_heap`, :func:`gc.freeze`): later collections walk only what the flight creates.
"""

from __future__ import annotations

import contextlib
import gc
import os
import threading

__all__ = [
    "FLIGHT_PRIORITY",
    "Previous",
    "raise_thread",
    "restore_thread",
    "raise_python_threads",
    "restore_python_threads",
    "to_normal",
    "freeze_heap",
    "thaw_heap",
]

FLIGHT_PRIORITY = 1
"""``SCHED_RR`` priority of the flight's threads (1-99, 1 the lowest)."""

Previous = tuple[int, int]
"""A thread's policy and priority before :func:`raise_thread`."""


def raise_thread(tid: int = 0) -> Previous | None:
    """Put a thread under ``SCHED_RR`` at :data:`FLIGHT_PRIORITY` where allowed.

    ``tid``: the thread's native id (``threading.get_native_id``); 0 for the calling thread.

    Returns: the policy and priority it had (for :func:`restore_thread`); None when nothing changed:
    not allowed, not available on this OS, already under a real-time policy, or no such thread.
    """
    if not hasattr(os, "sched_setscheduler"):
        return None
    try:
        policy = os.sched_getscheduler(tid)
        if policy in (os.SCHED_FIFO, os.SCHED_RR):
            return None
        before = (policy, os.sched_getparam(tid).sched_priority)
        os.sched_setscheduler(tid, os.SCHED_RR, os.sched_param(FLIGHT_PRIORITY))
    except OSError:  # PermissionError: neither root, CAP_SYS_NICE nor an RLIMIT_RTPRIO;
        return None  # ProcessLookupError: the thread has ended
    return before


def restore_thread(previous: Previous | None, tid: int = 0) -> None:
    """Give a thread back the policy it had before :func:`raise_thread`.

    ``previous``: what :func:`raise_thread` returned (None: nothing to give back). ``tid``: the
    thread's native id; 0 for the calling thread. A thread that has ended is left alone.
    """
    if previous is not None:
        with contextlib.suppress(ProcessLookupError):
            os.sched_setscheduler(tid, previous[0], os.sched_param(previous[1]))


def raise_python_threads() -> dict[int, Previous]:
    """:func:`raise_thread` every other Python thread of this process (see the module's note on
    the GIL).

    Returns: the previous policy of each thread changed, by native id (for
    :func:`restore_python_threads`); empty where the OS does not allow it.
    """
    own = threading.get_native_id()
    raised: dict[int, Previous] = {}
    for thread in threading.enumerate():
        tid = thread.native_id
        if tid is None or tid == own:
            continue
        previous = raise_thread(tid)
        if previous is not None:
            raised[tid] = previous
    return raised


def restore_python_threads(raised: dict[int, Previous]) -> None:
    """Give the threads :func:`raise_python_threads` changed their policy back (those still
    running)."""
    for tid, previous in raised.items():
        restore_thread(previous, tid)


def to_normal() -> None:
    """Put the calling thread under the normal policy if it runs under a real-time one (always
    allowed): for heavy work started by a raised thread, such as the learning worker."""
    if hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) in (
        os.SCHED_FIFO,
        os.SCHED_RR,
    ):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def freeze_heap() -> None:
    """Collect, then leave everything the process holds now out of later collections."""
    gc.collect()
    gc.freeze()


def thaw_heap() -> None:
    """Give the frozen objects back to the collector (a process that goes on after a flight)."""
    gc.unfreeze()
