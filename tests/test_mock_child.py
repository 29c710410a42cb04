"""The child-program helper of the mocks: READY awaited, failures named, SIGTERM then kill."""

from __future__ import annotations

import signal
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
