"""How a vehicle hovers: statistics of a hover, a verdict on it, and the settle test (pure).

A motion-capture vehicle holds a point to a few centimetres; a GPS-navigated one (PX4 SITL
with EKF2 and GPS, the recorded PX4 v1.16 SITL runs) sits 0.1-1 m from its setpoint in the reported
position, wandering slowly at up to 0.2-0.4 m/s while its estimate settles, with 1-2 cm of fast
noise. Nothing here assumes either: before the first trial the campaign measures the hover at
the start point (:func:`hover_stats`), refuses a vehicle that does not hold position at all
(:func:`judge_hover`: drifting away, oscillating, or too far off), and derives from the
measurement the tolerances of the settle test before every trial (:func:`is_settled`): the
vehicle must be as close to the point as it is half of the time (the median distance, at least
``settle_tolerance_m``) and no faster than its hover (1.5 times the 95th-percentile speed, at
least ``settle_speed_m_s``) for ``settle_time_s``. The settle thereby picks a typical moment of
the hover to start the trial's initial-reset hold from, on any vehicle: a mocap-grade one is
held to centimetres (the floor), a GPS one to its own decimetres. When a settle times out
(the wander grew), the hover is judged again and the tolerances widen (:func:`widened`).

Every function takes arrays in and gives numbers out (no MAVSDK, no clock), so they are tested
on recorded hovers.

Definitions, all on the vehicle's own time stamps, positions relative to the target:

- *distance*: 3-D distance from the target [m];
- *speed*: displacement over :data:`SPEED_SPAN_S` divided by the time it took (fast noise of
  ``s`` metres adds about ``1.4 s / SPEED_SPAN_S`` to it);
- *fast noise*: RMS of what a centred moving mean over :data:`NOISE_SPAN_S` leaves;
- *drift*: speed of the least-squares straight line through the positions;
- *oscillation*: the strongest sinusoid with at least :data:`MIN_CYCLES` cycles in the
  window (least-squares fit over a frequency grid, all three axes together), its amplitude
  and the share of the detrended variance it explains.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gcs.io.settings import FlightSettings

__all__ = [
    "HoverStats",
    "HoverVerdict",
    "hover_stats",
    "judge_hover",
    "is_settled",
    "speeds",
    "SPEED_SPAN_S",
    "NOISE_SPAN_S",
    "MIN_CYCLES",
    "TOLERANCE_FACTOR",
    "widened",
    "OSCILLATION_SHARE",
]

SPEED_SPAN_S = 1.0
"""Span of the position differences a speed is measured over [s]."""
NOISE_SPAN_S = 1.0
"""Span of the moving mean that separates fast noise from wander [s]."""
MIN_CYCLES = 3.0
"""An oscillation needs this many cycles in the window to count (slower is wander)."""
MAX_OSCILLATION_HZ = 5.0
"""Highest oscillation frequency searched [Hz] (a position loop cannot oscillate faster)."""
OSCILLATION_SHARE = 0.5
"""A sinusoid explaining at least this share of the detrended variance is an oscillation."""
TOLERANCE_FACTOR = 1.5
"""The settle's speed tolerance is this factor times the hover's 95th-percentile speed."""
MIN_SAMPLES = 10


@dataclass(frozen=True)
class HoverStats:
    """Statistics of one hover at a target point.

    ``duration_s``: time spanned by the samples [s, vehicle time]. ``offset_ned_m``: mean position
    minus target, north, east, down [m]. ``offset_m``: 3-D length of ``offset_ned_m`` [m].
    ``distance_p50_m``: median 3-D distance from the target [m]. ``distance_p95_m``: 95th percentile
    of the 3-D distance from the target [m]. ``distance_max_m``: largest 3-D distance from the
    target [m]. ``noise_m``: fast noise: RMS (3-D) of the residual from a moving mean over
    ``NOISE_SPAN_S`` [m]. ``drift_m_s``: speed of the least-squares straight line through the
    positions (3-D) [m/s]. ``drift_away``: the straight line ends further from the target than it
    starts. ``speed_p50_m_s``, ``speed_p95_m_s``: median and 95th percentile of the speed over
    ``SPEED_SPAN_S`` (3-D) [m/s]. ``oscillation_m``: amplitude (3-D) of the strongest sinusoid with
    ``MIN_CYCLES`` or more cycles [m]. ``oscillation_period_s``: its period [s] (NaN when the window
    is too short to search). ``oscillation_share``: share of the detrended variance it explains
    (0..1).
    """

    duration_s: float
    n_samples: int
    offset_ned_m: tuple[float, float, float]
    offset_m: float
    distance_p50_m: float
    distance_p95_m: float
    distance_max_m: float
    noise_m: float
    drift_m_s: float
    drift_away: bool
    speed_p50_m_s: float
    speed_p95_m_s: float
    oscillation_m: float
    oscillation_period_s: float
    oscillation_share: float

    def describe(self) -> str:
        """One line for the operator, e.g. ``0.24 m off (95 % within 0.34 m), ...``."""
        text = (
            f"{self.offset_m:.2f} m off on average (95 % within {self.distance_p95_m:.2f} m, "
            f"at most {self.distance_max_m:.2f} m), {100 * self.noise_m:.1f} cm fast noise, "
            f"speed {self.speed_p50_m_s:.2f} m/s median, drift {self.drift_m_s:.2f} m/s"
        )
        if self.oscillation_share >= OSCILLATION_SHARE:
            text += (
                f", oscillating {self.oscillation_m:.2f} m every {self.oscillation_period_s:.1f} s"
            )
        return text + f" over {self.duration_s:.1f} s"


@dataclass(frozen=True)
class HoverVerdict:
    """Whether a hover is good enough to fly trials from, and the settle tolerances it gives.

    ``ok``: the vehicle holds position well enough. ``kind``: ``"ok"``, ``"short"`` (too few
    samples), ``"approaching"`` (still converging on the target: measure again), ``"oscillating"``,
    ``"drifting"`` or ``"off"`` (beyond ``hover_max_offset_m``). ``reason``: why, one line that
    follows "the vehicle ..." (empty when ``ok``). ``tolerance_m``: settle tolerance on the distance
    from the target [m]. ``speed_tolerance_m_s``: settle tolerance on the speed [m/s].
    """

    ok: bool
    kind: str
    reason: str
    tolerance_m: float
    speed_tolerance_m_s: float


def _check_samples(t_s: object, pos_ned_m: object) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(t_s, dtype=float)
    pos = np.asarray(pos_ned_m, dtype=float)
    if t.ndim != 1 or pos.ndim != 2 or pos.shape != (t.size, 3):
        raise ValueError(f"expected t_s (N,) and pos_ned_m (N, 3), got {t.shape} and {pos.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(pos))):
        raise ValueError("hover samples contain NaN or infinite values")
    if np.any(np.diff(t) < 0):
        raise ValueError("t_s must be non-decreasing")
    return t, pos


def speeds(t_s: object, pos_ned_m: object, span_s: float = SPEED_SPAN_S) -> np.ndarray:
    """Speed of each sample over the following ``span_s``: displacement / elapsed time.

    ``t_s``: sample times [s], non-decreasing. ``pos_ned_m``: positions, local NED [m]. ``span_s``:
    span of the differences [s].

    Returns: 3-D speeds [m/s] of the M samples that have a sample ``span_s`` or more later.
    """
    t, pos = _check_samples(t_s, pos_ned_m)
    later = np.searchsorted(t, t + span_s, side="left")
    has = later < t.size
    i, j = np.nonzero(has)[0], later[has]
    return np.linalg.norm(pos[j] - pos[i], axis=1) / (t[j] - t[i])


def _moving_mean(t: np.ndarray, x: np.ndarray, span_s: float) -> np.ndarray:
    """Centred moving mean over ``span_s`` of irregularly sampled ``x`` (N, D)."""
    csum = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    lo = np.searchsorted(t, t - span_s / 2, side="left")
    hi = np.searchsorted(t, t + span_s / 2, side="right")
    return (csum[hi] - csum[lo]) / (hi - lo)[:, None]


def _sinusoid_fits(
    t: np.ndarray, x: np.ndarray, freqs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares ``a sin + b cos`` per frequency (F,) and axis of ``x`` (N, D).

    Returns the variance explained per frequency (F,) and the coefficients a, b (F, D).
    """
    phase = 2.0 * np.pi * np.outer(freqs, t - t[0])  # (F, N)
    s, c = np.sin(phase), np.cos(phase)
    ss, cc, sc = np.sum(s * s, 1), np.sum(c * c, 1), np.sum(s * c, 1)
    sx, cx = s @ x, c @ x  # (F, D)
    det = (ss * cc - sc**2)[:, None]
    a = (cc[:, None] * sx - sc[:, None] * cx) / det
    b = (ss[:, None] * cx - sc[:, None] * sx) / det
    return np.sum(a * sx + b * cx, axis=1), a, b


def _oscillation(t: np.ndarray, x: np.ndarray) -> tuple[float, float, float]:
    """Strongest sinusoid with >= MIN_CYCLES cycles in detrended ``x`` (N, 3).

    A grid of a quarter of the window's frequency resolution, then a finer one around its
    best. Returns amplitude [m], period [s] and explained share of the variance.
    """
    duration = t[-1] - t[0]
    total = float(np.sum(x**2))
    if total <= 0 or duration <= 0:
        return 0.0, math.nan, 0.0
    f_min = MIN_CYCLES / duration
    f_max = min(MAX_OSCILLATION_HZ, 0.25 * (t.size - 1) / duration)  # 4 samples a period
    if f_min >= f_max:
        return 0.0, math.nan, 0.0
    step = 1.0 / (4.0 * duration)
    freqs = np.arange(f_min, f_max, step)
    explained, _, _ = _sinusoid_fits(t, x, freqs)
    best = freqs[int(np.argmax(explained))]
    fine = np.clip(np.linspace(best - step, best + step, 21), f_min, f_max)
    explained, a, b = _sinusoid_fits(t, x, fine)
    k = int(np.argmax(explained))
    amplitude = float(np.sqrt(np.sum(a[k] ** 2 + b[k] ** 2)))
    return amplitude, 1.0 / float(fine[k]), float(explained[k] / total)


def hover_stats(t_s: object, pos_ned_m: object, target_ned_m: object) -> HoverStats:
    """Statistics of a hover at ``target_ned_m`` (see the module docstring).

    ``t_s``: sample times [s] (the vehicle's clock), non-decreasing, N >= 10. ``pos_ned_m``:
    reported positions, local NED [m]. ``target_ned_m``: the hover setpoint, local NED [m].

    Raises ``ValueError``: wrong shapes, NaN, decreasing times, or fewer than 10 samples.
    """
    t, pos = _check_samples(t_s, pos_ned_m)
    target = np.asarray(target_ned_m, dtype=float).reshape(3)
    if t.size < MIN_SAMPLES or t[-1] <= t[0]:
        raise ValueError(f"a hover needs at least {MIN_SAMPLES} samples over a positive time")
    rel = pos - target
    dist = np.linalg.norm(rel, axis=1)
    offset = rel.mean(axis=0)
    tc = t - t.mean()
    slope = (tc @ (rel - offset)) / (tc @ tc)  # (3,) least-squares trend [m/s]
    line_start = offset + slope * tc[0]
    line_end = offset + slope * tc[-1]
    detrended = rel - offset - np.outer(tc, slope)
    noise = detrended - _moving_mean(t, detrended, NOISE_SPAN_S)
    v = speeds(t, pos)
    if v.size == 0:
        v = np.array([np.linalg.norm(pos[-1] - pos[0]) / (t[-1] - t[0])])
    amplitude, period, share = _oscillation(t, detrended)
    return HoverStats(
        duration_s=float(t[-1] - t[0]),
        n_samples=int(t.size),
        offset_ned_m=(float(offset[0]), float(offset[1]), float(offset[2])),
        offset_m=float(np.linalg.norm(offset)),
        distance_p50_m=float(np.median(dist)),
        distance_p95_m=float(np.percentile(dist, 95)),
        distance_max_m=float(dist.max()),
        noise_m=float(np.sqrt(np.mean(np.sum(noise**2, axis=1)))),
        drift_m_s=float(np.linalg.norm(slope)),
        drift_away=bool(np.linalg.norm(line_end) > np.linalg.norm(line_start)),
        speed_p50_m_s=float(np.median(v)),
        speed_p95_m_s=float(np.percentile(v, 95)),
        oscillation_m=amplitude,
        oscillation_period_s=period,
        oscillation_share=share,
    )


def judge_hover(stats: HoverStats, settings: FlightSettings) -> HoverVerdict:
    """Decide whether a measured hover is good enough, and derive the settle tolerances.

    Refused, in this order: an oscillation (a sinusoid with ``MIN_CYCLES`` or more cycles
    explaining ``OSCILLATION_SHARE`` of the motion, larger than ``hover_max_oscillation_m``);
    a drift away from the target faster than ``hover_max_drift_m_s`` (the same drift towards
    it is ``"approaching"``: the vehicle has not arrived yet); a hover that gets further than
    ``hover_max_offset_m`` from the target. Anything else is a vehicle that hovers, however
    loosely: its settle tolerances are the median distance and ``TOLERANCE_FACTOR`` times the
    95th-percentile speed measured, at least ``settle_tolerance_m`` and ``settle_speed_m_s``.

    ``settings``: limits (``hover_max_*``) and floors (``settle_tolerance_m``,
    ``settle_speed_m_s``).
    """
    s = settings
    tolerance_m = max(s.settle_tolerance_m, stats.distance_p50_m)
    speed_m_s = max(s.settle_speed_m_s, TOLERANCE_FACTOR * stats.speed_p95_m_s)

    def refuse(kind: str, reason: str) -> HoverVerdict:
        return HoverVerdict(False, kind, reason, tolerance_m, speed_m_s)

    if stats.oscillation_share >= OSCILLATION_SHARE and (
        stats.oscillation_m > s.hover_max_oscillation_m
    ):
        return refuse(
            "oscillating",
            f"oscillates {stats.oscillation_m:.2f} m every {stats.oscillation_period_s:.1f} s "
            f"({100 * stats.oscillation_share:.0f} % of its motion; flight.hover_max_oscillation_m"
            f" {s.hover_max_oscillation_m:g} m)",
        )
    if stats.drift_m_s > s.hover_max_drift_m_s:
        if not stats.drift_away:
            return refuse(
                "approaching",
                f"is still approaching the point at {stats.drift_m_s:.2f} m/s "
                f"(flight.hover_max_drift_m_s {s.hover_max_drift_m_s:g} m/s)",
            )
        return refuse(
            "drifting",
            f"drifts away at {stats.drift_m_s:.2f} m/s, {stats.distance_max_m:.2f} m off after "
            f"{stats.duration_s:.1f} s (flight.hover_max_drift_m_s {s.hover_max_drift_m_s:g} m/s)",
        )
    if stats.distance_max_m > s.hover_max_offset_m:
        return refuse(
            "off",
            f"hovers up to {stats.distance_max_m:.2f} m from the point "
            f"(flight.hover_max_offset_m {s.hover_max_offset_m:g} m)",
        )
    return HoverVerdict(True, "ok", "", tolerance_m, speed_m_s)


def widened(
    tolerance_m: float, speed_tolerance_m_s: float, stats: HoverStats, settings: FlightSettings
) -> tuple[float, float]:
    """Settle tolerances after a settle timed out on a vehicle that hovers (never narrower).

    The hover had been judged on a window where the vehicle stayed further out than the
    median distance measured before; the distance tolerance becomes the 95th percentile of
    that window, so that the next settle finds the vehicle within it most of the time.

    ``tolerance_m``: distance tolerance so far [m]. ``speed_tolerance_m_s``: speed tolerance so far
    [m/s]. ``stats``: the hover of the settle that timed out. ``settings``: floors
    (``settle_tolerance_m``, ``settle_speed_m_s``).
    """
    verdict = judge_hover(stats, settings)
    return (
        max(tolerance_m, stats.distance_p95_m, verdict.tolerance_m),
        max(speed_tolerance_m_s, verdict.speed_tolerance_m_s),
    )


def is_settled(
    t_s: object,
    pos_ned_m: object,
    target_ned_m: object,
    tolerance_m: float,
    speed_tolerance_m_s: float,
    window_s: float,
) -> bool:
    """Whether the last ``window_s`` of samples stayed within both settle tolerances.

    ``t_s``: sample times [s] (vehicle clock), non-decreasing. ``pos_ned_m``: positions, local NED
    [m]. ``target_ned_m``: hover point [m]. ``tolerance_m``: largest allowed 3-D distance from the
    target [m]. ``speed_tolerance_m_s``: largest allowed speed over ``SPEED_SPAN_S`` [m/s].
    ``window_s``: how long both must have held, up to the newest sample [s].

    Returns: False too when the samples span less than ``window_s + SPEED_SPAN_S``.
    """
    t, pos = _check_samples(t_s, pos_ned_m)
    if t.size < 2 or t[-1] - t[0] < window_s + SPEED_SPAN_S:
        return False
    recent = t >= t[-1] - window_s
    dist = np.linalg.norm(pos[recent] - np.asarray(target_ned_m, dtype=float).reshape(3), axis=1)
    if np.any(dist > tolerance_m):
        return False
    first = int(np.searchsorted(t, t[-1] - window_s - SPEED_SPAN_S, side="left"))
    v = speeds(t[first:], pos[first:])
    return bool(v.size > 0 and np.all(v <= speed_tolerance_m_s))
