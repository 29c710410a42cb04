"""Mock drone physics: equilibrium, calibration against eq. (11), disturbances, limits."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from gcs.errors import ProfileError
from gcs.mock.config import MockConfig, load_mock_config, mock_config_from_dict
from gcs.mock.physics import (
    EQ11,
    QuadPhysics,
    Target,
    eq11_step,
    fit_step_response,
    measure_axes,
    second_order_step,
    step_response,
)

CFG = MockConfig()
QUIET = replace(
    CFG, disturbance=replace(CFG.disturbance, field_amplitude_m_s2=0.0, gust_sigma_m_s2=0.0)
)


def test_hover_is_an_equilibrium() -> None:
    sim = QuadPhysics(QUIET, pos_ned_m=(0.3, -0.2, -2.0))
    sim.command(0.0, Target((0.3, -0.2, -2.0)))
    sim.advance_to(5.0)
    assert sim.t_s == pytest.approx(5.0)
    np.testing.assert_allclose(sim.pos, [0.3, -0.2, -2.0], atol=1e-9)
    np.testing.assert_allclose(sim.vel, [0.0, 0.0, 0.0], atol=1e-9)


def test_disarmed_on_the_ground_stays_there() -> None:
    sim = QuadPhysics(CFG)
    sim.advance_to(2.0)
    assert sim.on_ground and sim.pos == [0.0, 0.0, 0.0]


def test_fit_recovers_a_known_second_order_model() -> None:
    t = np.arange(0, 12, 0.05)
    truth = replace(EQ11, gain=0.9)
    fit = fit_step_response(t, second_order_step(t, truth))
    assert fit.wn_rad_s == pytest.approx(truth.wn_rad_s, rel=1e-3)
    assert fit.zeta == pytest.approx(truth.zeta, rel=1e-3)
    assert fit.gain == pytest.approx(0.9, rel=1e-3)
    assert fit.delay_s == pytest.approx(truth.delay_s, abs=2e-3)


def test_step_response_is_a_fair_but_imperfect_eq11() -> None:
    fx, fy = measure_axes(CFG)
    for fit in (fx, fy):
        assert 0.05 <= abs(fit.wn_rad_s / EQ11.wn_rad_s - 1) <= 0.15
        assert 0.05 <= abs(fit.zeta / EQ11.zeta - 1) <= 0.15
        assert abs(fit.gain / EQ11.gain - 1) <= 0.15
        assert abs(fit.delay_s - EQ11.delay_s) <= 0.05
        assert fit.rms_residual_m < 0.01  # a second-order-plus-delay describes it well
    # the two axes differ
    assert abs(fx.wn_rad_s - fy.wn_rad_s) > 0.1
    # and the whole response stays close to eq. (11)'s
    t, y = step_response(CFG, 0)
    assert np.max(np.abs(y - eq11_step(t))) < 0.15


def _fly_circle(cfg: MockConfig, seed: int) -> np.ndarray:
    """Positions along a slow circle, sampled at 50 Hz for 8 s."""
    sim = QuadPhysics(cfg, seed=seed, pos_ned_m=(0.0, 0.0, -2.0))
    out = []
    for k in range(400):
        t = k * 0.02
        sim.command(t, Target((math.sin(0.5 * t), 1 - math.cos(0.5 * t), -2.0)))
        sim.advance_to(t)
        out.append(list(sim.pos))
    return np.array(out)


def test_disturbance_field_is_repeatable_and_gusts_are_seeded() -> None:
    a, b, c = _fly_circle(CFG, 1), _fly_circle(CFG, 1), _fly_circle(CFG, 2)
    np.testing.assert_array_equal(a, b)  # same seed: identical
    assert np.max(np.abs(a - c)) > 1e-3  # other seed: other gusts
    # without gusts the disturbance is a pure function of the path: identical across seeds
    no_gusts = replace(CFG, disturbance=replace(CFG.disturbance, gust_sigma_m_s2=0.0))
    field_only = _fly_circle(no_gusts, 1)
    np.testing.assert_array_equal(field_only, _fly_circle(no_gusts, 5))
    # and it is really there
    assert np.max(np.abs(field_only - _fly_circle(QUIET, 1))) > 0.005


def test_speed_acceleration_and_tilt_limits_hold() -> None:
    cfg = replace(
        QUIET,
        physics=replace(QUIET.physics, drag_lin_1_s=0.0, drag_quad_1_m=0.0),
        controller=replace(QUIET.controller, vel_max_xy_m_s=2.0, acc_max_xy_m_s2=3.0),
    )
    sim = QuadPhysics(cfg, pos_ned_m=(0.0, 0.0, -2.0))
    sim.command(0.0, Target((30.0, 30.0, -2.0)))
    speeds, accs, tilts = [], [], []
    for k in range(1, 800):
        sim.advance_to(k * 0.01)
        speeds.append(math.hypot(sim.vel[0], sim.vel[1]))
        accs.append(math.hypot(sim.acc[0], sim.acc[1]))
        roll, pitch, *_ = sim.attitude()
        tilts.append(math.degrees(math.acos(math.cos(roll) * math.cos(pitch))))
    assert 1.9 < max(speeds) <= 2.0 * 1.05
    assert max(accs) <= 3.0 + 1e-9
    assert max(tilts) <= cfg.controller.tilt_max_deg


def test_measurement_noise_is_millimetres() -> None:
    sim = QuadPhysics(QUIET, seed=3, pos_ned_m=(1.0, 2.0, -2.0))
    sim.command(0.0, Target((1.0, 2.0, -2.0)))
    err = np.array([np.subtract(sim.measure()[0], sim.pos) for _ in range(2000)])
    assert 0.001 < err.std() < 0.005


def test_profile_defaults_and_errors(tmp_path) -> None:  # type: ignore[no-untyped-def]
    shipped = load_mock_config("profiles/mock.yaml")
    assert shipped == MockConfig()
    bad = tmp_path / "bad.yaml"
    bad.write_text("physics:\n  drag_quad_1_m: fast\n")
    with pytest.raises(ProfileError, match=r"bad\.yaml.*physics\.drag_quad_1_m"):
        load_mock_config(bad)
    bad.write_text("px4:\n  no_such_field: 1\n")
    with pytest.raises(ProfileError, match=r"px4\.no_such_field"):
        load_mock_config(bad)
    bad.write_text("physics: [1, 2\n")
    with pytest.raises(ProfileError, match="malformed YAML"):
        load_mock_config(bad)
    with pytest.raises(ProfileError, match="initial_mode"):
        mock_config_from_dict({"px4": {"initial_mode": "ACRO"}})
    with pytest.raises(ProfileError, match=r"px4\.nav_dll_act.*the actions the mock models"):
        mock_config_from_dict({"px4": {"nav_dll_act": 2}})
    with pytest.raises(ProfileError, match=r"px4\.ekf2_ev_ctrl.*bitmask"):
        mock_config_from_dict({"px4": {"ekf2_ev_ctrl": 16}})
    with pytest.raises(ProfileError, match=r"px4\.ekf2_hgt_ref"):
        mock_config_from_dict({"px4": {"ekf2_hgt_ref": 4}})
