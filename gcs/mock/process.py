"""Run the mock drone as a subprocess: ``with MockProcess(...) as mock: fly(mock.url)``."""

from __future__ import annotations

import json
import signal
import sys
import tempfile
from pathlib import Path
from types import TracebackType
from typing import Any

from gcs.errors import VehicleError
from gcs.mock.child import ChildNotReady, ChildProgram
from gcs.mock.cli import faults_cli_args
from gcs.mock.config import Faults
from gcs.mock.mocap.arena import ArenaOptions

__all__ = ["MockProcess"]


class MockProcess:
    """Context manager around ``python -m gcs.mock``.

    On entry it starts the mock (:class:`gcs.mock.child.ChildProgram`: its own session, its
    ``READY <url>`` line awaited) and exposes :attr:`url`. On exit it sends SIGTERM, waits,
    kills as a fallback, and loads the statistics file into :attr:`stats`.

    ``config_path``: mock profile (YAML); None for the defaults. ``seed``: seed of gusts, noise and
    packet loss. ``faults``: injected faults (times after the first OFFBOARD entry). ``stats_path``:
    where the mock writes its JSON statistics; None uses a temporary file that is removed after
    reading. ``port``: UDP port (0 = any free port). ``gcs_port``: also send to a GCS listening on
    this port. ``ready_timeout_s``: how long to wait for the READY line. ``stop_timeout_s``: how
    long to wait after SIGTERM before SIGKILL. ``arena``: also serve the vehicle's true pose as a
    mock OptiTrack Motive (``--mocap``).

    ``url``: MAVSDK URL, ``udpout://127.0.0.1:<port>``. ``stats``: statistics read on exit (None if
    the mock wrote none). ``mocap_url``: the mock Motive's URL with ``arena`` (empty without).
    """

    def __init__(
        self,
        config_path: str | Path | None = None,
        seed: int = 0,
        faults: Faults | None = None,
        stats_path: str | Path | None = None,
        port: int = 0,
        gcs_port: int | None = None,
        ready_timeout_s: float = 30.0,
        stop_timeout_s: float = 5.0,
        arena: ArenaOptions | None = None,
    ) -> None:
        self.config_path = None if config_path is None else Path(config_path)
        self.seed = seed
        self.faults = faults or Faults()
        self._own_stats = stats_path is None
        self._tmpdir: tempfile.TemporaryDirectory[str] | None = None
        self.stats_path = None if stats_path is None else Path(stats_path)
        self.port_request = port
        self.gcs_port = gcs_port
        self.ready_timeout_s = ready_timeout_s
        self.stop_timeout_s = stop_timeout_s
        self.arena = arena
        self.mocap_url = ""
        self.url = ""
        self.port = 0
        self.pid = 0
        self.stats: dict[str, Any] | None = None
        self._child: ChildProgram | None = None

    def argv(self) -> list[str]:
        """Command line of the mock."""
        args = [sys.executable, "-m", "gcs.mock", "--seed", str(self.seed)]
        args += ["--port", str(self.port_request)]
        if self.config_path is not None:
            args += ["--config", str(self.config_path)]
        if self.gcs_port is not None:
            args += ["--gcs-port", str(self.gcs_port)]
        if self.stats_path is not None:
            args += ["--stats-out", str(self.stats_path)]
        if self.arena is not None:
            args += self.arena.cli_args()
        return args + faults_cli_args(self.faults)

    def __enter__(self) -> MockProcess:
        if self._own_stats:
            self._tmpdir = tempfile.TemporaryDirectory(prefix="gcs-mock-")
            self.stats_path = Path(self._tmpdir.name) / "stats.json"
        self._child = ChildProgram(
            self.argv(), self.ready_timeout_s, self.stop_timeout_s, self._read_line
        )
        try:
            self.url = self._child.start()
        except ChildNotReady as exc:
            self._cleanup()
            raise VehicleError(f"mock drone did not start: {exc}") from None
        self.pid = self._child.pid
        self.port = int(self.url.rsplit(":", 1)[1])
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._child is not None:
            self._child.stop()
        try:
            if self.stats_path is not None and self.stats_path.exists():
                self.stats = json.loads(self.stats_path.read_text())
        finally:
            self._cleanup()

    def lose_link(self) -> None:
        """Start a link loss of ``faults.link_loss_duration_s`` now (the mock's SIGUSR1).

        Lets a test time the loss on an event it saw (e.g. gcs printed that a trial started)
        instead of guessing from the clock how long take-off and settling will take.
        """
        if self._child is None:
            raise RuntimeError("the mock is not running")
        self._child.send_signal(signal.SIGUSR1)

    # -- internals ------------------------------------------------------------------------
    def _read_line(self, line: str) -> None:
        if line.startswith("MOCAP ") and not self.mocap_url:
            self.mocap_url = line.split(None, 1)[1].strip()

    def _cleanup(self) -> None:
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
            self._tmpdir = None
