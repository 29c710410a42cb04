"""At most two real-time flights per core on one machine, whichever test runs fly them.

A real-time flight keeps about half a core busy at a real-time priority: gcs's flight process
(``SCHED_RR``, :mod:`gcs.io.scheduling`), the mock drone and its mock Motive or the lab rig, and
PX4 SITL's own ``SCHED_FIFO`` threads. ``make test`` flies four at once on two cores; two test
runs beside each other (two checkouts, or CI beside a developer's run) flew eight, and real-time
work then exceeded the cores: measured, up to 21 runnable real-time threads at once and four
firmware flights of both runs aborted in the same two minutes, each on a setpoint sent 407-451 ms
late (gcs's limit in the tests: 400 ms). A test run cannot see how busy the real-time class
is; it can share a count with the other runs on the machine.

So each test of the flights (markers ``e2e``, ``px4``, ``live``) holds one of
:func:`slot_count` slots while it runs: lock files under the temporary directory, taken with
``flock`` (the system lets go when a process ends, however it ends). A test takes a free slot
if there is one, else waits for the slot of its worker's number: one run alone never waits,
two runs share the slots. Processes that are not gcs's tests take no slot; at a normal priority
they cannot delay a flight's streams anyway.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

SLOTS_PER_CORE = 2


def slot_count() -> int:
    """Slots of this machine: :data:`SLOTS_PER_CORE` per core this process may run on."""
    return SLOTS_PER_CORE * max(1, len(os.sched_getaffinity(0)))


def slot_directory() -> Path:
    """Where the slots' lock files are (one directory per user)."""
    return Path(tempfile.gettempdir()) / f"gcs-test-flight-slots-{os.getuid()}"


def worker_number() -> int:
    """This pytest-xdist worker's number (``gw3``: 3), 0 outside xdist."""
    name = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    return int(name[2:]) if name[2:].isdigit() else 0


def _open(directory: Path, k: int) -> IO[str]:
    return open(directory / f"slot-{k}.lock", "a")  # noqa: SIM115 (kept open while held)


@contextmanager
def flight_slot(
    worker: int, slots: int | None = None, directory: Path | None = None
) -> Iterator[int]:
    """Hold one slot while the block runs: a free one, else wait for slot ``worker mod slots``.

    Parameters
    ----------
    worker : int
        The test worker's number (:func:`worker_number`).
    slots : int, optional
        How many slots (default :func:`slot_count`).
    directory : Path, optional
        Where the lock files are (default :func:`slot_directory`).

    Yields
    ------
    int
        The slot held.
    """
    n = slots or slot_count()
    where = directory or slot_directory()
    where.mkdir(parents=True, exist_ok=True)
    held: tuple[int, IO[str]] | None = None
    for k in range(n):
        handle = _open(where, k)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            continue
        held = (k, handle)
        break
    if held is None:
        k = worker % n
        handle = _open(where, k)
        fcntl.flock(handle, fcntl.LOCK_EX)  # until the run holding it ends its test
        held = (k, handle)
    k, handle = held
    try:
        yield k
    finally:
        fcntl.flock(handle, fcntl.LOCK_UN)
        handle.close()
