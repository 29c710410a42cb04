"""The motion-capture lab of the real-firmware tests: PX4 SIH's ground truth served over NatNet
as a lab's OptiTrack Motive would (the lab's rig).

The rig is a program of its own, as Motive runs on a PC of its own: :class:`LabRig` starts it
and gives its URL; from the checkout it runs as ``PYTHONPATH=tests python -m px4.lab_rig N
[options]``. It serves PX4 SITL instance ``N``'s ground truth (:class:`SihTruth`) through gcs's
mock Motive (:func:`gcs.mock.mocap.cli.serve`: one ``READY <url>`` line on stdout, its
counters on stderr when SIGTERM or Ctrl-C stops it), with the mock Motive's own options for
the frame rate, NatNet version, marker noise and seed, command port, the room's axes and
heading, latency and body name (:func:`rig_command`).

PX4 SITL with the built-in SIH physics streams the simulated vehicle's true state as MAVLink
``HIL_STATE_QUATERNION`` (25 Hz) on its display link: PX4 instance ``N`` sends it to UDP port
``19410 + N`` on 127.0.0.1 (``px4-rc.mavlink``). :class:`SihTruth` listens there and keeps the
last states with their receipt times; it turns each into a NED pose relative to where the
vehicle was first seen (the room's origin under the vehicle at start, as a lab sets its ground
plane and origin once), and :class:`gcs.mock.mocap.server.NatNetServer` serves that as an
OptiTrack rigid body: what a lab's Motive would stream while the vehicle flies.

The served pose. Asked for time ``t`` (the frame's instant minus the rig's latency, on the
receipt clock), :class:`SihTruth` gives the truth as it was at ``t``: interpolated between the
two states made around ``t`` (position linearly, attitude along the shortest rotation;
states are 40 ms apart), never extrapolated past a newer state. Only when ``t`` is newer than
the newest state is that state carried forward with its velocity (for at most 60 ms: beyond,
it is held), so the mocap rate (120 Hz) sees a moving body rather than steps; a state is served
for up to 2 s (PX4 SITL's clock, and its vehicle, stop while the machine starves it). Before
the first state, or older than the states kept, the body is out of view.

When a state was made. The message's ``time_usec`` is 0 in PX4 v1.16 SIH's display stream, so
the receipt is the only clock, and on a loaded machine a state can reach the rig tens of
milliseconds late (PX4 or the rig descheduled). Taken as made at its receipt, such a state
would move the served body by its speed times the delay in one frame: 0.125 m at 2.5 m/s and
50 ms, a jump no vehicle makes, which gcs's mocap watch rightly refuses. So each state's time
is its predecessor's plus the stream's mean interval, pulled a tenth of the way toward its
receipt (:func:`state_time`), and never later than its receipt: a late state moves the body by
a tenth of that; a receipt more than 0.2 s after the prediction (PX4 stopped) restarts the
clock there.

The message carries latitude and longitude in 1e-7 degrees (about 1.1 cm north, 0.75 cm
east at 47 degrees) and altitude in millimetres: the served pose has that resolution, coarser
than a real mocap's sub-millimetre noise but far below the simulated vehicle's own wander
(decimetres).
"""

from __future__ import annotations

import math
import socket
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from pymavlink.dialects.v20 import common as mavlink2

from gcs.core.frames import SYSTEM_FRAMES
from gcs.io.scheduling import raise_thread
from gcs.mock.mocap.cli import parse_version, serve
from gcs.mock.mocap.process import MocapServerProcess

__all__ = [
    "SIH_DISPLAY_PORT",
    "LabRig",
    "SihState",
    "SihTruth",
    "main",
    "pose_between",
    "rig_command",
    "sih_display_port",
    "state_time",
]

#: UDP port PX4 instance 0 sends the SIH display stream to (instance N: this + N).
SIH_DISPLAY_PORT = 19410
_EARTH_RADIUS_M = 6_378_137.0


def sih_display_port(instance: int) -> int:
    """The UDP port PX4 SITL instance ``instance`` sends its SIH ground truth to.

    Parameters
    ----------
    instance : int
        PX4's ``-i`` instance number (>= 0).

    Returns
    -------
    int
    """
    if instance < 0:
        raise ValueError(f"instance must be >= 0, got {instance}")
    return SIH_DISPLAY_PORT + instance


def state_time(
    previous_s: float | None,
    receipt_s: float,
    period_s: float | None,
    gain: float = 0.1,
    resync_s: float = 0.2,
) -> float:
    """When a state was made, on the receipt clock (see the module's docstring).

    Parameters
    ----------
    previous_s : float or None
        The previous state's time [s]; None for the first state.
    receipt_s : float
        This state's receipt [s].
    period_s : float or None
        The stream's mean interval between states [s]; None while unknown.
    gain : float
        Fraction of the way from the prediction to the receipt, in (0, 1].
    resync_s : float
        A receipt this much later than the prediction restarts the clock at the receipt [s].

    Returns
    -------
    float
        The state's time [s]: the receipt for the first state, without a period or after a
        stop; else ``previous + period + gain (receipt - previous - period)``, at most the
        receipt.
    """
    if previous_s is None or period_s is None:
        return receipt_s
    predicted = previous_s + period_s
    if receipt_s - predicted > resync_s:
        return receipt_s
    # never after its receipt: states that come faster than the mean interval (a burst after a
    # stall) would otherwise run the clock ahead of the receipts, and then backwards
    return min(predicted + gain * (receipt_s - predicted), receipt_s)


@dataclass(frozen=True)
class SihState:
    """One ground-truth state, relative to the first one seen.

    Parameters
    ----------
    t_s : float
        When it was made, on the receipt clock (:func:`state_time`) [s].
    t_receipt_s : float
        Receipt time on ``time.monotonic()`` [s].
    pos_ned_m : numpy.ndarray
        Position from the first state seen, shape (3,) [m, NED].
    vel_ned_m_s : numpy.ndarray
        Velocity, shape (3,) [m/s, NED].
    quat_wxyz : numpy.ndarray
        Attitude FRD to NED, shape (4,).
    """

    t_s: float
    t_receipt_s: float
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    quat_wxyz: np.ndarray


def _slerp(q0: np.ndarray, q1: np.ndarray, w: float) -> np.ndarray:
    """The attitude a fraction ``w`` of the way from ``q0`` to ``q1`` (shortest rotation)."""
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly equal: the chord is the arc
        q = q0 + w * (q1 - q0)
    else:
        theta = math.acos(dot)
        q = (math.sin((1.0 - w) * theta) * q0 + math.sin(w * theta) * q1) / math.sin(theta)
    return q / np.linalg.norm(q)


def pose_between(
    states: tuple[SihState, ...] | list[SihState],
    t_s: float,
    max_age_s: float,
    max_extrapolation_s: float,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The pose at ``t_s`` from states in order (see the module's docstring).

    Parameters
    ----------
    states : sequence of SihState
        States, oldest first.
    t_s : float
        Time on the receipt clock, as the states' ``t_s`` [s].
    max_age_s : float
        A newest state older than this at ``t_s`` is not served [s].
    max_extrapolation_s : float
        Longest time the newest state is carried forward with its velocity [s].

    Returns
    -------
    tuple of numpy.ndarray or None
        Position (3,) [m, NED] and attitude ``w, x, y, z`` (4,); None before the first state,
        or when the newest is older than ``max_age_s``.
    """
    if not states or t_s < states[0].t_s:
        return None
    newest = states[-1]
    if t_s >= newest.t_s:
        age_s = t_s - newest.t_s
        if age_s > max_age_s:
            return None
        ahead_s = min(age_s, max_extrapolation_s)
        return newest.pos_ned_m + newest.vel_ned_m_s * ahead_s, newest.quat_wxyz
    after = next(i for i, s in enumerate(states) if s.t_s > t_s)
    a, b = states[after - 1], states[after]
    w = (t_s - a.t_s) / (b.t_s - a.t_s)
    return a.pos_ned_m + w * (b.pos_ned_m - a.pos_ned_m), _slerp(a.quat_wxyz, b.quat_wxyz, w)


class SihTruth:
    """Receives PX4 SIH's ``HIL_STATE_QUATERNION`` on 127.0.0.1 in a thread.

    Use as a context manager, or :meth:`start` and :meth:`close`. Calling the object is the
    pose function of :class:`gcs.mock.mocap.server.NatNetServer` in NED (wrap it with
    :func:`gcs.mock.mocap.scripted.in_room` for the room's axes).

    Parameters
    ----------
    port : int
        UDP port to listen on (:func:`sih_display_port`); 0: a free one, then in :attr:`port`.
    max_age_s : float
        A state older than this is not served (the body counts as out of view) [s]. PX4 SITL's
        clock stops while the machine starves it of CPU (0.5 s and more at a load average of
        14-30 on 2 cores), and its simulated vehicle with it: the last state is then still
        where the vehicle is, and a lab's Motive would go on streaming it. So the default
        serves it for 2 s; a PX4 that has stopped for longer (or died) is out of view.
    epoch_s : float
        ``time.monotonic()`` at time 0 of the calls (the server's epoch,
        :attr:`gcs.mock.mocap.server.NatNetServer.epoch_s`); 0: calls take monotonic time.
    """

    #: Longest time a state is carried forward with its velocity [s] (beyond, it is held:
    #: PX4's own clock may have stopped, and its vehicle with it): one and a half intervals,
    #: so that a stream that stopped and resumes moves the body by little more than one.
    MAX_EXTRAPOLATION_S = 0.06
    #: States kept (25 Hz: 2.6 s, far more than any latency of the rig looks back).
    HISTORY = 64
    #: A receipt this much later than predicted restarts the states' clock (PX4 stopped) [s].
    RESYNC_S = 0.2

    def __init__(self, port: int, max_age_s: float = 2.0, epoch_s: float = 0.0) -> None:
        self.port = port
        self.max_age_s = max_age_s
        self.epoch_s = epoch_s
        self.received = 0
        self._ref: tuple[float, float, float] | None = None
        self._states: deque[SihState] = deque(maxlen=self.HISTORY)
        self._intervals: deque[float] = deque(maxlen=self.HISTORY)
        self._lock = threading.Lock()
        self._first = threading.Event()
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", port))
        self.port = self._sock.getsockname()[1]
        self._sock.settimeout(0.2)
        self._mav = mavlink2.MAVLink(None)
        self._mav.robust_parsing = True
        self._thread = threading.Thread(target=self._run, name="sih-truth", daemon=True)

    def start(self) -> SihTruth:
        """Start receiving.

        Returns
        -------
        SihTruth
            Itself.
        """
        self._thread.start()
        return self

    def __enter__(self) -> SihTruth:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop receiving and release the port."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._sock.close()

    def wait_first(self, timeout_s: float) -> bool:
        """Wait until a first state arrived.

        Parameters
        ----------
        timeout_s : float
            Limit [s].

        Returns
        -------
        bool
            Whether one arrived.
        """
        return self._first.wait(timeout_s)

    def wait_received(self, count: int, timeout_s: float) -> bool:
        """Wait until ``count`` states have arrived in all.

        Parameters
        ----------
        count : int
            Total number of states.
        timeout_s : float
            Limit [s].

        Returns
        -------
        bool
            Whether they did.
        """
        with self._cond:
            return self._cond.wait_for(lambda: self.received >= count, timeout_s)

    @property
    def latest(self) -> SihState | None:
        """The newest state, or None before the first."""
        with self._lock:
            return self._states[-1] if self._states else None

    @property
    def states(self) -> tuple[SihState, ...]:
        """The states kept (at most :attr:`HISTORY`), oldest first."""
        with self._lock:
            return tuple(self._states)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data = self._sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            for msg in self._mav.parse_buffer(data) or []:
                if msg.get_type() == "HIL_STATE_QUATERNION":
                    self._take(msg, time.monotonic())

    def _take(self, msg: mavlink2.MAVLink_hil_state_quaternion_message, t_s: float) -> None:
        lat, lon, alt = msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3
        if self._ref is None:
            self._ref = (lat, lon, alt)
        lat0, lon0, alt0 = self._ref
        north = math.radians(lat - lat0) * _EARTH_RADIUS_M
        east = math.radians(lon - lon0) * _EARTH_RADIUS_M * math.cos(math.radians(lat0))
        with self._lock:
            previous = self._states[-1] if self._states else None
            if previous is not None and t_s - previous.t_receipt_s <= self.RESYNC_S:
                self._intervals.append(t_s - previous.t_receipt_s)  # a stop is no interval
            period = sum(self._intervals) / len(self._intervals) if self._intervals else None
        state = SihState(
            t_s=state_time(None if previous is None else previous.t_s, t_s, period),
            t_receipt_s=t_s,
            pos_ned_m=np.array([north, east, alt0 - alt]),
            vel_ned_m_s=np.array([msg.vx, msg.vy, msg.vz], dtype=float) * 0.01,
            quat_wxyz=np.asarray(msg.attitude_quaternion, dtype=float),
        )
        with self._lock:
            self._states.append(state)
        with self._cond:
            self.received += 1
            self._cond.notify_all()
        self._first.set()

    def pose_at(self, t_mono_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The pose as it was at ``t_mono_s`` (see the module's docstring).

        Parameters
        ----------
        t_mono_s : float
            ``time.monotonic()`` of the pose wanted [s].

        Returns
        -------
        tuple of numpy.ndarray or None
            Position (3,) [m, NED] and attitude ``w, x, y, z`` (4,); None before the first
            state, before the oldest kept, or when the newest is older than ``max_age_s``.
        """
        return pose_between(self.states, t_mono_s, self.max_age_s, self.MAX_EXTRAPOLATION_S)

    def __call__(self, t_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The pose at ``t_s`` after :attr:`epoch_s`, in NED (:meth:`pose_at`).

        Parameters
        ----------
        t_s : float
            Server time of the pose wanted (the frame's instant minus the latency) [s].

        Returns
        -------
        tuple of numpy.ndarray or None
            Position (3,) [m, NED] and attitude ``w, x, y, z`` (4,), or None (out of view).
        """
        return self.pose_at(self.epoch_s + t_s)


def rig_command(
    instance: Annotated[
        int, typer.Argument(min=0, help="PX4 SITL instance whose SIH ground truth is served.")
    ],
    body: Annotated[str, typer.Option("--body", help="Rigid body name.")] = "drone",
    rate_hz: Annotated[
        float, typer.Option("--rate", min=50.0, max=360.0, help="Frame rate, Hz.")
    ] = 120.0,
    natnet: Annotated[
        str, typer.Option("--natnet", help="NatNet version: 3.0 3.1 4.0 4.1.")
    ] = "4.1",
    noise_mm: Annotated[
        float, typer.Option("--noise-mm", min=0.0, help="Marker noise, mm (1 sigma per axis).")
    ] = 0.2,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the marker noise.")] = 0,
    port: Annotated[
        int, typer.Option("--port", min=0, max=65535, help="Command port on 127.0.0.1; 0 = free.")
    ] = 0,
    room: Annotated[
        str, typer.Option("--room", help=f"Axes of the mocap: {', '.join(SYSTEM_FRAMES)}.")
    ] = "optitrack",
    yaw_offset_deg: Annotated[
        float, typer.Option("--yaw-offset-deg", help="Heading of the room's north axis, deg.")
    ] = 0.0,
    latency_ms: Annotated[
        float,
        typer.Option(
            "--latency-ms", min=0.0, max=50.0, help="Time from the body's motion to the frame, ms."
        ),
    ] = 0.0,
) -> None:
    """Serve PX4 SITL instance N's SIH ground truth as a lab's OptiTrack Motive would.

    The truth PX4 streams on its display link (UDP 19410+N) is served over NatNet by gcs's
    mock Motive, origin where the vehicle was first seen; the options are the mock Motive's
    (``python -m gcs.mock.mocap --help``). Example, from the checkout:

        PYTHONPATH=tests python -m px4.lab_rig 0 --latency-ms 20
    \f
    Parameters
    ----------
    instance : int
        PX4's ``-i`` instance number.
    body : str
        Rigid body name.
    rate_hz : float
        Frame rate [Hz].
    natnet : str
        NatNet version.
    noise_mm : float
        Marker noise [mm].
    seed : int
        Seed of the noise.
    port : int
        Command port (0 = any free port).
    room : str
        Named convention of the room's axes.
    yaw_offset_deg : float
        Heading of the room's north axis [deg].
    latency_ms : float
        Time from the body's motion to the frame [ms].
    """
    version = parse_version(natnet)
    raise_thread()  # the truth's receiving thread too (gcs.io.scheduling), as PX4's own threads
    epoch_s = time.monotonic()  # server time 0, shared with the ground truth's receipt clock
    with SihTruth(sih_display_port(instance), epoch_s=epoch_s) as truth:
        serve(
            truth,
            body=body,
            rate_hz=rate_hz,
            version=version,
            noise_mm=noise_mm,
            seed=seed,
            port=port,
            room=room,
            yaw_offset_deg=yaw_offset_deg,
            latency_ms=latency_ms,
            epoch_s=epoch_s,
        )


def main() -> None:
    """Run :func:`rig_command` as a program (its arguments from ``sys.argv``)."""
    app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)
    app.command()(rig_command)
    app(prog_name="px4.lab_rig")


#: tests/ and the checkout: the rig's process imports this checkout's gcs and the px4 package.
_TESTS = Path(__file__).resolve().parents[1]
_PATH = [str(_TESTS.parent), str(_TESTS)]
#: The rig's process: the two paths first on ``sys.path`` (taken from ``argv``), then :func:`main`.
_RUN = (
    "import sys; sys.path[:0] = sys.argv[1:3]; del sys.argv[1:3]; "
    "import px4.lab_rig as rig; rig.main()"
)


class LabRig(MocapServerProcess):
    """The rig as a process of its own: ``with LabRig(n, ["--rate", "240"]) as rig: rig.url``.

    On entry it starts the program (:class:`gcs.mock.child.ChildProgram`: its own session, its
    ``READY <url>`` line awaited) and exposes :attr:`url`; on exit it sends SIGTERM, waits,
    and kills as a fallback.

    Parameters
    ----------
    instance : int
        PX4 SITL instance whose ground truth is served.
    args : list of str
        Options of the rig (:func:`rig_command`: ``--rate``, ``--latency-ms``...).
    ready_timeout_s : float
        How long to wait for the READY line [s]: as long as for PX4's own start, since on a
        machine running two suites the rig's imports alone have taken over 20 s (the bound
        only ends a rig that never starts).

    Attributes
    ----------
    url : str
        The mocap URL (``optitrack://127.0.0.1:<port>/<body>?interface=127.0.0.1``).
    pid : int
        Process id.
    stderr_text : str
        What the program wrote on stderr (its counters as JSON last), read on exit.
    """

    def __init__(
        self, instance: int, args: list[str] | None = None, ready_timeout_s: float = 90.0
    ) -> None:
        program = [sys.executable, "-c", _RUN, *_PATH, str(instance)]
        super().__init__(args, ready_timeout_s, program=program, name="lab rig")
        self.instance = instance


if __name__ == "__main__":
    main()
