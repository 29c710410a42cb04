"""The machine's flight slots (tests/flight_slots.py): a free slot first, else the worker's;
the firmware's slots apart; the firmware's tests dealt to as many workers as it has slots, the
mock's long flights to the parts with the least flight time, after ``-m`` has deselected."""

from __future__ import annotations

import ast
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from flight_slots import (
    FIRMWARE_SLOTS_PER_CORE,
    SLOTS_PER_CORE,
    cores,
    deal,
    firmware_slot_count,
    flight_slot,
    slot_count,
    slot_directory,
    worker_number,
)
from hypothesis import given
from hypothesis import strategies as st


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


def test_firmware_slots_fewer_than_flight_slots_in_their_own_directory() -> None:
    assert firmware_slot_count() == max(1, int(FIRMWARE_SLOTS_PER_CORE * cores())) < slot_count()
    assert slot_directory("firmware") != slot_directory() == slot_directory("flight")


def test_a_firmware_test_waits_for_a_firmware_slot_while_a_mock_flight_flies(
    tmp_path: Path,
) -> None:
    """Two pools as conftest takes them: a firmware slot, then a flight slot."""
    firmware, flights = tmp_path / "firmware", tmp_path / "flight"
    order: list[str] = []
    second_started = threading.Event()

    def second_firmware_test() -> None:
        second_started.set()
        with flight_slot(1, 1, firmware), flight_slot(1, 4, flights) as k:
            order.append(f"second firmware flight in slot {k}")

    with flight_slot(0, 1, firmware), flight_slot(0, 4, flights):
        waiter = threading.Thread(target=second_firmware_test)
        waiter.start()
        second_started.wait()
        with flight_slot(2, 4, flights) as k:  # a mock flight is not held back
            order.append(f"mock flight in slot {k}")
        order.append("first firmware flight lets go")
    waiter.join()
    assert order == [
        "mock flight in slot 1",
        "first firmware flight lets go",
        "second firmware flight in slot 0",
    ]


def _parts(dealt: list, workers: int) -> list[list]:
    """Split as pytest-xdist's worksteal does: equal contiguous parts, the last ones longer."""
    parts, left, at = [], len(dealt), 0
    for i in range(workers):
        size = left // (workers - i)
        parts.append(dealt[at : at + size])
        at, left = at + size, left - size
    return parts


def test_the_firmware_tests_head_the_first_parts_and_the_mocks_the_others() -> None:
    items = [f"px4-{k}" for k in range(5)] + [f"mock-{k}" for k in range(7)] + ["quick"] * 8
    parts = _parts(deal(items, 4, 2, lambda item: item.startswith("px4")), 4)
    assert [p[0] for p in parts] == ["px4-0", "px4-1", "mock-0", "mock-1"]
    assert parts[0][:3] == ["px4-0", "px4-2", "px4-4"] and parts[1][:2] == ["px4-1", "px4-3"]


@given(
    st.lists(st.booleans(), max_size=40),
    st.integers(min_value=1, max_value=6),
    st.integers(min_value=0, max_value=8),
)
def test_dealing_keeps_every_item_and_each_kinds_order(
    kinds: list[bool], workers: int, firmware_workers: int
) -> None:
    items = list(enumerate(sorted(kinds, reverse=True)))  # the firmware's first, as conftest
    dealt = deal(items, workers, firmware_workers, lambda item: item[1])
    assert sorted(dealt) == items
    parts = _parts(dealt, workers)
    for part in parts:  # within a part, the given order
        assert part == sorted(part)
    first = min(max(firmware_workers, 1), workers)
    room = sum(len(p) for p in parts[:first])
    # the firmware's tests go to the first parts as long as those have room for them
    assert sum(1 for p in parts[:first] for item in p if item[1]) == min(sum(kinds), room)


@given(
    st.lists(st.floats(min_value=0.0, max_value=600.0), max_size=20),
    st.integers(min_value=1, max_value=4),
)
def test_the_firmwares_parts_end_within_one_flight_of_each_other(
    lengths: list[float], firmware_workers: int
) -> None:
    items = [(k, s) for k, s in enumerate(sorted(lengths, reverse=True))] + [(-1, 0.0)] * 60
    dealt = deal(items, 4, firmware_workers, lambda item: item[0] >= 0, lambda item: item[1])
    parts = _parts(dealt, 4)
    sums = [sum(s for k, s in p if k >= 0) for p in parts[:firmware_workers]]
    # each flight went to the least loaded part: no part ends more than the longest flight
    # after another
    assert max(sums) - min(sums) <= max(lengths, default=0.0) + 1e-9, sums
    assert sum(sums) == pytest.approx(sum(lengths))


@given(
    st.lists(st.floats(min_value=1.0, max_value=600.0), max_size=12),
    st.lists(st.floats(min_value=1.0, max_value=100.0), max_size=12),
    st.integers(min_value=1, max_value=4),
)
def test_the_mocks_long_flights_even_out_every_parts_flight_time(
    firmware_s: list[float], mock_s: list[float], firmware_workers: int
) -> None:
    """The mock's flights of known length fill the parts with the least flight time dealt,
    the firmware's parts included: a part with a mock flight ends at most the longest mock
    flight after the least loaded part, and no firmware flight leaves the firmware's parts."""
    firmware_s, mock_s = sorted(firmware_s, reverse=True), sorted(mock_s, reverse=True)
    items = [("px4", s) for s in firmware_s] + [("mock", s) for s in mock_s]
    items += [("quick", 0.0)] * 80
    dealt = deal(items, 4, firmware_workers, lambda item: item[0] == "px4", lambda item: item[1])
    parts = _parts(dealt, 4)
    assert sum(1 for p in parts[:firmware_workers] for i in p if i[0] == "px4") == len(firmware_s)
    sums = [sum(s for _, s in p) for p in parts]
    for k, part in enumerate(parts):  # its last mock flight went to the least loaded part
        if any(i[0] == "mock" for i in part):
            assert sums[k] - min(sums) <= mock_s[0] + 1e-9, sums
    assert sum(sums) == pytest.approx(sum(firmware_s) + sum(mock_s))


def test_every_firmware_test_says_its_length() -> None:
    """The deal needs each firmware test's ``flight_s``: a test without it would be dealt as 0 s."""
    missing = []
    for path in sorted((Path(__file__).parent / "px4").glob("test_*.py")):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.FunctionDef) and node.name.startswith("test_"):
                marks = [ast.unparse(d) for d in node.decorator_list]
                if not any(m.startswith("pytest.mark.flight_s(") for m in marks):
                    missing.append(f"{path.name}::{node.name}")
    assert not missing, missing


def test_the_deal_is_of_the_tests_that_run_after_m_deselects(tmp_path: Path) -> None:
    """Collected with ``-m`` as the flights part of ``make test`` is, each of the first parts
    starts with a firmware flight: the suite's hook deals what ``-m`` left, not every test."""
    tests = Path(__file__).parent
    (tmp_path / "conftest.py").write_text(
        "import importlib.util\nimport pytest\n"
        f"spec = importlib.util.spec_from_file_location('suite', {str(tests / 'conftest.py')!r})\n"
        "suite = importlib.util.module_from_spec(spec)\nspec.loader.exec_module(suite)\n"
        "pytest_collection_modifyitems = suite.pytest_collection_modifyitems\n\n"
        "@pytest.hookimpl(tryfirst=True)\n"
        "def pytest_configure(config):\n"
        "    config.workerinput = {'workercount': 4}\n"
        "    for name in ('px4', 'e2e', 'flight_s'):\n"
        "        config.addinivalue_line('markers', name)\n"
    )
    lengths = [400, 184, 149, 126, 98, 95, 61]
    flights = "".join(
        f"@pytest.mark.px4\n@pytest.mark.flight_s({s})\ndef test_px4_{s}(): pass\n" for s in lengths
    )
    mocks = "".join(f"@pytest.mark.e2e\ndef test_mock_{k}(): pass\n" for k in range(40))
    quick = "".join(f"def test_quick_{k}(): pass\n" for k in range(400))
    (tmp_path / "test_synthetic.py").write_text(f"import pytest\n{flights}{mocks}{quick}")
    out = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "--strict-markers",
         "-p", "no:xdist", "-p", "no:cacheprovider", "-m", "px4 or e2e", str(tmp_path)],
        cwd=tmp_path, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    order = [line.split("::")[-1] for line in out.stdout.splitlines() if "::" in line]
    assert len(order) == len(lengths) + 40, out.stdout
    parts = _parts(order, 4)
    heads = [p[0] for p in parts]
    # the longest flights head the firmware's parts (three on two cores), the mocks the others
    first = min(firmware_slot_count(), 4)
    assert heads[:first] == [f"test_px4_{s}" for s in lengths[:first]], parts
    assert all(head.startswith("test_mock_") for head in heads[first:]), parts
