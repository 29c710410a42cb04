"""Is the motion-capture stream usable right now? (pure: arrays in, one-line reason out)

Each check takes the recent samples of one rigid body (:class:`MocapSeries`, receipt times on
the monotonic clock, poses in the system's axes, any frame: the checks only use distances and
angles) and returns None when all is well or a one-line reason, as
:meth:`gcs.flight.vehicle.Vehicle.control_problem` does for telemetry, so that a trial can
abort on it the same way:

- **stale**: the newest sample is older than ``max_age_s`` (frames stopped coming: server
  stopped, network down, dropout);
- **occluded**: frames come, but the rigid body has not been tracked for ``max_occluded_s``
  (markers hidden, body left the volume), or never was;
- **frozen**: the last ``frozen_s`` of tracked samples (at least ``frozen_min_repeats``)
  are bit-identical: the server repeats a frame. Real marker noise makes consecutive solves
  differ in their last bits, so only a stream that replays the same frame stays identical;
  a noise-free simulation would trip it;
- **jump**: between consecutive tracked samples the body moved farther than physics allows,
  ``v_max dt + a_max dt^2 / 2 + margin``, or turned more than ``w_max dt + margin``, with
  ``dt`` the receipt interval but at least the mean interval of the window (frames that
  arrive in a burst are a frame period apart in reality). A mis-solve (markers swapped
  between bodies, a symmetric marker set flipping) shows as such a jump.

The thresholds (:class:`HealthLimits`) are chosen for an indoor multirotor at 50-360 Hz;
docs/mocap.md gives the reasoning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from gcs.core.frames import quat_angle_rad
from gcs.errors import ProfileError
from gcs.io.mocap_samples import MocapSeries

__all__ = [
    "HealthLimits",
    "stale_problem",
    "occlusion_problem",
    "frozen_problem",
    "jump_problem",
    "stream_problem",
]


@dataclass(frozen=True)
class HealthLimits:
    """Thresholds of the stream checks.

    Parameters
    ----------
    max_age_s : float
        Newest sample older than this: stale [s]. 0.4 s by default: PX4's EKF2 stops fusing
        vision 2 x EV_MAX_INTERVAL = 0.4 s after the last sample, so a shorter gap is invisible
        to the vehicle's navigation (0.2 s, the earlier default, ended nine flights in a row on
        real PX4 SITL on this 2-core machine under a load average of 12-14, where a NatNet
        server thread alone in its process paused up to 0.36 s).
    max_occluded_s : float
        Rigid body untracked for longer than this while frames come: occluded [s].
    frozen_s : float
        Identical tracked samples over at least this long: frozen [s].
    frozen_min_repeats : int
        ... and at least this many identical samples in a row.
    max_speed_m_s : float
        Fastest believable speed of the body [m/s].
    max_accel_m_s2 : float
        Largest believable acceleration [m/s^2].
    jump_margin_m : float
        Allowance on top of the physics bound (noise, timing) [m].
    max_rate_deg_s : float
        Fastest believable rotation [deg/s].
    turn_margin_deg : float
        Allowance on top of the rotation bound [deg].
    """

    max_age_s: float = 0.4
    max_occluded_s: float = 0.2
    frozen_s: float = 0.1
    frozen_min_repeats: int = 3
    max_speed_m_s: float = 10.0
    max_accel_m_s2: float = 30.0
    jump_margin_m: float = 0.02
    max_rate_deg_s: float = 2000.0
    turn_margin_deg: float = 10.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value > 0):
                raise ProfileError(f"mocap health: {f.name} must be positive, got {value}")


def stale_problem(series: MocapSeries, now_s: float, limits: HealthLimits) -> str | None:
    """Whether the stream has stopped.

    Parameters
    ----------
    series : MocapSeries
        Recent samples.
    now_s : float
        Current monotonic time [s].
    limits : HealthLimits
        Thresholds.

    Returns
    -------
    str or None
        Reason, or None if the newest sample is recent enough.
    """
    if len(series) == 0:
        return "no mocap frames received"
    age = now_s - float(series.t_receipt_s[-1])
    if age > limits.max_age_s:
        return f"mocap stream stale ({age:.2f} s since the last frame)"
    return None


def occlusion_problem(series: MocapSeries, now_s: float, limits: HealthLimits) -> str | None:
    """Whether the rigid body has been out of the frames for too long.

    Parameters
    ----------
    series : MocapSeries
        Recent samples (at least ``max_occluded_s`` of them for the check to bite).
    now_s : float
        Current monotonic time [s].
    limits : HealthLimits
        Thresholds.

    Returns
    -------
    str or None
    """
    if len(series) == 0:
        return None  # nothing to judge: that is staleness
    if series.tracked[-1]:
        return None
    tracked = np.flatnonzero(series.tracked)
    if tracked.size == 0:
        span = now_s - float(series.t_receipt_s[0])
        if span > limits.max_occluded_s:
            return f"rigid body not tracked in any frame of the last {span:.2f} s"
        return None
    lost_s = now_s - float(series.t_receipt_s[tracked[-1]])
    if lost_s > limits.max_occluded_s:
        return f"rigid body lost (not tracked for {lost_s:.2f} s)"
    return None


def frozen_problem(series: MocapSeries, limits: HealthLimits) -> str | None:
    """Whether the stream repeats the same frame.

    Parameters
    ----------
    series : MocapSeries
        Recent samples.
    limits : HealthLimits
        Thresholds.

    Returns
    -------
    str or None
    """
    idx = np.flatnonzero(series.tracked)
    if idx.size < 2:
        return None
    pose = np.hstack([series.pos_m[idx], series.quat_wxyz[idx]])
    last = pose[-1]
    same = np.all(pose == last, axis=1)
    # length of the trailing run of samples identical to the newest
    run = idx.size if same.all() else idx.size - 1 - int(np.flatnonzero(~same)[-1])
    if run < limits.frozen_min_repeats:
        return None
    span = float(series.t_receipt_s[idx[-1]] - series.t_receipt_s[idx[-run]])
    if span >= limits.frozen_s:
        return f"mocap stream frozen ({run} identical frames over {span:.2f} s)"
    return None


def _intervals(t: np.ndarray) -> np.ndarray:
    """Receipt intervals, each at least the window's mean frame interval."""
    dt = np.diff(t)
    if dt.size == 0:
        return dt
    return np.maximum(dt, float(t[-1] - t[0]) / dt.size)


def jump_problem(series: MocapSeries, limits: HealthLimits) -> str | None:
    """Whether the body moved or turned faster than physics allows between two frames.

    Parameters
    ----------
    series : MocapSeries
        Recent samples.
    limits : HealthLimits
        Thresholds.

    Returns
    -------
    str or None
        The largest violation, or None.
    """
    idx = np.flatnonzero(series.tracked)
    if idx.size < 2:
        return None
    t = series.t_receipt_s[idx]
    dt = _intervals(t)
    step = np.linalg.norm(np.diff(series.pos_m[idx], axis=0), axis=1)
    bound = limits.max_speed_m_s * dt + 0.5 * limits.max_accel_m_s2 * dt**2 + limits.jump_margin_m
    ratio = step / bound
    k = int(np.argmax(ratio))
    if ratio[k] > 1.0:
        return (
            f"mocap position jumped {step[k]:.3f} m in {dt[k] * 1e3:.1f} ms "
            f"(more than {bound[k]:.3f} m possible)"
        )
    q = series.quat_wxyz[idx]
    turn = np.degrees(quat_angle_rad(q[1:], q[:-1]))
    turn_bound = limits.max_rate_deg_s * dt + limits.turn_margin_deg
    k = int(np.argmax(turn / turn_bound))
    if turn[k] > turn_bound[k]:
        return (
            f"mocap attitude jumped {turn[k]:.0f} deg in {dt[k] * 1e3:.1f} ms "
            f"(more than {turn_bound[k]:.0f} deg possible)"
        )
    return None


def stream_problem(
    series: MocapSeries, now_s: float, limits: HealthLimits | None = None
) -> str | None:
    """The first problem of the stream (stale, occluded, frozen, jump), or None.

    Parameters
    ----------
    series : MocapSeries
        Recent samples, e.g. ``client.recent(0.5)``.
    now_s : float
        Current monotonic time [s].
    limits : HealthLimits or None
        Thresholds (defaults if None).

    Returns
    -------
    str or None
    """
    limits = limits or HealthLimits()
    return (
        stale_problem(series, now_s, limits)
        or occlusion_problem(series, now_s, limits)
        or frozen_problem(series, limits)
        or jump_problem(series, limits)
    )
