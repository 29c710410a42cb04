"""The mock on external vision only (``profiles/mock-mocap.yaml``), as pure logic.

EKF2 with vision as its only aiding: no local position before the first sample, the estimate
pulled onto the vision at ``EKF2_EV_DELAY``, outliers gated, the position declared invalid
``EKF2_NOAID_TOUT`` after the aiding ended, and the commander's failsafe when that happens in
the air. Times and values are checked against the laws ``gcs.mock.estimator`` documents,
computed here independently.
"""

from __future__ import annotations

import math
import random
from dataclasses import fields, replace
from pathlib import Path

import pytest

from gcs.errors import ProfileError
from gcs.mock.config import MockConfig, VisionConfig, load_mock_config, mock_config_from_dict
from gcs.mock.estimator import EV_MAX_INTERVAL_S, NO_AID_TIMEOUT_S, VisionAidedError
from gcs.mock.vehicle import EV_PREARM_DELAY_S, Failsafe, MavResult, Mode, Vehicle

ROOT = Path(__file__).resolve().parents[1]
VISION = load_mock_config(ROOT / "profiles" / "mock-mocap.yaml")
DT = 0.005  # the vision process's step in the direct tests [s]


def fast(noaid_s: float = 2.0, delay_ms: float = 0.0) -> MockConfig:
    """The vision profile with a low take-off, a quick landing and a short no-aid timeout."""
    px4 = replace(
        VISION.px4,
        mis_takeoff_alt_m=1.0,
        mpc_land_speed_m_s=1.0,
        land_detect_s=0.3,
        com_disarm_land_s=0.5,
        ekf2_noaid_tout_s=noaid_s,
        ekf2_ev_delay_ms=delay_ms,
    )
    return replace(VISION, px4=px4)


def process(cfg: VisionConfig | None = None) -> tuple[VisionAidedError, list[float]]:
    truth = [0.0, 0.0, 0.0]
    return VisionAidedError(cfg or VISION.vision, truth, random.Random(1)), truth


def ready(v: Vehicle, t: float) -> float:
    """Set a global origin and fly the vision past PX4's pre-arm delay; the time after."""
    v.set_origin(47.397742, 8.545594, 488.0)
    return run(v, t, max(t, EV_PREARM_DELAY_S + 0.05))


def run(
    v: Vehicle,
    t0: float,
    t1: float,
    vision: bool = True,
    setpoint: tuple[float, float, float] | None = None,
    rate_hz: float = 50.0,
) -> float:
    """Step the vehicle from t0 to t1; forward its true position at ``rate_hz`` (and setpoints)."""
    t = t0
    while t < t1 - 1e-9:
        t = round(t + 1.0 / rate_hz, 9)
        v.update(t)
        if vision:
            v.on_vision(t, tuple(v.physics.pos))
        if setpoint is not None:
            v.on_setpoint(t, setpoint, 0.0)
    return t


def texts(v: Vehicle) -> list[str]:
    return [text for _, text in v.events]


# -- the profile -------------------------------------------------------------------------------


def test_profile_is_the_indoor_mock_with_vision_only_ekf2_parameters() -> None:
    default = MockConfig()
    assert VISION.vision.enabled and not VISION.estimator.enabled
    for section in ("physics", "controller", "disturbance", "noise", "rates"):
        assert getattr(VISION, section) == getattr(default, section), section
    ekf2 = {"ekf2_gps_ctrl", "ekf2_ev_ctrl", "ekf2_hgt_ref", "ekf2_ev_delay_ms"}
    for f in fields(default.px4):
        if f.name not in ekf2:
            assert getattr(VISION.px4, f.name) == getattr(default.px4, f.name), f.name
    params = Vehicle(VISION).params
    assert params["EKF2_GPS_CTRL"] == 0  # no GPS
    assert params["EKF2_EV_CTRL"] == 1 | 2 | 8  # horizontal and vertical position, yaw
    assert params["EKF2_HGT_REF"] == 3  # vision height
    assert 0 < params["EKF2_EV_DELAY"] <= 20  # a mocap chain, not PX4's camera default 175
    assert params["EKF2_NOAID_TOUT"] == 5_000_000  # PX4's default, in microseconds


def test_the_indoor_default_has_no_vision_and_ignores_it() -> None:
    v = Vehicle(MockConfig())
    assert v.vision is None and v.local_position_valid
    assert v.on_vision(0.1, (1.0, 2.0, 3.0)) is False
    assert v.arm(True) is MavResult.ACCEPTED


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"vision": {"enabled": True}, "estimator": {"enabled": True}}, "vision.enabled"),
        ({"vision": {"time_constant_s": 0.0}}, "vision.time_constant_s"),
        ({"vision": {"innovation_gate_m": -1.0}}, "vision.innovation_gate_m"),
        ({"px4": {"ekf2_ev_delay_ms": 400.0}}, "px4.ekf2_ev_delay_ms"),
        ({"px4": {"ekf2_noaid_tout_s": 0.1}}, "px4.ekf2_noaid_tout_s"),
        ({"vision": {"enabled": "yes"}}, "vision.enabled"),
    ],
)
def test_bad_vision_settings_are_refused_by_name(data: dict, field: str) -> None:
    with pytest.raises(ProfileError, match=field.replace(".", r"\.")):
        mock_config_from_dict(data, "arena.yaml")


# -- the fusion (VisionAidedError alone) -----------------------------------------------------


def test_first_sample_resets_then_the_estimate_follows_with_the_time_constant() -> None:
    ev, truth = process()
    ev.step(DT)
    assert ev.fuse(DT, (0.3, -0.2, 0.1), 0.0, 3) is True  # reset onto the sample
    assert ev.pos_err_m == pytest.approx([0.3, -0.2, 0.1])
    assert ev.events == ["vision fusion started"] and ev.resets == 1
    t, tau, period = DT, VISION.vision.time_constant_s, 0.02
    for _ in range(10):  # the truth is measured exactly from now on, every 20 ms
        for _ in range(4):
            t += DT
            ev.step(DT)
        assert ev.fuse(t, tuple(truth), 0.0, 3) is True
    decay = math.exp(-10 * period / tau)
    assert ev.pos_err_m == pytest.approx([0.3 * decay, -0.2 * decay, 0.1 * decay], abs=1e-9)


def test_a_wrong_ev_delay_leaves_the_velocity_times_the_mismatch() -> None:
    true_delay_s, speed = 0.1, 1.0

    def settle(set_delay_s: float) -> float:
        ev, truth = process()
        t, history = 0.0, []
        for k in range(1, 601):  # 3 s, moving north at 1 m/s, a sample every 20 ms
            t = k * DT
            truth[0] = speed * t
            ev.step(DT)
            history.append((t, truth[0]))
            if k % 4 == 0 and t > true_delay_s:
                seen = speed * (t - true_delay_s)  # the sample is the truth 0.1 s ago
                ev.fuse(t, (seen, 0.0, 0.0), set_delay_s, 3)
        return ev.pos_err_m[0]

    assert settle(true_delay_s) == pytest.approx(0.0, abs=2 * speed * DT)
    # compared with the estimate of now instead of 0.1 s ago: it lags by v * 0.1 s
    assert settle(0.0) == pytest.approx(-speed * true_delay_s, abs=2 * speed * DT)


def test_outliers_are_gated_and_a_persistent_offset_is_reset_onto() -> None:
    ev, truth = process()
    t = DT
    ev.step(DT)
    ev.fuse(t, (0.0, 0.0, 0.0), 0.0, 3)
    gate, reset_after = VISION.vision.innovation_gate_m, VISION.vision.reset_after_s
    outcome = []
    while t < reset_after + 0.1:
        for _ in range(4):
            t = round(t + DT, 9)
            ev.step(DT)
        outcome.append((t, ev.fuse(t, (gate + 0.1, 0.0, 0.0), 0.0, 3)))
    rejected = [s for s, fused in outcome if not fused]
    fused = [s for s, ok in outcome if ok]
    assert rejected[0] == pytest.approx(DT + 4 * DT) and max(rejected) <= DT + reset_after
    assert fused and fused[0] > DT + reset_after  # the first sample past 7 s resets
    assert ev.pos_err_m[0] == pytest.approx(gate + 0.1)
    assert "vision position reset (innovations rejected)" in ev.events


@pytest.mark.parametrize(
    ("ev_ctrl", "xy", "z"), [(1, True, False), (3, True, True), (2, False, True)]
)
def test_ev_ctrl_chooses_the_fused_axes(ev_ctrl: int, xy: bool, z: bool) -> None:
    ev, _ = process()
    ev.step(DT)
    assert ev.fuse(DT, (0.2, 0.2, 0.2), 0.0, ev_ctrl) is True
    assert ev.pos_err_m == pytest.approx([0.2 if xy else 0.0] * 2 + [0.2 if z else 0.0])
    assert ev.xy_valid(DT, 5.0) is xy  # a horizontal position needs the horizontal fusion


def test_nothing_is_fused_without_ev_ctrl_or_with_a_non_finite_sample() -> None:
    ev, _ = process()
    ev.step(DT)
    assert ev.fuse(DT, (0.2, 0.2, 0.2), 0.0, 0) is False
    assert ev.fuse(DT, (math.nan, 0.2, 0.2), 0.0, 11) is False
    assert not ev.xy_valid(DT, 5.0) and ev.fused == 0


def test_the_position_is_invalid_noaid_tout_after_the_aiding_ended() -> None:
    noaid_s, last_s = 5.0, 2.0
    ev, _ = process()
    assert not ev.xy_valid(0.0, noaid_s)  # never before the first sample
    t, k = 0.0, 0
    stopped_at = invalid_at = None
    while t < 8.0:
        k += 1
        t = round(k * DT, 9)
        ev.step(DT)
        if t <= last_s and k % 4 == 0:
            ev.fuse(t, (0.0, 0.0, 0.0), 0.0, 3)
        if stopped_at is None and "vision data stopped" in ev.events:
            stopped_at = t
        if invalid_at is None and t > last_s and not ev.xy_valid(t, noaid_s):
            invalid_at = t
    # EKF2: fusion stops 2 EV_MAX_INTERVAL after the last sample; the aiding time is kept 1 s
    # (no_aid_timeout_max) behind, and the position is invalid EKF2_NOAID_TOUT after it
    assert stopped_at == pytest.approx(last_s + 2 * EV_MAX_INTERVAL_S, abs=1.5 * DT)
    expected = last_s + 2 * EV_MAX_INTERVAL_S - NO_AID_TIMEOUT_S + noaid_s
    assert invalid_at == pytest.approx(expected, abs=1.5 * DT)
    # meanwhile the estimate dead-reckons away with the accelerometer error, a t^2 / 2
    a = VISION.vision.dead_reckoning_accel_m_s2
    drift = math.hypot(ev.pos_err_m[0], ev.pos_err_m[1])
    assert drift == pytest.approx(a * (8.0 - stopped_at) ** 2 / 2, rel=0.02)


def test_rejected_samples_end_the_aiding_one_second_after_the_last_fused_one() -> None:
    noaid_s, last_fused_s = 5.0, 2.0
    ev, _ = process()
    t, k, invalid_at, valid_again_at = 0.0, 0, None, None
    while t < 10.0:
        k += 1
        t = round(k * DT, 9)
        ev.step(DT)
        if k % 4 == 0:
            offset = 0.0 if t <= last_fused_s else 1.0  # beyond the gate from 2 s on
            ev.fuse(t, (offset, 0.0, 0.0), 0.0, 3)
        valid = ev.xy_valid(t, noaid_s)
        if invalid_at is None and t > last_fused_s and not valid:
            invalid_at = t
        if invalid_at is not None and valid_again_at is None and valid:
            valid_again_at = t
    assert invalid_at == pytest.approx(last_fused_s + noaid_s, abs=1.5 * DT)
    assert valid_again_at == pytest.approx(
        last_fused_s + VISION.vision.reset_after_s, abs=4 * DT + 1e-9
    )


# -- the vehicle (commander on the vision) ---------------------------------------------------


def test_without_vision_there_is_no_local_position_and_nothing_to_fly() -> None:
    v = Vehicle(VISION)
    v.update(1.0)
    assert not v.local_position_valid and not v.armable
    assert v.arm(True) is MavResult.TEMPORARILY_REJECTED
    assert "Arming denied: no local position estimate (is vision fused?)" in texts(v)
    for mode in (Mode.HOLD, Mode.TAKEOFF, Mode.OFFBOARD):
        assert not v.can_run(mode), mode
    assert v.arm(True, force=True) is MavResult.ACCEPTED  # forced, as PX4's 21196
    v.update(1.02)
    assert v.takeoff() is MavResult.TEMPORARILY_REJECTED
    assert v.set_mode(Mode.HOLD) is MavResult.TEMPORARILY_REJECTED


def test_with_vision_it_arms_takes_off_and_holds_on_the_vision() -> None:
    v = Vehicle(VISION)
    t = run(v, 0.0, 0.5)
    assert v.local_position_valid and not v.armable  # PX4: checks pass later, with an origin
    assert texts(v)[:2] == ["EKF2: vision fusion started", "Local position estimate valid"]
    t = ready(v, t)
    assert v.armable
    assert v.arm(True) is MavResult.ACCEPTED and v.takeoff() is MavResult.ACCEPTED
    t = run(v, t, t + 8.0)
    assert v.mode is Mode.HOLD and not v.landed
    ph = v.physics
    assert ph.pos[2] == pytest.approx(-VISION.px4.mis_takeoff_alt_m, abs=0.05)
    assert max(abs(n - p) for n, p in zip(ph.nav_pos, ph.pos, strict=True)) < 0.01


def test_vision_lost_in_offboard_descends_without_position_lands_and_disarms() -> None:
    cfg = fast(noaid_s=2.0)
    v = Vehicle(cfg)
    t = ready(v, run(v, 0.0, 0.3))
    assert v.arm(True) is MavResult.ACCEPTED
    v.takeoff()
    t = run(v, t, t + 4.0)
    sp = (0.5, 0.0, -1.0)
    t = run(v, t, t + 0.5, setpoint=sp)
    assert v.set_mode(Mode.OFFBOARD) is MavResult.ACCEPTED
    t = run(v, t, t + 3.0, setpoint=sp)
    assert v.mode is Mode.OFFBOARD and v.local_position_valid
    last_vision = t
    failsafe_at = level_at = landed_at = disarmed_at = None
    while t < last_vision + 10.0 and disarmed_at is None:
        t = run(v, t, t + 0.005, vision=False, setpoint=sp, rate_hz=200.0)
        if failsafe_at is None and v.mode is Mode.LAND:
            failsafe_at = t
        if level_at is None and not v.physics.target.hold_xy:
            level_at = t  # Descend: no horizontal control (after the input delay)
        if landed_at is None and v.landed:
            landed_at = t
        if disarmed_at is None and not v.armed:
            disarmed_at = t
    expected = last_vision + 2 * EV_MAX_INTERVAL_S - NO_AID_TIMEOUT_S + 2.0
    assert failsafe_at == pytest.approx(expected, abs=0.011)
    assert "Failsafe activated: no local position, descending" in texts(v)
    assert level_at == pytest.approx(failsafe_at + cfg.physics.input_delay_s, abs=0.011)
    assert landed_at is not None and disarmed_at is not None
    # 1 m at MPC_LAND_SPEED 1 m/s, the land detector, then COM_DISARM_LAND
    assert landed_at - failsafe_at < 1.0 / 1.0 + 0.3 + 1.0
    assert disarmed_at - landed_at == pytest.approx(0.5, abs=0.02)
    # the setpoints kept coming: the vehicle did not go back to OFFBOARD on its own
    log = [(m.mode, m.armed) for m in v.mode_log]
    after = log[log.index(("LAND", True)) :]
    assert {mode for mode, armed in after if armed} == {"LAND"}


def test_vision_lost_on_the_ground_takes_no_failsafe_and_refuses_arming_again() -> None:
    v = Vehicle(fast(noaid_s=1.0))
    t = ready(v, run(v, 0.0, 0.5))
    assert v.arm(True) is MavResult.ACCEPTED and v.arm(False) is MavResult.ACCEPTED
    t = run(v, t, t + 2.0, vision=False)
    assert not v.local_position_valid and v.failsafe is Failsafe.NONE and v.mode is Mode.HOLD
    assert v.arm(True) is MavResult.TEMPORARILY_REJECTED
    run(v, t, t + 0.1)  # vision back: fusion restarts, arming allowed
    assert v.local_position_valid and v.arm(True) is MavResult.ACCEPTED
