"""Read one rigid body from a motion-capture system, off the asyncio loop.

:class:`MocapClient` starts the reader process (:mod:`gcs.flight.mocap.reader`, the
``motioncapture`` library), and a thread of this process that turns its records into
:class:`MocapSample` objects: it keeps the last seconds for the health checks
(:meth:`MocapClient.recent`), a journal of the samples from :meth:`MocapClient.start_journal`
to :meth:`MocapClient.drain` (a trial's raw-sample file; none is kept outside) and calls
``on_sample`` for each frame (in that thread: hand work to the asyncio loop with
``loop.call_soon_threadsafe``). Every accessor is thread-safe and returns at once, so the
setpoint loop can poll :meth:`MocapClient.latest` without ever waiting for the mocap.

Samples are in the mocap system's axes; map them with
:class:`gcs.core.frames.FrameMapping`.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import numpy as np

from gcs.errors import MocapError
from gcs.flight.mocap.reader import HEADER, SAMPLE
from gcs.io.mocap_samples import MocapSeries
from gcs.io.mocap_source import MocapSource
from gcs.io.scheduling import raise_thread

__all__ = ["MocapSample", "MocapClient", "series_of"]

#: Most frames a client keeps per second of history (the highest rate it expects).
_MAX_RATE_HZ = 1000
#: An open journal (a trial's raw-sample file) keeps at most this many undrained samples.
_JOURNAL_MAX = 2_000_000


@dataclass(frozen=True)
class MocapSample:
    """One frame of the rigid body, as delivered (system axes).

    Parameters
    ----------
    seq : int
        Delivery counter of the client (0, 1, 2, ...).
    t_receipt_s : float
        ``time.monotonic()`` when the library returned the frame [s].
    t_mocap_s : float
        The system's own time stamp [s]; NaN (the library gives none).
    tracked : bool
        The rigid body was in the frame.
    pos_m : tuple of float
        Position in the system's axes [m] (NaN when not tracked).
    quat_wxyz : tuple of float
        Orientation body to system world, ``w, x, y, z`` (NaN when not tracked).
    """

    seq: int
    t_receipt_s: float
    t_mocap_s: float
    tracked: bool
    pos_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]


def connect_hint(source: MocapSource, problem: str) -> str:
    """What fixes a failed connection, appended to the library's message ('' if unknown).

    An OptiTrack client joins Motive's multicast group on an interface: without
    ``?interface=`` it asks the system's default, and a machine without a multicast route
    answers with the library's ``set_option: No such device``.

    Parameters
    ----------
    source : MocapSource
        What was connected to.
    problem : str
        The failure as reported.

    Returns
    -------
    str
        ``"; ..."`` naming the option or setting, or ``""``.
    """
    text = problem.lower()
    multicast = "no such device" in text or "set_option" in text or "multicast" in text
    silent = "no answer" in text and source.interface_ip == "0.0.0.0"
    if source.system == "optitrack" and (multicast or silent):
        where = source.interface_ip
        return (
            f"; the client joins Motive's multicast group on interface {where}: give the local "
            "address that reaches Motive with ?interface=IP in the URL (e.g. "
            f"optitrack://{source.host}/{source.rigid_body}?interface=192.168.1.20), or add a "
            "multicast route"
        )
    return ""


def series_of(samples: list[MocapSample]) -> MocapSeries:
    """Arrays of a list of samples.

    Parameters
    ----------
    samples : list of MocapSample
        Samples in delivery order.

    Returns
    -------
    MocapSeries
    """
    if not samples:
        return MocapSeries.empty()
    return MocapSeries(
        np.array([s.seq for s in samples], dtype=np.int64),
        np.array([s.t_receipt_s for s in samples]),
        np.array([s.t_mocap_s for s in samples]),
        np.array([s.tracked for s in samples], dtype=bool),
        np.array([s.pos_m for s in samples]),
        np.array([s.quat_wxyz for s in samples]),
    )


def _proc_cpu_s(stat: str) -> float:
    """CPU seconds (user + system) from a /proc ``stat`` file (Linux), NaN if unknown."""
    try:
        fields = Path(stat).read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return math.nan


class MocapClient:
    """A motion-capture stream of one rigid body (context manager).

    Parameters
    ----------
    source : MocapSource
        System, server and rigid body.
    on_sample : callable or None
        Called with each :class:`MocapSample`, in the client's thread.
    history_s : float
        How much of the stream :meth:`recent` can return [s].
    connect_timeout_s : float
        How long :meth:`start` waits for the server's answer [s].
    """

    def __init__(
        self,
        source: MocapSource,
        on_sample: Callable[[MocapSample], None] | None = None,
        history_s: float = 5.0,
        connect_timeout_s: float = 5.0,
    ) -> None:
        self.source = source
        self.on_sample = on_sample
        self.connect_timeout_s = connect_timeout_s
        self._history: deque[MocapSample] = deque(maxlen=int(history_s * _MAX_RATE_HZ))
        self._journal: list[MocapSample] | None = None  # open between start_journal and drain
        self._journal_dropped = 0
        self._cond = threading.Condition()
        self._connected = threading.Event()
        self._ended = threading.Event()
        self._problem: str | None = None
        self._names: tuple[str, ...] = ()
        self._count = 0
        self._proc: subprocess.Popen[bytes] | None = None
        self._thread: threading.Thread | None = None
        self._cpu_at_stop = {"reader": math.nan, "thread": math.nan}
        self._t_start = math.nan

    # lifecycle -----------------------------------------------------------------------------

    def start(self) -> MocapClient:
        """Start the reader and wait until the server answered.

        Returns
        -------
        MocapClient
            self

        Raises
        ------
        MocapError
            No answer within ``connect_timeout_s``, or the library refused the connection.
        """
        if self._proc is not None:
            raise MocapError("mocap client already started (a client runs once)")
        read_fd, write_fd = os.pipe()
        spec = {
            "system": self.source.system,
            "config": self.source.library_config(),
            "body": self.source.rigid_body,
        }
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "gcs.flight.mocap.reader", str(write_fd), json.dumps(spec)],
                pass_fds=(write_fd,),
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,  # the library prints diagnostics there
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        finally:
            os.close(write_fd)
        self._t_start = time.monotonic()
        self._thread = threading.Thread(
            target=self._read, args=(os.fdopen(read_fd, "rb"),), name="mocap-client", daemon=True
        )
        self._thread.start()
        where = f"{self.source.system} server {self.source.host}:{self.source.port}"
        with self._cond:
            self._cond.wait_for(
                lambda: self._connected.is_set() or self._ended.is_set(), self.connect_timeout_s
            )
        if not self._connected.is_set():
            problem = self._problem or f"no answer from {where} within {self.connect_timeout_s} s"
            self.stop()
            raise MocapError(problem + connect_hint(self.source, problem))
        return self

    def stop(self) -> None:
        """End the reader process and the thread (idempotent)."""
        proc = self._proc
        if proc is not None and proc.poll() is None:
            self._cpu_at_stop = self.cpu_seconds()
            proc.terminate()
            try:
                proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)

    def __enter__(self) -> MocapClient:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    # the thread ----------------------------------------------------------------------------

    def _read(self, stream) -> None:
        raise_thread()  # it forwards the frames to the vehicle: gcs.io.scheduling
        try:
            while True:
                head = stream.read(HEADER.size)
                if len(head) < HEADER.size:
                    break
                kind, length = HEADER.unpack(head)
                payload = stream.read(length)
                if len(payload) < length:
                    break
                self._record(kind, payload)
        except Exception as exc:  # a failing on_sample ends the stream, with the reason
            self._problem = f"mocap client failed: {exc!r}"
        finally:
            stream.close()
            self._end()

    def _record(self, kind: bytes, payload: bytes) -> None:
        if kind == b"S":
            seq, t, tracked, *values = SAMPLE.unpack(payload)
            sample = MocapSample(seq, t, math.nan, tracked, tuple(values[:3]), tuple(values[3:]))
            with self._cond:
                self._history.append(sample)
                journal = self._journal
                if journal is not None:
                    journal.append(sample)
                    if len(journal) > _JOURNAL_MAX:
                        del journal[0]
                        self._journal_dropped += 1
                self._count += 1
                self._cond.notify_all()
            if self.on_sample is not None:
                self.on_sample(sample)
        elif kind == b"C":
            with self._cond:
                self._connected.set()
                self._cond.notify_all()
        elif kind == b"N":
            self._names = tuple(json.loads(payload))
        elif kind == b"E":
            self._problem = payload.decode(errors="replace")

    def _end(self) -> None:
        if self._proc is not None and self._proc.poll() is None:
            self._cpu_at_stop = self.cpu_seconds()
            self._proc.terminate()  # we stopped reading (a failure here): end the reader too
        if self._problem is None:
            code = self._proc.wait() if self._proc is not None else None
            if code is not None and code < 0:
                self._problem = f"mocap reader ended by signal {-code}"
            else:
                self._problem = f"mocap reader exited (code {code})"
        with self._cond:
            self._ended.set()
            self._cond.notify_all()

    # accessors (any thread) ----------------------------------------------------------------

    @property
    def reader_pid(self) -> int | None:
        """Process id of the reader (None before :meth:`start`)."""
        return None if self._proc is None else self._proc.pid

    @property
    def names_seen(self) -> tuple[str, ...]:
        """Names of the rigid bodies in the most recent frame that changed them."""
        return self._names

    def problem(self) -> str | None:
        """Why the stream has ended (None while the reader runs).

        Returns
        -------
        str or None
        """
        return self._problem if self._ended.is_set() else None

    def latest(self) -> MocapSample | None:
        """The newest sample, tracked or not (None before the first).

        Returns
        -------
        MocapSample or None
        """
        with self._cond:
            return self._history[-1] if self._history else None

    def recent(self, duration_s: float, now_s: float | None = None) -> MocapSeries:
        """Samples received in the last ``duration_s`` seconds.

        Parameters
        ----------
        duration_s : float
            Window length [s] (at most ``history_s``).
        now_s : float or None
            End of the window (``time.monotonic()`` if None).

        Returns
        -------
        MocapSeries
        """
        start = (time.monotonic() if now_s is None else now_s) - duration_s
        with self._cond:
            newest_first = itertools.takewhile(
                lambda s: s.t_receipt_s >= start, reversed(self._history)
            )
            picked = list(newest_first)[::-1]
        return series_of(picked)

    def start_journal(self, pre_s: float = 0.0, now_s: float | None = None) -> None:
        """Journal the samples delivered from now on, until :meth:`drain` (a trial's raw file),
        beginning with those received in the last ``pre_s`` seconds.

        No journal is kept outside a recording, so opening one costs only its ``pre_s`` of
        history, whatever ran before: one kept from the client's start held the whole stream
        before the first trial (minutes of frames), and emptying it ran on the flight's event
        loop just before the trial's first setpoint. An open journal is dropped and a new one
        opened.

        Parameters
        ----------
        pre_s : float
            How much of the recent stream the journal starts with [s] (at most ``history_s``).
        now_s : float or None
            The start (``time.monotonic()`` if None).
        """
        start = (time.monotonic() if now_s is None else now_s) - pre_s
        with self._cond:
            recent = itertools.takewhile(lambda s: s.t_receipt_s >= start, reversed(self._history))
            self._journal = list(recent)[::-1] if pre_s > 0 else []

    def drain(self) -> MocapSeries:
        """The samples journaled since :meth:`start_journal`; the journal is closed (empty
        when none was open).

        Returns
        -------
        MocapSeries
        """
        with self._cond:
            taken, self._journal = self._journal, None
        return series_of(taken or [])

    def wait_until(self, predicate: Callable[[MocapSample], bool], timeout_s: float) -> MocapSample:
        """Block until a sample delivered from now on satisfies ``predicate``.

        Parameters
        ----------
        predicate : callable
            Test on a :class:`MocapSample`.
        timeout_s : float
            Longest wait [s].

        Returns
        -------
        MocapSample
            The first sample that satisfied it.

        Raises
        ------
        MocapError
            Timeout, or the stream ended.
        """
        deadline = time.monotonic() + timeout_s
        with self._cond:
            seen = self._count
            while True:
                new = self._count - seen
                if new:
                    recent = list(itertools.islice(reversed(self._history), new))[::-1]
                    seen = self._count
                    for sample in recent:
                        if predicate(sample):
                            return sample
                if self._ended.is_set():
                    raise MocapError(f"mocap stream ended: {self._problem}")
                left = deadline - time.monotonic()
                if left <= 0:
                    raise MocapError(f"no matching mocap sample within {timeout_s} s")
                self._cond.wait(left)

    def cpu_seconds(self) -> dict[str, float]:
        """CPU time used so far by the reader process and by the client thread (Linux).

        After :meth:`stop`, the figures at the moment of stopping.

        Returns
        -------
        dict
            ``{"reader": s, "thread": s}``, NaN where unknown.
        """
        proc, thread = self._proc, self._thread
        if proc is None or proc.poll() is not None or thread is None:
            return dict(self._cpu_at_stop)
        return {
            "reader": _proc_cpu_s(f"/proc/{proc.pid}/stat"),
            "thread": _proc_cpu_s(f"/proc/self/task/{thread.native_id}/stat"),
        }

    def stats(self) -> dict[str, float]:
        """Counters: samples delivered, tracked samples in the history, samples an open journal
        dropped (undrained for too long), seconds since start.

        Returns
        -------
        dict
        """
        with self._cond:
            history = list(self._history)
        return {
            "samples": float(self._count),
            "tracked_in_history": float(sum(s.tracked for s in history)),
            "journal_dropped": float(self._journal_dropped),
            "running_s": time.monotonic() - self._t_start,
        }
