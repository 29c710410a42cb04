"""Reference trajectories: the horizontal eight-shape, sampled on the ILC grid, and checks.

The eight is the Lissajous curve ``north = a sin(s)``, ``east = (b / 2) sin(2 s)`` around a
centre point, flown at constant altitude. The phase ``s(t)`` starts at rest, accelerates with a
quintic smooth-step of the phase rate over ``ramp_s`` seconds, flies whole loops at constant
phase rate ``2 pi / period_s``, decelerates the same way and ends at rest where it began, so
that start and end are the same hover point and the acceleration phases are part of what is
learned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gcs.errors import TrajectoryError

__all__ = ["EightShape", "Reference", "Box", "sample_eight", "check_reference"]


@dataclass(frozen=True)
class EightShape:
    """Parameters of the eight-shape.

    Parameters
    ----------
    center_ned_m : tuple of float
        Centre of the eight (also the start and end hover point), local NED [m];
        the down component sets the altitude (negative up).
    amplitude_north_m : float
        Half length of the eight along north ``a`` [m].
    amplitude_east_m : float
        Width parameter ``b``: east excursion is ``b / 2`` [m].
    period_s : float
        Duration of one loop at full speed [s].
    loops : int
        Number of loops.
    ramp_s : float
        Duration of the acceleration and of the deceleration phase [s].
    hover_s : float
        Hover time at the start point before and after the motion [s].
    """

    center_ned_m: tuple[float, float, float] = (0.0, 0.0, -1.5)
    amplitude_north_m: float = 1.2
    amplitude_east_m: float = 1.2
    period_s: float = 5.0
    loops: int = 2
    ramp_s: float = 2.0
    hover_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("amplitude_north_m", "amplitude_east_m", "period_s"):
            if not getattr(self, name) > 0:
                raise TrajectoryError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.loops < 1:
            raise TrajectoryError(f"loops must be >= 1, got {self.loops}")
        if self.ramp_s < 0 or self.hover_s < 0:
            raise TrajectoryError("ramp_s and hover_s must be >= 0")
        if len(self.center_ned_m) != 3:
            raise TrajectoryError("center_ned_m must have three components (north, east, down)")


@dataclass(frozen=True)
class Reference:
    """A reference sampled on the ILC grid ``t_k = k t_ilc_s``, k = 0..N.

    Parameters
    ----------
    t_s : ndarray, shape (N+1,)
        Grid times [s].
    pos_ned_m : ndarray, shape (N+1, 3)
        Desired position, local NED [m]; row 0 is the start hover point.
    vel_ned_m_s : ndarray, shape (N+1, 3)
        Desired velocity [m/s].
    acc_ned_m_s2 : ndarray, shape (N+1, 3)
        Desired acceleration [m/s^2].
    """

    t_s: np.ndarray
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    acc_ned_m_s2: np.ndarray

    @property
    def n_samples(self) -> int:
        """Number of learned samples N (the grid has N + 1 points)."""
        return len(self.t_s) - 1

    @property
    def t_ilc_s(self) -> float:
        """Sample time of the grid [s]."""
        return float(self.t_s[1] - self.t_s[0])


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in local NED [m] (the flight volume).

    Parameters
    ----------
    north_m, east_m, down_m : tuple of float
        ``(min, max)`` per axis [m].
    """

    north_m: tuple[float, float]
    east_m: tuple[float, float]
    down_m: tuple[float, float]

    def bounds(self) -> np.ndarray:
        """Array of shape (3, 2) of (min, max) per NED axis [m]."""
        return np.array([self.north_m, self.east_m, self.down_m], dtype=float)


def _smoothstep(tau: np.ndarray) -> np.ndarray:
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


def _phase(t: np.ndarray, shape: EightShape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Phase s(t), its rate and its second derivative (all exact, vectorised)."""
    w = 2.0 * np.pi / shape.period_s
    T = shape.ramp_s
    cruise = shape.loops * shape.period_s - T  # ramps cover half their duration in phase
    if cruise < 0:
        raise TrajectoryError("ramp_s is too long for the number of loops and the period")
    tm = t - shape.hover_s
    t_end = 2.0 * T + cruise
    s = np.zeros_like(t)
    sd = np.zeros_like(t)
    sdd = np.zeros_like(t)
    if T > 0:
        up = (tm > 0) & (tm < T)
        tau = tm[up] / T
        # integral of the smooth-step: T (5/2 tau^4 - 3 tau^5 + tau^6)
        s[up] = w * T * (2.5 * tau**4 - 3.0 * tau**5 + tau**6)
        sd[up] = w * _smoothstep(tau)
        sdd[up] = w / T * 30.0 * tau**2 * (1.0 - tau) ** 2
    mid = (tm >= T) & (tm <= T + cruise)
    s[mid] = w * (T / 2.0 + (tm[mid] - T))
    sd[mid] = w
    if T > 0:
        down = (tm > T + cruise) & (tm < t_end)
        tau = (t_end - tm[down]) / T
        s_total = w * (T + cruise)
        s[down] = s_total - w * T * (2.5 * tau**4 - 3.0 * tau**5 + tau**6)
        sd[down] = w * _smoothstep(tau)
        sdd[down] = -w / T * 30.0 * tau**2 * (1.0 - tau) ** 2
    s[tm >= t_end] = w * (T + cruise)
    return s, sd, sdd


def sample_eight(shape: EightShape, t_ilc_s: float) -> Reference:
    """Sample the eight-shape on the grid ``k t_ilc_s``.

    Parameters
    ----------
    shape : EightShape
        Trajectory parameters.
    t_ilc_s : float
        ILC sample time [s].

    Returns
    -------
    Reference
        N + 1 samples, N = ceil(duration / t_ilc_s), first and last at the centre.
    """
    if not t_ilc_s > 0:
        raise TrajectoryError(f"t_ilc_s must be > 0, got {t_ilc_s}")
    duration = 2.0 * shape.hover_s + shape.ramp_s + shape.loops * shape.period_s
    # ceil, not round: the last sample must not fall before the end of the motion
    n = int(np.ceil(duration / t_ilc_s - 1e-9))
    t = np.arange(n + 1) * t_ilc_s
    s, sd, sdd = _phase(t, shape)
    a, b = shape.amplitude_north_m, shape.amplitude_east_m
    pos = np.zeros((n + 1, 3))
    vel = np.zeros((n + 1, 3))
    acc = np.zeros((n + 1, 3))
    pos[:, 0] = a * np.sin(s)
    pos[:, 1] = 0.5 * b * np.sin(2.0 * s)
    vel[:, 0] = a * np.cos(s) * sd
    vel[:, 1] = b * np.cos(2.0 * s) * sd
    acc[:, 0] = a * (np.cos(s) * sdd - np.sin(s) * sd**2)
    acc[:, 1] = b * (np.cos(2.0 * s) * sdd - 2.0 * np.sin(2.0 * s) * sd**2)
    pos += np.asarray(shape.center_ned_m, dtype=float)
    return Reference(t_s=t, pos_ned_m=pos, vel_ned_m_s=vel, acc_ned_m_s2=acc)


def check_reference(
    ref: Reference, max_speed_m_s: float, max_accel_m_s2: float, arena: Box
) -> None:
    """Refuse a reference beyond the vehicle's limits or outside the arena.

    Parameters
    ----------
    ref : Reference
        The sampled reference.
    max_speed_m_s : float
        Largest horizontal speed the vehicle may be asked for [m/s].
    max_accel_m_s2 : float
        Largest horizontal acceleration [m/s^2].
    arena : Box
        Flight volume in local NED [m].

    Raises
    ------
    TrajectoryError
        Naming the limit, the value and the time at which it is first exceeded.
    """
    speed = np.hypot(ref.vel_ned_m_s[:, 0], ref.vel_ned_m_s[:, 1])
    accel = np.hypot(ref.acc_ned_m_s2[:, 0], ref.acc_ned_m_s2[:, 1])
    for values, limit, what, unit in (
        (speed, max_speed_m_s, "speed", "m/s"),
        (accel, max_accel_m_s2, "acceleration", "m/s^2"),
    ):
        over = np.flatnonzero(values > limit + 1e-9)
        if over.size:
            k = over[0]
            raise TrajectoryError(
                f"{what} {values.max():.2f} {unit} exceeds the vehicle limit {limit:g} {unit} "
                f"(first at t = {ref.t_s[k]:.2f} s)"
            )
    outside = points_outside(ref.pos_ned_m, arena)
    if outside.size:
        k = outside[0]
        p = ref.pos_ned_m[k]
        raise TrajectoryError(
            f"trajectory leaves the arena at t = {ref.t_s[k]:.2f} s: NED "
            f"({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}) m is outside {arena}"
        )


def points_outside(pos_ned_m: np.ndarray, arena: Box, tol_m: float = 1e-9) -> np.ndarray:
    """Indices of the rows of ``pos_ned_m`` (shape (N, 3), NED [m]) outside ``arena``.

    Parameters
    ----------
    pos_ned_m : ndarray, shape (N, 3)
        Points in local NED [m].
    arena : Box
        Flight volume.
    tol_m : float
        Tolerance [m].

    Returns
    -------
    ndarray of int
    """
    b = arena.bounds()
    p = np.asarray(pos_ned_m, dtype=float)
    bad = np.any((p < b[:, 0] - tol_m) | (p > b[:, 1] + tol_m), axis=1)
    return np.flatnonzero(bad)
