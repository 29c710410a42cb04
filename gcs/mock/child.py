"""A mock program as a child process: started in its own session, ready when it says so.

The mock drone (``python -m gcs.mock``) and the mock motion capture (``python -m
gcs.mock.mocap``) both print ``READY <url>`` on stdout once they serve. :class:`ChildProgram`
starts such a program in a session of its own (a Ctrl-C in the terminal reaches gcs, which then
lands the mock, and not the mock, which would die before it could be landed), waits for that
line (an event set by a reader thread: no polling), hands every other stdout line to a
callback, and stops it with SIGTERM, then SIGKILL if it does not end in time.

A parent that dies without stopping it (killed, crashed) would leave it serving for ever, its
own session out of reach of the terminal. So the child is handed the read end of a pipe whose
only write end the parent holds: when the parent ends, however it ends, the pipe reads EOF and
the program stops as on SIGTERM (:func:`end_with_parent`, called by each mock's main). A pipe
rather than Linux's ``PR_SET_PDEATHSIG``, which follows the parent's *thread* (the mock is often
started from a worker thread) and exists on Linux alone.
"""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
import threading
from collections.abc import Callable, Sequence
from typing import IO

__all__ = ["ChildProgram", "ChildNotReady", "end_with_parent"]

#: The environment variable that names the child's end of the parent's pipe.
PARENT_PIPE_ENV = "GCS_PARENT_PIPE_FD"

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
        self._parent_end: int | None = None
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
        read_end, self._parent_end = os.pipe()  # neither inherited by other children
        try:
            self._proc = subprocess.Popen(
                self.argv,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=self._stderr,
                text=True,
                env={**os.environ, "PYTHONUNBUFFERED": "1", PARENT_PIPE_ENV: str(read_end)},
                start_new_session=True,
                pass_fds=(read_end,),
            )
        finally:
            os.close(read_end)
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
        if self._parent_end is not None:
            os.close(self._parent_end)
            self._parent_end = None
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


def end_with_parent() -> None:
    """In a program started by :class:`ChildProgram`: SIGTERM to this process once the parent
    has ended (its pipe reads EOF), so that the program's own SIGTERM handling stops it. Does
    nothing in a program started otherwise (a user's terminal)."""
    fd = os.environ.pop(PARENT_PIPE_ENV, None)
    if fd is None or not fd.isdigit():
        return

    def watch() -> None:
        try:
            while os.read(int(fd), 64):  # the parent never writes: only EOF returns
                pass
        except OSError:
            pass
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=watch, name="end-with-parent", daemon=True).start()
