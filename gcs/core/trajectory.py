"""Reference trajectories: the horizontal eight-shape, sampled on the ILC grid, and checks.

The other sources (circle and ellipse, waypoints, samples from a file) are in
:mod:`gcs.core.trajectory_sources`; every source gives a :class:`Reference`, checked here
against the vehicle's limits and the arena on the grid that is flown.

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

#: Longest trial gcs flies, in samples: twice the N = 6000 whose learning update is benchmarked
#: (0.6 s, 170 MB; docs/update.md); time and memory grow about linearly beyond.
MAX_SAMPLES = 12_000

__all__ = [
    "MAX_SAMPLES",
    "EightShape",
    "Reference",
    "Box",
    "sample_eight",
    "loop_phase",
    "check_reference",
    "check_setpoints",
    "setpoint_array",
    "points_outside",
]


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
    yaw_deg : float or None
        Constant yaw reference [deg]; None: held.
    """

    center_ned_m: tuple[float, float, float] = (0.0, 0.0, -1.5)
    amplitude_north_m: float = 1.2
    amplitude_east_m: float = 1.2
    period_s: float = 5.0
    loops: int = 2
    ramp_s: float = 2.0
    hover_s: float = 1.0
    yaw_deg: float | None = None

    @property
    def duration_s(self) -> float:
        """Length of the trial: hovers, ramps and loops [s]."""
        return 2.0 * self.hover_s + self.ramp_s + self.loops * self.period_s

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
    yaw_rad : ndarray, shape (N+1,), or None
        Desired yaw (heading from north, clockwise seen from above) [rad]; None: held (the
        vehicle keeps the heading of the profile's ``flight.yaw_deg``).
    """

    t_s: np.ndarray
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    acc_ned_m_s2: np.ndarray
    yaw_rad: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        """Number of learned samples N (the grid has N + 1 points)."""
        return len(self.t_s) - 1

    @property
    def t_ilc_s(self) -> float:
        """Sample time of the grid [s]."""
        return float(self.t_s[1] - self.t_s[0])

    @property
    def pos_ne_m(self) -> np.ndarray:
        """The horizontal part, shape (N+1, 2): north and east [m] (the learned axes)."""
        return self.pos_ned_m[:, :2]

    @property
    def down_m(self) -> np.ndarray:
        """The vertical part, shape (N+1,): down [m] (flown as the reference)."""
        return self.pos_ned_m[:, 2]


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
    return loop_phase(t, shape.period_s, shape.loops, shape.ramp_s, shape.hover_s)


def loop_phase(
    t: np.ndarray, period_s: float, loops: int, ramp_s: float, hover_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Phase of a looped path: hover, quintic ramp up, whole loops, ramp down, hover.

    The phase rate rises from 0 to ``2 pi / period_s`` with a quintic smooth-step over
    ``ramp_s``, stays there, and falls the same way; the total phase is ``2 pi loops``.

    Parameters
    ----------
    t : ndarray, shape (M,)
        Times from the start of the trial [s].
    period_s : float
        One loop at full phase rate [s].
    loops : int
        Number of loops.
    ramp_s : float
        Duration of each ramp [s].
    hover_s : float
        Hover before and after the motion [s].

    Returns
    -------
    s, s_dot, s_ddot : ndarray, shape (M,)
        Phase [rad], its rate [rad/s] and its second derivative [rad/s^2] (exact).
    """
    w = 2.0 * np.pi / period_s
    T = ramp_s
    cruise = loops * period_s - T  # ramps cover half their duration in phase
    if cruise < 0:
        raise TrajectoryError("ramp_s is too long for the number of loops and the period")
    tm = t - hover_s
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
    duration = shape.duration_s
    # ceil, not round: the last sample must not fall before the end of the motion
    n = int(np.ceil(duration / t_ilc_s - 1e-9))
    if n < 2:
        raise TrajectoryError(
            f"a trial of {duration:g} s has fewer than 2 samples of {t_ilc_s:g} s"
        )
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
    yaw = None if shape.yaw_deg is None else np.full(n + 1, np.radians(shape.yaw_deg))
    return Reference(t_s=t, pos_ned_m=pos, vel_ned_m_s=vel, acc_ned_m_s2=acc, yaw_rad=yaw)


def check_reference(
    ref: Reference,
    max_speed_m_s: float,
    max_accel_m_s2: float,
    arena: Box,
    *,
    max_jerk_m_s3: float | None = None,
    max_vertical_speed_m_s: float | None = None,
    max_vertical_accel_m_s2: float | None = None,
    max_vertical_jerk_m_s3: float | None = None,
    max_yaw_rate_deg_s: float | None = None,
) -> None:
    """Refuse a reference beyond the vehicle's limits or outside the arena.

    Speed and acceleration are checked twice: as designed (the analytic derivatives of the
    reference) and as flown, on the grid: the first and second finite differences of the
    sampled positions, ``(p(k+1) - p(k)) / dt`` and ``(p(k+1) - 2 p(k) + p(k-1)) / dt^2``. The
    vehicle receives samples, not the curve: a phase rate that jumps within one sample
    (``ramp_s: 0``) has bounded analytic derivatives but asks for the jump in one sample.
    Horizontal limits bound the norm of the north and east components; vertical ones the
    down component alone (up or down). Jerk is checked on the grid only, as the third
    difference over ``dt^3``.

    Parameters
    ----------
    ref : Reference
        The sampled reference.
    max_speed_m_s : float
        Largest horizontal speed the vehicle may be asked for [m/s].
    max_accel_m_s2 : float
        Largest horizontal acceleration [m/s^2].
    arena : Box
        Flight volume in local NED [m] (its down interval: ceiling and floor).
    max_jerk_m_s3 : float or None
        Largest horizontal jerk [m/s^3]; None: not checked.
    max_vertical_speed_m_s : float or None
        Largest vertical speed, up or down [m/s]; None: not checked.
    max_vertical_accel_m_s2 : float or None
        Largest vertical acceleration [m/s^2]; None: not checked.
    max_vertical_jerk_m_s3 : float or None
        Largest vertical jerk [m/s^3]; None: not checked.
    max_yaw_rate_deg_s : float or None
        Largest yaw rate of a reference with a yaw [deg/s], on the flown grid (the first
        difference of the unwrapped yaw); None: not checked.

    Raises
    ------
    TrajectoryError
        Naming the limit, the value and the time at which it is first exceeded.
    """
    dt = ref.t_ilc_s
    p = np.asarray(ref.pos_ned_m, dtype=float)
    ne, d = p[:, :2], p[:, 2]
    h_speed = "vehicle.max_speed_m_s"
    h_accel = "vehicle.max_accel_m_s2"
    checks = [
        (np.hypot(*ref.vel_ned_m_s[:, :2].T), ref.t_s, max_speed_m_s, "speed", "m/s", h_speed),
        (
            np.hypot(*ref.acc_ned_m_s2[:, :2].T),
            ref.t_s, max_accel_m_s2, "acceleration", "m/s^2", h_accel,
        ),
        (
            np.abs(ref.vel_ned_m_s[:, 2]), ref.t_s, max_vertical_speed_m_s,
            "vertical speed", "m/s", "vehicle.max_vertical_speed_m_s",
        ),
        (
            np.abs(ref.acc_ned_m_s2[:, 2]), ref.t_s, max_vertical_accel_m_s2,
            "vertical acceleration", "m/s^2", "vehicle.max_vertical_accel_m_s2",
        ),
    ]  # fmt: skip
    if p.shape[0] >= 3:
        flown = "on the flown grid"
        checks += [
            (
                np.hypot(*(np.diff(ne, axis=0) / dt).T), ref.t_s[:-1], max_speed_m_s,
                f"speed {flown}", "m/s", h_speed,
            ),
            (
                np.hypot(*(np.diff(ne, 2, axis=0) / dt**2).T), ref.t_s[1:-1], max_accel_m_s2,
                f"acceleration {flown}", "m/s^2", h_accel,
            ),
            (
                np.abs(np.diff(d) / dt), ref.t_s[:-1], max_vertical_speed_m_s,
                f"vertical speed {flown}", "m/s", "vehicle.max_vertical_speed_m_s",
            ),
            (
                np.abs(np.diff(d, 2) / dt**2), ref.t_s[1:-1], max_vertical_accel_m_s2,
                f"vertical acceleration {flown}", "m/s^2", "vehicle.max_vertical_accel_m_s2",
            ),
        ]  # fmt: skip
    if p.shape[0] >= 4:
        checks += [
            (
                np.hypot(*(np.diff(ne, 3, axis=0) / dt**3).T), ref.t_s[1:-2], max_jerk_m_s3,
                f"jerk {flown}", "m/s^3", "vehicle.max_jerk_m_s3",
            ),
            (
                np.abs(np.diff(d, 3) / dt**3), ref.t_s[1:-2], max_vertical_jerk_m_s3,
                f"vertical jerk {flown}", "m/s^3", "vehicle.max_vertical_jerk_m_s3",
            ),
        ]  # fmt: skip
    if ref.yaw_rad is not None:
        if not np.all(np.isfinite(ref.yaw_rad)):
            raise TrajectoryError("yaw is not finite (NaN or inf in the reference)")
        if ref.yaw_rad.size >= 2:
            checks.append(
                (
                    np.degrees(np.abs(np.diff(ref.yaw_rad))) / dt, ref.t_s[:-1],
                    max_yaw_rate_deg_s, "yaw rate on the flown grid", "deg/s",
                    "vehicle.max_yaw_rate_deg_s",
                )
            )  # fmt: skip
    for values, times, limit, what, unit, field in checks:
        if not np.all(np.isfinite(values)):
            raise TrajectoryError(f"{what} is not finite (NaN or inf in the reference)")
        if limit is None:
            continue
        over = np.flatnonzero(values > limit + 1e-9)
        if over.size:
            k = over[0]
            raise TrajectoryError(
                f"{what} {values.max():.2f} {unit} exceeds the vehicle limit {limit:g} {unit} "
                f"({field}; first at t = {times[k]:.2f} s)"
            )
    outside = points_outside(ref.pos_ned_m, arena)
    if outside.size:
        k = outside[0]
        p = ref.pos_ned_m[k]
        raise TrajectoryError(
            f"trajectory leaves the arena at t = {ref.t_s[k]:.2f} s: NED "
            f"({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}) m is outside {arena}{_beyond(p, arena)}"
        )


def _beyond(p: np.ndarray, arena: Box) -> str:
    """The first arena interval a point is outside of, in words."""
    b = arena.bounds()
    for axis, key in enumerate(("north_m", "east_m", "down_m")):
        lo, hi = b[axis]
        if lo - 1e-9 <= p[axis] <= hi + 1e-9:
            continue
        side = ""
        if key == "down_m":
            side = "above the ceiling, " if p[axis] < lo else "below the floor, "
        return f" ({side}arena.{key} is [{lo:g}, {hi:g}])"
    return ""


def setpoint_array(sp_ned_m: object, n: int | None = None) -> np.ndarray:
    """A setpoint sequence as a finite float array of shape (N, 3), or a refusal.

    Parameters
    ----------
    sp_ned_m : array_like, shape (N, 3)
        Setpoints ``u(0) .. u(N-1)``, local NED [m], N >= 1.
    n : int or None
        The N it must have (the reference's); None: any N >= 1.

    Returns
    -------
    ndarray, shape (N, 3)
        A float64 copy.

    Raises
    ------
    TrajectoryError
        Wrong shape, empty, or a NaN or infinite value (naming its sample).
    """
    sp = np.array(sp_ned_m, dtype=float)
    if sp.ndim != 2 or sp.shape[1] != 3 or sp.shape[0] < 1 or n not in (None, sp.shape[0]):
        need = "(N, 3) with N >= 1" if n is None else f"({n}, 3)"
        raise TrajectoryError(f"setpoints have shape {sp.shape}, expected {need}")
    bad = np.argwhere(~np.isfinite(sp))
    if bad.size:
        raise TrajectoryError(f"setpoint k = {bad[0][0]} is NaN or inf")
    return sp


def check_setpoints(
    sp_ned_m: np.ndarray,
    ref: Reference,
    arena: Box,
    max_step_m: float | None = None,
    max_deviation_m: float | None = None,
    relative_degrees: tuple[int, ...] = (1, 1),
    tol_m: float = 1e-6,
    vertical: tuple[float | None, float | None] | None = None,
) -> None:
    """Refuse a learned setpoint sequence that breaks a limit the learning keeps, on its grid.

    The input update keeps these limits as constraints of its QP; this checks the numbers that
    will be flown, independently of the solver: finite values, inside the arena, the step
    ``|u(k) - u(k-1)|`` per learned axis with ``u(-1)`` the reference's start (the hover
    point before the trial), and the deviation ``|u(k) - yd(k + r)|`` from the reference
    aligned by each axis's relative degree ``r`` (the tail held at the last reference sample).

    Parameters
    ----------
    sp_ned_m : ndarray, shape (N, 3)
        Setpoints ``u(0) .. u(N-1)``, local NED [m].
    ref : Reference
        The run's reference, N + 1 samples.
    arena : Box
        Flight volume [m].
    max_step_m : float or None
        Bound on the step per sample and horizontal axis [m]; None: not checked.
    max_deviation_m : float or None
        Bound on the deviation from the aligned reference per horizontal axis [m]; None: not
        checked.
    relative_degrees : tuple of int
        Relative degree of the north and east models (``>= 1``), and of the down model when
        down is learned (three entries).
    tol_m : float
        Tolerance of every bound [m] (the solver's constraints hold to about 1e-9 m).
    vertical : tuple of (float or None), optional
        ``(max_step_m, max_deviation_m)`` of the down axis when it is learned (then
        ``relative_degrees`` has three entries); None: down is not learned (flown as the
        reference, inside the arena).

    Raises
    ------
    TrajectoryError
        Naming the limit, the sample, the axis and the value.
    """
    sp = setpoint_array(sp_ned_m, ref.n_samples)
    outside = points_outside(sp, arena, tol_m)
    if outside.size:
        k = int(outside[0])
        raise TrajectoryError(
            f"setpoint k = {k} {np.round(sp[k], 3).tolist()} is outside the arena {arena}"
        )
    checks = [(a, name, max_step_m, max_deviation_m, "") for a, name in ((0, "north"), (1, "east"))]
    if vertical is not None:
        checks.append((2, "down", vertical[0], vertical[1], "vertical_"))
    yd = ref.pos_ned_m
    for axis, name, step_m, deviation_m, prefix in checks:
        u = sp[:, axis]
        if step_m is not None:
            step = np.abs(np.diff(np.concatenate([[yd[0, axis]], u])))
            over = np.flatnonzero(step > step_m + tol_m)
            if over.size:
                k = int(over[0])
                raise TrajectoryError(
                    f"setpoint k = {k} steps {step[k]:.3f} m on {name} "
                    f"(limit max_{prefix}step_m = {step_m:g} m)"
                )
        if deviation_m is not None:
            r = int(relative_degrees[axis])
            aligned = np.concatenate([yd[r:, axis], np.full(r - 1, yd[-1, axis])])
            dev = np.abs(u - aligned)
            over = np.flatnonzero(dev > deviation_m + tol_m)
            if over.size:
                k = int(over[0])
                raise TrajectoryError(
                    f"setpoint k = {k} is {dev[k]:.3f} m from the reference on {name} "
                    f"(limit max_{prefix}deviation_m = {deviation_m:g} m)"
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
    ndarray of int, shape (K,)
        The indices, ascending (empty when every point is inside).
    """
    b = arena.bounds()
    p = np.asarray(pos_ned_m, dtype=float)
    bad = np.any((p < b[:, 0] - tol_m) | (p > b[:, 1] + tol_m), axis=1)
    return np.flatnonzero(bad)
