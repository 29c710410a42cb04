"""Fly one trial: stream a setpoint sequence on a fixed grid and record the response on it.

Everything runs on the vehicle's clock (``gcs.flight.clock``): the ILC model and the sample
grid are in the vehicle's time, and a simulator under load runs that clock slower than the
wall clock (PX4 SITL in lockstep: 0.72-0.9x). Streaming on the wall clock would then fly the
manoeuvre faster in the vehicle's physics than it was designed (by 1/rate), against a model
whose time base is the vehicle's, and differently in every trial as the load changes.

Streaming (zero-order hold). Setpoint ``k`` holds for one ILC sample from vehicle time
``v0 + k t_ilc_s``. With ``stream_rate_hz = m / t_ilc_s`` the stream has ``m`` ticks per sample;
tick ``i`` goes out at the local time of vehicle time ``v0 + i t_ilc_s / m`` through the current
clock fit (an absolute deadline on the local clock, ``time.monotonic()`` on the wire,
refitted about once a second) and
carries setpoint ``i // m``. The first tick of each sample is on the sample boundary, so the
vehicle sees a true ZOH; the repeats keep MAVSDK's own 20 Hz re-send from firing in between (it
is reset by every send). After the last setpoint the final one is repeated (hover) until a
sample stamped at or after ``v0 + N t_ilc_s`` has arrived, so that ``y(N)`` is measured.

Recording. Position samples carry the vehicle's time stamps; they are aligned to the grid
``v0 + k t_ilc_s`` (k = 0..N) by linear interpolation between the two neighbouring samples, so
receipt jitter does not enter the data. A grid point whose neighbours are more than 2
telemetry periods apart is flagged "interpolated across a gap". The first-send time of each
setpoint is kept too, mapped to vehicle time, and the trial's own clock fit (its vehicle-time
rate) comes with the recording.

Watchdog (checked after every send): position telemetry older than ``max_telemetry_age_s``,
link loss, any flight mode other than OFFBOARD, or a breach of the vehicle's watches ends the
trial with :class:`gcs.errors.TrialAborted`; a setpoint sent more than ``max_setpoint_late_s``
after its deadline while none of those is wrong ends it with :class:`gcs.errors.TrialPaused`
(the stream fell behind, the vehicle did not: the campaign flies the trial again). Either's
``recording`` attribute holds the partial recording (``complete=False``).

Progress. ``on_progress(k, n, err_m)`` is called at most 10 times a second; ``err_m`` is the
horizontal distance between the newest measured position and the setpoint that was in force
at its time stamp. It is a live indicator only: it includes the closed loop's lag and is not
the ILC tracking error (which needs the reference, unknown to this layer).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from gcs.core.trajectory import setpoint_array
from gcs.errors import TrajectoryError, TrialAborted, TrialPaused
from gcs.flight.clock import ClockFit, fit_clock
from gcs.flight.link import TelemetrySample
from gcs.flight.manoeuvres import sleep_until
from gcs.flight.vehicle import Vehicle
from gcs.io.mocap_samples import MocapTrial
from gcs.io.settings import FlightSettings

__all__ = [
    "TrialRecording",
    "TrialRun",
    "ProgressCallback",
    "fly_trial",
    "send_schedule",
    "align_to_grid",
]

ProgressCallback = Callable[[int, int, float], None]
"""``on_progress(k, n, err_m)``: current setpoint index, number of setpoints, live error [m]."""

PROGRESS_PERIOD_S = 0.1
LEAD_TICKS = 2  # t0 lies this many stream periods after the trial is entered
REFIT_S = 1.0  # the clock fit behind the deadlines is renewed this often [s, vehicle time]


@dataclass(frozen=True)
class TrialRecording:
    """What one trial sent and measured, on the ILC sample grid.

    All times are on the vehicle's clock, relative to the trial's start ``v0`` (when setpoint 0
    takes over), except ``t0_monotonic_s``.

    ``t_s``: grid times ``k t_ilc_s`` relative to v0 [s]. ``pos_ned_m``: measured position at the
    grid times, local NED [m]; NaN where no sample brackets the grid time (only in incomplete
    recordings). ``vel_ned_m_s``: measured velocity at the grid times, local NED [m/s]; NaN like
    ``pos_ned_m``. ``sent_s``: time the first send of each setpoint was issued, relative to v0 [s,
    vehicle time]; NaN if never sent. ``interpolated``: grid point interpolated between samples more
    than 2 telemetry periods apart. ``complete``: the trial ran to its end (``y(N)`` recorded).
    ``abort_reason``: why it stopped early; None when complete. ``setpoints_ned_m``: the setpoints
    flown, local NED [m]. ``t_ilc_s``: ILC sample time [s]. ``raw_t_s``: vehicle time stamps of the
    raw position samples relative to v0 [s], sorted. ``raw_pos_ned_m``: raw positions, local NED
    [m]. ``raw_vel_ned_m_s``: raw velocities, local NED [m/s]. ``max_send_late_s``: largest delay of
    a send after its deadline [s]. ``t0_monotonic_s``: the start on the local clock [s]
    (``time.monotonic()``, CLOCK_MONOTONIC, comparable with other local processes; virtual time on a
    simulated link): where the clock fit put vehicle time v0. ``t0_vehicle_s``: v0, the start in
    continuous vehicle time [s]. ``clock``: fit of the vehicle clock over the trial's own samples:
    ``clock.rate`` is the trial's vehicle-time / wall-time rate (None with fewer than two samples).
    ``mocap``: the motion capture of the trial (raw samples, on the grid, the estimate's lag), when
    the flight had one.
    """

    t_s: np.ndarray
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    sent_s: np.ndarray
    interpolated: np.ndarray
    complete: bool
    abort_reason: str | None
    setpoints_ned_m: np.ndarray
    t_ilc_s: float
    raw_t_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    raw_pos_ned_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    raw_vel_ned_m_s: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    max_send_late_s: float = 0.0
    t0_monotonic_s: float = math.nan
    t0_vehicle_s: float = math.nan
    clock: ClockFit | None = None
    mocap: MocapTrial | None = None

    @property
    def n_setpoints(self) -> int:
        """Number of setpoints N."""
        return int(self.setpoints_ned_m.shape[0])

    @property
    def interpolated_share(self) -> float:
        """Share of the N+1 grid points interpolated across a telemetry gap (0..1)."""
        return float(np.mean(self.interpolated)) if self.interpolated.size else 0.0


def send_schedule(
    n_setpoints: int, sends_per_sample: int, t_ilc_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Deadlines and setpoint indices of the stream over one trial.

    ``sends_per_sample``: sends per ILC sample ``m`` (``stream_rate_hz * t_ilc_s``). ``t_ilc_s``:
    ILC sample time [s].

    Returns: ``deadlines_s``: send deadlines relative to t0 [s]: ``i * t_ilc_s / m``. ``index``:
    setpoint sent at each deadline: ``i // m``.
    """
    ticks = np.arange(n_setpoints * sends_per_sample)
    return ticks * (t_ilc_s / sends_per_sample), ticks // sends_per_sample


def align_to_grid(
    sample_t_s: Sequence[float] | np.ndarray,
    sample_values: np.ndarray,
    grid_t_s: np.ndarray,
    max_gap_s: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Linearly interpolate time-stamped samples onto a time grid and flag gaps.

    ``sample_t_s``: non-decreasing sample times [s] (same clock and origin as ``grid_t_s``).
    ``sample_values``: sample values (any unit). ``grid_t_s``: grid times [s]. ``max_gap_s``:
    neighbours further apart than this make a grid point "interpolated across a gap" [s].

    Returns: ``values``: interpolated values; NaN where the grid time is not bracketed by samples
    (before the first or after the last). A grid time equal to a sample time takes that sample.
    ``gap``: grid point interpolated between neighbours more than ``max_gap_s`` apart.
    """
    t = np.asarray(sample_t_s, dtype=float).reshape(-1)
    x = np.asarray(sample_values, dtype=float)
    x = x.reshape(t.size, -1) if x.ndim != 2 else x
    grid = np.asarray(grid_t_s, dtype=float).reshape(-1)
    values = np.full((grid.size, x.shape[1]), np.nan)
    gap = np.zeros(grid.size, dtype=bool)
    if t.size == 0:
        return values, gap
    if np.any(np.diff(t) < 0):
        raise ValueError("sample_t_s must be non-decreasing")
    hi = np.searchsorted(t, grid, side="left")  # first sample at or after the grid time
    lo = np.searchsorted(t, grid, side="right") - 1  # last sample at or before it
    valid = (lo >= 0) & (hi < t.size)
    lo_v, hi_v, g = lo[valid], hi[valid], grid[valid]
    span = t[hi_v] - t[lo_v]
    weight = np.divide(g - t[lo_v], span, out=np.zeros_like(g), where=span > 0)
    values[valid] = x[lo_v] + weight[:, None] * (x[hi_v] - x[lo_v])
    gap[valid] = span > max_gap_s
    return values, gap


def _yaw_array(yaw_deg: object | None, n: int) -> np.ndarray | None:
    """A trial's headings as a finite float array of shape (n,), or a refusal."""
    if yaw_deg is None:
        return None
    yaw = np.array(yaw_deg, dtype=float)
    if yaw.shape != (n,):
        raise TrajectoryError(f"yaw has shape {yaw.shape}, expected ({n},): one per setpoint")
    bad = np.flatnonzero(~np.isfinite(yaw))
    if bad.size:
        raise TrajectoryError(f"yaw of setpoint k = {bad[0]} is NaN or inf")
    return yaw


class TrialRun:
    """One trial in flight; :func:`fly_trial` is the usual entry point.

    Kept as an object so that a caller who is cancelled mid-trial can still take the partial
    recording with :meth:`recording`.

    ``vehicle``: connected vehicle in OFFBOARD, hovering near the first setpoint.
    ``setpoints_ned_m``: absolute local NED setpoints [m]. ``t_ilc_s``: ILC sample time [s].
    ``on_progress``: ``on_progress(k, n, err_m)``, called at most 10 times a second on the event
    loop (must return quickly). ``yaw_deg``: heading of each setpoint [deg]; None: the profile's
    ``flight.yaw_deg`` throughout.
    """

    def __init__(
        self,
        vehicle: Vehicle,
        setpoints_ned_m: object,
        t_ilc_s: float,
        settings: FlightSettings,
        on_progress: ProgressCallback | None = None,
        yaw_deg: object | None = None,
    ) -> None:
        self.vehicle = vehicle
        self.setpoints_ned_m = setpoint_array(setpoints_ned_m)
        self.yaw_deg = _yaw_array(yaw_deg, self.setpoints_ned_m.shape[0])
        self.t_ilc_s = float(t_ilc_s)
        self.settings = settings
        self.sends_per_sample = settings.sends_per_sample(self.t_ilc_s)
        self.on_progress = on_progress
        n = self.setpoints_ned_m.shape[0]
        self.t0: float | None = None
        self.v0: float | None = None
        self.sent_abs_s = np.full(n, np.nan)
        self.max_send_late_s = 0.0
        self.samples: list[TelemetrySample] = []

    async def fly(self) -> TrialRecording:
        """Stream the trial and return the complete recording (``complete=True``).

        Raises ``TrialAborted``: the watchdog fired; ``.recording`` holds the partial recording;
        ``VehicleError``: no clock fit yet (no time-stamped samples).
        """
        vehicle, settings, sp, yaw = self.vehicle, self.settings, self.setpoints_ned_m, self.yaw_deg
        n, m = sp.shape[0], self.sends_per_sample
        tick_s = self.t_ilc_s / m  # vehicle time between ticks
        refit_ticks = max(1, round(REFIT_S / tick_s))
        next_progress_s = 0.0
        fit = vehicle.clock_fit()
        with vehicle.record_telemetry() as samples:
            self.samples = samples
            clock = vehicle.local_clock
            self.t0 = clock.now() + LEAD_TICKS / settings.stream_rate_hz
            self.v0 = v0 = float(fit.to_vehicle(self.t0))
            v_end = v0 + n * self.t_ilc_s
            i = 0
            while True:
                if i % refit_ticks == 0:
                    fit = vehicle.clock_fit()
                deadline_s = float(fit.to_local(v0 + i * tick_s))
                await sleep_until(deadline_s, clock)
                k = i // m
                if k >= n and samples and samples[-1].t_vehicle_s >= v_end:
                    break  # y(N) is measured
                issued_s = clock.now()
                kk = min(k, n - 1)
                await vehicle.send_setpoint(sp[kk], None if yaw is None else yaw[kk])
                if k < n and i % m == 0:
                    self.sent_abs_s[k] = issued_s
                late_s = issued_s - deadline_s
                self.max_send_late_s = max(self.max_send_late_s, late_s)
                problem = vehicle.control_problem()
                paused = problem is None and late_s > settings.max_setpoint_late_s
                if paused:
                    problem = (
                        f"setpoint {min(k, n - 1)} sent {late_s * 1e3:.0f} ms late "
                        f"(limit {settings.max_setpoint_late_s * 1e3:.0f} ms)"
                    )
                if problem is not None:
                    kind = TrialPaused if paused else TrialAborted
                    exc = kind(f"trial aborted at sample {min(k, n)}/{n}: {problem}")
                    exc.recording = self.recording(problem)  # type: ignore[attr-defined]
                    raise exc
                if self.on_progress is not None and issued_s >= next_progress_s:
                    next_progress_s = issued_s + PROGRESS_PERIOD_S
                    self.on_progress(min(k, n), n, self._live_error_m())
                i += 1
        return self.recording(None)

    def _live_error_m(self) -> float:
        """Horizontal distance of the newest sample from the setpoint in force at its stamp."""
        if not self.samples or self.v0 is None:
            return math.nan
        sample = self.samples[-1]
        n = self.setpoints_ned_m.shape[0]
        k = min(max(math.floor((sample.t_vehicle_s - self.v0) / self.t_ilc_s), 0), n - 1)
        d_n = sample.pos_ned_m[0] - self.setpoints_ned_m[k, 0]
        d_e = sample.pos_ned_m[1] - self.setpoints_ned_m[k, 1]
        return math.hypot(d_n, d_e)

    def recording(self, abort_reason: str | None) -> TrialRecording:
        """The recording so far, aligned to the grid in vehicle time.

        ``abort_reason``: None for a complete trial; otherwise why it stopped (the recording is then
        marked incomplete).

        Returns: grid points after the last sample are NaN.
        """
        sp = self.setpoints_ned_m
        n = sp.shape[0]
        grid_rel_s = np.arange(n + 1) * self.t_ilc_s
        v0 = self.v0 if self.v0 is not None else math.nan
        samples = sorted(self.samples, key=lambda s: s.t_vehicle_s)
        raw_v = np.array([s.t_vehicle_s for s in samples], dtype=float)
        raw_pos = np.array([s.pos_ned_m for s in samples], dtype=float).reshape(-1, 3)
        raw_vel = np.array([s.vel_ned_m_s for s in samples], dtype=float).reshape(-1, 3)
        clock = _trial_clock(raw_v, np.array([s.t_s for s in samples], dtype=float))
        gap_s = self.settings.telemetry_gap_s
        if self.v0 is None:
            pos = np.full((n + 1, 3), np.nan)
            vel = np.full((n + 1, 3), np.nan)
            gap = np.zeros(n + 1, dtype=bool)
        else:
            pos, gap = align_to_grid(raw_v - v0, raw_pos, grid_rel_s, gap_s)
            vel, _ = align_to_grid(raw_v - v0, raw_vel, grid_rel_s, gap_s)
        sent_v = np.full(n, np.nan)
        if clock is not None:
            sent_v = clock.to_vehicle(self.sent_abs_s) - v0
        return TrialRecording(
            t_s=grid_rel_s,
            pos_ned_m=pos,
            vel_ned_m_s=vel,
            sent_s=sent_v,
            interpolated=gap,
            complete=abort_reason is None,
            abort_reason=abort_reason,
            setpoints_ned_m=sp.copy(),
            t_ilc_s=self.t_ilc_s,
            raw_t_s=raw_v - v0,
            raw_pos_ned_m=raw_pos,
            raw_vel_ned_m_s=raw_vel,
            max_send_late_s=self.max_send_late_s,
            t0_monotonic_s=self.t0 if self.t0 is not None else math.nan,
            t0_vehicle_s=v0,
            clock=clock,
        )


def _trial_clock(vehicle_t_s: np.ndarray, receipt_t_s: np.ndarray) -> ClockFit | None:
    """Clock fit over one trial's samples (sorted by vehicle time), None if too few."""
    try:
        return fit_clock(vehicle_t_s, receipt_t_s)
    except ValueError:
        return None


async def fly_trial(
    vehicle: Vehicle,
    setpoints_ned_m: object,
    t_ilc_s: float,
    settings: FlightSettings,
    on_progress: ProgressCallback | None = None,
    yaw_deg: object | None = None,
) -> TrialRecording:
    """Fly one trial's setpoint sequence and record the response on the sample grid.

    ``vehicle``: connected vehicle in OFFBOARD, hovering at (or near) ``setpoints_ned_m[0]``.
    ``setpoints_ned_m``: absolute local NED setpoints [m]; setpoint k holds for one sample from t0 +
    k t_ilc_s. ``t_ilc_s``: ILC sample time [s]. ``settings``: stream rate (an integer multiple of
    1/t_ilc_s) and watchdog limits. ``on_progress``: ``on_progress(k, n, err_m)`` at most 10 times a
    second (see the module docstring). ``yaw_deg``: heading of each setpoint [deg, clockwise from
    north]; None: the profile's ``flight.yaw_deg`` throughout.

    Returns: complete recording: grid times, positions and velocities at k = 0..N, send times.

    Raises ``TrialPaused``: a late setpoint; ``TrialAborted``: stale telemetry, link loss, a
    breach or a mode other than OFFBOARD; either's ``recording`` attribute holds the partial
    recording; ``TrajectoryError``:
    ``setpoints_ned_m`` is not a finite (N, 3) array, or ``yaw_deg`` not N finite values.
    """
    run = TrialRun(vehicle, setpoints_ned_m, t_ilc_s, settings, on_progress, yaw_deg)
    return await run.fly()
