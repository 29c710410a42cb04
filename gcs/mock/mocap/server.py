"""A mock OptiTrack Motive: one rigid body streamed over NatNet, in real time.

Sockets, as Motive opens them: a **command** socket (Motive's 1510) answers ``NAT_CONNECT``
with ``NAT_SERVERINFO`` and ``NAT_REQUEST_MODELDEF`` with ``NAT_MODELDEF``, ignores
``NAT_KEEPALIVE`` and answers any other request with ``NAT_UNRECOGNIZED_REQUEST``; a **data**
socket (Motive's 1511) sends every ``NAT_FRAMEOFDATA`` to the multicast group (Motive's
239.255.42.99), so the source port of frames is the data port. Both sockets are bound to
127.0.0.1 on ports the system picks (port 0), and frames leave through the loopback interface
with a multicast TTL of 0: they never leave the machine. Parallel servers are kept apart by
their data ports, which the system hands out once: a client learns the data port and the group
from ``NAT_SERVERINFO`` and listens on that port only (Linux delivers a group's datagrams to
the sockets bound to their destination port). The data socket gets ``SO_REUSEADDR`` once bound,
so that a client on the same machine can bind the same port, as beside a real Motive; set
before the bind, Linux may hand out a port another such socket already holds, and two
servers' frames would then reach each other's clients.

Each frame, at ``rate_hz`` on a grid of the monotonic clock, the true pose comes from
``pose_fn(t_s - latency_s)`` in the system's own axes (Motive: Y up); the rigid body's markers
are placed with it, each gets Gaussian noise of ``noise_m`` per axis, and the pose is solved
back from the noisy markers (least squares, as Motive's rigid-body solver does), which also
gives the mean marker error of the frame. Faults (:class:`FaultWindow`) act on top: an
occlusion clears the tracking-valid flag, a dropout sends nothing, a freeze repeats the last
datagram byte for byte, a jump offsets the solved position.

Latency (``latency_s``): the time from the body's motion to the frame. The frame due at server
time ``t`` carries the pose ``pose_fn(t - latency_s)``: the body as it was, not extrapolated to
now (a scripted trajectory at that time; a truth received from elsewhere, such as a
simulator's ground truth, as it was then, from the states it keeps). A pose function that only
knows the present (the mock drone's arena) must be served without latency.

Time stamps: the frame's ``timestamp`` counts frames over the rate since the first frame (as
Motive's does); the high-resolution stamps are this machine's monotonic clock in ticks of
:data:`CLOCK_HZ`: mid-exposure = the instant the pose shows (the frame's instant on the grid
minus the latency), data-received = the frame's instant on the grid, transmit = the moment of
sending. Motive's system latency, transmit minus mid-exposure (NatNet SDK's sample client and
OptiTrack's "Latency Measurements" page), is then the latency plus the sending's own delay, so
a client on this machine can measure it against them. (gcs's client, libmotioncapture's Python
binding, reads none of these stamps.)
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import select
import socket
import struct
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from gcs.core.frames import matrix_to_quat, quat_to_matrix
from gcs.mock.mocap import natnet

__all__ = [
    "parse_fault_window",
    "CLOCK_HZ",
    "DEFAULT_MARKERS_M",
    "FAULT_KINDS",
    "FaultWindow",
    "NatNetServer",
    "SentFrame",
    "frame_stamps",
    "solve_rigid_body",
]

#: Ticks per second of the high-resolution stamps (Windows' QueryPerformanceCounter rate).
CLOCK_HZ = 10_000_000
#: Markers of the default rigid body in its own frame [m]: five, asymmetric, about 10 cm.
DEFAULT_MARKERS_M = np.array(
    [
        [0.080, 0.010, 0.000],
        [-0.060, 0.020, 0.050],
        [-0.050, 0.005, -0.070],
        [0.000, 0.030, 0.090],
        [0.030, -0.010, -0.040],
    ]
)
FAULT_KINDS = ("occlusion", "dropout", "freeze", "jump")
PoseFn = Callable[[float], tuple[np.ndarray, np.ndarray] | None]


@dataclass(frozen=True)
class FaultWindow:
    """A fault over a window of server time.

    ``kind``: ``"occlusion"`` (body not tracked), ``"dropout"`` (no frames), ``"freeze"`` (the last
    datagram repeated) or ``"jump"`` (position offset by ``offset_m``). ``start_s``: start [s of
    server time, see :meth:`NatNetServer.now_s`]. ``duration_s``: length [s]. ``offset_m``: offset
    of a jump, system axes [m].
    """

    kind: str
    start_s: float
    duration_s: float
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"fault kind must be one of {FAULT_KINDS}, got {self.kind!r}")
        if not (self.duration_s > 0 and math.isfinite(self.start_s + self.duration_s)):
            raise ValueError(f"{self.kind}: duration must be positive and times finite")

    def active(self, t_s: float) -> bool:
        """Whether the window covers server time ``t_s``.

        ``t_s``: server time [s].
        """
        return self.start_s <= t_s < self.start_s + self.duration_s


def parse_fault_window(kind: str, text: str, option: str) -> FaultWindow:
    """Parse a fault option ``START:DURATION`` (``START:DURATION:DX:DY:DZ`` for a jump).

    ``text``: option value [s, s, m, m, m]. ``option``: the option's name, for the message
    (``--jump``, ``--mocap-jump``).

    Raises ``ValueError``: an unknown kind, not that form, or a bad window.
    """
    if kind not in FAULT_KINDS:
        raise ValueError(f"unknown mocap fault {kind!r}")
    count = 5 if kind == "jump" else 2
    try:
        values = [float(v) for v in text.split(":")]
    except ValueError:
        values = []
    if len(values) != count:
        form = "START:DURATION:DX:DY:DZ" if kind == "jump" else "START:DURATION"
        raise ValueError(f"{option} must be {form}, got {text!r}")
    offset = (values[2], values[3], values[4]) if kind == "jump" else (0.0, 0.0, 0.0)
    return FaultWindow(kind, values[0], values[1], offset)


@dataclass(frozen=True)
class SentFrame:
    """What the server sent in one frame (for tests and latency measurements).

    ``frame_number``: NatNet frame number. ``t_s``: server time of the frame (its instant on the
    rate grid) [s]. ``t_pose_s``: server time whose pose the frame carries: ``t_s`` minus the
    latency [s]. ``stamps``: the frame's time stamps as sent. ``t_send_s``: ``time.monotonic()``
    just before the datagram left. ``pos_m``: position sent (float32 values), system frame [m].
    ``quat_wxyz``: orientation sent (float32 values). ``true_pos_m``: position given by the pose
    function, system frame [m].
    """

    frame_number: int
    t_s: float
    t_pose_s: float
    stamps: natnet.FrameStamps
    t_send_s: float
    tracked: bool
    pos_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    true_pos_m: tuple[float, float, float]


def frame_stamps(
    frame_number: int, rate_hz: float, t_grid_s: float, latency_s: float, t_transmit_s: float
) -> natnet.FrameStamps:
    """The time stamps of a frame, as Motive fills them.

    ``frame_number``: frame number (frames since the first). ``rate_hz``: frame rate [Hz].
    ``t_grid_s``: the frame's instant on the rate grid, ``time.monotonic()`` [s]. ``latency_s``:
    time from the body's motion to the frame [s]. ``t_transmit_s``: ``time.monotonic()`` as the
    frame is sent [s].

    Returns: ``timestamp`` = frame number over the rate; mid-exposure = ``t_grid_s - latency_s``
    (the instant the pose shows), data received = ``t_grid_s``, transmit = ``t_transmit_s``, in
    ticks of :data:`CLOCK_HZ`.
    """
    return natnet.FrameStamps(
        timestamp_s=frame_number / rate_hz,
        mid_exposure_ticks=round((t_grid_s - latency_s) * CLOCK_HZ),
        data_received_ticks=round(t_grid_s * CLOCK_HZ),
        transmit_ticks=round(t_transmit_s * CLOCK_HZ),
    )


def solve_rigid_body(
    markers_body_m: np.ndarray, markers_world_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares pose of a rigid body from its markers (Kabsch).

    ``markers_body_m``: marker positions in the body frame, shape (M, 3) [m]. ``markers_world_m``:
    the same markers measured in the world frame, shape (M, 3) [m].

    Returns: ``pos_m``: body origin in the world, shape (3,) [m]. ``quat_wxyz``: body-to-world
    orientation, shape (4,). ``error_m``: mean distance between the measured markers and the fitted
    ones [m].
    """
    b = np.asarray(markers_body_m, dtype=float)
    w = np.asarray(markers_world_m, dtype=float)
    cb, cw = b.mean(axis=0), w.mean(axis=0)
    u, _, vt = np.linalg.svd((b - cb).T @ (w - cw))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    pos = cw - rot @ cb
    error = float(np.mean(np.linalg.norm(w - (b @ rot.T + pos), axis=1)))
    return pos, matrix_to_quat(rot), error


@dataclass
class _Stats:
    frames: int = 0
    sent: int = 0
    connects: int = 0
    modeldef_requests: int = 0
    clients: set[tuple[str, int]] = field(default_factory=set)
    last_send_s: float = math.nan
    max_send_gap_s: float = 0.0


class NatNetServer:
    """Serve one rigid body over NatNet like OptiTrack Motive (multicast on loopback).

    ``pose_fn``: ``pose_fn(t_s) -> (pos_m, quat_wxyz)`` in the system's own axes, or None when the
    body is out of view; ``t_s`` is the server time (:meth:`now_s`) whose pose is wanted: the
    frame's instant minus ``latency_s``. ``body_name``: rigid body name in the model definitions.
    ``rate_hz``: frame rate [Hz], 1 to 1000 (Motive: 30-360 and more). ``version``: NatNet bitstream
    version announced and written (see :data:`natnet.VERSIONS`). ``noise_m``: standard deviation of
    the noise of each marker coordinate [m]. ``faults``: faults from the start; more can be added
    with :meth:`add_fault`. ``host``: address both sockets bind to (loopback). ``command_port``:
    command port, 0 for any free one. ``multicast_group``: group the frames go to. ``markers_m``:
    rigid body markers in its own frame, shape (M, 3) [m]. ``history``: how many :class:`SentFrame`
    records :attr:`sent` keeps. ``latency_s``: time from the body's motion to the frame [s], >= 0:
    each frame carries the pose of ``latency_s`` before its instant, and its mid-exposure stamp says
    so. ``epoch_s``: ``time.monotonic()`` at server time 0; None: when the server is created. A pose
    function on the monotonic clock (a truth timed by when its states arrived) is given the same
    epoch.

    ``sent``: the most recent frames sent.
    """

    def __init__(
        self,
        pose_fn: PoseFn,
        body_name: str = "drone",
        body_id: int = 1,
        rate_hz: float = 120.0,
        version: tuple[int, int] = (4, 1),
        noise_m: float = 2e-4,
        faults: tuple[FaultWindow, ...] = (),
        seed: int = 0,
        host: str = "127.0.0.1",
        command_port: int = 0,
        multicast_group: str = "239.255.42.99",
        markers_m: np.ndarray = DEFAULT_MARKERS_M,
        history: int = 20_000,
        latency_s: float = 0.0,
        epoch_s: float | None = None,
    ) -> None:
        if not 1.0 <= rate_hz <= 1000.0:
            raise ValueError(f"rate_hz must be within 1..1000, got {rate_hz}")
        if noise_m < 0 or not math.isfinite(noise_m):
            raise ValueError(f"noise_m must be finite and >= 0, got {noise_m}")
        if not 0.0 <= latency_s <= 1.0:
            raise ValueError(f"latency_s must be within 0..1 s, got {latency_s}")
        self.pose_fn = pose_fn
        self.model = natnet.RigidBodyModel(body_name, body_id, markers_m)
        self.rate_hz = float(rate_hz)
        self.version = tuple(version)
        natnet.server_info(self.version, (0, 0, 0, 0), CLOCK_HZ, 0, None)  # validates version
        self.noise_m = float(noise_m)
        self.latency_s = float(latency_s)
        self.multicast_group = multicast_group
        self.host = host
        self.sent: deque[SentFrame] = deque(maxlen=history)
        self._faults: list[FaultWindow] = list(faults)
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._stats = _Stats()
        self._last_datagram: bytes | None = None
        self._t0 = time.monotonic() if epoch_s is None else float(epoch_s)
        self._cmd = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._data = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._cmd.bind((host, command_port))
            # the port first, then SO_REUSEADDR: set before binding to port 0, Linux may hand
            # out a port that another SO_REUSEADDR socket holds (another server's, or its
            # client's), and two servers' frames would reach both clients
            self._data.bind((host, 0))
            self._data.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(host))
            self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
            self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        except OSError:
            self.close()
            raise
        self.command_port = self._cmd.getsockname()[1]
        self.data_port = self._data.getsockname()[1]
        self._wake_r, self._wake_w = socket.socketpair()

    @property
    def url(self) -> str:
        """``optitrack://HOST:COMMAND_PORT/BODY?interface=HOST``, for gcs's mocap client."""
        return (
            f"optitrack://{self.host}:{self.command_port}/{self.model.name}?interface={self.host}"
        )

    @property
    def epoch_s(self) -> float:
        """``time.monotonic()`` at server time 0 [s]."""
        return self._t0

    def now_s(self) -> float:
        """Server time [s]: monotonic seconds since the server was created."""
        return time.monotonic() - self._t0

    def add_fault(self, fault: FaultWindow) -> None:
        """Add a fault window (thread-safe; times are server time)."""
        with self._lock:
            self._faults.append(fault)

    def stats(self) -> dict[str, float]:
        """Counters: frames due, datagrams sent, connects, model-definition requests, clients,
        and the longest interval between two datagrams sent (``max_send_gap_s``: a stall of
        the server itself, as against one of its receiver).
        """
        s = self._stats
        return {
            "frames": s.frames,
            "sent": s.sent,
            "connects": s.connects,
            "modeldef_requests": s.modeldef_requests,
            "clients": len(s.clients),
            "max_send_gap_s": round(s.max_send_gap_s, 4),
        }

    def start(self) -> NatNetServer:
        """Serve in a background thread; returns self."""
        self._thread = threading.Thread(target=self.serve, name="natnet-server", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving (from any thread or a signal handler) and close the sockets."""
        self._stop.set()
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self.close()

    def close(self) -> None:
        """Close the sockets."""
        for sock in (self._cmd, self._data, getattr(self, "_wake_r", None)):
            if sock is not None:
                sock.close()
        if hasattr(self, "_wake_w"):
            self._wake_w.close()

    def __enter__(self) -> NatNetServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def serve(self) -> None:
        """Serve until :meth:`stop`: frames on the rate grid, commands as they arrive."""
        period = 1.0 / self.rate_hz
        k = 0
        while not self._stop.is_set():
            due = self._t0 + k * period
            try:
                ready, _, _ = select.select(
                    [self._cmd, self._wake_r], [], [], max(0.0, due - time.monotonic())
                )
            except (OSError, ValueError):
                return  # closed under us
            if self._cmd in ready:
                self._answer_command()
            now = time.monotonic()
            if now >= due and not self._stop.is_set():
                self.send_frame(k, due)
                # after a stall of more than a period, skip the frames already missed
                k = max(k + 1, math.floor((now - self._t0) / period))

    def _answer_command(self) -> None:
        try:
            datagram, addr = self._cmd.recvfrom(65535)
        except OSError:
            return
        msg = natnet.message_id(datagram)
        if msg == natnet.NAT_CONNECT:
            self._stats.connects += 1
            self._stats.clients.add(addr)
            reply = natnet.server_info(
                self.version, (3, 1, 0, 0), CLOCK_HZ, self.data_port, self.multicast_group
            )
        elif msg == natnet.NAT_REQUEST_MODELDEF:
            self._stats.modeldef_requests += 1
            reply = natnet.model_definitions(self.version, [self.model])
        elif msg == natnet.NAT_ECHOREQUEST and len(datagram) >= 12:
            # clock synchronisation of the SDK: its stamp back, with ours
            reply = natnet.packet(
                natnet.NAT_ECHORESPONSE,
                datagram[4:12] + struct.pack("<Q", int(time.monotonic() * CLOCK_HZ)),
            )
        elif msg == natnet.NAT_KEEPALIVE or msg is None:
            return
        else:
            reply = natnet.packet(natnet.NAT_UNRECOGNIZED_REQUEST, b"")
        with contextlib.suppress(OSError):
            self._cmd.sendto(reply, addr)

    def _active(self, t_s: float) -> dict[str, FaultWindow]:
        with self._lock:
            return {f.kind: f for f in self._faults if f.active(t_s)}

    def _measure(
        self, t_s: float, jump: FaultWindow | None
    ) -> tuple[natnet.RigidBodyState, tuple[float, float, float]]:
        """The body as the cameras see it at ``t_s`` (noisy markers, solved pose); true position."""
        pose = self.pose_fn(t_s)
        body = self.model.markers_m
        if pose is None:
            lost = natnet.RigidBodyState(False, np.zeros(3), np.array([1.0, 0, 0, 0]), 0.0, body)
            return lost, (math.nan, math.nan, math.nan)
        pos, quat = np.asarray(pose[0], float), np.asarray(pose[1], float)
        markers = body @ quat_to_matrix(quat).T + pos
        if self.noise_m > 0:
            markers = markers + self._rng.normal(0.0, self.noise_m, markers.shape)
        solved_pos, solved_q, error = solve_rigid_body(body, markers)
        if jump is not None:
            offset = np.asarray(jump.offset_m, dtype=float)
            solved_pos, markers = solved_pos + offset, markers + offset
        state = natnet.RigidBodyState(True, solved_pos, solved_q, error, markers)
        return state, (float(pos[0]), float(pos[1]), float(pos[2]))

    def send_frame(self, k: int, t_grid: float) -> None:
        """Build frame ``k`` due at ``t_grid`` and send it (what :meth:`serve` does on its
        grid; called directly, it steps the server without waiting for real time).

        ``k``: frame number. ``t_grid``: the frame's instant, ``time.monotonic()`` [s]; its server
        time sets the faults and, minus the latency, the pose.
        """
        t_s = t_grid - self._t0
        self._stats.frames += 1
        faults = self._active(t_s)
        if "dropout" in faults:
            return
        if "freeze" in faults and self._last_datagram is not None:
            self._send(self._last_datagram, None)
            return
        t_pose = t_s - self.latency_s
        state, true_pos = self._measure(t_pose, faults.get("jump"))
        if "occlusion" in faults:
            state = natnet.RigidBodyState(
                False, np.zeros(3), np.array([1.0, 0, 0, 0]), 0.0, state.markers_m
            )
        stamps = frame_stamps(k, self.rate_hz, t_grid, self.latency_s, time.monotonic())
        datagram = natnet.frame_of_data(self.version, k, [self.model], [state], stamps)
        self._last_datagram = datagram
        self._send(
            datagram,
            SentFrame(
                frame_number=k,
                t_s=t_s,
                t_pose_s=t_pose,
                stamps=stamps,
                t_send_s=math.nan,
                tracked=state.tracked,
                pos_m=tuple(float(v) for v in np.float32(state.pos_m)),
                quat_wxyz=tuple(float(v) for v in np.float32(state.quat_wxyz)),
                true_pos_m=true_pos,
            ),
        )

    def _send(self, datagram: bytes, record: SentFrame | None) -> None:
        t_send = time.monotonic()
        try:
            self._data.sendto(datagram, (self.multicast_group, self.data_port))
        except OSError:
            return
        self._stats.sent += 1
        if self._stats.sent > 1:
            gap = t_send - self._stats.last_send_s
            self._stats.max_send_gap_s = max(self._stats.max_send_gap_s, gap)
        self._stats.last_send_s = t_send
        if record is not None:
            self.sent.append(dataclasses.replace(record, t_send_s=t_send))
