"""The mock drone in an indoor arena: its true pose served by a mock OptiTrack Motive.

``gcs mock --mocap`` (and ``gcs fly --mock --mocap mock``) runs a :class:`NatNetServer` in a
thread of the mock drone's process. Its pose function reads the vehicle's true pose, which the
mock's real-time loop publishes after every physics step (:meth:`Arena.publish`, one tuple
assignment: the server thread never sees half a pose; carried forward at the vehicle's velocity
to the frame's instant), and turns it into the room's axes
(Motive's Y-up by default, with the room's yaw offset): what gcs's mocap client receives over
NatNet is the truth of the simulation, with marker noise, at the server's rate. Together with
``vision.enabled`` in the mock profile (``profiles/mock-mocap.yaml``) the vehicle then navigates
only on what gcs forwards of this stream.

Faults (:class:`ArenaFault`: occlusion, dropout, freeze, jump) are timed, like the mock's link
faults, in seconds after the vehicle first enters OFFBOARD, so that they land at the same point
of a trial whatever the take-off took; they are handed to the server as windows of its own
time when that happens.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gcs.core.frames import mapping_for
from gcs.mock.mocap.natnet import VERSIONS
from gcs.mock.mocap.scripted import in_room
from gcs.mock.mocap.server import FaultWindow, NatNetServer, parse_fault_window

__all__ = ["ArenaFault", "ArenaOptions", "Arena", "CARRY_S", "quat_from_euler", "parse_arena_fault"]

Pose = tuple[
    float, tuple[float, float, float], tuple[float, float, float, float], tuple[float, float, float]
]

CARRY_S = 0.5
"""Longest time a published pose is carried forward at its velocity [s] (:meth:`Arena.publish`)."""


@dataclass(frozen=True)
class ArenaFault:
    """A fault of the arena's motion capture.

    ``kind``: ``occlusion``, ``dropout``, ``freeze`` or ``jump`` (:data:`FAULT_KINDS`). ``start_s``:
    start, seconds after the vehicle first enters OFFBOARD [s]. ``duration_s``: length [s].
    ``offset_m``: offset of a jump, in the room's (mocap) axes [m].
    """

    kind: str
    start_s: float
    duration_s: float
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        FaultWindow(self.kind, self.start_s, self.duration_s, self.offset_m)  # validates


@dataclass(frozen=True)
class ArenaOptions:
    """How the arena's motion capture streams.

    ``rate_hz``: frame rate [Hz]. ``noise_m``: marker noise, standard deviation per coordinate [m].
    ``room``: named convention of the room's axes (:data:`gcs.core.frames.SYSTEM_FRAMES`).
    ``yaw_offset_deg``: heading in NED of the room's north axis [deg].
    """

    rate_hz: float = 120.0
    noise_m: float = 2e-4
    room: str = "optitrack"
    yaw_offset_deg: float = 0.0
    body: str = "drone"
    natnet: tuple[int, int] = (4, 1)
    faults: tuple[ArenaFault, ...] = field(default_factory=tuple)
    seed: int = 0

    def __post_init__(self) -> None:
        if not 1.0 <= self.rate_hz <= 1000.0:
            raise ValueError(f"mocap rate must be within 1..1000 Hz, got {self.rate_hz}")
        if not (math.isfinite(self.noise_m) and self.noise_m >= 0):
            raise ValueError(f"mocap noise must be finite and >= 0, got {self.noise_m}")
        if tuple(self.natnet) not in VERSIONS:
            raise ValueError(f"NatNet version {self.natnet} not implemented ({VERSIONS})")
        mapping_for(self.room, self.yaw_offset_deg)  # validates the room's convention

    def cli_args(self) -> list[str]:
        """The options of ``gcs mock`` that reproduce these."""
        args = [
            "--mocap", "--mocap-rate", repr(self.rate_hz),
            "--mocap-noise-mm", repr(self.noise_m * 1000.0), "--mocap-room", self.room,
            "--mocap-yaw-offset-deg", repr(self.yaw_offset_deg), "--mocap-body", self.body,
        ]  # fmt: skip
        for f in self.faults:
            value = f"{f.start_s!r}:{f.duration_s!r}"
            if f.kind == "jump":
                value += ":" + ":".join(repr(float(x)) for x in f.offset_m)
            args += [f"--mocap-{f.kind}", value]
        return args


def quat_from_euler(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """Quaternion ``w, x, y, z`` (FRD to NED) of roll, pitch, yaw (ZYX) [rad].

    ``roll``, ``pitch``, ``yaw``: euler angles [rad].
    """
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


class Arena:
    """The mock Motive serving a vehicle's true pose (see the module docstring)."""

    def __init__(self, options: ArenaOptions) -> None:
        self.options = options
        self._pose: Pose | None = None
        self._faults_placed = False
        room = mapping_for(options.room, options.yaw_offset_deg)
        self.server = NatNetServer(
            in_room(self._truth, room),
            body_name=options.body,
            rate_hz=options.rate_hz,
            version=tuple(options.natnet),
            noise_m=options.noise_m,
            seed=options.seed,
        )

    @property
    def url(self) -> str:
        """The mocap URL gcs connects to (``optitrack://127.0.0.1:PORT/BODY?interface=...``)."""
        return self.server.url

    def _truth(self, t_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        pose = self._pose
        if pose is None:
            return None  # nothing published yet: out of view
        t_pub_s, pos, quat, vel = pose
        carried_s = min(max(t_s - t_pub_s, 0.0), CARRY_S)
        position = np.asarray(pos, dtype=float) + carried_s * np.asarray(vel, dtype=float)
        return position, np.asarray(quat, dtype=float)

    def publish(self, pos_ned_m: Any, quat_wxyz: Any, vel_ned_m_s: Any = (0.0, 0.0, 0.0)) -> None:
        """The vehicle's true pose now (called by the mock's loop after each physics step).

        ``pos_ned_m``: true position, NED [m]. ``quat_wxyz``: true attitude, FRD to NED.
        ``vel_ned_m_s``: true velocity, NED [m/s]. A frame due after the publication carries the
        position moved on at that velocity (for at most :data:`CARRY_S`): when the mock's loop
        misses its steps for a while (a loaded machine, a burst of messages to answer) and then
        catches up, the body it stands for moved all along, as a real one does, instead of
        standing still and then jumping (seen: 0.114 m between two frames 8 ms apart, which
        gcs's mocap watch rightly refused).
        """
        self._pose = (
            self.server.now_s(),
            (float(pos_ned_m[0]), float(pos_ned_m[1]), float(pos_ned_m[2])),
            tuple(float(q) for q in quat_wxyz),  # type: ignore[assignment]
            (float(vel_ned_m_s[0]), float(vel_ned_m_s[1]), float(vel_ned_m_s[2])),
        )

    def on_first_offboard(self) -> None:
        """The vehicle entered OFFBOARD for the first time: the faults' clock starts now."""
        if self._faults_placed:
            return
        self._faults_placed = True
        now = self.server.now_s()
        for f in self.options.faults:
            window = FaultWindow(f.kind, f.start_s, f.duration_s, f.offset_m)
            self.server.add_fault(replace(window, start_s=now + f.start_s))

    def start(self) -> Arena:
        """Serve in a thread; returns self."""
        self.server.start()
        return self

    def stop(self) -> None:
        """Stop serving."""
        self.server.stop()

    def stats(self) -> dict[str, Any]:
        """Counters and the faults as placed, for the mock's statistics."""
        return {
            "url": self.url,
            "rate_hz": self.options.rate_hz,
            "noise_m": self.options.noise_m,
            "room": self.options.room,
            "faults": [
                {"kind": f.kind, "start_s": f.start_s, "duration_s": f.duration_s}
                for f in self.options.faults
            ],
            "faults_placed": self._faults_placed,
            **self.server.stats(),
        }


def parse_arena_fault(kind: str, text: str) -> ArenaFault:
    """Parse ``START:DURATION`` (``START:DURATION:DX:DY:DZ`` for a jump).

    ``text``: option value [s, s, m, m, m].

    Raises ``ValueError``: not that form, or a bad window.
    """
    window = parse_fault_window(kind, text, f"--mocap-{kind}")
    return ArenaFault(kind, window.start_s, window.duration_s, window.offset_m)
