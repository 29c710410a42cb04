"""The mock's vertical loop: PX4's cascade with its thrust and speed limits, calibrated on the
shared PX4 capture (``benchmarks/mock_vertical_calibration.py``); horizontal flight unchanged.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.signal
from records import assert_scaled

from gcs.mock.config import MockConfig, load_mock_config
from gcs.mock.physics import QuadPhysics, Target, step_response
from gcs.mock.vehicle import Mode, Vehicle

ROOT = Path(__file__).resolve().parents[1]

# horizontal_rows(cfg, seed=3) as the mock computed them before its vertical loop was calibrated
# (recorded as digests, turned into values where today's code still gave those digests): with
# the altitude held, the horizontal flight is as before, within the tolerance of docs/results.md's
# "Reproducibility"
RECORD = ROOT / "tests" / "data" / "mock-flights.npz"
HORIZONTAL_BEFORE = ("mock.yaml", "mock-gps.yaml")
RTOL = 1e-12  # of each column's largest magnitude, across machines


def horizontal_rows(cfg: MockConfig, seed: int) -> np.ndarray:
    """Arm, take off, fly an eight at a held altitude in OFFBOARD, land: north and east only.

    One row every 20 ms: time, true position and velocity, measured position and velocity."""
    v = Vehicle(cfg, seed)
    rows = []
    v.arm(True)
    v.takeoff()
    for k in range(1, 2001):  # 40 s at 50 Hz
        t = k * 0.02
        if t >= 8.0 and k < 1900:
            if v.mode is not Mode.OFFBOARD:
                v.on_setpoint(t, (0.0, 0.0, -2.0), 0.0)
                v.set_mode(Mode.OFFBOARD)
            s = t - 8.0
            v.on_setpoint(t, (1.2 * math.sin(0.6 * s), 0.8 * math.sin(1.2 * s), -2.0), 0.0)
        if k == 1900:
            v.land()
        v.update(t)
        pos, vel = v.physics.measure()
        p, u = v.physics.pos, v.physics.vel
        rows.append((v.t_s, p[0], p[1], u[0], u[1], pos[0], pos[1], vel[0], vel[1]))
    return np.array(rows)


def test_horizontal_flight_at_a_held_altitude_is_as_before() -> None:
    with np.load(RECORD) as record:
        for name in HORIZONTAL_BEFORE:
            rows = horizontal_rows(load_mock_config(ROOT / "profiles" / name), 3)
            assert_scaled(rows, record[f"horizontal/{name}"], RTOL, name, axis=0)


# -- the vertical loop against independently computed values ----------------------------------

QUIET = replace(
    MockConfig(),
    disturbance=replace(MockConfig().disturbance, field_amplitude_m_s2=0.0, gust_sigma_m_s2=0.0),
)


def fly(cfg: MockConfig, start: tuple[float, float, float], target: Target, seconds: float):  # type: ignore[no-untyped-def]
    """Hover at ``start``, then follow ``target``: times, positions, velocities, accelerations."""
    sim = QuadPhysics(cfg, pos_ned_m=start)
    sim.command(0.0, target)
    rows = []
    for k in range(1, int(round(seconds / cfg.physics.dt_s)) + 1):
        sim.step()
        rows.append((k * cfg.physics.dt_s, *sim.pos, *sim.vel, *sim.acc))
    out = np.array(rows)
    return out[:, 0], out[:, 1:4], out[:, 4:7], out[:, 7:10]


@pytest.mark.parametrize("up_m_s, down_m_s", [(3.0, 1.5), (1.2, 0.7)])
def test_steady_climb_and_sink_speeds_are_the_profiles_limits(
    up_m_s: float, down_m_s: float
) -> None:
    c = replace(QUIET.controller, vel_max_up_m_s=up_m_s, vel_max_down_m_s=down_m_s)
    cfg = replace(QUIET, controller=c)
    # long climbs and descents: the limit binds, the integrator has taken up the drag
    t, pos, vel, _ = fly(cfg, (0.0, 0.0, -2.0), Target((0.0, 0.0, -200.0)), 30.0)
    assert np.mean(-vel[t > 29.0, 2]) == pytest.approx(up_m_s, abs=0.002)
    t, pos, vel, _ = fly(cfg, (0.0, 0.0, -100.0), Target((0.0, 0.0, -2.0)), 45.0)
    assert np.mean(vel[(t > 39.0) & (t <= 40.0), 2]) == pytest.approx(down_m_s, abs=0.002)
    # a take-off target's own limit (MPC_TKO_SPEED) below the profile's
    tko = Target((0.0, 0.0, -40.0), vel_up_max_m_s=0.5)
    t, _, vel, _ = fly(cfg, (0.0, 0.0, -2.0), tko, 15.0)
    assert np.mean(-vel[t > 14.0, 2]) == pytest.approx(0.5, abs=0.002)


def linear_vertical_step(cfg: MockConfig, t_s: np.ndarray) -> np.ndarray:
    """Unit step of the linearised vertical cascade, computed with scipy from the equations.

    States (z, vz, a, I): vz_sp = Kp (r - z), dI/dt = vz_sp - vz, a_sp = Kv (vz_sp - vz) + Ki I,
    da/dt = (a_sp - a) / tau, dvz/dt = a - d vz (linear drag), dz/dt = vz; r delayed by L.
    """
    c, p = cfg.controller, cfg.physics
    kp, kv, ki, tau, d = c.pos_p_z_1_s, c.vel_p_z_1_s, c.vel_i_z_1_s2, p.tilt_lag_s, p.drag_lin_1_s
    a = np.array(
        [
            [0.0, 1.0, 0.0, 0.0],
            [0.0, -d, 1.0, 0.0],
            [-kv * kp / tau, -kv / tau, -1.0 / tau, ki / tau],
            [-kp, -1.0, 0.0, 0.0],
        ]
    )
    b = np.array([[0.0], [0.0], [kv * kp / tau], [kp]])
    sys = scipy.signal.StateSpace(a, b, np.array([[1.0, 0.0, 0.0, 0.0]]), np.zeros((1, 1)))
    shifted = np.maximum(t_s - p.input_delay_s, 0.0)
    grid = np.linspace(0.0, float(shifted.max()), 6001)
    _, y = scipy.signal.step(sys, T=grid)
    return np.interp(shifted, grid, y)


@pytest.mark.parametrize("profile", ["mock.yaml", "mock-gps.yaml"])
def test_a_small_altitude_step_follows_the_linear_cascade(profile: str) -> None:
    cfg = load_mock_config(ROOT / "profiles" / profile)
    t, y = step_response(cfg, 2, amplitude_m=-0.05, duration_s=8.0)
    expected = linear_vertical_step(cfg, t)
    # Euler on a 5 ms grid and the quadratic drag are all that separates them
    assert np.max(np.abs(y - expected)) < 0.01
    assert y[-1] == pytest.approx(1.0, abs=0.01)


@pytest.mark.parametrize("profile", ["mock.yaml", "mock-gps.yaml"])
def test_on_a_climbing_circle_the_height_lags_by_the_loops_following_error(profile: str) -> None:
    # a 3-D path (setpoints at 50 Hz, position only as MAVSDK sends them): the velocity loop's
    # integrator follows any constant climb rate v, so the height trails the reference by the
    # transport delay's v L plus the P loop's v / Kp_z, whatever the circle does meanwhile
    base = load_mock_config(ROOT / "profiles" / profile)
    cfg = replace(
        base,
        disturbance=replace(base.disturbance, field_amplitude_m_s2=0.0, gust_sigma_m_s2=0.0),
        estimator=replace(base.estimator, enabled=False),
    )
    sim = QuadPhysics(cfg, pos_ned_m=(1.0, 0.0, -2.0))
    v, w = 0.3, 0.5
    lag = []
    for k in range(1, 1501):
        t = 0.02 * k
        sim.command(t, Target((math.cos(w * t), math.sin(w * t), -2.0 - v * t)))
        sim.advance_to(t)
        if t > 20.0:
            lag.append(sim.pos[2] - (-2.0 - v * t))
    expected = v * (cfg.physics.input_delay_s + 1.0 / cfg.controller.pos_p_z_1_s)
    assert np.mean(lag) == pytest.approx(expected, abs=0.003)
    assert np.ptp(lag) < 0.003


def test_thrust_stays_within_its_limits_and_the_vertical_comes_first() -> None:
    c = replace(QUIET.controller, vel_p_z_1_s=20.0, vel_max_up_m_s=30.0, vel_max_down_m_s=30.0)
    cfg = replace(QUIET, controller=c)
    g, p = cfg.physics.gravity_m_s2, cfg.physics
    thr_max, thr_min = p.thrust_max_g * g, p.thrust_min_g * g
    margin = c.thrust_xy_margin * thr_max
    # climb hard while moving sideways: the thrust vector is bounded by the maximum thrust and
    # the vertical takes what a horizontal demand below the margin leaves
    t, _, _, acc = fly(cfg, (0.0, 0.0, -2.0), Target((30.0, 0.0, -60.0)), 3.0)
    up = g - acc[:, 2]
    horizontal = np.hypot(acc[:, 0], acc[:, 1])
    total = np.hypot(horizontal, up)
    assert total.max() <= thr_max * (1 + 1e-9)
    assert total.max() > 0.999 * thr_max  # saturated
    settled = t > 10 * cfg.physics.tilt_lag_s  # the lag has caught up with the demand
    at_top = settled & (up > 0.999 * up.max())
    assert at_top.any()
    assert np.all(horizontal[at_top] >= min(c.acc_max_xy_m_s2, margin) * 0.999)
    # sink hard: never below the idle thrust
    _, _, _, acc = fly(cfg, (0.0, 0.0, -60.0), Target((0.0, 0.0, -2.0)), 3.0)
    assert (g - acc[:, 2]).min() >= thr_min * (1 - 1e-9)
    assert (g - acc[:, 2]).min() < 1.01 * thr_min  # reached


def test_px4_take_off_handling_spools_up_then_ramps_the_climb_limit() -> None:
    c = replace(QUIET.controller, spoolup_s=1.0, takeoff_ramp_s=3.0)
    cfg = replace(QUIET, physics=replace(QUIET.physics, input_delay_s=0.0), controller=c)
    sim = QuadPhysics(cfg)
    sim.set_armed(True)
    sim.command(0.0, Target((0.0, 0.0, -2.0)))
    g = cfg.physics.gravity_m_s2
    start = -g / c.vel_p_z_1_s  # the ramp starts at zero thrust
    t_lift = None
    for k in range(1, int(20.0 / cfg.physics.dt_s) + 1):
        sim.step()
        t = k * cfg.physics.dt_s
        if t < 1.0:  # spool-up: no thrust, no integrator
            assert sim.acc[2] == pytest.approx(g) and sim.vel_int == [0.0, 0.0, 0.0]
        if t_lift is None and sim.pos[2] < -0.01:
            t_lift = t
        if 1.0 < t < 4.0:  # the climb speed stays below the ramp's limit
            limit = start + (t - 1.0) / 3.0 * (c.vel_max_up_m_s - start)
            assert -sim.vel[2] <= max(limit, 0.0) + 1e-9
    assert t_lift is not None and 1.0 < t_lift < 4.0
    assert sim.pos[2] == pytest.approx(-2.0, abs=0.02)  # the wound-up integrator is slow
    # with both times zero the vehicle leaves the ground at once
    sim = QuadPhysics(QUIET)
    sim.set_armed(True)
    sim.command(0.0, Target((0.0, 0.0, -2.0)))
    sim.advance_to(0.5)
    assert sim.pos[2] < -0.01


# -- through MAVSDK ---------------------------------------------------------------------------


@pytest.mark.e2e
def test_an_altitude_setpoint_change_is_followed_at_the_profiles_climb_limit(
    tmp_path: Path,
) -> None:
    import asyncio

    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.offboard import OffboardAsync, PositionNedYaw
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
    from test_mock_mavsdk import connect, first

    from gcs.mock.process import MockProcess

    profile = tmp_path / "slow-climb.yaml"
    profile.write_text(
        "controller: {vel_max_up_m_s: 1.0}\n"
        "px4: {mis_takeoff_alt_m: 1.0, mpc_land_speed_m_s: 1.0, land_detect_s: 0.3,"
        " com_disarm_land_s: 0.5}\n"
    )
    climb: list[tuple[float, float]] = []  # (down position, down velocity) seen

    async def fly(url: str) -> None:
        m, system = await connect(url)
        try:
            action, offboard, tel = (
                ActionAsync(system),
                OffboardAsync(system),
                TelemetryAsync(system),
            )
            await first(tel.subscribe_health(), lambda h: h.is_armable, 5.0)
            await tel.set_rate_position_velocity_ned(50.0)
            await action.arm()
            await action.takeoff()
            await first(tel.subscribe_flight_mode(), lambda f: f.name == "HOLD", 10.0)
            await offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -1.0, 0.0))
            await offboard.start()
            await first(tel.subscribe_flight_mode(), lambda f: f.name == "OFFBOARD", 3.0)
            # 2.5 m up; MAVSDK repeats the setpoint at 20 Hz while the telemetry is watched
            await offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -3.5, 0.0))

            def arrived(pv: object) -> bool:
                climb.append((pv.position.down_m, pv.velocity.down_m_s))  # type: ignore[attr-defined]
                return abs(pv.position.down_m + 3.5) < 0.02 and abs(pv.velocity.down_m_s) < 0.05  # type: ignore[attr-defined]

            await first(tel.subscribe_position_velocity_ned(), arrived, 15.0)
            await action.land()
            await first(tel.subscribe_armed(), lambda a: not a, 15.0)
        finally:
            m.destroy()

    with MockProcess(profile, seed=5) as mock:
        asyncio.run(fly(mock.url))
    down = np.array(climb)
    assert down[-1, 0] == pytest.approx(-3.5, abs=0.02)
    # the climb rate reaches the profile's 1.0 m/s (PX4's 3 m/s would be reached otherwise)
    # and keeps to it, within the PI loop's small overshoot and the telemetry noise
    assert 0.95 <= -down[:, 1].min() <= 1.08
