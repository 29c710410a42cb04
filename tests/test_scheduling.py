"""Real-time scheduling of the threads that carry a flight's streams (gcs.io.scheduling)."""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from typing import Any

import pytest
from realtime import ALLOWED, RAISED

from gcs.flight.mocap.client import MocapClient
from gcs.io.mocap_source import parse_mocap_url
from gcs.io.scheduling import raise_thread, restore_thread, to_normal
from gcs.mock.mocap.process import MocapServerProcess
from gcs.mock.process import MockProcess


def in_thread(fn: Callable[[], Any]) -> Any:
    """``fn()`` in a thread of its own (a policy belongs to a thread: the test's stays)."""
    out: list[Any] = []
    thread = threading.Thread(target=lambda: out.append(fn()))
    thread.start()
    thread.join()
    return out[0]


def policy() -> tuple[int, int]:
    return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority


def test_a_raised_thread_runs_round_robin_where_allowed_and_gets_its_policy_back() -> None:
    def run() -> tuple[Any, ...]:
        before = policy()
        previous = raise_thread()
        during = policy()
        restore_thread(previous)
        return before, previous, during, policy()

    before, previous, during, after = in_thread(run)
    assert before == (os.SCHED_OTHER, 0)
    assert during == RAISED
    assert previous == (before if ALLOWED else None)
    assert after == before
    assert policy() == (os.SCHED_OTHER, 0)  # the test's own thread never changed


def test_where_the_os_refuses_nothing_changes(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    assert in_thread(lambda: (raise_thread(), policy())) == (None, (os.SCHED_OTHER, 0))


@pytest.mark.skipif(not ALLOWED, reason="this user may not use a real-time policy")
def test_a_thread_already_real_time_keeps_its_priority_and_to_normal_ends_it() -> None:
    def run() -> tuple[Any, ...]:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(5))
        kept = (raise_thread(), policy())
        to_normal()
        return kept, policy()

    kept, normal = in_thread(run)
    assert kept == (None, (os.SCHED_FIFO, 5))
    assert normal == (os.SCHED_OTHER, 0)


@pytest.mark.e2e
def test_the_mock_drone_the_mock_motive_and_gcs_mocap_reader_run_raised() -> None:
    """The simulators' loops as PX4 SITL's threads, and gcs's reader of their frames."""
    with MockProcess(seed=0) as mock:
        assert (os.sched_getscheduler(mock.pid), os.sched_getparam(mock.pid).sched_priority) == (
            RAISED
        )
    with MocapServerProcess(["--rate", "100"]) as motive:
        assert os.sched_getscheduler(motive.pid) == RAISED[0]
        client = MocapClient(parse_mocap_url(motive.url)).start()
        try:
            client.wait_until(lambda s: s.tracked, 10.0)
            reader = client.reader_pid
            assert reader is not None and os.sched_getscheduler(reader) == RAISED[0]
        finally:
            client.stop()


def test_a_frozen_heap_is_left_out_of_collections_until_thawed() -> None:
    import gc

    from gcs.io.scheduling import freeze_heap, thaw_heap

    held = [[i] for i in range(1000)]  # tracked objects alive before the flight
    try:
        freeze_heap()
        assert gc.get_freeze_count() >= len(held)
    finally:
        thaw_heap()
    assert gc.get_freeze_count() == 0


def test_another_threads_policy_is_raised_by_its_id_and_a_gone_thread_is_left_alone() -> None:
    started, go = threading.Event(), threading.Event()
    tids: list[int] = []

    def waiting() -> None:
        tids.append(threading.get_native_id())
        started.set()
        go.wait()

    thread = threading.Thread(target=waiting)
    thread.start()
    started.wait()
    tid = tids[0]
    previous = in_thread(lambda: raise_thread(tid))
    assert (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority) == RAISED
    assert policy() == (os.SCHED_OTHER, 0)  # only that thread
    go.set()
    thread.join()
    # join() returns before the kernel has let the thread go (a CI run raised it again after
    # join), so "gone" is an id the kernel never hands out: ids stay below pid_max.
    with open("/proc/sys/kernel/pid_max") as f:
        gone = int(f.read())
    restore_thread(previous, gone)  # nothing to give back, no error
    assert raise_thread(gone) is None
