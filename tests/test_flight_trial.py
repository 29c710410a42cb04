"""Pure parts of the flight layer: settings, deadline schedule, grid alignment, trial loop.

The trial loop is exercised against a fake vehicle (no MAVSDK, no sockets) that records the
setpoints it is sent and feeds position samples from a task, on virtual time
(:func:`gcs.sim.loop.virtual_time`): a send's lateness is the loop's, not the machine's load.
"""

from __future__ import annotations

import asyncio
import contextlib

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gcs.errors import ProfileError, TrajectoryError, TrialAborted, TrialPaused
from gcs.flight.clock import LoopClock, VehicleClock
from gcs.flight.link import TelemetrySample
from gcs.flight.manoeuvres import heading_deg, min_jerk
from gcs.flight.trial import (
    TrialRun,
    align_to_grid,
    fly_trial,
    send_schedule,
)
from gcs.io.settings import FlightSettings
from gcs.sim.loop import virtual_time

# ---------------------------------------------------------------- settings


def test_sends_per_sample_integer_multiple() -> None:
    assert FlightSettings(stream_rate_hz=60).sends_per_sample(0.05) == 3
    assert FlightSettings(stream_rate_hz=20).sends_per_sample(0.05) == 1
    assert FlightSettings(stream_rate_hz=50).sends_per_sample(0.02) == 1
    assert FlightSettings().sends_per_sample(0.05) == 3  # default 60 Hz


@pytest.mark.parametrize(("rate_hz", "t_ilc_s"), [(50, 0.05), (30, 0.05), (10, 0.05)])
def test_sends_per_sample_rejects_non_multiples(rate_hz: float, t_ilc_s: float) -> None:
    with pytest.raises(ProfileError, match="stream_rate_hz"):
        FlightSettings(stream_rate_hz=rate_hz).sends_per_sample(t_ilc_s)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"stream_rate_hz": 0.0},
        {"telemetry_rate_hz": -1.0},
        {"max_setpoint_late_s": float("nan")},
        {"settle_tolerance_m": float("inf")},
        {"stream_rate_hz": 1.0},
        {"yaw_deg": float("nan")},
        {"hover_before_trial_s": -1.0},
        {"hover_before_trial_s": float("inf")},
        {"hover_measure_s": 0.5},
        {"hover_max_offset_m": 0.0},
        {"hover_max_drift_m_s": -0.1},
        {"hover_max_oscillation_m": float("nan")},
        {"settle_speed_m_s": 0.0},
    ],
)
def test_settings_validation(kwargs: dict[str, float]) -> None:
    with pytest.raises(ProfileError, match="flight\\."):
        FlightSettings(**kwargs)


def test_settings_accepts_negative_yaw_and_gap_is_two_periods() -> None:
    s = FlightSettings(yaw_deg=-90.0, telemetry_rate_hz=50.0)
    assert s.telemetry_gap_s == pytest.approx(0.04)


def test_settings_hold_before_trial_may_be_zero_and_covers_the_loop() -> None:
    assert FlightSettings(hover_before_trial_s=0.0).hover_before_trial_s == 0.0
    s = FlightSettings()
    # default hold (with the settle window) covers the 2 % settling time of eq. (11)'s loop
    wn, zeta = 1.418, 0.618
    assert s.settle_time_s + s.hover_before_trial_s >= 4.0 / (zeta * wn)


# ---------------------------------------------------------------- schedule


def test_send_schedule_zero_order_hold() -> None:
    deadlines, index = send_schedule(n_setpoints=4, sends_per_sample=3, t_ilc_s=0.05)
    assert deadlines.shape == index.shape == (12,)
    np.testing.assert_allclose(deadlines, np.arange(12) * 0.05 / 3)
    np.testing.assert_array_equal(index, [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3])
    # the first send of every setpoint is exactly on its sample boundary
    first = deadlines[::3]
    np.testing.assert_allclose(first, np.arange(4) * 0.05)


@given(st.floats(-1e5, 1e5))
def test_heading_is_the_same_direction_in_range(yaw: float) -> None:
    h = heading_deg(yaw)
    assert -180.0 <= h < 180.0
    # the same direction: compared as unit vectors (independent of the wrapping arithmetic)
    a, b = np.radians(yaw), np.radians(h)
    assert np.hypot(np.cos(a) - np.cos(b), np.sin(a) - np.sin(b)) < 1e-9
    if -180.0 <= yaw < 180.0:
        assert h == yaw  # in range: sent exactly as given


def test_heading_of_turns_past_half_a_turn() -> None:
    assert heading_deg(190.0) == -170.0 and heading_deg(-190.0) == 170.0
    assert heading_deg(180.0) == -180.0 and heading_deg(720.0) == 0.0


def test_min_jerk_profile() -> None:
    assert min_jerk(0.0) == 0.0
    assert min_jerk(1.0) == 1.0
    assert min_jerk(0.5) == pytest.approx(0.5)
    assert min_jerk(-1.0) == 0.0 and min_jerk(2.0) == 1.0
    s = np.linspace(0, 1, 1001)
    slope = np.gradient([min_jerk(x) for x in s], s)
    assert slope.max() == pytest.approx(1.875, rel=1e-3)


# ---------------------------------------------------------------- alignment


def test_align_linear_signal_is_exact() -> None:
    t = np.arange(0.0, 1.0, 0.02) + 0.003
    x = np.stack([2.0 * t, -t, 5.0 + 0 * t], axis=1)
    grid = np.arange(0.0, 0.9, 0.05) + 0.01
    values, gap = align_to_grid(t, x, grid, max_gap_s=0.04)
    np.testing.assert_allclose(values[:, 0], 2.0 * grid)
    np.testing.assert_allclose(values[:, 1], -grid)
    np.testing.assert_allclose(values[:, 2], 5.0)
    assert not gap.any()


def test_align_flags_gaps_and_nans_outside() -> None:
    t = np.array([0.00, 0.02, 0.04, 0.14, 0.16])  # 100 ms hole between 0.04 and 0.14
    x = t[:, None] * 10.0
    grid = np.array([-0.01, 0.00, 0.03, 0.05, 0.10, 0.14, 0.16, 0.17])
    values, gap = align_to_grid(t, x, grid, max_gap_s=0.04)
    np.testing.assert_array_equal(np.isnan(values[:, 0]), [1, 0, 0, 0, 0, 0, 0, 1])
    np.testing.assert_allclose(values[1:7, 0], [0.0, 0.3, 0.5, 1.0, 1.4, 1.6])
    np.testing.assert_array_equal(gap, [0, 0, 0, 1, 1, 0, 0, 0])


def test_align_exact_hits_and_duplicate_stamps() -> None:
    t = np.array([0.0, 0.02, 0.02, 0.04])
    x = np.array([[0.0], [1.0], [2.0], [3.0]])
    values, gap = align_to_grid(t, x, np.array([0.0, 0.02, 0.03, 0.04]), max_gap_s=0.04)
    assert np.all(np.isfinite(values))
    assert values[0, 0] == 0.0 and values[3, 0] == 3.0
    assert values[2, 0] == pytest.approx(2.5)
    assert not gap.any()


def test_align_gap_threshold_is_strict() -> None:
    t = np.array([0.0, 0.04, 0.0801])  # exactly 2 periods, then just over
    x = np.zeros((3, 1))
    _, gap = align_to_grid(t, x, np.array([0.02, 0.06]), max_gap_s=0.04 + 1e-9)
    np.testing.assert_array_equal(gap, [False, True])


def test_align_rejects_unsorted_and_handles_empty() -> None:
    with pytest.raises(ValueError):
        align_to_grid([0.1, 0.0], np.zeros((2, 1)), np.array([0.05]), 0.04)
    values, gap = align_to_grid([], np.zeros((0, 3)), np.array([0.0, 0.1]), 0.04)
    assert values.shape == (2, 3) and np.isnan(values).all() and not gap.any()


# ---------------------------------------------------------------- trial loop on a fake vehicle


class FakeVehicle:
    """Just enough of Vehicle for TrialRun: first-order response, telemetry at 50 Hz.

    Local time is the running loop's (virtual in :func:`run`). Its clock runs at ``rate``
    times the local clock; telemetry comes every ``1 / telemetry_hz``
    of vehicle time, stamped with it. ``motion(t_vehicle_s)``, when given, is the position
    reported instead of the first-order response.
    """

    def __init__(
        self,
        telemetry_hz: float = 50.0,
        drop: tuple[float, float] | None = None,
        rate: float = 1.0,
        motion=None,  # type: ignore[no-untyped-def]
    ):
        self.sent: list[tuple[float, np.ndarray]] = []
        self.yaws: list[float | None] = []
        self.pos = np.zeros(3)
        self.target = np.zeros(3)
        self.latest: TelemetrySample | None = None
        self._recorders: list[list[TelemetrySample]] = []
        self.problem: str | None = None
        self.period_s = 1.0 / telemetry_hz
        self.drop = drop  # (start, end) relative to the first setpoint: no samples then
        self.t_first: float | None = None
        self.rate = rate
        self.motion = motion
        self.local_clock = LoopClock()
        self.boot_s = -100.0  # booted a while before the loop's time 0
        self.clock = VehicleClock()

    def vehicle_time(self, wall_s: float) -> float:
        return (wall_s - self.boot_s) * self.rate

    async def send_setpoint(self, pos_ned_m: np.ndarray, yaw_deg: float | None = None) -> None:
        now = self.local_clock.now()
        self.t_first = self.t_first if self.t_first is not None else now
        self.sent.append((now, np.array(pos_ned_m)))
        self.yaws.append(yaw_deg)
        self.target = np.array(pos_ned_m)

    def control_problem(self) -> str | None:
        return self.problem

    def clock_fit(self):  # type: ignore[no-untyped-def]
        fit = self.clock.fit()
        assert fit is not None
        return fit

    @contextlib.contextmanager
    def record_telemetry(self):  # type: ignore[no-untyped-def]
        samples: list[TelemetrySample] = [] if self.latest is None else [self.latest]
        self._recorders.append(samples)
        try:
            yield samples
        finally:
            self._recorders.remove(samples)

    async def telemetry(self) -> None:
        t0 = self.local_clock.now()
        i = 0
        while True:
            i += 1
            delay = t0 + i * self.period_s / self.rate - self.local_clock.now()
            await asyncio.sleep(max(delay, 0))
            self.pos = self.pos + 0.5 * (self.target - self.pos)
            now = self.local_clock.now()
            if self.drop and self.t_first is not None:
                rel = now - self.t_first
                if self.drop[0] <= rel < self.drop[1]:
                    continue
            stamp_s = round(self.vehicle_time(now) * 1000) / 1000  # time_boot_ms
            v = self.clock.add(stamp_s, now)
            pos = tuple(self.motion(v)) if self.motion is not None else tuple(self.pos)
            sample = TelemetrySample(now, pos, (0.0, 0.0, 0.0), v)  # type: ignore[arg-type]
            self.latest = sample
            for r in self._recorders:
                r.append(sample)


def run(coro):  # type: ignore[no-untyped-def]
    """``asyncio.run(coro)`` on virtual time."""
    with virtual_time():
        return asyncio.run(coro)


async def _with_telemetry(vehicle: FakeVehicle, coro):  # type: ignore[no-untyped-def]
    feeder = asyncio.create_task(vehicle.telemetry())
    try:
        while vehicle.clock.fit() is None or vehicle.clock.fit().span_s < 0.2:
            await asyncio.sleep(0.005)
        return await coro
    finally:
        feeder.cancel()


def _circle(n: int) -> np.ndarray:
    phase = np.linspace(0, 2 * np.pi, n)
    return np.stack([np.cos(phase), np.sin(phase), -2.0 + 0 * phase], axis=1)


def test_trial_streams_on_deadlines_and_records_grid() -> None:
    settings = FlightSettings(stream_rate_hz=60, telemetry_rate_hz=50)
    sp = _circle(12)
    vehicle = FakeVehicle()
    progress: list[tuple[int, int, float]] = []
    rec = run(
        _with_telemetry(
            vehicle,
            fly_trial(vehicle, sp, 0.05, settings, lambda *a: progress.append(a)),  # type: ignore[arg-type]
        )
    )
    assert rec.complete and rec.abort_reason is None
    assert rec.t_s.shape == (13,) and rec.pos_ned_m.shape == (13, 3)
    assert rec.vel_ned_m_s.shape == (13, 3) and rec.sent_s.shape == (12,)
    assert rec.interpolated.shape == (13,)
    assert np.all(np.isfinite(rec.pos_ned_m))
    np.testing.assert_allclose(rec.t_s, np.arange(13) * 0.05)
    # each setpoint is first sent at its sample boundary (loop jitter allowed)
    assert np.all(rec.sent_s >= -1e-6)
    np.testing.assert_allclose(rec.sent_s, np.arange(12) * 0.05, atol=0.03)
    # three sends per sample with the same value, then the final one repeated until y(N)
    values = np.array([v for _, v in vehicle.sent])
    assert len(values) >= 36
    np.testing.assert_allclose(values[:36], np.repeat(sp, 3, axis=0))
    np.testing.assert_allclose(values[36:], np.repeat(sp[-1:], len(values) - 36, axis=0))
    assert rec.raw_t_s[-1] >= rec.t_s[-1]  # y(N) was measured, not extrapolated
    assert 1 <= len(progress) <= 12 and progress[-1][1] == 12
    np.testing.assert_array_equal(rec.setpoints_ned_m, sp)


def test_trial_sends_each_setpoint_with_its_own_yaw_and_none_without_one() -> None:
    settings = FlightSettings(stream_rate_hz=60, telemetry_rate_hz=50)
    sp = _circle(12)
    yaw = np.linspace(0.0, 330.0, 12)  # a turn: one heading per setpoint
    vehicle = FakeVehicle()
    rec = run(
        _with_telemetry(vehicle, fly_trial(vehicle, sp, 0.05, settings, yaw_deg=yaw))  # type: ignore[arg-type]
    )
    assert rec.complete
    sent = np.array(vehicle.yaws, dtype=float)
    # three sends per sample, each with its setpoint's yaw, then the last repeated until y(N)
    np.testing.assert_array_equal(sent[:36], np.repeat(yaw, 3))
    assert np.all(sent[36:] == yaw[-1])
    held = FakeVehicle()
    run(_with_telemetry(held, fly_trial(held, sp, 0.05, settings)))  # type: ignore[arg-type]
    assert held.yaws and all(y is None for y in held.yaws)  # the profile's flight.yaw_deg


@pytest.mark.parametrize(
    ("yaw", "match"), [(np.zeros(11), "one per setpoint"), (np.full(12, np.nan), "k = 0")]
)
def test_trial_refuses_a_yaw_not_one_finite_value_per_setpoint(yaw: np.ndarray, match: str) -> None:
    with pytest.raises(TrajectoryError, match=match):
        TrialRun(FakeVehicle(), _circle(12), 0.05, FlightSettings(), yaw_deg=yaw)  # type: ignore[arg-type]


def test_trial_flags_telemetry_gap() -> None:
    settings = FlightSettings(stream_rate_hz=20, telemetry_rate_hz=50, max_telemetry_age_s=1.0)
    vehicle = FakeVehicle(drop=(0.20, 0.32))
    rec = run(_with_telemetry(vehicle, fly_trial(vehicle, _circle(10), 0.05, settings)))
    assert rec.complete
    flagged = rec.t_s[rec.interpolated]
    assert flagged.size >= 1
    assert np.all((flagged > 0.15) & (flagged < 0.40))
    assert 0 < rec.interpolated_share < 0.5


def test_trial_watchdog_aborts_with_partial_recording() -> None:
    settings = FlightSettings(stream_rate_hz=20)
    vehicle = FakeVehicle()

    async def scenario():  # type: ignore[no-untyped-def]
        run = TrialRun(vehicle, _circle(40), 0.05, settings)
        fly = asyncio.create_task(run.fly())
        while len(vehicle.sent) < 10:
            await asyncio.sleep(0.01)
        vehicle.problem = "flight mode is HOLD, not OFFBOARD"
        with pytest.raises(TrialAborted, match="HOLD") as info:
            await fly
        return info.value

    exc = run(_with_telemetry(vehicle, scenario()))
    rec = exc.recording
    assert not rec.complete and "HOLD" in rec.abort_reason
    assert rec.pos_ned_m.shape == (41, 3)
    assert np.isfinite(rec.pos_ned_m[0]).all() and np.isnan(rec.pos_ned_m[-1]).all()
    assert np.isnan(rec.sent_s[-1]) and np.isfinite(rec.sent_s[0])
    assert len(vehicle.sent) < 20


@pytest.mark.parametrize("problem", [None, "flight mode is HOLD, not OFFBOARD"])
def test_trial_stops_on_a_late_setpoint_as_paused_unless_control_is_lost(problem) -> None:
    settings = FlightSettings(stream_rate_hz=20, max_setpoint_late_s=0.05)
    vehicle = FakeVehicle()

    async def scenario():  # type: ignore[no-untyped-def]
        fly = asyncio.create_task(fly_trial(vehicle, _circle(40), 0.05, settings))
        while len(vehicle.sent) < 5:
            await asyncio.sleep(0.005)
        # the loop blocked for 0.2 s (as by a heavy call in it): the next send is late
        asyncio.get_running_loop().advance(0.2)  # type: ignore[attr-defined]
        vehicle.problem = problem
        with pytest.raises(TrialAborted) as info:
            await fly
        return info.value

    exc = run(_with_telemetry(vehicle, scenario()))
    if problem is None:  # the stream fell behind, the vehicle did not: flown again
        assert isinstance(exc, TrialPaused) and "ms late (limit 50 ms)" in str(exc)
    else:  # a lost control is named first, and ends the flight
        assert not isinstance(exc, TrialPaused) and "HOLD" in str(exc)
    assert not exc.recording.complete and exc.recording.abort_reason in str(exc)


def test_trial_streams_and_records_on_the_vehicle_clock() -> None:
    # a simulator at 0.9x real time reporting x = its own time: setpoints must change every
    # t_ilc of vehicle time (not 0.9 t_ilc), and y(k) must be the position at v0 + k t_ilc
    settings = FlightSettings(stream_rate_hz=60, telemetry_rate_hz=50)
    vehicle = FakeVehicle(rate=0.9, motion=lambda v: (v, 0.0, -2.0))
    sp = _circle(16)
    rec = run(_with_telemetry(vehicle, fly_trial(vehicle, sp, 0.05, settings)))
    assert rec.complete and rec.clock is not None
    assert rec.clock.rate == pytest.approx(0.9, abs=0.01)
    first_sends = np.array([t for t, _ in vehicle.sent][::3][:16])
    steps = np.diff(vehicle.vehicle_time(first_sends))
    assert np.median(steps) == pytest.approx(0.05, abs=0.002), steps
    np.testing.assert_allclose(rec.pos_ned_m[:, 0], rec.t0_vehicle_s + rec.t_s, atol=1e-6)
    np.testing.assert_allclose(rec.sent_s, rec.t_s[:-1], atol=0.03)
