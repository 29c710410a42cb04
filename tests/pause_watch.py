"""How long the machine left a real-time thread unscheduled while the tests ran.

A flight's streams are watched for gaps (a setpoint sent late, a stale mocap stream), and a
test of the flights fails when the machine pauses gcs's threads for longer than those limits.
Whether such a pause was the machine's (every real-time thread late at the same moment, time
the host took from the virtual machine) or one process's own is not in a failed flight's
output. So the test session starts a process of its own (``python tests/pause_watch.py``: a thread
in pytest's process would wait for the interpreter lock whenever a test holds it) whose thread
at the flight threads' priority (:func:`gcs.io.scheduling.raise_thread`) wakes every
:data:`PERIOD_S` and notes each wake later than :data:`PAUSE_S`, and which reads the host's
steal time (``/proc/stat``). When its input closes it prints one line: what it saw, with
wall-clock times to set beside a failed flight's, for the session's summary.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from gcs.io.scheduling import raise_thread

PERIOD_S = 0.01
"""How often the watching thread wakes [s]."""

PAUSE_S = 0.15
"""A wake later than this is a pause [s] (gcs's flight loop sends every 17-50 ms)."""

SHOWN = 8
"""The longest pauses listed in the summary."""


def steal_s(stat: Path = Path("/proc/stat")) -> float | None:
    """Time the host has taken from this machine's CPUs since boot [s], or None if unknown.

    Parameters
    ----------
    stat : pathlib.Path
        The kernel's CPU statistics (the ``cpu`` line's eighth field, in clock ticks).
    """
    try:
        fields = stat.read_text().splitlines()[0].split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


@dataclass
class PauseWatch:
    """A thread that notes when it was woken late (see the module's docstring).

    Parameters
    ----------
    clock, sleep, wall : callable
        The monotonic clock [s], a sleep [s] and the wall clock [s since the epoch]; the
        system's by default.
    """

    clock: Callable[[], float] = time.monotonic
    sleep: Callable[[float], None] = time.sleep
    wall: Callable[[], float] = time.time
    pauses: list[tuple[float, float]] = field(default_factory=list)  # (wall time, late) [s]
    raised: bool = False
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None
    _started_s: float = 0.0
    _steal_before_s: float | None = None

    def start(self) -> None:
        """Start watching in a daemon thread."""
        self._started_s = self.clock()
        self._steal_before_s = steal_s()
        self._thread = threading.Thread(target=self._run, name="pause-watch", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop watching (waits for the thread)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()

    def watch(self, wakes: int | None = None) -> None:
        """Wake every :data:`PERIOD_S` until stopped (or ``wakes`` times), noting pauses."""
        count = 0
        while not self._stop.is_set() and (wakes is None or count < wakes):
            before = self.clock()
            self.sleep(PERIOD_S)
            late_s = self.clock() - before - PERIOD_S
            if late_s > PAUSE_S:
                self.pauses.append((self.wall() - late_s, late_s))
            count += 1

    def _run(self) -> None:
        self.raised = raise_thread() is not None
        self.watch()

    def summary(self) -> str:
        """One line: the pauses seen (the longest, with their wall-clock times) and the steal."""
        watched_s = self.clock() - self._started_s
        after = steal_s()
        steal = (
            ""
            if after is None or self._steal_before_s is None
            else f"; host steal {after - self._steal_before_s:.1f} s"
        )
        where = "a real-time thread" if self.raised else "a thread at normal priority"
        head = f"machine pauses ({where} woken more than {PAUSE_S * 1e3:.0f} ms late)"
        if not self.pauses:
            return f"{head}: none in {watched_s:.0f} s{steal}"
        longest = sorted(self.pauses, key=lambda p: -p[1])[:SHOWN]
        listed = ", ".join(
            f"{late_s:.2f} s at {time.strftime('%H:%M:%S', time.gmtime(at_s))}"
            f".{int(at_s % 1 * 10)} UTC"
            for at_s, late_s in sorted(longest)
        )
        return f"{head}: {len(self.pauses)} in {watched_s:.0f} s, the longest {listed}{steal}"


def start_process() -> subprocess.Popen[str]:
    """This module as a process watching until its input closes (:func:`main`)."""
    return subprocess.Popen(
        [sys.executable, __file__], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )


def summary_of(process: subprocess.Popen[str]) -> str:
    """Close the input of a :func:`start_process` process; the line it printed."""
    out, _ = process.communicate("", timeout=10)
    return out.strip() or f"machine pauses: the watch ended with code {process.returncode}"


def main() -> None:
    """Watch until standard input closes, then print :meth:`PauseWatch.summary`."""
    watch = PauseWatch()
    watch.start()
    sys.stdin.read()
    watch.stop()
    print(watch.summary(), flush=True)


if __name__ == "__main__":
    main()
