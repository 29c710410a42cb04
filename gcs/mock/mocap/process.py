"""Run the mock motion capture as a subprocess: ``with MocapServerProcess() as m: m.url``."""

from __future__ import annotations

import sys
from types import TracebackType

from gcs.errors import MocapError
from gcs.mock.child import ChildNotReady, ChildProgram

__all__ = ["MocapServerProcess"]


class MocapServerProcess:
    """Context manager around ``python -m gcs.mock.mocap``.

    On entry it starts the program (:class:`gcs.mock.child.ChildProgram`: its own session,
    its ``READY <url>`` line awaited) and exposes :attr:`url`; on exit it sends SIGTERM,
    waits, and kills as a fallback.

    ``args``: options of ``python -m gcs.mock.mocap`` (``--rate``, ``--circle``, faults...).
    ``ready_timeout_s``: how long to wait for the READY line [s]. ``program``: the command before
    ``args`` (None: ``python -m gcs.mock.mocap``); another program that serves NatNet the same way
    (prints ``READY <url>``, counters on stderr). ``name``: what the program is called in the error
    when it does not start.

    ``url``: the mocap URL (``optitrack://127.0.0.1:<port>/<body>?interface=127.0.0.1``).
    ``stderr_text``: what the program wrote on stderr (its counters as JSON last), read on exit.
    """

    def __init__(
        self,
        args: list[str] | None = None,
        ready_timeout_s: float = 20.0,
        *,
        program: list[str] | None = None,
        name: str = "mock motion capture",
    ) -> None:
        self.args = list(args or [])
        self.ready_timeout_s = ready_timeout_s
        self.url = ""
        self.pid = 0
        self.stderr_text = ""
        self._name = name
        command = [sys.executable, "-m", "gcs.mock.mocap"] if program is None else program
        self._child = ChildProgram([*command, *self.args], ready_timeout_s)

    def __enter__(self) -> MocapServerProcess:
        try:
            self.url = self._child.start()
        except ChildNotReady as exc:
            self.stderr_text = self._child.stderr_text
            raise MocapError(f"{self._name} did not start: {exc}") from None
        self.pid = self._child.pid
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._child.stop()
        self.stderr_text = self._child.stderr_text
