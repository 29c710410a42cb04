"""Scripted poses for the mock motion capture: a vehicle's truth in NED, seen in a room's axes.

The server wants poses in the mocap system's own axes; a vehicle (the mock drone, or a script)
knows its pose in local NED. :func:`in_room` turns the one into the other with the room's
:class:`FrameMapping` (how the mocap was calibrated in this arena), so that gcs's client, which
maps back with its own configuration, exercises the mapping: right configuration, identity;
wrong one (a mirrored axis), a visibly wrong motion.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gcs.core.frames import FrameMapping, matrix_to_quat

__all__ = ["NedPose", "Circle", "Hover", "in_room"]

NedPose = Callable[[float], tuple[np.ndarray, np.ndarray] | None]


def _yaw_quat(yaw_rad: float) -> np.ndarray:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return matrix_to_quat(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))


@dataclass(frozen=True)
class Hover:
    """A vehicle holding a point.

    ``pos_ned_m``: the point [m, NED]. ``yaw_deg``: heading [deg].
    """

    pos_ned_m: tuple[float, float, float] = (0.0, 0.0, -1.0)
    yaw_deg: float = 0.0

    def __call__(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose at ``t_s``.

        ``t_s``: time [s].

        Returns: position (3,) [m, NED] and attitude FRD to NED ``w, x, y, z`` (4,).
        """
        return np.asarray(self.pos_ned_m, float), _yaw_quat(math.radians(self.yaw_deg))


@dataclass(frozen=True)
class Circle:
    """A vehicle flying a horizontal circle, nose along its velocity.

    ``center_ned_m``: centre [m, NED]. ``radius_m``: radius [m]. ``period_s``: time per lap [s];
    negative flies it the other way.
    """

    center_ned_m: tuple[float, float, float] = (0.0, 0.0, -1.0)
    radius_m: float = 1.0
    period_s: float = 8.0

    def __call__(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose at ``t_s`` (starts due north of the centre).

        ``t_s``: time [s].

        Returns: position (3,) [m, NED] and attitude FRD to NED ``w, x, y, z`` (4,).
        """
        phase = 2.0 * math.pi * t_s / self.period_s
        offset = self.radius_m * np.array([math.cos(phase), math.sin(phase), 0.0])
        heading = phase + math.copysign(math.pi / 2, self.period_s)
        return np.asarray(self.center_ned_m, float) + offset, _yaw_quat(heading)


def in_room(pose_ned: NedPose, room: FrameMapping) -> Callable[[float], tuple | None]:
    """A NED pose function seen in the room's mocap axes (for :class:`NatNetServer`).

    ``pose_ned``: ``pose_ned(t_s) -> (pos_ned_m, quat_ned_wxyz)`` or None. ``room``: how the room's
    mocap axes relate to NED.

    Returns: ``pose(t_s) -> (pos_m, quat_wxyz)`` in the mocap's axes, or None.
    """

    def pose(t_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        truth = pose_ned(t_s)
        if truth is None:
            return None
        return room.position_from_ned(truth[0]), room.attitude_from_ned(truth[1])

    return pose
