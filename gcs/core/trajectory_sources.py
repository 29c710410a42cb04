"""Trajectory sources beside the eight: circle and ellipse, waypoints, samples from a planner.

Every source is sampled on the ILC grid ``t_k = k t_ilc_s`` into a
:class:`gcs.core.trajectory.Reference` that starts and ends in hover at its start point (the
initial-reset condition of iterative learning control), in local NED [m]; paths may be
three-dimensional. A constant yaw reference is optional (default: held).

- :class:`EllipseShape` (``circle`` and ``ellipse``): ``p(s) = c + a cos(s0 + s) u +
  b sin(s0 + s) v`` in a plane spanned by ``u`` and ``v``, plus an optional climb and return
  along the vertical; the phase ``s(t)`` ramps up and down exactly as the eight's
  (:func:`gcs.core.trajectory.loop_phase`).
- :class:`WaypointsShape`: the waypoints joined by an interpolating quintic B-spline in time
  (:func:`scipy.interpolate.make_interp_spline`, degree 5) with zero velocity and acceleration
  at both ends; a quintic spline is four times continuously differentiable at its knots, so
  velocity, acceleration and jerk are continuous. Times are given, or derived from a peak
  speed (chord-length times, scaled so that the curve's peak speed is the given one).
- :class:`SamplesShape`: time-stamped positions from any planner, resampled onto the grid by
  piecewise-cubic Hermite interpolation (:class:`scipy.interpolate.PchipInterpolator`):
  it passes through every sample, has a continuous velocity, and never overshoots the samples
  on any axis, so a path whose samples are inside the arena stays inside it and a hover in
  the file stays a hover.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator, make_interp_spline

from gcs.core.trajectory import EightShape, Reference, loop_phase, sample_eight
from gcs.errors import TrajectoryError

__all__ = [
    "PLANES",
    "EllipseShape",
    "WaypointsShape",
    "SamplesShape",
    "plane_axes",
    "sample_ellipse",
    "sample_waypoints",
    "sample_samples",
    "sample_reference",
    "waypoint_times",
]

#: Named planes of a circle or an ellipse: the axes ``u`` (angle 0) and ``v`` (angle 90 deg).
PLANES = {
    "horizontal": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "north-down": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "east-down": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
}
#: Start and end of a samples file must agree to this [m] (the hover point of every trial).
SAMPLES_CLOSE_M = 1e-3
#: Samples of a file this close to its first (last) one count as its hover lead-in (-out) [m].
_STILL_M = 1e-6
#: Points per spline segment at which the peak speed of a waypoints curve is evaluated.
_DENSE = 200


def plane_axes(plane: str | tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Unit axes ``u`` (angle 0) and ``v`` (angle 90 deg) of a circle's plane, NED.

    A named plane from :data:`PLANES`, or a normal vector: ``u`` is north projected onto the
    plane (east if the normal is north) and ``v = n x u``, so that the normal ``down`` gives
    the horizontal plane, flown clockwise seen from above.

    Parameters
    ----------
    plane : str or tuple of float
        A name of :data:`PLANES`, or the plane's normal (north, east, down), any length > 0.

    Returns
    -------
    u, v : ndarray, shape (3,)
        Orthonormal axes of the plane.
    """
    if isinstance(plane, str):
        if plane not in PLANES:
            raise TrajectoryError(
                f"plane must be one of {', '.join(PLANES)} or a normal vector, got {plane!r}"
            )
        u, v = PLANES[plane]
        return np.array(u), np.array(v)
    n = np.asarray(plane, dtype=float)
    if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-9:
        raise TrajectoryError(f"plane normal must be three finite numbers, not all 0, got {plane}")
    n = n / np.linalg.norm(n)
    for axis in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        u = axis - np.dot(axis, n) * n
        if np.linalg.norm(u) > 1e-6:
            u = u / np.linalg.norm(u)
            return u, np.cross(n, u)
    raise AssertionError("unreachable: north or east has a component in any plane")


def _grid(duration_s: float, t_ilc_s: float) -> np.ndarray:
    if not t_ilc_s > 0:
        raise TrajectoryError(f"t_ilc_s must be > 0, got {t_ilc_s}")
    n = int(np.ceil(duration_s / t_ilc_s - 1e-9))
    if n < 2:
        raise TrajectoryError(
            f"a trial of {duration_s:g} s has fewer than 2 samples of {t_ilc_s:g} s"
        )
    return np.arange(n + 1) * t_ilc_s


def _yaw(yaw_deg: float | None, n: int) -> np.ndarray | None:
    return None if yaw_deg is None else np.full(n, math.radians(yaw_deg))


def _check_common(hover_s: float, yaw_deg: float | None) -> None:
    if not hover_s >= 0:
        raise TrajectoryError(f"hover_s must be >= 0, got {hover_s}")
    if yaw_deg is not None and not math.isfinite(yaw_deg):
        raise TrajectoryError(f"yaw_deg must be finite, got {yaw_deg}")


# ------------------------------------------------------------------------ circle and ellipse


@dataclass(frozen=True)
class EllipseShape:
    """A circle or an ellipse, flown ``loops`` times from and back to its start point.

    Parameters
    ----------
    center_ned_m : tuple of float
        Centre, local NED [m] (down sets the altitude, negative up).
    radii_m : tuple of float
        Semi-axes ``a`` along ``u`` and ``b`` along ``v`` [m] (equal for a circle).
    plane : str or tuple of float
        A name of :data:`PLANES` or the plane's normal (:func:`plane_axes`).
    start_angle_deg : float
        Angle of the start (and end) point from ``u`` towards ``v`` [deg].
    period_s : float
        Duration of one loop at full speed [s].
    loops : int
        Number of loops.
    ramp_s : float
        Duration of the acceleration and of the deceleration phase [s].
    hover_s : float
        Hover time at the start point before and after the motion [s].
    climb_m : float
        Height gained (up) at mid-manoeuvre and lost again by the end, as ``climb_m (1 -
        cos(s / loops)) / 2`` of the phase ``s``: a climbing then descending helix [m].
    yaw_deg : float or None
        Constant yaw reference [deg]; None: held.
    """

    center_ned_m: tuple[float, float, float]
    radii_m: tuple[float, float]
    period_s: float
    plane: str | tuple[float, float, float] = "horizontal"
    start_angle_deg: float = 0.0
    loops: int = 1
    ramp_s: float = 2.0
    hover_s: float = 1.0
    climb_m: float = 0.0
    yaw_deg: float | None = None

    @property
    def duration_s(self) -> float:
        """Length of the trial: hovers, ramps and loops [s]."""
        return 2.0 * self.hover_s + self.ramp_s + self.loops * self.period_s

    def __post_init__(self) -> None:
        if len(self.center_ned_m) != 3:
            raise TrajectoryError("center_ned_m must have three components (north, east, down)")
        if len(self.radii_m) != 2 or not all(r > 0 for r in self.radii_m):
            raise TrajectoryError(f"radii_m must be two numbers > 0, got {self.radii_m}")
        if not self.period_s > 0:
            raise TrajectoryError(f"period_s must be > 0, got {self.period_s}")
        if self.loops < 1:
            raise TrajectoryError(f"loops must be >= 1, got {self.loops}")
        if not self.ramp_s >= 0:
            raise TrajectoryError(f"ramp_s must be >= 0, got {self.ramp_s}")
        if self.ramp_s > self.loops * self.period_s:
            raise TrajectoryError("ramp_s is too long for the number of loops and the period")
        _check_common(self.hover_s, self.yaw_deg)
        plane_axes(self.plane)

    @property
    def start_ned_m(self) -> np.ndarray:
        """The start and end hover point, local NED [m]."""
        u, v = plane_axes(self.plane)
        a, b = self.radii_m
        th = math.radians(self.start_angle_deg)
        return np.asarray(self.center_ned_m, float) + a * math.cos(th) * u + b * math.sin(th) * v


def sample_ellipse(shape: EllipseShape, t_ilc_s: float) -> Reference:
    """Sample a circle or an ellipse on the grid ``k t_ilc_s``.

    Parameters
    ----------
    shape : EllipseShape
        Trajectory parameters.
    t_ilc_s : float
        ILC sample time [s].

    Returns
    -------
    Reference
        N + 1 samples, N = ceil(duration / t_ilc_s), first and last at the start point.
    """
    t = _grid(shape.duration_s, t_ilc_s)
    s, sd, sdd = loop_phase(t, shape.period_s, shape.loops, shape.ramp_s, shape.hover_s)
    u, v = plane_axes(shape.plane)
    a, b = shape.radii_m
    th = s + math.radians(shape.start_angle_deg)
    c, sn = np.cos(th)[:, None], np.sin(th)[:, None]
    p = a * c * u + b * sn * v  # position, first and second derivative in the phase
    dp = -a * sn * u + b * c * v
    ddp = -a * c * u - b * sn * v
    if shape.climb_m:
        L, h = shape.loops, shape.climb_m
        p[:, 2] -= 0.5 * h * (1.0 - np.cos(s / L))
        dp[:, 2] -= 0.5 * h * np.sin(s / L) / L
        ddp[:, 2] -= 0.5 * h * np.cos(s / L) / L**2
    pos = np.asarray(shape.center_ned_m, float) + p
    vel = dp * sd[:, None]
    acc = ddp * sd[:, None] ** 2 + dp * sdd[:, None]
    return Reference(t, pos, vel, acc, _yaw(shape.yaw_deg, len(t)))


# ----------------------------------------------------------------------------------- waypoints


@dataclass(frozen=True)
class WaypointsShape:
    """Waypoints joined by a quintic spline in time, from rest at the first back to rest there.

    Parameters
    ----------
    points_ned_m : tuple of tuple of float
        Waypoints, local NED [m], at least three; the last must be the first (the trial ends
        where it began).
    times_s : tuple of float or None
        Time of each waypoint from the start of the motion [s]: 0 first, strictly increasing
        by at least one ILC sample. None: from ``speed_m_s`` (:func:`waypoint_times`).
    speed_m_s : float or None
        Peak speed of the curve when ``times_s`` is not given [m/s].
    hover_s : float
        Hover time at the start point before and after the motion [s].
    yaw_deg : float or None
        Constant yaw reference [deg]; None: held.
    """

    points_ned_m: tuple[tuple[float, float, float], ...]
    times_s: tuple[float, ...] | None = None
    speed_m_s: float | None = None
    hover_s: float = 1.0
    yaw_deg: float | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.points_ned_m, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 3:
            raise TrajectoryError(
                f"points_ned_m must be at least three [north, east, down] points, got shape "
                f"{p.shape}"
            )
        if not np.all(np.isfinite(p)):
            raise TrajectoryError("points_ned_m must be finite")
        if not np.allclose(p[0], p[-1], rtol=0.0, atol=1e-9):
            raise TrajectoryError(
                f"the last waypoint {p[-1].tolist()} must be the first {p[0].tolist()} "
                "(the trial ends in hover where it began)"
            )
        if (self.times_s is None) == (self.speed_m_s is None):
            raise TrajectoryError("give either times_s or speed_m_s (not both)")
        if self.times_s is not None:
            t = np.asarray(self.times_s, dtype=float)
            if t.shape != (p.shape[0],):
                raise TrajectoryError(
                    f"times_s has {t.size} entries for {p.shape[0]} waypoints (one each)"
                )
            if not np.all(np.isfinite(t)) or t[0] != 0.0:
                raise TrajectoryError(f"times_s must be finite and start at 0, got {t[0]:g}")
            bad = np.flatnonzero(np.diff(t) <= 0)
            if bad.size:
                i = int(bad[0])
                raise TrajectoryError(
                    f"times_s must increase: waypoint {i + 1} at {t[i + 1]:g} s is not after "
                    f"waypoint {i} at {t[i]:g} s"
                )
        else:
            if not (self.speed_m_s is not None and self.speed_m_s > 0):
                raise TrajectoryError(f"speed_m_s must be > 0, got {self.speed_m_s}")
            step = np.linalg.norm(np.diff(p, axis=0), axis=1)
            same = np.flatnonzero(step < 1e-6)
            if same.size:
                i = int(same[0])
                raise TrajectoryError(
                    f"waypoints {i} and {i + 1} are the same point: no time between them can "
                    "be derived from speed_m_s (give times_s)"
                )
        _check_common(self.hover_s, self.yaw_deg)

    @property
    def duration_s(self) -> float:
        """Length of the trial: hovers and motion [s]."""
        return 2.0 * self.hover_s + float(waypoint_times(self)[-1])


def _spline(times_s: np.ndarray, points: np.ndarray):
    zero = np.zeros(3)
    ends = [(1, zero), (2, zero)]
    return make_interp_spline(times_s, points, k=5, bc_type=(ends, ends), axis=0)


def waypoint_times(shape: WaypointsShape) -> np.ndarray:
    """Time of each waypoint from the start of the motion [s].

    Given times are used as they are. Otherwise the times are the cumulative distances
    between the waypoints (chord length), then stretched uniformly so that the spline's peak
    speed is ``speed_m_s``: stretching time by ``alpha`` divides speed by ``alpha``,
    acceleration by ``alpha^2`` and jerk by ``alpha^3``, and leaves the path itself and the
    zero end conditions as they are.

    Parameters
    ----------
    shape : WaypointsShape
        The waypoints.

    Returns
    -------
    ndarray, shape (M,)
        Waypoint times [s], 0 first.
    """
    if shape.times_s is not None:
        return np.asarray(shape.times_s, dtype=float)
    p = np.asarray(shape.points_ned_m, dtype=float)
    tau = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    spline = _spline(tau, p)
    dense = np.linspace(0.0, tau[-1], _DENSE * (len(tau) - 1) + 1)
    peak = float(np.max(np.linalg.norm(spline.derivative(1)(dense), axis=1)))
    return tau * (peak / shape.speed_m_s)


def sample_waypoints(shape: WaypointsShape, t_ilc_s: float) -> Reference:
    """Sample a waypoints curve on the grid ``k t_ilc_s``.

    Parameters
    ----------
    shape : WaypointsShape
        The waypoints.
    t_ilc_s : float
        ILC sample time [s].

    Returns
    -------
    Reference
        N + 1 samples, first and last at the first waypoint.

    Raises
    ------
    TrajectoryError
        Two waypoints closer in time than one ILC sample.
    """
    times = waypoint_times(shape)
    gaps = np.diff(times)
    short = np.flatnonzero(gaps < t_ilc_s - 1e-12)
    if short.size:
        i = int(short[0])
        raise TrajectoryError(
            f"waypoints {i} and {i + 1} are {gaps[i]:.3g} s apart, less than one ILC sample "
            f"({t_ilc_s:g} s)"
        )
    p = np.asarray(shape.points_ned_m, dtype=float)
    spline = _spline(times, p)
    t = _grid(shape.duration_s, t_ilc_s)
    tm = np.clip(t - shape.hover_s, 0.0, times[-1])
    moving = ((t - shape.hover_s) > 0) & ((t - shape.hover_s) < times[-1])
    pos = spline(tm)
    vel = np.where(moving[:, None], spline.derivative(1)(tm), 0.0)
    acc = np.where(moving[:, None], spline.derivative(2)(tm), 0.0)
    pos[~moving & (t - shape.hover_s <= 0)] = p[0]
    pos[~moving & (t - shape.hover_s >= times[-1])] = p[-1]
    return Reference(t, pos, vel, acc, _yaw(shape.yaw_deg, len(t)))


# ------------------------------------------------------------------------------------- samples


@dataclass(frozen=True, eq=False)
class SamplesShape:
    """Time-stamped positions from a planner, to be resampled onto the ILC grid.

    Parameters
    ----------
    t_s : ndarray, shape (M,)
        Sample times [s], strictly increasing; counted from the first.
    pos_ned_m : ndarray, shape (M, 3)
        Positions, local NED [m]; the first and the last agree to :data:`SAMPLES_CLOSE_M`.
    yaw_rad : ndarray, shape (M,), or None
        Yaw [rad]; None: held.
    hover_s : float
        Hover at the first (last) point the trial has before (after) the motion [s]: what
        the file's own still samples at its start (end) do not cover is added.
    file : str
        Where the samples came from (for messages and the manifest).
    """

    t_s: np.ndarray
    pos_ned_m: np.ndarray
    yaw_rad: np.ndarray | None = None
    hover_s: float = 1.0
    file: str = "<samples>"

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, dtype=float)
        p = np.asarray(self.pos_ned_m, dtype=float)
        if t.ndim != 1 or t.size < 2 or p.shape != (t.size, 3):
            raise TrajectoryError(
                f"{self.file}: needs at least 2 samples of time and north, east, down"
            )
        for name, arr in (("time", t), ("position", p), ("yaw", self.yaw_rad)):
            if arr is not None and not np.all(np.isfinite(arr)):
                row = int(np.argwhere(~np.isfinite(np.asarray(arr)))[0][0])
                raise TrajectoryError(f"{self.file}: sample {row}: {name} is NaN or infinite")
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise TrajectoryError(
                f"{self.file}: sample {i}: time {t[i]:g} s is not after the previous "
                f"{t[i - 1]:g} s (times must strictly increase)"
            )
        gap = float(np.linalg.norm(p[-1] - p[0]))
        if gap > SAMPLES_CLOSE_M:
            raise TrajectoryError(
                f"{self.file}: the last sample {np.round(p[-1], 3).tolist()} is {gap:.3f} m "
                f"from the first {np.round(p[0], 3).tolist()}: the trial must end in hover "
                "where it began"
            )
        _check_common(self.hover_s, None)

    def _leads(self) -> tuple[float, float]:
        """Hover added before and after the file's samples [s]."""
        t = np.asarray(self.t_s, dtype=float)
        p = np.asarray(self.pos_ned_m, dtype=float)
        moved0 = np.flatnonzero(np.linalg.norm(p - p[0], axis=1) > _STILL_M)
        moved1 = np.flatnonzero(np.linalg.norm(p - p[-1], axis=1) > _STILL_M)
        still0 = t[moved0[0] - 1] - t[0] if moved0.size else t[-1] - t[0]
        still1 = t[-1] - t[moved1[-1] + 1] if moved1.size else t[-1] - t[0]
        return max(0.0, self.hover_s - still0), max(0.0, self.hover_s - still1)

    @property
    def duration_s(self) -> float:
        """Length of the trial: the samples' span and the hover added around it [s]."""
        lead_in, lead_out = self._leads()
        return lead_in + float(self.t_s[-1] - self.t_s[0]) + lead_out


def sample_samples(shape: SamplesShape, t_ilc_s: float) -> Reference:
    """Resample a planner's samples onto the grid ``k t_ilc_s``, hover added where missing.

    The file's first sample falls at the end of the added lead-in; between samples the path
    is the piecewise-cubic Hermite interpolant of each axis (see the module's note), before
    the first and after the last it holds them. Velocity and acceleration are the central
    differences of the resampled positions (zero at both ends, in hover): a planner's samples
    carry rounding that the interpolant's second derivative would magnify between close
    samples, while the differences are what the vehicle is asked for on the grid.

    Parameters
    ----------
    shape : SamplesShape
        The samples.
    t_ilc_s : float
        ILC sample time [s].

    Returns
    -------
    Reference
        N + 1 samples, N = ceil(duration / t_ilc_s).
    """
    lead_in, _ = shape._leads()
    ts = np.asarray(shape.t_s, dtype=float)
    ts = ts - ts[0] + lead_in
    t = _grid(shape.duration_s, t_ilc_s)
    tc = np.clip(t, ts[0], ts[-1])
    pos = PchipInterpolator(ts, np.asarray(shape.pos_ned_m, dtype=float), axis=0)(tc)
    vel = np.zeros_like(pos)
    acc = np.zeros_like(pos)
    vel[1:-1] = (pos[2:] - pos[:-2]) / (2.0 * t_ilc_s)
    acc[1:-1] = (pos[2:] - 2.0 * pos[1:-1] + pos[:-2]) / t_ilc_s**2
    yaw = None
    if shape.yaw_rad is not None:
        yaw = PchipInterpolator(ts, np.unwrap(np.asarray(shape.yaw_rad, dtype=float)))(tc)
    return Reference(t, pos, vel, acc, yaw)


# ---------------------------------------------------------------------------------- any source


def sample_reference(
    shape: EightShape | EllipseShape | WaypointsShape | SamplesShape, t_ilc_s: float
) -> Reference:
    """Sample any trajectory source on the grid ``k t_ilc_s``.

    Parameters
    ----------
    shape : EightShape, EllipseShape, WaypointsShape or SamplesShape
        The source.
    t_ilc_s : float
        ILC sample time [s].

    Returns
    -------
    Reference
    """
    if isinstance(shape, EightShape):
        return sample_eight(shape, t_ilc_s)
    if isinstance(shape, EllipseShape):
        return sample_ellipse(shape, t_ilc_s)
    if isinstance(shape, WaypointsShape):
        return sample_waypoints(shape, t_ilc_s)
    if isinstance(shape, SamplesShape):
        return sample_samples(shape, t_ilc_s)
    raise TrajectoryError(f"not a trajectory source: {type(shape).__name__}")
