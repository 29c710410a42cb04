"""The fence as pure functions: what may be sent, what ends a flight, the geofence's shape.

The thresholds are checked against the real data we have too: not one breach over every
trial of the shared PX4 SITL runs (GPS and vision) and the shared capture while armed.
"""

from __future__ import annotations

import glob
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from px4_data import capture_armed, shared

from gcs.core.frames import global_to_ned
from gcs.flight.fence import (
    DRIFT_WINDOW_S,
    MAX_ACCEL_M_S2,
    EstimateMonitor,
    Fence,
    fence_polygon,
)
from gcs.flight.geofence import GF_ACTION, GeofenceState, vertical_limit_m
from gcs.io.settings import FlightSettings

SETTINGS = FlightSettings()
ARENA = [[-3.0, 3.0], [-3.0, 3.0], [-3.0, 0.0]]
FENCE = Fence.around(ARENA, SETTINGS, max_speed_m_s=3.0, max_vertical_speed_m_s=1.5)
RATE_HZ = 50.0


def test_the_limits_come_from_the_profile_and_the_flight_settings() -> None:
    assert FENCE.margin_m == SETTINGS.fence_margin_m == 1.5
    assert FENCE.max_speed_xy_m_s == pytest.approx(1.5 * 3.0)
    assert FENCE.max_speed_z_m_s == pytest.approx(1.5 * 1.5)
    assert (FENCE.jump_m, FENCE.drift_m) == (0.5, 2.0)
    for bad in (
        [[3.0, -3.0], [-3, 3], [-3, 0]],
        [[-3, 3], [-3, 3]],
        [[-3, math.nan], [-3, 3], [-3, 0]],
    ):
        with pytest.raises(ValueError, match="arena_ned_m"):
            Fence.around(bad, SETTINGS, 3.0, 1.5)
    with pytest.raises(ValueError, match="margin_m"):
        Fence(FENCE.arena_ned_m, 0.0, 1.0, 1.0, 1.0, 1.0)


def test_setpoints_lie_in_the_arena_itself_the_boundary_included() -> None:
    assert FENCE.setpoint_problem([3.0, -3.0, 0.0]) is None
    assert FENCE.setpoint_problem([0.0, 0.0, -1.5]) is None
    problem = FENCE.setpoint_problem([0.0, 3.2, -1.0])
    assert (
        problem is not None and "0.20 m outside the arena N [-3, 3] E [-3, 3] D [-3, 0]" in problem
    )
    assert "not finite" in (FENCE.setpoint_problem([math.nan, 0, -1]) or "")
    sp = np.zeros((10, 3)) + [0.0, 0.0, -1.0]
    assert FENCE.setpoints_problem(sp) is None
    sp[7] = [0.0, 0.0, -3.5]  # above the ceiling
    assert (FENCE.setpoints_problem(sp) or "").startswith("setpoint k = 7: ")


def test_a_measured_position_ends_the_flight_only_beyond_the_margin() -> None:
    assert FENCE.position_problem([4.4, 0.0, -1.0]) is None  # 1.4 m outside: within 1.5
    assert FENCE.position_problem([0.0, 0.0, 1.4]) is None  # 1.4 m below the ground
    below = FENCE.position_problem([0.0, 0.0, 480.0])  # the incident's estimate
    assert below is not None and "480.00 m outside the arena" in below
    assert FENCE.position_problem([0.0, -4.6, -1.0]) is not None
    np.testing.assert_allclose(FENCE.clamp([5.0, -0.5, 2.0]), [3.0, -0.5, 0.0])


def _trajectory(t: np.ndarray, amp: float, w: float) -> tuple[np.ndarray, np.ndarray]:
    """An eight at (0, 0, -1.5): positions and exact velocities."""
    pos = np.column_stack([amp * np.sin(w * t), amp / 2 * np.sin(2 * w * t), -1.5 + 0 * t])
    vel = np.column_stack([amp * w * np.cos(w * t), amp * w * np.cos(2 * w * t), 0 * t])
    return pos, vel


def _run(monitor: EstimateMonitor, t, pos, vel) -> list[tuple[float, str]]:
    out = []
    for tk, p, v in zip(t, pos, vel, strict=True):
        problem = monitor.update(float(tk), p, v)
        if problem is not None:
            out.append((float(tk), problem))
    return out


def test_a_consistent_flight_is_never_stopped_and_the_peaks_are_kept() -> None:
    t = np.arange(0, 20, 1 / RATE_HZ)
    pos, vel = _trajectory(t, 1.2, 2 * np.pi / 5)
    monitor = EstimateMonitor(FENCE)
    assert _run(monitor, t, pos, vel) == []
    assert monitor.peaks["speed_xy_m_s"] == pytest.approx(np.hypot(vel[:, 0], vel[:, 1]).max())
    assert monitor.peaks["outside_m"] == 0.0 and monitor.peaks["drift_m"] < 0.01


def test_each_check_names_what_it_saw() -> None:
    t = np.arange(0, 4, 1 / RATE_HZ)
    hover = np.zeros((len(t), 3)) + [0, 0, -1.5]
    still = np.zeros((len(t), 3))
    # a jump: 0.6 m between two samples, velocity unchanged
    jumped = hover.copy()
    jumped[100:, 1] += 0.6
    (first, *_) = _run(EstimateMonitor(FENCE), t, jumped, still)
    assert first[0] == pytest.approx(t[100]) and "jumped 0.60 m" in first[1]
    # a jump out of the arena and its margin (an estimate reset by 5 m): both, the breach first
    reset = hover.copy()
    reset[100:, 1] += 5.0
    (first, *_) = _run(EstimateMonitor(FENCE), t, reset, still)
    assert first[0] == pytest.approx(t[100]), first
    assert re.fullmatch(r".* is 2\.00 m outside the arena .*, after the position jumped 5\.00 m .*",
                        first[1]), first  # fmt: skip
    # a drift: the position walks at 3 m/s, the velocity says it stands still
    drifting = hover.copy()
    drifting[100:, 0] += 3.0 * (t[100:] - t[100])
    (first, *_) = _run(EstimateMonitor(FENCE), t, drifting, still)
    assert first[0] - t[100] == pytest.approx(FENCE.drift_m / 3.0, abs=1.5 / RATE_HZ)
    assert "against its velocity within 1 s" in first[1] and "contradicts itself" in first[1]
    # speeds: horizontal and vertical, reported as such
    fast = still.copy()
    fast[50:, 1] = 4.6
    assert "horizontal speed 4.60 m/s" in _run(EstimateMonitor(FENCE), t, hover, fast)[0][1]
    climb = still.copy()
    climb[50:, 2] = -2.3
    assert "climbing at 2.30 m/s" in _run(EstimateMonitor(FENCE), t, hover, climb)[0][1]
    # outside: beyond the arena plus margin
    gone = hover.copy()
    gone[60:, 2] = 1.6
    gone_vel = still.copy()
    (first, *_) = _run(EstimateMonitor(FENCE), t[59:], gone[59:], gone_vel[59:])
    assert "outside the arena" in first[1]


def test_while_landing_only_a_reading_below_the_floor_is_let_through() -> None:
    # the PX4 SITL GPS landing: on the ground, the estimate sinks 1.57 m below it, its
    # velocity saying so (0.3-0.6 m/s down), for about 10 s until the land detector
    t = np.arange(0.0, 10.0, 1 / RATE_HZ)
    vel = np.zeros((len(t), 3))
    vel[:, 2] = 0.157
    sinking = np.column_stack([0 * t - 0.58, 0 * t + 0.63, 0.157 * t])
    landing = EstimateMonitor(FENCE)
    samples = zip(t, sinking, vel, strict=True)
    seen = [landing.update(float(tk), p, v, landing=True) for tk, p, v in samples]
    assert seen == [None] * len(t)
    assert landing.below_floor_landing_m == pytest.approx(sinking[-1, 2])
    assert landing.peaks["outside_m"] == pytest.approx(sinking[-1, 2])  # the evidence kept
    (first, *_) = _run(EstimateMonitor(FENCE), t, sinking, vel)  # in any other phase: a breach
    assert "outside the arena" in first[1] and first[0] == pytest.approx(1.5 / 0.157, abs=0.02)
    # every other limit holds while landing: beside the arena, above its ceiling, too fast
    for pos, v, what in (([0.0, -4.6, -1.0], [0, 0, 0], "outside the arena"),
                         ([0.0, 0.0, -4.6], [0, 0, 0], "outside the arena"),
                         ([0.0, 0.0, 0.5], [0, 0, 2.3], "descending at 2.30 m/s")):  # fmt: skip
        assert what in (EstimateMonitor(FENCE).update(0.0, pos, v, landing=True) or "")
    assert EstimateMonitor(FENCE).below_floor_landing_m == 0.0


def test_the_landing_flag_reaches_the_monitor_and_nothing_else_changes() -> None:
    from gcs.flight.link import Link, TelemetrySample
    from gcs.flight.watches import Watches

    mirror = Link(SETTINGS)
    mirror.armed = True
    watches = Watches(mirror, SETTINGS, FENCE)
    below = TelemetrySample(1.0, (0.0, 0.0, 1.6), (0.0, 0.0, 0.0), 1.0)
    watches.landing = True
    watches.check_sample(below)
    assert watches.breach is None and watches.below_floor_landing_m == pytest.approx(1.6)
    watches.landing = False
    watches.check_sample(TelemetrySample(1.1, (0.0, 0.0, 1.6), (0.0, 0.0, 0.0), 1.1))
    assert (watches.breach or "").startswith("fence: the measured position NED (0.00, 0.00, 1.60)")


def test_a_telemetry_gap_is_not_a_jump_and_a_reordered_sample_is_ignored() -> None:
    monitor = EstimateMonitor(FENCE)
    # 0.5 s without samples while braking at 8 m/s^2 from 2 m/s: the position moves as
    # physics allows, beyond what the trapezoid of the two velocities says
    assert monitor.update(0.0, [0.0, 0.0, -1.5], [2.0, 0.0, 0.0]) is None
    dt, a = 0.5, -MAX_ACCEL_M_S2 / 2
    p = [2.0 * dt + 0.5 * a * dt * dt, 0.0, -1.5]
    assert monitor.update(dt, p, [2.0 + a * dt, 0.0, 0.0]) is None
    assert monitor.update(0.2, [9.0, 9.0, 9.0], [0, 0, 0]) is None  # older: not taken


@settings(max_examples=60, deadline=None)
@given(
    amp=st.floats(0.1, 2.5),
    period_s=st.floats(2.5, 20.0),
    noise_m=st.floats(0.0, 0.03),
    seed=st.integers(0, 2**16),
)
def test_no_breach_on_any_smooth_flight_within_the_limits(amp, period_s, noise_m, seed) -> None:
    w = 2 * np.pi / period_s
    if amp * w * math.sqrt(2) > FENCE.max_speed_xy_m_s / 1.5:  # within the vehicle's own limit
        return
    t = np.arange(0, 2 * period_s, 1 / RATE_HZ)
    pos, vel = _trajectory(t, amp, w)
    pos = pos + np.random.default_rng(seed).normal(0, noise_m, pos.shape)  # fast noise
    assert _run(EstimateMonitor(FENCE), t, pos, vel) == []


@settings(max_examples=60, deadline=None)
@given(step=st.floats(0.0, 3.0), gap_s=st.floats(0.01, 1.0), axis=st.integers(0, 2))
def test_every_step_beyond_physics_is_caught(step, gap_s, axis) -> None:
    monitor = EstimateMonitor(FENCE)
    start = np.array([0.0, 0.0, -1.5])
    assert monitor.update(0.0, start, [0, 0, 0]) is None
    end = start.copy()
    end[axis] += step * (1 if axis < 2 else -1)
    problem = monitor.update(gap_s, end, [0, 0, 0])
    allowed = FENCE.jump_m + 0.5 * MAX_ACCEL_M_S2 * gap_s**2
    assert (problem is not None and "jumped" in problem) == (step > allowed)


def test_the_thresholds_do_not_fire_on_the_shared_px4_data() -> None:
    # every trial of PX4 v1.16 SITL on GPS and on vision, and the capture from take-off to
    # landing: a vehicle that is merely poor is never stopped (benchmarks/fence_thresholds.py
    # prints the peaks next to the thresholds)
    paths = sorted(glob.glob(str(shared() / "data" / "px4-sitl" / "*" / "trial-*.csv")))
    assert len(paths) >= 30
    peaks = dict.fromkeys(("speed_xy_m_s", "drift_m", "jump_m"), 0.0)
    for path in paths:
        t = np.genfromtxt(path, delimiter=",", names=True)
        pos = np.column_stack([t[f"pos_{a}_m"] for a in ("north", "east", "down")])
        vel = np.column_stack([t[f"vel_{a}_m_s"] for a in ("north", "east", "down")])
        ok = np.all(np.isfinite(pos), axis=1)
        monitor = EstimateMonitor(FENCE)
        assert _run(monitor, t["t_s"][ok], pos[ok], vel[ok]) == [], path
        peaks = {k: max(v, monitor.peaks[k]) for k, v in peaks.items()}
    monitor = EstimateMonitor(FENCE)
    assert _run(monitor, *capture_armed()) == []
    # and not by a hair: the GPS vehicle's own contradiction is below half the threshold
    assert peaks["drift_m"] < 0.5 * FENCE.drift_m and monitor.peaks["drift_m"] < 0.5 * FENCE.drift_m
    assert peaks["jump_m"] < 0.1 * FENCE.jump_m
    assert DRIFT_WINDOW_S == 1.0


def test_the_geofence_polygon_is_the_arena_plus_margin_around_the_origin() -> None:
    origin = (47.3977431, 8.5455947)
    vertices = fence_polygon(FENCE, *origin)
    corners = [global_to_ned(*origin, lat, lon) for lat, lon in vertices]
    np.testing.assert_allclose(
        corners, [(-4.5, -4.5), (-4.5, 4.5), (4.5, 4.5), (4.5, -4.5)], atol=1e-6
    )
    assert vertical_limit_m(FENCE) == pytest.approx(4.5)  # ceiling 3 m plus the margin


def test_the_geofence_status_line_says_what_the_vehicle_has() -> None:
    ok = GeofenceState(True, (47.0, 8.0, 400.0), ((47.0, 8.0),) * 4, GF_ACTION, 4.5, 0.0)
    assert ok.ok
    line = ok.text(1.5)
    assert "arena + 1.5 m uploaded" in line and "GF_ACTION 5 (Land)" in line
    assert "GF_MAX_VER_DIST 4.5 m above home (no floor)" in line and "(off)" in line
    refused = GeofenceState(False, None, (), None, None, None, "geofence upload failed: ERROR")
    assert not refused.ok
    assert refused.text(1.5).startswith("geofence not installed on the vehicle (geofence upload")
    assert "only while gcs is connected" in refused.text(1.5)
    partial = GeofenceState(True, (47.0, 8.0, 400.0), ((47.0, 8.0),) * 4, None, None, 2.0, "x")
    assert not partial.ok and "GF_MAX_HOR_DIST 2 m;" in partial.text(1.5)


# -- the vehicle's side: one place for every send, one abort path for every watch -------------


def test_the_vehicle_sends_no_setpoint_outside_the_arena_and_none_without_a_fence() -> None:
    import asyncio

    from gcs.errors import VehicleError
    from gcs.flight.vehicle import Vehicle

    vehicle = Vehicle(SETTINGS, FENCE)
    with pytest.raises(VehicleError, match=r"^fence: setpoint NED \(0.00, 3.50, -1.00\) m is 0.50"):
        asyncio.run(vehicle.send_setpoint([0.0, 3.5, -1.0]))
    with pytest.raises(VehicleError, match="no arena fence"):
        asyncio.run(Vehicle(SETTINGS).send_setpoint([0.0, 0.0, -1.0]))


def test_every_watch_trips_the_same_abort_path_and_only_while_armed() -> None:
    import asyncio

    from gcs.errors import VehicleError
    from gcs.flight.link import Link
    from gcs.flight.manoeuvres import Manoeuvres
    from gcs.flight.watches import Watches

    mirror = Link(SETTINGS)  # the vehicle's parts, on a mirror that is told it is armed
    watches = Watches(mirror, SETTINGS, FENCE)
    reasons = ["mocap stream stale (0.40 s since the last frame)"]
    watches.add_watch("mocap", lambda: reasons[0])  # a motion-capture client's problem()
    assert watches.safety_problem() is None  # on the ground, disarmed: not watched
    mirror.armed = True
    assert watches.safety_problem() == "mocap: mocap stream stale (0.40 s since the last frame)"
    watches.trip("fence", "something else")  # the first breach is the one kept
    assert watches.breach == "mocap: mocap stream stale (0.40 s since the last frame)"
    assert watches.control_problem() == watches.breach  # ends moves, holds and trials
    manoeuvres = Manoeuvres(mirror, watches, SETTINGS, FENCE)
    with pytest.raises(VehicleError, match="^mocap: mocap stream stale .* while waiting for a"):
        asyncio.run(manoeuvres.wait_healthy_local_position(timeout_s=1.0))  # and every wait


class _Refusing:
    """Just enough of Vehicle for install_geofence; each call can be made to fail."""

    def __init__(self, fail: str | None) -> None:
        self.fail, self.uploaded, self.params = fail, None, None

    def _maybe(self, what: str) -> None:
        from gcs.errors import VehicleError

        if self.fail == what:
            raise VehicleError(f"{what} failed: ERROR")

    async def gps_global_origin(self):  # type: ignore[no-untyped-def]
        self._maybe("origin")
        return (47.3977431, 8.5455947, 489.244)

    async def upload_inclusion_polygon(self, vertices):  # type: ignore[no-untyped-def]
        self._maybe("upload")
        self.uploaded = vertices

    async def set_params(self, values):  # type: ignore[no-untyped-def]
        self._maybe("params")
        self.params = values

    async def read_float_param(self, name: str) -> float | None:
        return 0.0


@pytest.mark.parametrize("fail", [None, "origin", "upload", "params"])
def test_a_vehicle_that_refuses_the_geofence_is_said_not_stopped(fail: str | None) -> None:
    import asyncio

    from gcs.flight.geofence import install_geofence

    vehicle = _Refusing(fail)
    state = asyncio.run(install_geofence(vehicle, FENCE))  # never raises
    assert state.ok == (fail is None)
    assert state.uploaded == (fail in (None, "params"))
    if fail is None:
        assert vehicle.params == {"GF_ACTION": 5, "GF_MAX_VER_DIST": 4.5}
        assert vehicle.uploaded == fence_polygon(FENCE, 47.3977431, 8.5455947)
    elif fail == "params":  # the polygon is there, but what PX4 does on a breach is unknown
        assert state.gf_action is None and "breach action is unknown" in state.text(1.5)
    else:
        assert state.text(1.5).startswith("geofence not installed on the vehicle")
        assert f"{fail} failed: ERROR" in state.text(1.5)
