"""Run the mock drone as a subprocess: ``with MockProcess(...) as mock: fly(mock.url)``."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from gcs.errors import VehicleError
from gcs.mock.cli import faults_cli_args
from gcs.mock.config import Faults
from gcs.mock.mocap.arena import ArenaOptions

__all__ = ["MockProcess"]


class MockProcess:
    """Context manager around ``python -m gcs.mock``.

    On entry it starts the mock, waits for its ``READY <url>`` line (an event set by a reader
    thread, no polling) and exposes :attr:`url`. On exit it sends SIGTERM, waits, kills as a
    fallback, and loads the statistics file into :attr:`stats`.

    Parameters
    ----------
    config_path : str, Path or None
        Mock profile (YAML); None for the defaults.
    seed : int
        Seed of gusts, noise and packet loss.
    faults : Faults or None
        Injected faults (times after the first OFFBOARD entry).
    stats_path : str, Path or None
        Where the mock writes its JSON statistics; None uses a temporary file that is removed
        after reading.
    port : int
        UDP port (0 = any free port).
    gcs_port : int or None
        Also send to a GCS listening on this port.
    ready_timeout_s : float
        How long to wait for the READY line.
    stop_timeout_s : float
        How long to wait after SIGTERM before SIGKILL.
    arena : ArenaOptions or None
        Also serve the vehicle's true pose as a mock OptiTrack Motive (``--mocap``).

    Attributes
    ----------
    url : str
        MAVSDK URL, ``udpout://127.0.0.1:<port>``.
    port : int
        Bound UDP port.
    pid : int
        Process id of the mock.
    stats : dict or None
        Statistics read on exit (None if the mock wrote none).
    mocap_url : str
        The mock Motive's URL with ``arena`` (empty without).
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
        self._proc: subprocess.Popen[str] | None = None
        self._ready = threading.Event()
        self._stderr: IO[str] | None = None
        self._reader: threading.Thread | None = None

    def argv(self) -> list[str]:
        """Command line of the mock.

        Returns
        -------
        list of str
        """
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
        self._stderr = tempfile.TemporaryFile("w+")
        self._proc = subprocess.Popen(
            self.argv(),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
            # own session: a Ctrl-C in the terminal reaches gcs, which lands the mock, and not
            # the mock itself (which would die before it could be landed)
            start_new_session=True,
        )
        self.pid = self._proc.pid
        self._reader = threading.Thread(target=self._read_stdout, daemon=True)
        self._reader.start()
        if not self._ready.wait(self.ready_timeout_s) or not self.url:
            why = self._failure()
            self._terminate()
            self._cleanup()
            raise VehicleError(f"mock drone did not start: {why}")
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._terminate()
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
        assert self._proc is not None, "the mock is not running"
        self._proc.send_signal(signal.SIGUSR1)

    # -- internals ------------------------------------------------------------------------
    def _read_stdout(self) -> None:
        assert self._proc is not None and self._proc.stdout is not None
        for line in self._proc.stdout:
            if line.startswith("MOCAP ") and not self.mocap_url:
                self.mocap_url = line.split(None, 1)[1].strip()
            if line.startswith("READY ") and not self.url:
                self.url = line.split(None, 1)[1].strip()
                self.port = int(self.url.rsplit(":", 1)[1])
                self._ready.set()
        self._ready.set()  # EOF: the process ended (before READY if url is empty)

    def _failure(self) -> str:
        assert self._proc is not None
        code = self._proc.poll()
        if code is None and self._ready.is_set():
            # stdout reached EOF: the process is exiting, but may not have been reaped yet
            try:
                code = self._proc.wait(self.stop_timeout_s)
            except subprocess.TimeoutExpired:
                code = None
        tail = ""
        if self._stderr is not None:
            self._stderr.seek(0)
            lines = [ln.strip() for ln in self._stderr.read().splitlines() if ln.strip()]
            tail = lines[-1] if lines else ""
        if code is None:
            return f"no READY line within {self.ready_timeout_s:g} s"
        return f"exited with code {code}" + (f" ({tail})" if tail else "")

    def _terminate(self) -> None:
        proc = self._proc
        if proc is None or proc.poll() is not None:
            return
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(self.stop_timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()

    def _cleanup(self) -> None:
        if self._reader is not None:
            self._reader.join(1.0)
        if self._proc is not None and self._proc.stdout is not None:
            self._proc.stdout.close()
        if self._stderr is not None:
            self._stderr.close()
            self._stderr = None
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
            self._tmpdir = None
