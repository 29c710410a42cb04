"""A mock program as a child process: started in its own session, ready when it says so.

The mock drone (``python -m gcs.mock``) and the mock motion capture (``python -m
gcs.mock.mocap``) both print ``READY <url>`` on stdout once they serve. :class:`ChildProgram`
starts such a program in a session of its own (a Ctrl-C in the terminal reaches gcs, which then
lands the mock, and not the mock, which would die before it could be landed), waits for that
line (an event set by a reader thread: no polling), hands every other stdout line to a
callback, and stops it with SIGTERM, then SIGKILL if it does not end in time.
"""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
import threading
from collections.abc import Callable, Sequence
from typing import IO

__all__ = ["ChildProgram", "ChildNotReady"]

#: Box-drawing characters of the panels Typer prints errors in.
_FRAME = "│╭╮╰╯─┃┏┓┗┛━ "


class ChildNotReady(RuntimeError):
    """The program ended, or said nothing, before its READY line; the message says which."""


class ChildProgram:
    """One run of a program that announces ``READY <text>`` on stdout.

    ``ready_timeout_s``: how long :meth:`start` waits for the READY line [s]. ``stop_timeout_s``:
    how long :meth:`stop` waits after SIGTERM before SIGKILL [s]. ``on_line``: called from the
    reader thread with every other stdout line (e.g. the mock's ``MOCAP <url>``, printed before
    READY).

    ``ready``: what followed ``READY`` (the program's URL); empty before. ``pid``: process id (0
    before :meth:`start`). ``stderr_text``: everything the program wrote on stderr, read by
    :meth:`stop`.
    """

    def __init__(
        self,
        argv: Sequence[str],
        ready_timeout_s: float,
        stop_timeout_s: float = 5.0,
        on_line: Callable[[str], None] | None = None,
    ) -> None:
        self.argv = list(argv)
        self.ready_timeout_s = ready_timeout_s
        self.stop_timeout_s = stop_timeout_s
        self.on_line = on_line
        self.ready = ""
        self.pid = 0
        self.stderr_text = ""
        self._proc: subprocess.Popen[str] | None = None
        self._event = threading.Event()
        self._stderr: IO[str] | None = None
        self._reader: threading.Thread | None = None

    def start(self) -> str:
        """Start the program and wait for its READY line.

        Returns: what followed ``READY``.

        Raises ``ChildNotReady``: it exited first (with its code and last stderr line) or stayed
        silent for ``ready_timeout_s``; it is stopped before this is raised.
        """
        self._stderr = tempfile.TemporaryFile("w+")  # noqa: SIM115 (closed in stop())
        self._proc = subprocess.Popen(
            self.argv,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
            start_new_session=True,
        )
        self.pid = self._proc.pid
        self._reader = threading.Thread(target=self._read_stdout, daemon=True)
        self._reader.start()
        if not self._event.wait(self.ready_timeout_s) or not self.ready:
            why = self._failure()
            self.stop()
            raise ChildNotReady(why)
        return self.ready

    @property
    def returncode(self) -> int | None:
        """Exit status of the program: None before :meth:`start` and while it runs; negative
        when a signal ended it (``-signal.SIGKILL`` when :meth:`stop` had to kill it), as
        :attr:`subprocess.Popen.returncode`."""
        return None if self._proc is None else self._proc.poll()

    def send_signal(self, sig: int) -> None:
        """Send a signal to the running program.

        ``sig``: e.g. ``signal.SIGUSR1``.
        """
        if self._proc is None:
            raise RuntimeError("the program is not running")
        self._proc.send_signal(sig)

    def stop(self) -> None:
        """SIGTERM, wait ``stop_timeout_s``, SIGKILL if still running; then read its stderr."""
        proc = self._proc
        if proc is not None and proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(self.stop_timeout_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if self._reader is not None:
            self._reader.join(1.0)
        if proc is not None and proc.stdout is not None:
            proc.stdout.close()
        if self._stderr is not None:
            self._stderr.seek(0)
            self.stderr_text = self._stderr.read()
            self._stderr.close()
            self._stderr = None

    def _read_stdout(self) -> None:
        assert self._proc is not None and self._proc.stdout is not None
        for line in self._proc.stdout:
            if line.startswith("READY ") and not self.ready:
                self.ready = line.split(None, 1)[1].strip()
                self._event.set()
            elif self.on_line is not None:
                self.on_line(line)
        self._event.set()  # EOF: the program ended (before READY if ready is empty)

    def _failure(self) -> str:
        assert self._proc is not None
        code = self._proc.poll()
        if code is None and self._event.is_set():
            # stdout reached EOF: the process is exiting, but may not have been reaped yet
            try:
                code = self._proc.wait(self.stop_timeout_s)
            except subprocess.TimeoutExpired:
                code = None
        tail = ""
        if self._stderr is not None:
            self._stderr.seek(0)
            # the last line that says something (not the frame of a rich error panel)
            lines = [ln.strip().strip(_FRAME).strip() for ln in self._stderr.read().splitlines()]
            lines = [ln for ln in lines if ln]
            tail = lines[-1] if lines else ""
        if code is None:
            return f"no READY line within {self.ready_timeout_s:g} s"
        return f"exited with code {code}" + (f" ({tail})" if tail else "")
