"""The child-program helper of the mocks: READY awaited, failures named, SIGTERM then kill."""

from __future__ import annotations

import contextlib
import os
import select
import signal
import subprocess
import sys

import pytest

from gcs.mock.child import ChildNotReady, ChildProgram


def program(code: str) -> list[str]:
    return [sys.executable, "-c", code]


def test_ready_line_other_lines_and_stderr() -> None:
    lines: list[str] = []
    code = (
        "import sys, time; sys.stderr.write('counters\\n'); sys.stderr.flush();"
        "print('MOCAP x://1'); print('READY udpout://127.0.0.1:5', flush=True); time.sleep(60)"
    )
    child = ChildProgram(program(code), ready_timeout_s=20.0, on_line=lines.append)
    assert child.start() == "udpout://127.0.0.1:5" == child.ready
    assert lines == ["MOCAP x://1\n"] and child.pid > 0
    child.stop()
    assert child.stderr_text == "counters\n"


def test_an_early_exit_is_named_with_its_code_and_last_stderr_line() -> None:
    code = (
        "import sys; sys.stderr.write('usage\\nerror: --natnet must be one of 3.1\\n'); sys.exit(2)"
    )
    child = ChildProgram(program(code), ready_timeout_s=20.0)
    with pytest.raises(ChildNotReady, match=r"exited with code 2 \(error: --natnet must be one"):
        child.start()


def test_a_silent_program_times_out_and_is_stopped() -> None:
    child = ChildProgram(program("import time; time.sleep(60)"), ready_timeout_s=0.5)
    with pytest.raises(ChildNotReady, match="no READY line within 0.5 s"):
        child.start()
    assert child.returncode is not None  # not left running


def test_a_program_that_ignores_sigterm_is_killed() -> None:
    code = (
        "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN);"
        "print('READY ok', flush=True); time.sleep(60)"
    )
    child = ChildProgram(program(code), ready_timeout_s=20.0, stop_timeout_s=0.5)
    child.start()
    assert child.returncode is None
    child.stop()
    assert child.returncode == -signal.SIGKILL


def test_the_program_ends_when_its_parent_is_killed() -> None:
    """A parent killed without stopping its child (SIGKILL: no handler runs) leaves no
    program serving: the child's end of the parent's pipe reads EOF and it stops as on
    SIGTERM."""
    child_code = (
        "import time; from gcs.mock.child import end_with_parent; end_with_parent();"
        "print('READY ok', flush=True); time.sleep(60)"
    )
    parent_code = (
        "import sys, time; from gcs.mock.child import ChildProgram;"
        f"c = ChildProgram([sys.executable, '-c', {child_code!r}], ready_timeout_s=20.0);"
        "c.start(); print(c.pid, flush=True); time.sleep(60)"
    )
    parent = subprocess.Popen(program(parent_code), stdout=subprocess.PIPE, text=True)
    assert parent.stdout is not None
    pid = int(parent.stdout.readline())
    pidfd = os.pidfd_open(pid)  # readable once that process has ended
    try:
        assert not select.select([pidfd], [], [], 0.0)[0]  # serving while its parent lives
        parent.kill()
        parent.wait()
        assert select.select([pidfd], [], [], 20.0)[0], "the child outlived its killed parent"
    finally:
        os.close(pidfd)
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
