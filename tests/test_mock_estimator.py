"""The mock's navigation error: error processes, the controller on the estimate, the defaults.

The indoor mock (estimator off) must fly exactly as before the estimator existed; the mock-gps
profile flies on an estimate whose error behaves as ``gcs.mock.estimator`` documents.
"""

from __future__ import annotations

import math
import random
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from records import assert_scaled

from gcs.errors import ProfileError
from gcs.mock.config import EstimatorConfig, MockConfig, load_mock_config, mock_config_from_dict
from gcs.mock.estimator import (
    ESTIMATOR_SEED_OFFSET,
    AidedInertialError,
    Estimator,
    make_estimator,
)
from gcs.mock.physics import QuadPhysics, Target, fit_step_response, step_response
from gcs.mock.vehicle import Mode, Vehicle

ROOT = Path(__file__).resolve().parents[1]
GPS = load_mock_config(ROOT / "profiles" / "mock-gps.yaml")

# flight_rows(MockConfig(), seed=3) as the mock computed it before the estimator existed (main at
# 606f2ad; recorded as a digest, turned into values where today's code still gave that digest): the
# indoor default flies as before, within the tolerance of docs/results.md's "Reproducibility"
RECORD = ROOT / "tests" / "data" / "mock-flights.npz"
RTOL = 1e-12  # of each column's largest magnitude, across machines


def flight_rows(cfg: MockConfig, seed: int) -> np.ndarray:
    """Arm, take off, hold, fly a circle in OFFBOARD, land: 30 s of truth and measurements.

    One row every 20 ms: time, true position and velocity, measured position and velocity."""
    v = Vehicle(cfg, seed)
    rows = []
    v.arm(True)
    v.takeoff()
    for k in range(1, 1501):  # 30 s at 50 Hz
        t = k * 0.02
        if t >= 8.0 and k < 1400:
            if v.mode is not Mode.OFFBOARD:
                v.on_setpoint(t, (0.0, 0.0, -2.5), 0.0)
                v.set_mode(Mode.OFFBOARD)
            s = t - 8.0
            v.on_setpoint(t, (math.sin(0.8 * s), 1.0 - math.cos(0.8 * s), -2.5), 0.0)
        if k == 1400:
            v.land()
        v.update(t)
        pos, vel = v.physics.measure()
        rows.append((v.t_s, *v.physics.pos, *v.physics.vel, *pos, *vel))
    return np.array(rows)


def test_indoor_default_flies_as_before_the_estimator() -> None:
    assert MockConfig().estimator.enabled is False
    rows = flight_rows(MockConfig(), 3)
    with np.load(RECORD) as record:
        recorded = record["before-estimator/seed-3"]
    assert_scaled(rows, recorded, RTOL, "flight", axis=0)
    assert make_estimator(MockConfig().estimator, 3) is None


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2**20))
def test_an_estimator_without_error_leaves_the_truth_and_its_random_streams_alone(
    seed: int,
) -> None:
    # the estimator draws from its own stream: switched on with zero error it changes nothing
    zero = replace(MockConfig(), estimator=EstimatorConfig(enabled=True))
    np.testing.assert_array_equal(flight_rows(zero, seed), flight_rows(MockConfig(), seed))


def _run(proc: AidedInertialError, seconds: float, dt: float = 0.005) -> np.ndarray:
    """Step a process; rows (vel err (3), pos err (3), aid err (3)) every 0.05 s."""
    rows = []
    for k in range(int(round(seconds / dt))):
        proc.step(dt)
        if k % 10 == 9:
            rows.append([*proc.vel_err_m_s, *proc.pos_err_m, *proc.aid_err_m])
    return np.array(rows)


def test_velocity_error_is_the_configured_ornstein_uhlenbeck_process() -> None:
    cfg = EstimatorConfig(enabled=True, vel_sigma_ned_m_s=(0.1, 0.3, 0.2), vel_tau_ned_s=(2, 1, 4))
    rows = _run(AidedInertialError(cfg, random.Random(1)), 4000.0)
    vel = rows[:, :3]
    np.testing.assert_allclose(vel.std(axis=0), cfg.vel_sigma_ned_m_s, rtol=0.1)
    for axis, tau in enumerate(cfg.vel_tau_ned_s):
        lag = int(round(tau / 0.05))
        x = vel[:, axis]
        rho = np.corrcoef(x[:-lag], x[lag:])[0, 1]
        assert rho == pytest.approx(math.exp(-1.0), abs=0.06), (axis, rho)


def test_position_error_is_the_velocity_error_low_passed_by_the_aiding() -> None:
    # dx/dt = v - x / T with v Ornstein-Uhlenbeck (sigma, tau): var x = T^2 sigma^2 tau / (tau + T)
    sigma, tau, t_aid = 0.3, 2.0, 0.5
    cfg = EstimatorConfig(
        enabled=True, vel_sigma_ned_m_s=(sigma, sigma, sigma), vel_tau_ned_s=(tau, tau, tau),
        aid_time_constant_s=t_aid,
    )  # fmt: skip
    rows = _run(AidedInertialError(cfg, random.Random(2)), 3000.0)
    expected = t_aid * sigma * math.sqrt(tau / (tau + t_aid))
    np.testing.assert_allclose(rows[:, 3:6].std(axis=0), expected, rtol=0.1)
    # and it cannot run away: without aiding error it stays within a few of those sigmas
    assert np.abs(rows[:, 3:6]).max() < 6 * expected


def test_aiding_error_pulls_the_position_error_and_resets_snap_onto_it() -> None:
    cfg = EstimatorConfig(
        enabled=True, aid_sigma_ned_m=(0.2, 0.2, 0.1), aid_tau_s=30.0, aid_time_constant_s=1.0,
        reset_rate_1_s=0.05,
    )  # fmt: skip
    proc = AidedInertialError(cfg, random.Random(3))
    rows = _run(proc, 2000.0)
    # no velocity error: the position error follows the aiding error with a lag of T << tau
    assert np.corrcoef(rows[:, 3], rows[:, 6])[0, 1] > 0.95
    assert rows[:, 6].std() == pytest.approx(0.2, rel=0.25)
    # Poisson resets at 0.05 /s over 2000 s: 100 +- 4 sigma
    assert abs(proc.resets - 100) < 40, proc.resets
    proc.pos_err_m[0] += 1.0
    proc.reset()
    assert proc.pos_err_m == proc.aid_err_m


def test_the_estimator_sums_its_processes_and_applies_them() -> None:
    cfg = EstimatorConfig(enabled=True, vel_sigma_ned_m_s=(0.1, 0.2, 0.3))
    a, b = AidedInertialError(cfg, random.Random(4)), AidedInertialError(cfg, random.Random(5))
    est = Estimator([a, b])
    est.step(0.005)
    for i in range(3):
        assert est.pos_err_m[i] == a.pos_err_m[i] + b.pos_err_m[i]
        assert est.vel_err_m_s[i] == a.vel_err_m_s[i] + b.vel_err_m_s[i]
    pos, vel = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    est.apply((1.0, 2.0, -3.0), (0.5, 0.0, 0.0), pos, vel)
    assert pos == [1.0 + est.pos_err_m[0], 2.0 + est.pos_err_m[1], -3.0 + est.pos_err_m[2]]
    assert vel[0] == 0.5 + est.vel_err_m_s[0]


def test_make_estimator_draws_from_its_own_seeded_stream() -> None:
    one, two = make_estimator(GPS.estimator, 7), make_estimator(GPS.estimator, 7)
    assert one is not None and two is not None
    for _ in range(100):
        one.step(0.005)
        two.step(0.005)
    assert one.pos_err_m == two.pos_err_m
    fresh = make_estimator(GPS.estimator, 7)
    ref = AidedInertialError(GPS.estimator, random.Random(7 + ESTIMATOR_SEED_OFFSET))
    assert fresh is not None and fresh.vel_err_m_s == ref.vel_err_m_s
    other = make_estimator(GPS.estimator, 8)
    assert other is not None and other.vel_err_m_s != fresh.vel_err_m_s


def _hover_on_the_estimate(seconds: float, seed: int = 0):
    """mock-gps without gusts hovering at (0, 0, -2): reported, true, errors every 0.1 s."""
    quiet = replace(GPS, disturbance=replace(GPS.disturbance, gust_sigma_m_s2=0.0))
    sim = QuadPhysics(quiet, seed=seed, pos_ned_m=(0.0, 0.0, -2.0))
    sim.command(0.0, Target((0.0, 0.0, -2.0)))
    nav, nav_vel, true, v_err = [], [], [], []
    for k in range(1, int(seconds * 10) + 1):
        sim.advance_to(0.1 * k)
        nav.append(list(sim.nav_pos))
        nav_vel.append(list(sim.nav_vel))
        true.append(list(sim.pos))
        v_err.append(list(sim.estimator.vel_err_m_s))
    return np.array(nav), np.array(nav_vel), np.array(true), np.array(v_err), sim


def test_the_controller_flies_the_estimate_and_the_truth_wanders_with_it() -> None:
    nav, nav_vel, true, v_err, sim = _hover_on_the_estimate(300.0)
    # reported = truth + the estimator's error, exactly (the fast noise is measure()'s)
    assert sim.nav_pos == [p + e for p, e in zip(sim.pos, sim.estimator.pos_err_m, strict=True)]
    # PX4's velocity loop drives the *estimated* velocity to Kp (r - pos_est): the reported
    # hover sits (reported velocity) / Kp off the setpoint, as in the shared PX4 hovers, and
    # what holds it there is the velocity error
    kp = GPS.controller.pos_p_x_1_s
    for axis in (0, 1):
        slope = np.polyfit(-nav_vel[:, axis] / kp, nav[:, axis], 1)[0]
        assert 0.8 < slope < 1.1, (axis, slope)
        assert np.corrcoef(-v_err[:, axis], nav[:, axis])[0, 1] > 0.5
    # the true vehicle is elsewhere: it wanders with the estimate by decimetres
    assert 0.05 < np.sqrt(np.mean((nav[:, :2] - true[:, :2]) ** 2)) < 0.3
    assert np.sqrt(np.mean(true[:, :2] ** 2)) > 0.1


def test_reported_velocity_disagrees_with_the_reported_position_as_documented() -> None:
    sim = QuadPhysics(GPS, seed=1, pos_ned_m=(0.0, 0.0, -2.0))
    sim.command(0.0, Target((0.0, 0.0, -2.0)))
    sim.advance_to(5.0)
    est = sim.estimator
    before = list(sim.nav_pos)
    x = [p - g for p, g in zip(est.processes[0].pos_err_m, est.processes[0].aid_err_m, strict=True)]
    sim.step()
    dt = sim.dt_s
    t_aid = GPS.estimator.aid_time_constant_s
    for i in range(3):
        # d(pos_est)/dt - vel_est = -(p_err - g) / T, up to the step's own change of it
        disagreement = (sim.nav_pos[i] - before[i]) / dt - sim.nav_vel[i]
        assert disagreement == pytest.approx(-x[i] / t_aid, abs=0.02 + 0.05 * abs(x[i] / t_aid))


def test_hold_and_home_are_where_the_vehicle_believes_it_is() -> None:
    v = Vehicle(GPS, seed=2)
    v.update(1.0)
    v.arm(True)
    nav = tuple(v.physics.nav_pos)
    assert v.home_ned_m == nav and v.home_ned_m != tuple(v.physics.pos)
    v.takeoff()
    v.update(15.0)
    assert v.mode is Mode.HOLD
    target = v.physics.target.pos_ned_m
    assert abs(target[2] - (nav[2] - GPS.px4.mis_takeoff_alt_m)) < 0.1  # estimated altitude


def test_mock_gps_profile_is_gps_with_the_shared_closed_loop() -> None:
    assert GPS.estimator.enabled and GPS.estimator.reset_rate_1_s == 0.0
    assert (GPS.px4.ekf2_gps_ctrl, GPS.px4.ekf2_ev_ctrl, GPS.px4.ekf2_hgt_ref) == (7, 0, 1)
    assert GPS.disturbance.field_amplitude_m_s2 == 0.0
    # the shared README: 1 m steps, wn about 1.0 rad/s, zeta 0.5-0.85, no measurable dead time
    for axis in (0, 1):
        fit = fit_step_response(*step_response(GPS, axis, amplitude_m=1.0))
        assert fit.wn_rad_s == pytest.approx(1.0, abs=0.1)
        assert 0.5 <= fit.zeta <= 0.85
        assert fit.gain == pytest.approx(1.0, abs=0.1)
        assert fit.delay_s < 0.05


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ({"vel_sigma_ned_m_s": 0.3}, "must be three numbers"),
        ({"vel_sigma_ned_m_s": [0.1, 0.2]}, "must be three numbers"),
        ({"vel_sigma_ned_m_s": [0.1, "x", 0.2]}, "must be a number"),
        ({"vel_sigma_ned_m_s": [0.1, -0.2, 0.2]}, "estimator.vel_sigma_ned_m_s' must be >= 0"),
        ({"vel_tau_ned_s": [1.0, 0.0, 1.0]}, "estimator.vel_tau_ned_s' must be > 0"),
        ({"aid_time_constant_s": 0.001}, "estimator.aid_time_constant_s' must be >= 2"),
        ({"reset_rate_1_s": -1.0}, "estimator.reset_rate_1_s' must be >= 0"),
        ({"enabled": "yes"}, "must be true or false"),
        ({"drift": 1.0}, "estimator.drift' is not a known field"),
    ],
)
def test_bad_estimator_fields_are_refused_by_name(section: dict, message: str) -> None:
    with pytest.raises(ProfileError, match=message) as info:
        mock_config_from_dict({"estimator": section}, "mock-gps.yaml")
    assert "mock-gps.yaml" in str(info.value)


# -- injected faults ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kind", "vector", "expected"),
    [
        # (after 0.5 s, after 1.5 s, after 4 s: the growth stops at 2 s)
        ("drift", (0.0, 2.0, 0.0), (1.0, 3.0, 4.0)),
        ("divergence", (0.0, 2.0, 0.0), (0.25, 2.25, 4.0)),
        ("jump", (0.0, 2.0, 0.0), (2.0, 2.0, 2.0)),
    ],
)
def test_injected_faults_follow_their_law_from_their_onset(kind, vector, expected) -> None:
    from gcs.mock.estimator import PositionDivergence, PositionDrift, PositionJump

    cls = {"drift": PositionDrift, "divergence": PositionDivergence, "jump": PositionJump}[kind]
    fault = cls(1.0, 2.0 if kind != "jump" else None, vector)
    dt = 0.005
    for _ in range(400):  # 2 s before the clock starts: nothing
        fault.step(dt)
    assert fault.pos_err_m == [0.0, 0.0, 0.0] and fault.onset_s is None
    fault.start_clock(fault.t_s)  # "armed" at 2 s: onset at 3 s
    fault.start_clock(99.0)  # later arming: changes nothing
    assert fault.onset_s == pytest.approx(3.0)
    seen = []
    for elapsed in (0.5, 1.5, 4.0):
        while fault.t_s < 3.0 + elapsed - 1e-9:
            fault.step(dt)
        seen.append(fault.pos_err_m[1])
        assert fault.pos_err_m[0] == fault.pos_err_m[2] == 0.0
        assert fault.vel_err_m_s == [0.0, 0.0, 0.0]  # the velocity stays the inertial one
    np.testing.assert_allclose(seen, expected, atol=0.02)
    assert fault.record()["kind"] == kind and fault.record()["onset_vehicle_s"] == fault.onset_s


def test_faults_on_the_indoor_mock_change_nothing_until_their_onset() -> None:
    from gcs.mock.estimator import PositionJump

    plain = QuadPhysics(MockConfig(), seed=3, pos_ned_m=(0.0, 0.0, -2.0))
    faulty = QuadPhysics(MockConfig(), seed=3, pos_ned_m=(0.0, 0.0, -2.0))
    jump = PositionJump(1.0, None, (0.5, 0.0, 0.0))
    faulty.add_error(jump)
    for sim in (plain, faulty):
        sim.command(0.0, Target((0.3, -0.2, -2.0)))
    jump.start_clock(0.0)
    plain.advance_to(0.9)
    faulty.advance_to(0.9)
    assert plain.pos == faulty.pos and plain.measure() == faulty.measure()  # bit for bit
    faulty.advance_to(1.2)
    assert faulty.nav_pos[0] == pytest.approx(faulty.pos[0] + 0.5)
