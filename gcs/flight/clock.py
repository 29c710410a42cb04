"""The vehicle's clock against ours: continuous vehicle time and a robust rate/offset fit (pure).

PX4 stamps LOCAL_POSITION_NED with ``time_boot_ms``, its own clock since boot. A simulator
under load runs that clock slower than the wall clock (PX4 SITL in lockstep was seen at
0.72-0.9x; the shared capture ``px4-sih-offboard.tlog`` at 0.994x), and samples reach gcs
after a latency that is never negative but often larger than usual (scheduling, a busy
link). The model is::

    receipt_time = offset + vehicle_time / rate + latency,   latency >= 0

:func:`fit_clock` fits it by the lower envelope of the points ``(vehicle_time,
receipt_time)``: the line under all points that is closest to them on average. It is the
edge of their lower convex hull above the mean vehicle time (Moon, Skelly and Towsley's
one-way-delay estimator). Late samples lie above the hull and cannot move it, however late,
so latency spikes cost nothing; the offset it gives includes the smallest latency seen.

:func:`unwrap_vehicle_time` turns the raw stamps into a continuous time: a ``time_boot_ms``
counter wrap (uint32, after 49.7 days) adds ``2**32`` ms, and a restart of the vehicle (its
clock jumps back) continues from where the old clock would have been by the receipt times,
so that nothing downstream sees time go backwards. :class:`VehicleClock` does the same
sample by sample and keeps a sliding window for the fit.

:class:`Clock` is the *local* clock itself, injected into the flight layer (``now``, ``sleep``):
:class:`WallClock` by default, the simulated link's virtual clock in the tests
(:mod:`gcs.sim`), so that a flight can run in virtual time.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Protocol

import numpy as np

__all__ = [
    "BOOT_MS_WRAP_S",
    "Clock",
    "LoopClock",
    "WALL_CLOCK",
    "WallClock",
    "RESTART_JUMP_S",
    "ClockFit",
    "VehicleClock",
    "fit_clock",
    "unwrap_vehicle_time",
    "lower_hull",
    "rate_warning",
    "RATE_TOLERANCE",
]

BOOT_MS_WRAP_S = 2**32 / 1000.0
"""Period of the uint32 ``time_boot_ms`` counter [s]."""
RATE_TOLERANCE = 0.02
"""A trial whose vehicle-time rate is further than this from 1 is reported."""
RESTART_JUMP_S = 1.0
"""A vehicle clock that jumps back by more than this (and not by a wrap) has restarted [s];
smaller steps back are reordered datagrams and are kept as they are."""


@dataclass(frozen=True)
class ClockFit:
    """The vehicle clock as seen from the local clock: ``local = offset + vehicle / rate``.

    ``rate``: vehicle seconds per local (wall) second; 1 for real time, 0.9 for a simulator at 90 %
    of real time. ``offset_s``: local time at vehicle time 0, smallest latency included [s].
    ``span_s``: vehicle time they span [s]. ``latency_p50_s``: median receipt delay above the fitted
    line [s]. ``latency_max_s``: largest receipt delay above the fitted line [s].
    """

    rate: float
    offset_s: float
    n_samples: int
    span_s: float
    latency_p50_s: float
    latency_max_s: float

    def to_local(self, vehicle_t_s: float | np.ndarray) -> float | np.ndarray:
        """Local time of a vehicle time (plus the smallest latency).

        ``vehicle_t_s``: continuous vehicle time [s].

        Returns: local time [s].
        """
        return self.offset_s + vehicle_t_s / self.rate

    def to_vehicle(self, local_t_s: float | np.ndarray) -> float | np.ndarray:
        """Vehicle time at a local time (inverse of :meth:`to_local`).

        ``local_t_s``: local time [s].

        Returns: continuous vehicle time [s].
        """
        return (local_t_s - self.offset_s) * self.rate


def lower_hull(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Indices of the lower convex hull of points sorted by ``x`` (Andrew's monotone chain).

    Returns: hull vertices from left to right; of equal ``x`` only the lowest point can be one.
    """
    hull: list[int] = []
    xs, ys = x.tolist(), y.tolist()
    for i in range(len(xs)):
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            # drop b unless it lies strictly below the segment a-i (turns counter-clockwise)
            cross = (xs[b] - xs[a]) * (ys[i] - ys[a]) - (ys[b] - ys[a]) * (xs[i] - xs[a])
            if cross > 0:
                break
            hull.pop()
        if hull and xs[hull[-1]] == xs[i]:
            if ys[i] >= ys[hull[-1]]:
                continue
            hull.pop()
        hull.append(i)
    return np.array(hull, dtype=int)


def fit_clock(vehicle_t_s: object, receipt_t_s: object) -> ClockFit:
    """Fit ``receipt = offset + vehicle / rate + latency`` (latency >= 0) by the lower envelope.

    ``vehicle_t_s``: continuous vehicle time of each sample [s] (see :func:`unwrap_vehicle_time`),
    non-decreasing. ``receipt_t_s``: local receipt time of each sample [s].

    Raises ``ValueError``: shapes differ, NaN, decreasing vehicle time, fewer than two distinct
    vehicle times, or a fitted rate that is not positive.
    """
    v = np.asarray(vehicle_t_s, dtype=float).reshape(-1)
    r = np.asarray(receipt_t_s, dtype=float).reshape(-1)
    if v.shape != r.shape or not (np.all(np.isfinite(v)) and np.all(np.isfinite(r))):
        raise ValueError("vehicle_t_s and receipt_t_s must be finite and of equal length")
    if np.any(np.diff(v) < 0):
        raise ValueError("vehicle_t_s must be non-decreasing (unwrap it first)")
    if v.size < 2 or v[-1] <= v[0]:
        raise ValueError("a clock fit needs samples at two or more vehicle times")
    hull = lower_hull(v, r)
    # the hull edge above the mean vehicle time minimises the mean latency under the constraint
    k = int(np.clip(np.searchsorted(v[hull], v.mean(), side="right") - 1, 0, hull.size - 2))
    a, b = hull[k], hull[k + 1]
    slope = (r[b] - r[a]) / (v[b] - v[a])
    if not slope > 0:
        raise ValueError(f"vehicle clock does not advance with the local clock (slope {slope})")
    offset = r[a] - slope * v[a]
    latency = r - (offset + slope * v)
    return ClockFit(
        rate=float(1.0 / slope),
        offset_s=float(offset),
        n_samples=int(v.size),
        span_s=float(v[-1] - v[0]),
        latency_p50_s=float(np.median(latency)),
        latency_max_s=float(latency.max()),
    )


def unwrap_vehicle_time(
    raw_t_s: object,
    receipt_t_s: object,
    wrap_s: float = BOOT_MS_WRAP_S,
    restart_jump_s: float = RESTART_JUMP_S,
) -> np.ndarray:
    """Continuous vehicle time from raw stamps: counter wraps removed, restarts bridged.

    ``raw_t_s``: the vehicle's stamps as received [s] (e.g. ``time_boot_ms / 1000``), in receipt
    order. ``receipt_t_s``: local receipt times [s], used to bridge a restart. ``wrap_s``: period of
    the counter [s]; ``inf`` for a stamp that does not wrap. ``restart_jump_s``: a step back larger
    than this, and not a wrap, is a restart [s].

    Returns: continuous vehicle time [s]: equal to ``raw_t_s`` until the first wrap or restart. A
    reordered datagram keeps its own (earlier) time: sort before interpolating.
    """
    clock = VehicleClock(wrap_s=wrap_s, restart_jump_s=restart_jump_s)
    raw = np.asarray(raw_t_s, dtype=float).reshape(-1)
    receipt = np.asarray(receipt_t_s, dtype=float).reshape(-1)
    if raw.shape != receipt.shape:
        raise ValueError("raw_t_s and receipt_t_s must have equal length")
    return np.array([clock.add(v, t) for v, t in zip(raw, receipt, strict=True)])


class VehicleClock:
    """Sample-by-sample continuous vehicle time and a sliding-window :func:`fit_clock`.

    ``window_s``: vehicle time kept for the fit [s]: long enough to average latency out, short
    enough to follow a simulator that changes speed (the flight layer uses 10 s). ``wrap_s``: period
    of the raw counter [s] (``time_boot_ms``: :data:`BOOT_MS_WRAP_S`). ``restart_jump_s``: a step
    back larger than this, and not a wrap, is a restart [s].
    """

    def __init__(
        self,
        window_s: float = 30.0,
        wrap_s: float = BOOT_MS_WRAP_S,
        restart_jump_s: float = RESTART_JUMP_S,
    ) -> None:
        self.window_s = window_s
        self.wrap_s = wrap_s
        self.restart_jump_s = restart_jump_s
        self.restarts = 0
        self._shift_s = 0.0
        self._last_raw_s: float | None = None
        self._last: tuple[float, float] | None = None  # (vehicle, receipt) of the newest sample
        self._window: deque[tuple[float, float]] = deque()
        self._fit: ClockFit | None = None

    def add(self, raw_t_s: float, receipt_t_s: float) -> float:
        """Take one sample; return its continuous vehicle time.

        ``raw_t_s``: the vehicle's stamp [s]. ``receipt_t_s``: local receipt time [s].

        Returns: continuous vehicle time [s].
        """
        if self._last_raw_s is not None:
            step = raw_t_s - self._last_raw_s
            if step < -self.wrap_s / 2:
                self._shift_s += self.wrap_s
            elif step < -self.restart_jump_s and self._last is not None:
                # the vehicle restarted: continue from where its old clock would be now
                fit = self.fit()
                rate = fit.rate if fit is not None else 1.0
                bridged = self._last[0] + max(receipt_t_s - self._last[1], 0.0) * rate
                self._shift_s = bridged - raw_t_s
                self._window.clear()
                self.restarts += 1
        self._last_raw_s = raw_t_s
        vehicle_t_s = raw_t_s + self._shift_s
        if self._last is not None and vehicle_t_s < self._last[0]:
            return vehicle_t_s  # a reordered datagram: its own time, but not in the fit
        self._last = (vehicle_t_s, receipt_t_s)
        self._window.append(self._last)
        while self._window and self._window[0][0] < vehicle_t_s - self.window_s:
            self._window.popleft()
        self._fit = None
        return vehicle_t_s

    def fit(self) -> ClockFit | None:
        """The fit over the window, or None with fewer than two distinct vehicle times."""
        if self._fit is None and len(self._window) >= 2:
            v, r = np.array(self._window).T
            if v[-1] > v[0]:
                try:
                    self._fit = fit_clock(v, r)
                except ValueError:
                    self._fit = None
        return self._fit

    @property
    def latest_s(self) -> float:
        """Continuous vehicle time of the newest sample [s] (NaN before the first)."""
        return math.nan if self._last is None else self._last[0]


def rate_warning(trial: int, rate: float, duration_s: float, t_ilc_s: float) -> str | None:
    """A line about a trial whose vehicle clock ran off real time, or None within 2 %.

    ``rate``: the trial's vehicle-time / wall-time rate. ``duration_s``: the trial's length in
    vehicle time [s]. ``t_ilc_s``: ILC sample time [s].
    """
    if not math.isfinite(rate) or abs(rate - 1.0) <= RATE_TOLERANCE:
        return None
    pace = "slower" if rate < 1.0 else "faster"
    return (
        f"trial {trial}: the vehicle's clock ran at {rate:.3f}x wall time (a simulator {pace} "
        f"than real time). Setpoints were streamed and positions recorded on the vehicle's "
        f"clock, so the trial lies on its {t_ilc_s:g} s grid in vehicle time, where the model "
        f"and the learning live; on the wall clock it took {duration_s / rate:.1f} s for "
        f"{duration_s:.1f} s, and the wall-clock limits (watchdog, MAVSDK timeouts) stretch "
        f"by {1.0 / rate:.2f}x in vehicle time"
    )


class Clock(Protocol):
    """The local clock the flight layer reads and sleeps on (injected; the wall clock by default).

    ``now`` must agree with the running event loop's ``time()``, on which ``asyncio.timeout``
    and ``asyncio.sleep`` count: :class:`WallClock` with asyncio's own loop
    (``time.monotonic``), :class:`LoopClock` with any loop (a virtual-time one in the tests).
    """

    def now(self) -> float:
        """The local time [s]."""
        ...

    async def sleep(self, delay_s: float) -> None:
        """Sleep ``delay_s`` of local time (no sleep, one yield, when not positive).

        ``delay_s``: delay [s].
        """
        ...


class WallClock:
    """``time.monotonic()``, the clock of asyncio's own event loop."""

    def now(self) -> float:
        """The local time [s] (``time.monotonic()``)."""
        return time.monotonic()

    async def sleep(self, delay_s: float) -> None:
        """Sleep ``delay_s`` seconds on the event loop.

        ``delay_s``: delay [s]; not positive: one yield.
        """
        await asyncio.sleep(max(delay_s, 0.0))


class LoopClock(WallClock):
    """The running event loop's own ``time()`` (a virtual-time loop's virtual time)."""

    def now(self) -> float:
        """The running loop's time [s] (``time.monotonic()`` outside a loop)."""
        try:
            return asyncio.get_running_loop().time()
        except RuntimeError:
            return time.monotonic()


WALL_CLOCK = WallClock()
"""The default :class:`Clock` of the flight layer."""
