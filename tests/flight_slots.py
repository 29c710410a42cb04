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

A flight on the real firmware weighs more than one on the mock: PX4 SITL, gcs and, in a lab, the
rig serving its motion capture keep about half a core busy between them (measured on 2026-12-01:
PX4 17 %, gcs 19 %, the rig 16 % of a core), a mock flight about a third. ``make test`` deals the
firmware's flights first, so four of them flew at once on two cores, all the real-time work the
cores had; with two runs beside each other, PX4's clock then ran at 0.84-0.98x wall time, gcs
sent setpoints 402-477 ms late and aborted, and a take-off did not happen within 30 s (three runs
of eight). So a test of the firmware (marker ``px4``) first
holds one of :func:`firmware_slot_count` firmware slots (three on two cores), then a flight slot.
One per core left a quiet run's second half at a load of 1-3 on two cores, the firmware's
flights alone (about 1050-1100 s of them) making the run: three firmware flights and one mock
flight at once are about 1.9 cores of real-time work, at most, and never four firmware flights.
Taken in that order, the two kinds cannot wait for each other in a cycle: whoever holds a flight
slot holds every slot it needs.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

SLOTS_PER_CORE = 2
"""Real-time flights of any kind at once, per core."""
FIRMWARE_SLOTS_PER_CORE = 1.5
"""Flights on the real firmware at once, per core, rounded down (each also holds a flight slot)."""


def cores() -> int:
    """The cores this process may run on (at least 1)."""
    return max(1, len(os.sched_getaffinity(0)))


def slot_count() -> int:
    """Flight slots of this machine: :data:`SLOTS_PER_CORE` per core."""
    return SLOTS_PER_CORE * cores()


def firmware_slot_count() -> int:
    """Firmware slots of this machine: :data:`FIRMWARE_SLOTS_PER_CORE` per core."""
    return max(1, int(FIRMWARE_SLOTS_PER_CORE * cores()))


def slot_directory(kind: str = "flight") -> Path:
    """Where the lock files of one kind of slot (``"flight"``, ``"firmware"``) are, per user."""
    return Path(tempfile.gettempdir()) / f"gcs-test-{kind}-slots-{os.getuid()}"


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


def deal(
    items: list,
    workers: int,
    firmware_workers: int,
    firmware: Callable,
    length: Callable | None = None,
) -> list:
    """Deal tests to the workers' equal parts, the firmware's to the first ``firmware_workers``.

    ``pytest-xdist``'s ``worksteal`` gives each worker an equal, contiguous part of the order
    (the last parts one more where they do not divide) and lets an idle one steal from the end
    of another's. The firmware's flights wait for one of :func:`firmware_slot_count` slots: dealt
    to every worker's head, all but that many workers would start by waiting. So each of them
    goes to the one of the first ``firmware_workers`` parts with the least flight time dealt so
    far (the lowest such part on a tie: in turn where the lengths are equal). Then each other
    test with a length (the mock's long flights) goes to the part, of all of them, with the
    least flight time dealt so far, firmware's included, and what follows in ``items`` in turn
    to every part, starting after the firmware's parts, each part up to its size. Given longest
    first, the flights then end at about the same time in every part (dealt in turn, one part's
    firmware flights took 608 s and the other's 455 s of a run's 623 s; with the mock's flights
    in turn after the firmware's, the mock's went on 130 s after the firmware's last landed).

    Parameters
    ----------
    items : list
        Tests in the order they should start (the firmware's first, longest first).
    workers : int
        Number of workers (parts), at least 1.
    firmware_workers : int
        Parts that take the firmware's tests first (clipped to 1..``workers``).
    firmware : callable
        ``firmware(item)``: True for a test of the firmware.
    length : callable, optional
        ``length(item)``: a test's expected length [s], 0 where not known; if not given, 1 s
        for every firmware test and 0 for the others.

    Returns
    -------
    list
        The same items, part after part.
    """
    sizes, left = [], len(items)
    for i in range(workers):
        sizes.append(left // (workers - i))
        left -= sizes[-1]
    parts: list[list] = [[] for _ in range(workers)]
    first = min(max(firmware_workers, 1), workers)
    dealt_s = [0.0] * workers  # flight time dealt to each part

    def seconds(item) -> float:
        if length is None:
            return 1.0 if firmware(item) else 0.0
        return float(length(item))

    turn = first % workers
    for item in items:
        s = seconds(item)
        # the firmware's to the first parts; another flight of known length to any part
        open_ = [k for k in range(first if firmware(item) else workers) if len(parts[k]) < sizes[k]]
        if open_ and (firmware(item) or s > 0.0):
            k = min(open_, key=lambda k: (dealt_s[k], k))
            dealt_s[k] += s
            parts[k].append(item)
            continue
        k = turn
        while len(parts[k]) >= sizes[k]:
            k = (k + 1) % workers
        parts[k].append(item)
        turn = (k + 1) % workers
    return [item for part in parts for item in part]
