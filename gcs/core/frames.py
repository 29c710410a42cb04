"""From a motion-capture system's axes to local NED, and back (pure).

A motion-capture system reports the pose of a rigid body in its own world frame, set at
calibration: OptiTrack Motive streams a right-handed **Y-up** frame by default (the
calibration square's short arm is +X, its long arm +Z), Vicon and Qualisys a right-handed
**Z-up** frame (X and Y along the arms of the L-frame or wand). PX4 wants local **NED** and a
body frame **FRD**. A :class:`FrameMapping` says how the two relate:

- ``up_axis``: the system axis that points up (``"+y"`` for Motive, ``"+z"`` for the others);
- ``north_axis``: the horizontal system axis that becomes local north (NED x);
- ``right_handed``: whether the system's axes form a right-handed set (all of the above do;
  a left-handed one, as streamed to some game engines, is mirrored);
- ``yaw_offset_deg``: a rotation about down applied afterwards, the heading in NED of the
  ``north_axis`` (positive from north towards east);
- ``origin_m``: the point, in system coordinates, that becomes the NED origin;
- ``body_forward_axis``: the rigid body's own axis along the vehicle's nose (default: the
  ``north_axis``).

East then follows from handedness: ``east = down x north`` in a right-handed system. The axis
part ``A`` (a signed permutation) and the yaw ``Rz`` give ``M = Rz A``, and::

    p_ned = M (p_sys - origin)          R_ned_frd = M R_sys B^T

``B`` does for the body what ``A`` does for the world, with ``body_forward_axis`` as forward
and the same up: FRD from the rigid body's own axes. A mocap rigid body's own axes are the
system's axes at the moment it was created (in Motive, Tracker or QTM), the vehicle level;
by default the nose is taken to lie along ``north_axis`` then (create the rigid body with the
vehicle facing that axis), so ``B = A``. Streams that follow ROS (REP-103: ENU world, body
x forward, y left, z up) have ``body_forward_axis = "+x"`` with ``north_axis = "+y"``. For a
left-handed system ``A`` and ``B`` are reflections; ``M R B^T`` is still a proper rotation.

Quaternions are ``w, x, y, z`` (scalar first, as MAVSDK's ``Quaternion``), Hamilton, active:
they rotate body vectors into the world frame.

Local NED and latitude/longitude (:func:`ned_to_global`, :func:`global_to_ned`) are PX4's own
map projection (azimuthal equidistant about the reference, ``lib/geo``): the arena uploaded to
the autopilot as its geofence, and the mock's GPS.

Bad arguments raise ``ValueError`` (the caller that read them from a file names the file).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "FrameMapping",
    "SYSTEM_FRAMES",
    "mapping_for",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_angle_rad",
    "ned_to_global",
    "global_to_ned",
    "EARTH_RADIUS_M",
]

#: Earth's radius of PX4's map projection (``CONSTANTS_RADIUS_OF_EARTH``) [m].
EARTH_RADIUS_M = 6_371_000.0

_AXES = {"x": 0, "y": 1, "z": 2}


def _unit(axis: str, field: str) -> np.ndarray:
    text = axis.strip().lower()
    if len(text) != 2 or text[0] not in "+-" or text[1] not in _AXES:
        raise ValueError(f"mocap frame: {field} must be one of +x -x +y -y +z -z, got {axis!r}")
    v = np.zeros(3)
    v[_AXES[text[1]]] = 1.0 if text[0] == "+" else -1.0
    return v


@dataclass(frozen=True)
class FrameMapping:
    """How a motion-capture system's world frame relates to local NED.

    Parameters
    ----------
    up_axis : str
        System axis pointing up: ``"+x"``, ``"-x"``, ``"+y"``, ``"-y"``, ``"+z"`` or ``"-z"``.
    north_axis : str
        Horizontal system axis that becomes north (before ``yaw_offset_deg``).
    right_handed : bool
        The system's axes are right-handed.
    yaw_offset_deg : float
        Heading in NED of ``north_axis`` [deg], positive from north towards east.
    origin_m : tuple of float
        System coordinates of the NED origin [m].
    body_forward_axis : str or None
        Rigid body axis along the vehicle's nose; None: ``north_axis``.
    """

    up_axis: str = "+z"
    north_axis: str = "+x"
    right_handed: bool = True
    yaw_offset_deg: float = 0.0
    origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    body_forward_axis: str | None = None

    def __post_init__(self) -> None:
        up = _unit(self.up_axis, "up_axis")
        for field in ("north_axis", "body_forward_axis"):
            axis = getattr(self, field)
            if axis is not None and abs(float(up @ _unit(axis, field))) > 0.5:
                raise ValueError(
                    f"mocap frame: {field} {axis} must be horizontal, not along up_axis "
                    f"{self.up_axis}"
                )
        origin = tuple(float(v) for v in self.origin_m)
        if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
            raise ValueError(f"mocap frame: origin_m must be 3 finite numbers, got {origin}")
        if not math.isfinite(self.yaw_offset_deg):
            raise ValueError("mocap frame: yaw_offset_deg must be finite")
        object.__setattr__(self, "origin_m", origin)
        # the matrices once: a mocap maps every frame with them (read-only, shared)
        axes = self._frame(self.north_axis)
        yaw = math.radians(self.yaw_offset_deg)
        c, s = math.cos(yaw), math.sin(yaw)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        cache = {
            "_axes": axes,
            "_body_axes": self._frame(self.body_forward_axis or self.north_axis),
            "_matrix": rz @ axes,
            "_origin": np.array(origin),
        }
        for name, value in cache.items():
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    def _frame(self, forward_axis: str) -> np.ndarray:
        forward = _unit(forward_axis, "axis")
        down = -_unit(self.up_axis, "up_axis")
        right = np.cross(down, forward)
        if not self.right_handed:
            right = -right  # the coordinate cross product points the other way in such a system
        return np.vstack([forward, right, down])

    def axes(self) -> np.ndarray:
        """Signed permutation ``A`` taking system coordinates to NED (no yaw, no origin).

        Returns
        -------
        numpy.ndarray
            Shape (3, 3), read-only; rows are north, east, down in system coordinates. Its
            determinant is +1 for a right-handed system, -1 for a left-handed one.
        """
        return self._axes

    def body_axes(self) -> np.ndarray:
        """Signed permutation ``B`` taking the rigid body's own axes to FRD.

        Returns
        -------
        numpy.ndarray
            Shape (3, 3), read-only; rows are forward, right, down in rigid-body coordinates.
        """
        return self._body_axes

    def matrix(self) -> np.ndarray:
        """``M = Rz(yaw_offset) A``: system vectors to NED vectors.

        Returns
        -------
        numpy.ndarray
            Shape (3, 3), read-only.
        """
        return self._matrix

    def position_to_ned(self, pos_m: np.ndarray) -> np.ndarray:
        """Positions in system coordinates to NED.

        Parameters
        ----------
        pos_m : numpy.ndarray
            Shape (3,) or (N, 3) [m], system frame.

        Returns
        -------
        numpy.ndarray
            Same shape [m], NED.
        """
        p = _points(pos_m, "pos_m")
        return (p - self._origin) @ self._matrix.T

    def position_from_ned(self, pos_ned_m: np.ndarray) -> np.ndarray:
        """NED positions to system coordinates (inverse of :meth:`position_to_ned`).

        Parameters
        ----------
        pos_ned_m : numpy.ndarray
            Shape (3,) or (N, 3) [m], NED.

        Returns
        -------
        numpy.ndarray
            Same shape [m], system frame.
        """
        p = _points(pos_ned_m, "pos_ned_m")
        return p @ self._matrix + self._origin

    def attitude_to_ned(self, quat_wxyz: np.ndarray) -> np.ndarray:
        """Rigid-body orientations (body to system world) to FRD-to-NED quaternions.

        Parameters
        ----------
        quat_wxyz : numpy.ndarray
            Shape (4,) or (N, 4), unit quaternions ``w, x, y, z``.

        Returns
        -------
        numpy.ndarray
            Same shape; ``w >= 0``.
        """
        m, b = self._matrix, self._body_axes
        return _map_quats(quat_wxyz, lambda r: m @ r @ b.T)

    def attitude_from_ned(self, quat_ned_wxyz: np.ndarray) -> np.ndarray:
        """FRD-to-NED quaternions to rigid-body orientations in the system frame.

        Parameters
        ----------
        quat_ned_wxyz : numpy.ndarray
            Shape (4,) or (N, 4), unit quaternions ``w, x, y, z``.

        Returns
        -------
        numpy.ndarray
            Same shape; ``w >= 0``.
        """
        m, b = self._matrix, self._body_axes
        return _map_quats(quat_ned_wxyz, lambda r: m.T @ r @ b)


#: Default mapping of each system as it ships (north along the system's +X; set
#: ``yaw_offset_deg`` and ``origin_m`` per arena).
SYSTEM_FRAMES: dict[str, FrameMapping] = {
    "optitrack": FrameMapping(up_axis="+y", north_axis="+x"),  # Motive default (Y up)
    "optitrack-zup": FrameMapping(up_axis="+z", north_axis="+x"),  # Motive "Up Axis: Z Up"
    "vicon": FrameMapping(up_axis="+z", north_axis="+x"),
    "qualisys": FrameMapping(up_axis="+z", north_axis="+x"),
    "vrpn": FrameMapping(up_axis="+z", north_axis="+x"),  # VRPN itself fixes no convention
    "enu": FrameMapping(up_axis="+z", north_axis="+y", body_forward_axis="+x"),  # ROS
    "flu": FrameMapping(up_axis="+z", north_axis="+x"),
    "ned": FrameMapping(up_axis="-z", north_axis="+x"),
}


def mapping_for(
    convention: str,
    yaw_offset_deg: float = 0.0,
    origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> FrameMapping:
    """The mapping of a named convention, with an arena's yaw offset and origin.

    Parameters
    ----------
    convention : str
        A key of :data:`SYSTEM_FRAMES` (``optitrack``, ``optitrack-zup``, ``vicon``,
        ``qualisys``, ``vrpn``, ``enu``, ``flu``, ``ned``).
    yaw_offset_deg : float
        Heading in NED of the convention's north axis [deg].
    origin_m : tuple of float
        System coordinates of the NED origin [m].

    Returns
    -------
    FrameMapping
    """
    try:
        base = SYSTEM_FRAMES[convention.lower()]
    except KeyError:
        known = ", ".join(SYSTEM_FRAMES)
        raise ValueError(f"mocap frame: unknown convention {convention!r} ({known})") from None
    return dataclasses.replace(base, yaw_offset_deg=yaw_offset_deg, origin_m=origin_m)


def _points(values: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.shape[-1:] != (3,) or arr.ndim > 2:
        raise ValueError(f"{name} must have shape (3,) or (N, 3), got {arr.shape}")
    return arr


def _quats(values: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.shape[-1:] != (4,) or arr.ndim > 2:
        raise ValueError(f"{name} must have shape (4,) or (N, 4), got {arr.shape}")
    norm = np.linalg.norm(arr, axis=-1)
    if not np.all(np.abs(norm - 1.0) < 1e-3):
        raise ValueError(
            f"{name} must hold unit quaternions (norms {np.min(norm)}..{np.max(norm)})"
        )
    return arr / norm[..., None]


def quat_to_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions.

    Parameters
    ----------
    quat_wxyz : numpy.ndarray
        Shape (4,) or (N, 4), ``w, x, y, z``.

    Returns
    -------
    numpy.ndarray
        Shape (3, 3) or (N, 3, 3).
    """
    q = _quats(quat_wxyz, "quat_wxyz")
    w, x, y, z = np.moveaxis(q, -1, 0)
    r = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )
    return r


def matrix_to_quat(rot: np.ndarray) -> np.ndarray:
    """Unit quaternions (``w >= 0``) of rotation matrices.

    Parameters
    ----------
    rot : numpy.ndarray
        Shape (3, 3) or (N, 3, 3), proper rotations.

    Returns
    -------
    numpy.ndarray
        Shape (4,) or (N, 4), ``w, x, y, z``.
    """
    r = np.asarray(rot, dtype=float)
    if r.shape[-2:] != (3, 3) or r.ndim > 3:
        raise ValueError(f"rot must have shape (3, 3) or (N, 3, 3), got {r.shape}")
    flat = r.reshape(-1, 3, 3)
    # Largest of the four 4q_i^2 terms first (numerically safe at every angle).
    diag = np.stack(
        [
            1 + flat[:, 0, 0] + flat[:, 1, 1] + flat[:, 2, 2],
            1 + flat[:, 0, 0] - flat[:, 1, 1] - flat[:, 2, 2],
            1 - flat[:, 0, 0] + flat[:, 1, 1] - flat[:, 2, 2],
            1 - flat[:, 0, 0] - flat[:, 1, 1] + flat[:, 2, 2],
        ],
        -1,
    )
    k = np.argmax(diag, axis=1)
    out = np.empty((flat.shape[0], 4))
    for i, (m, which) in enumerate(zip(flat, k, strict=True)):
        s = 2.0 * math.sqrt(max(diag[i, which], 1e-300))
        if which == 0:
            q = [s / 4, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
        elif which == 1:
            q = [(m[2, 1] - m[1, 2]) / s, s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
        elif which == 2:
            q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s]
        else:
            q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4]
        out[i] = q
    out *= np.where(out[:, :1] < 0, -1.0, 1.0)
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    return out[0] if r.ndim == 2 else out


def quat_angle_rad(q1_wxyz: np.ndarray, q2_wxyz: np.ndarray) -> np.ndarray:
    """Angle of the rotation between two orientations (0..pi).

    Parameters
    ----------
    q1_wxyz, q2_wxyz : numpy.ndarray
        Shape (4,) or (N, 4), unit quaternions.

    Returns
    -------
    numpy.ndarray
        Shape () or (N,) [rad].
    """
    a = _quats(q1_wxyz, "q1_wxyz")
    b = _quats(q2_wxyz, "q2_wxyz")
    dot = np.abs(np.sum(a * b, axis=-1))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))


def _map_quats(quat_wxyz: np.ndarray, fn) -> np.ndarray:
    r = quat_to_matrix(quat_wxyz)
    if r.ndim == 2:
        return matrix_to_quat(fn(r))
    return matrix_to_quat(np.stack([fn(m) for m in r]))


def ned_to_global(
    lat0_deg: float, lon0_deg: float, north_m: float, east_m: float
) -> tuple[float, float]:
    """Latitude and longitude of a local point: PX4's map projection (azimuthal equidistant).

    Parameters
    ----------
    lat0_deg, lon0_deg : float
        The local frame's origin [deg, WGS84].
    north_m, east_m : float
        The point [m].

    Returns
    -------
    tuple of float
        Latitude and longitude [deg].
    """
    lat0, lon0 = math.radians(lat0_deg), math.radians(lon0_deg)
    x, y = north_m / EARTH_RADIUS_M, east_m / EARTH_RADIUS_M
    c = math.hypot(x, y)
    if c == 0.0:
        return lat0_deg, lon0_deg
    sin_c, cos_c = math.sin(c), math.cos(c)
    lat = math.asin(cos_c * math.sin(lat0) + x * sin_c * math.cos(lat0) / c)
    lon = lon0 + math.atan2(y * sin_c, c * math.cos(lat0) * cos_c - x * math.sin(lat0) * sin_c)
    return math.degrees(lat), math.degrees(lon)


def global_to_ned(
    lat0_deg: float, lon0_deg: float, lat_deg: float, lon_deg: float
) -> tuple[float, float]:
    """Inverse of :func:`ned_to_global`.

    Parameters
    ----------
    lat0_deg, lon0_deg : float
        The local frame's origin [deg].
    lat_deg, lon_deg : float
        The point [deg].

    Returns
    -------
    tuple of float
        North and east [m].
    """
    lat0, lon0 = math.radians(lat0_deg), math.radians(lon0_deg)
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    cos_d = math.cos(lon - lon0)
    arg = math.sin(lat0) * math.sin(lat) + math.cos(lat0) * math.cos(lat) * cos_d
    arg = min(max(arg, -1.0), 1.0)
    c = math.acos(arg)
    k = c / math.sin(c) if c > 0.0 else 1.0
    north = k * (math.cos(lat0) * math.sin(lat) - math.sin(lat0) * math.cos(lat) * cos_d)
    east = k * math.cos(lat) * math.sin(lon - lon0)
    return north * EARTH_RADIUS_M, east * EARTH_RADIUS_M
