"""The machine's flight slots (tests/flight_slots.py): a free slot first, else the worker's."""

from __future__ import annotations

import threading
from pathlib import Path

from flight_slots import SLOTS_PER_CORE, flight_slot, slot_count, worker_number


def test_free_slots_are_taken_first_then_a_test_waits_for_its_workers_slot(
    tmp_path: Path,
) -> None:
    got: list[tuple[int, bool]] = []
    released = threading.Event()

    def third() -> None:
        with flight_slot(worker=3, slots=2, directory=tmp_path) as k:
            got.append((k, released.is_set()))

    with flight_slot(worker=0, slots=2, directory=tmp_path) as first:
        with flight_slot(worker=0, slots=2, directory=tmp_path) as second:
            assert (first, second) == (0, 1)  # both free: no worker waits for its own
            waiter = threading.Thread(target=third)
            waiter.start()
            released.set()  # set before slot 1 is let go: the waiter must see it
        waiter.join()
        # worker 3 of 2 slots waits for slot 1, and took it only once it was let go, while
        # slot 0 was still held
        assert got == [(1, True)]
    with flight_slot(worker=0, slots=2, directory=tmp_path) as again:
        assert again == 0  # all let go


def test_two_slots_per_core_and_the_worker_number(monkeypatch) -> None:
    assert slot_count() % SLOTS_PER_CORE == 0 and slot_count() >= SLOTS_PER_CORE
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw7")
    assert worker_number() == 7
    monkeypatch.delenv("PYTEST_XDIST_WORKER")
    assert worker_number() == 0
