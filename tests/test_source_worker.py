"""The trial source's worker process: calls, callbacks, errors, interrupts, shutdown.

(The flight measured at the vehicle while it learns: tests/test_source_worker_e2e.py.)
"""

from __future__ import annotations

import multiprocessing
import os
import select
import signal
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gcs.app.source_worker import WORKER_NICE, WorkerDied, WorkerSource
from gcs.errors import TrajectoryError


class Source:
    """A trial source that says which process it lives in and can be held mid-call."""

    def __init__(self, n: int, events: Any, notify: Any) -> None:
        self.n, self.events, self.notify = n, events, notify
        self.recorded: list[int] = []

    def setpoints_for(self, j: int) -> np.ndarray:
        if j < 0:
            raise TrajectoryError(f"setpoints-{j:03d}.csv: no such trial; not flown")
        sp = np.zeros((self.n, 3))
        sp[:, 0], sp[:, 1], sp[:, 2] = os.getpid(), os.nice(0), os.sched_getscheduler(0)
        return sp

    def hover_point_for(self, j: int) -> np.ndarray:
        if self.events is not None:  # hold the call until the test says go
            started, go = self.events
            started.set()
            go.wait()
        return np.array([float(j), 0.0, -1.0])

    def record(self, j: int, recording: Any) -> str | None:
        self.recorded.append(j)
        self.notify("row", list(self.recorded))
        self.notify("learn", f"learned from {j}")
        return None if j < 2 else f"enough after {j}"

    def record_incomplete(self, j: int, recording: Any, reason: str) -> None:
        raise KeyError(reason)

    def record_session(self, session: Any) -> None:
        pass


def build(n: int, events: Any = None, *, notify: Any) -> Source:
    return Source(n, events, notify)


def broken(*, notify: Any) -> Source:
    raise TrajectoryError("trajectory.yaml: field 'period_s': must be positive")


def worker_pid(source: WorkerSource) -> int:
    return int(source.setpoints_for(0)[0, 0])


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_calls_run_in_one_worker_process_and_callbacks_come_back_in_order() -> None:
    seen: list[tuple[str, object]] = []
    callbacks = {"row": lambda p: seen.append(("row", p)), "learn": lambda p: seen.append(("l", p))}
    with WorkerSource(build, (4,), callbacks) as source:
        sp = source.setpoints_for(0)
        assert sp.shape == (4, 3)
        pid = int(sp[0, 0])
        assert pid != os.getpid() and alive(pid)
        assert sp[0, 1] == min(os.nice(0) + WORKER_NICE, 19)  # the flight process comes first
        assert source.record(0, None) is None
        assert seen == [("row", [0]), ("l", "learned from 0")]  # before record returned
        assert source.record(1, None) is None and source.record(2, None) == "enough after 2"
        assert seen[-2:] == [("row", [0, 1, 2]), ("l", "learned from 2")]  # one long-lived source
        assert worker_pid(source) == pid
        np.testing.assert_array_equal(source.hover_point_for(3), [3.0, 0.0, -1.0])
    assert not alive(pid)  # shut down (and reaped) on leaving the block


def test_errors_reach_the_caller_with_their_type_and_one_line_message() -> None:
    with WorkerSource(build, (2,), {}) as source:
        with pytest.raises(TrajectoryError) as info:
            source.setpoints_for(-1)
        assert str(info.value) == "setpoints--01.csv: no such trial; not flown"
        with pytest.raises(KeyError, match="why"):
            source.record_incomplete(0, None, "why")
        assert source.setpoints_for(1).shape == (2, 3)  # the worker lives on after an error
    with WorkerSource(broken) as source, pytest.raises(TrajectoryError) as info:
        source.setpoints_for(0)  # the builder's error, at the first call
    assert str(info.value) == "trajectory.yaml: field 'period_s': must be positive"


def test_the_worker_ignores_ctrl_c_mid_call_and_a_dead_worker_is_named() -> None:
    ctx = multiprocessing.get_context("spawn")
    with ctx.Manager() as manager:
        started, go = manager.Event(), manager.Event()
        with WorkerSource(build, (1, (started, go)), {}) as source:
            pid = worker_pid(source)
            answer: list[np.ndarray] = []
            call = threading.Thread(target=lambda: answer.append(source.hover_point_for(5)))
            call.start()
            assert started.wait(60)
            os.kill(pid, signal.SIGINT)  # what a terminal's Ctrl-C sends the process group
            os.kill(pid, signal.SIGTERM)
            go.set()
            call.join(60)
            np.testing.assert_array_equal(answer[0], [5.0, 0.0, -1.0])  # the call finished
            assert worker_pid(source) == pid  # and the worker lives on
            os.kill(pid, signal.SIGKILL)
            with pytest.raises(WorkerDied, match="worker process ended"):
                source.setpoints_for(0)


def test_the_worker_is_shut_down_when_the_block_ends_with_an_exception() -> None:
    with pytest.raises(KeyboardInterrupt), WorkerSource(build, (1,), {}) as source:
        pid = worker_pid(source)
        raise KeyboardInterrupt
    assert not alive(pid)
    with pytest.raises(WorkerDied, match="not running"):
        source.setpoints_for(0)


def touching(path: str, *, notify: Any) -> Source:
    with open(path, "w") as f:
        f.write(str(os.getpid()))
    return Source(1, None, notify)


def test_start_returns_once_the_source_is_built(tmp_path) -> None:
    # the worker's imports and the build are over before the flight connects (they delayed
    # the connection on a busy machine, and PX4's origin was then set before vision fusion)
    marker = tmp_path / "built"
    with WorkerSource(touching, (str(marker),)) as source:
        built_by = int(marker.read_text())  # before any call
        assert built_by == worker_pid(source) != os.getpid()


def test_the_worker_ends_when_the_flight_process_is_killed() -> None:
    # a SIGKILLed gcs left its worker (and multiprocessing's resource tracker) running, holding
    # gcs's output open: whoever read it (a terminal's pipe, a test) waited for ever
    import subprocess
    import sys

    here = str(Path(__file__).resolve().parent)
    script = (
        f"import sys, signal; sys.path.insert(0, {here!r})\n"
        "from test_source_worker import build, worker_pid\n"
        "from gcs.app.source_worker import WorkerSource\n"
        "source = WorkerSource(build, (1,))\n"
        "source.start()\n"
        "print(worker_pid(source), flush=True)\n"
        "signal.pause()\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    pid = int(proc.stdout.readline())
    assert running(pid)
    pidfd = os.pidfd_open(pid)  # readable once the worker has ended
    try:
        proc.kill()
        proc.communicate(timeout=30)  # the output closes once every process holding it ended
        # the worker closed its files on its way out; at nice 19 on a loaded machine it may
        # wait for a core before it is gone
        assert select.select([pidfd], [], [], 20.0)[0], "the worker outlived its killed parent"
    finally:
        os.close(pidfd)
    assert not running(pid)


def running(pid: int) -> bool:
    """Whether ``pid`` runs: an ended process not yet reaped by init is a zombie (Linux)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return False
    return state != "Z"


def test_a_worker_of_a_real_time_flight_process_runs_at_normal_policy() -> None:
    """A flight process under SCHED_RR (chrt, as PX4 SITL runs its threads) must not hand that
    policy to the worker: its seconds of numerics would take a core from everything else."""
    try:
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(1))
    except PermissionError:
        pytest.skip("this user may not use a real-time policy (needs CAP_SYS_NICE)")
    try:
        with WorkerSource(build, (2,), {}) as source:
            sp = source.setpoints_for(0)
    finally:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    assert sp[0, 2] == os.SCHED_OTHER
    assert sp[0, 1] == min(os.nice(0) + WORKER_NICE, 19)


def test_the_pools_threads_started_before_take_off_are_raised_with_the_flight() -> None:
    """They pickle the calls and unpickle the answers between trials, holding the GIL the
    flight's raised threads wait for (gcs.io.scheduling)."""
    from realtime import RAISED

    from gcs.io.scheduling import raise_python_threads, restore_python_threads

    def policy(tid: int) -> tuple[int, int]:
        return os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority

    before = set(threading.enumerate())
    with WorkerSource(build, (2,), {}) as source:
        pool = [t.native_id for t in set(threading.enumerate()) - before if t.native_id]
        assert pool  # the pool's own threads, started by the test's thread (normal policy)
        assert all(policy(tid) == (os.SCHED_OTHER, 0) for tid in pool)
        out: list[Any] = []

        def flight() -> None:  # as MavsdkLink does on connecting, in the flight's thread
            raised = raise_python_threads()
            out.append([policy(tid) for tid in pool])
            out.append(source.hover_point_for(3))  # a call through the raised pool
            restore_python_threads(raised)
            out.append([policy(tid) for tid in pool])

        thread = threading.Thread(target=flight)
        thread.start()
        thread.join()
        during, answer, after = out
        assert during == [RAISED] * len(pool)
        assert answer.tolist() == [3.0, 0.0, -1.0]
        assert after == [(os.SCHED_OTHER, 0)] * len(pool)
    assert policy(0) == (os.SCHED_OTHER, 0)  # the test's own thread, raised and given back
