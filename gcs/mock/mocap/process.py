"""Run the mock motion capture as a subprocess: ``with MocapServerProcess() as m: m.url``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
from types import TracebackType

from gcs.errors import MocapError

__all__ = ["MocapServerProcess"]


class MocapServerProcess:
    """Context manager around ``python -m gcs.mock.mocap``.

    On entry it starts the program, waits for its ``READY <url>`` line (an event set by a
    reader thread) and exposes :attr:`url`; on exit it sends SIGTERM and waits.

    Parameters
    ----------
    args : list of str
        Options of ``python -m gcs.mock.mocap`` (``--rate``, ``--circle``, faults...).
    ready_timeout_s : float
        How long to wait for the READY line [s].

    Attributes
    ----------
    url : str
        The mocap URL (``optitrack://127.0.0.1:<port>/<body>?interface=127.0.0.1``).
    pid : int
        Process id.
    stderr_text : str
        What the program wrote on stderr (its counters as JSON last), read on exit.
    """

    def __init__(self, args: list[str] | None = None, ready_timeout_s: float = 20.0) -> None:
        self.args = list(args or [])
        self.ready_timeout_s = ready_timeout_s
        self.url = ""
        self.pid = 0
        self.stderr_text = ""
        self._proc: subprocess.Popen[str] | None = None
        self._ready = threading.Event()
        self._stderr = tempfile.TemporaryFile("w+")  # noqa: SIM115 (closed in __exit__)

    def _read_stdout(self) -> None:
        assert self._proc is not None and self._proc.stdout is not None
        for line in self._proc.stdout:
            if line.startswith("READY ") and not self.url:
                self.url = line.split(maxsplit=1)[1].strip()
                self._ready.set()
        self._ready.set()  # ended without READY

    def __enter__(self) -> MocapServerProcess:
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "gcs.mock.mocap", *self.args],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
            start_new_session=True,
        )
        self.pid = self._proc.pid
        threading.Thread(target=self._read_stdout, daemon=True).start()
        if not self._ready.wait(self.ready_timeout_s) or not self.url:
            self.__exit__(None, None, None)
            raise MocapError(f"mock motion capture did not start: {self.stderr_text.strip()}")
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        proc = self._proc
        if proc is not None and proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self._stderr.seek(0)
        self.stderr_text = self._stderr.read()
        self._stderr.close()
