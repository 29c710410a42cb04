"""Mock drone commander as pure logic: PX4's arming, offboard and landing rules."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from gcs.mock.cli import faults_cli_args
from gcs.mock.config import Faults, MockConfig
from gcs.mock.vehicle import (
    FAILSAFES,
    Failsafe,
    LandedState,
    MavResult,
    Mode,
    Vehicle,
    decode_param,
    encode_param,
)

CFG = MockConfig()


def airborne(t_end_s: float = 5.0) -> Vehicle:
    v = Vehicle(CFG)
    assert v.arm(True) is MavResult.ACCEPTED
    assert v.takeoff() is MavResult.ACCEPTED
    v.update(t_end_s)
    assert v.mode is Mode.HOLD and not v.landed
    return v


def stream(v: Vehicle, t0: float, t1: float, pos=(1.0, 0.0, -2.5)) -> None:
    t = t0
    while t < t1:
        v.update(t)
        v.on_setpoint(t, pos, 0.0)
        t += 0.02


def test_boots_disarmed_in_hold_on_the_ground() -> None:
    v = Vehicle(CFG)
    assert not v.armed and v.mode is Mode.HOLD and v.landed_state is LandedState.ON_GROUND
    assert v.armable
    assert Vehicle(replace(CFG, px4=replace(CFG.px4, initial_mode="POSCTL"))).mode is Mode.POSCTL


def test_takeoff_climbs_to_mis_takeoff_alt_then_holds() -> None:
    v = Vehicle(CFG)
    v.arm(True)
    v.takeoff()
    v.update(0.5)
    assert v.mode is Mode.TAKEOFF
    v.update(6.0)
    assert v.mode is Mode.HOLD and v.landed_state is LandedState.IN_AIR
    assert abs(v.physics.pos[2] + CFG.px4.mis_takeoff_alt_m) < 0.15


def test_offboard_refused_without_setpoints_accepted_with_a_stream() -> None:
    v = airborne()
    assert v.set_mode(Mode.OFFBOARD) is MavResult.TEMPORARILY_REJECTED
    assert v.mode is Mode.HOLD
    v.on_setpoint(v.t_s, (0.0, 0.0, -2.5), 0.0)
    assert v.set_mode(Mode.OFFBOARD) is MavResult.ACCEPTED
    assert v.mode is Mode.OFFBOARD and v.first_offboard_t_s is not None


def test_stale_stream_is_refused_and_min_stream_is_honoured() -> None:
    v = airborne()
    v.on_setpoint(v.t_s, (0.0, 0.0, -2.5), 0.0)
    v.update(v.t_s + CFG.px4.com_of_loss_t_s + 0.1)
    assert v.set_mode(Mode.OFFBOARD) is MavResult.TEMPORARILY_REJECTED
    cfg = replace(CFG, px4=replace(CFG.px4, offboard_min_stream_s=0.5))
    w = Vehicle(cfg)
    w.arm(True)
    w.takeoff()
    w.update(5.0)
    stream(w, 5.0, 5.2)
    assert w.set_mode(Mode.OFFBOARD) is MavResult.TEMPORARILY_REJECTED
    stream(w, 5.2, 5.7)
    assert w.set_mode(Mode.OFFBOARD) is MavResult.ACCEPTED


def test_offboard_loss_falls_back_to_hold_after_com_of_loss_t_and_resumes() -> None:
    v = airborne()
    stream(v, 5.0, 6.0)
    assert v.set_mode(Mode.OFFBOARD) is MavResult.ACCEPTED
    stream(v, 6.0, 8.0)
    last = v.last_setpoint_t_s
    v.update(last + CFG.px4.com_of_loss_t_s - 0.05)
    assert v.mode is Mode.OFFBOARD
    v.update(last + CFG.px4.com_of_loss_t_s + 0.05)
    assert v.mode is Mode.HOLD and v.failsafe is Failsafe.OFFBOARD_LOSS and v.armed
    held = list(v.physics.pos)
    v.update(v.t_s + 3.0)
    assert abs(v.physics.pos[0] - held[0]) < 0.3  # holds where it was
    stream(v, v.t_s, v.t_s + 0.1)  # setpoints come back: PX4 resumes offboard
    assert v.mode is Mode.OFFBOARD and v.failsafe is Failsafe.NONE


def test_land_then_auto_disarm_and_mode_after_disarm() -> None:
    v = airborne()
    stream(v, 5.0, 5.5)
    v.set_mode(Mode.OFFBOARD)
    stream(v, 5.5, 6.0)
    assert v.arm(False) is MavResult.TEMPORARILY_REJECTED  # not in the air
    assert v.land() is MavResult.ACCEPTED
    v.update(6.5)
    assert v.landed_state is LandedState.LANDING
    t = 6.5
    while not v.landed and t < 20:
        t += 0.1
        v.update(t)
    assert v.landed and v.armed and v.landed_state is LandedState.ON_GROUND
    v.update(t + CFG.px4.com_disarm_land_s + 0.05)
    assert not v.armed
    # PX4 returns to the operator's last armable mode (OFFBOARD in the SIH capture) ...
    assert v.mode is Mode.OFFBOARD
    # ... where arming is refused without setpoints
    assert not v.armable and v.arm(True) is MavResult.TEMPORARILY_REJECTED
    assert any(text == "Disarmed by landing" for _, text in v.events)


def test_arming_rules() -> None:
    v = airborne()
    assert v.arm(True) is MavResult.ACCEPTED  # already armed: no change
    assert v.arm(False, force=True) is MavResult.ACCEPTED and not v.armed  # kill in the air
    w = Vehicle(CFG)
    w.arm(True)
    w.update(CFG.px4.com_disarm_prflt_s + 0.1)
    assert not w.armed  # preflight auto-disarm


def test_params_bytewise_and_effective() -> None:
    v = Vehicle(CFG)
    idx, ptype, value = v.params.get("COM_RC_IN_MODE")
    assert ptype == 6 and value == 1.0
    assert decode_param(encode_param(7, 6), 6) == 7.0
    assert v.params.set("MIS_TAKEOFF_ALT", 1.5) is not None
    v.arm(True)
    v.takeoff()
    v.update(6.0)
    assert abs(v.physics.pos[2] + 1.5) < 0.15
    assert v.params.get("NO_SUCH") is None and v.params.names == sorted(v.params.names)


def test_ekf2_params_default_to_the_sih_capture_and_come_from_the_profile() -> None:
    from px4_data import capture

    captured = capture().params  # PX4 v1.16 SIH as MAVSDK read it
    v = Vehicle(CFG)
    for name in ("EKF2_GPS_CTRL", "EKF2_HGT_REF"):
        _, ptype, value = v.params.get(name)
        assert ptype == 6 and value == captured[name]
    assert v.params.get("EKF2_EV_CTRL")[2] == 0.0  # PX4's default (not read in the capture)
    vision = replace(CFG.px4, ekf2_gps_ctrl=0, ekf2_ev_ctrl=15, ekf2_hgt_ref=3)
    w = Vehicle(replace(CFG, px4=vision))
    assert [w.params[n] for n in ("EKF2_GPS_CTRL", "EKF2_EV_CTRL", "EKF2_HGT_REF")] == [0, 15, 3]


DL_LOSS_T_S = 2.0


def heard_until(action: int, t_last_s: float) -> Vehicle:
    """Airborne in OFFBOARD with ``NAV_DLL_ACT = action``; GCS heartbeats at 1 Hz until t_last."""
    cfg = replace(CFG, px4=replace(CFG.px4, nav_dll_act=action, com_dl_loss_t_s=DL_LOSS_T_S))
    v = Vehicle(cfg)
    v.arm(True)
    v.takeoff()
    t = 0.0
    while t <= t_last_s:
        v.update(t)
        v.on_gcs_heartbeat(t)
        t += 1.0
    stream(v, t_last_s, t_last_s + 0.5)
    assert v.set_mode(Mode.OFFBOARD) is MavResult.ACCEPTED
    return v


def test_data_link_loss_with_nav_dll_act_3_lands_and_disarms() -> None:
    v = heard_until(3, 6.0)
    stream(v, v.t_s, 6.0 + DL_LOSS_T_S - 0.05)  # setpoints still arrive, heartbeats do not
    assert v.mode is Mode.OFFBOARD and not v.data_link_lost
    stream(v, v.t_s, 6.0 + DL_LOSS_T_S + 0.05)
    assert v.mode is Mode.LAND and v.data_link_lost
    stream(v, v.t_s, v.t_s + 1.0)  # the setpoints do not take it back: it keeps landing
    assert v.mode is Mode.LAND
    v.update(v.t_s + 10.0)
    assert v.landed and not v.armed
    assert any("no connection to ground control, landing" in text for _, text in v.events)


def test_data_link_loss_with_nav_dll_act_1_holds_until_the_link_returns() -> None:
    v = heard_until(1, 6.0)
    stream(v, v.t_s, 6.0 + DL_LOSS_T_S + 0.05)
    assert v.mode is Mode.HOLD and v.failsafe is Failsafe.DATA_LINK_LOSS and v.data_link_lost
    stream(v, v.t_s, v.t_s + 1.0)  # setpoints alone do not end a data-link failsafe
    assert v.mode is Mode.HOLD
    v.on_gcs_heartbeat(v.t_s)
    stream(v, v.t_s, v.t_s + 0.1)
    assert v.mode is Mode.OFFBOARD and v.failsafe is Failsafe.NONE and not v.data_link_lost


def test_data_link_loss_with_the_px4_default_changes_nothing() -> None:
    v = heard_until(0, 6.0)
    stream(v, v.t_s, 6.0 + 3 * DL_LOSS_T_S)
    assert v.mode is Mode.OFFBOARD and v.armed and v.data_link_lost


def test_no_failsafe_before_a_ground_station_was_ever_heard() -> None:
    cfg = replace(CFG, px4=replace(CFG.px4, nav_dll_act=3, com_dl_loss_t_s=DL_LOSS_T_S))
    v = Vehicle(cfg)
    v.arm(True)
    v.takeoff()
    v.update(20.0)
    assert v.mode is Mode.HOLD and v.armed and not v.data_link_lost


def test_the_failsafe_table_says_how_each_failsafe_ends() -> None:
    assert set(FAILSAFES) == set(Failsafe)
    resuming = {f for f, rule in FAILSAFES.items() if rule.resumes}
    assert resuming == {Failsafe.OFFBOARD_LOSS, Failsafe.DATA_LINK_LOSS}
    assert {f for f, rule in FAILSAFES.items() if not rule.operator_ends} == {Failsafe.NO_POSITION}
    assert max(FAILSAFES, key=lambda f: FAILSAFES[f].severity) is Failsafe.NO_POSITION


def test_a_geofence_hold_outranks_the_data_link_hold_and_ends_with_the_operator() -> None:
    cfg = replace(
        CFG, px4=replace(CFG.px4, gf_action=2, gf_max_hor_dist_m=3.0, nav_dll_act=1,
                         com_dl_loss_t_s=5.0),
    )  # fmt: skip
    v = Vehicle(cfg)
    v.arm(True)
    v.takeoff()
    t = 0.0
    while t <= 6.0:
        v.update(t)
        v.on_gcs_heartbeat(t)
        t += 1.0
    stream(v, 6.0, 6.5, pos=(0.0, 0.0, -2.5))
    assert v.set_mode(Mode.OFFBOARD) is MavResult.ACCEPTED
    far = (6.0, 0.0, -2.5)  # twice GF_MAX_HOR_DIST from home
    stream(v, v.t_s, 6.0 + 5.0 - 0.2, pos=far)  # the heartbeats stopped at 6 s
    assert v.mode is Mode.HOLD and v.failsafe is Failsafe.GEOFENCE_HOLD and v.gf_breaches
    assert not v.data_link_lost
    stream(v, v.t_s, v.t_s + 1.0, pos=far)  # the link lost: its Hold, less severe, gives way
    assert v.data_link_lost and v.failsafe is Failsafe.GEOFENCE_HOLD and v.mode is Mode.HOLD
    v.on_gcs_heartbeat(v.t_s)
    stream(v, v.t_s, v.t_s + 1.0, pos=far)  # link and setpoints back: a geofence Hold stays
    assert v.mode is Mode.HOLD and v.failsafe is Failsafe.GEOFENCE_HOLD
    assert v.set_mode(Mode.OFFBOARD) is MavResult.ACCEPTED  # the operator takes over
    assert v.mode is Mode.OFFBOARD and v.failsafe is Failsafe.NONE


def test_clock_rate_is_a_fault_of_the_run_passed_on_the_command_line() -> None:
    assert faults_cli_args(Faults(clock_rate=0.9)) == ["--clock-rate", "0.9"]
    assert faults_cli_args(Faults()) == []
    for rate in (0.0, 0.05, 11.0):
        with pytest.raises(ValueError, match="clock rate"):
            Faults(clock_rate=rate)


# -- the geofence (gcs.mock.geofence) and the estimator faults ------------------------------


def fenced(action: int, faults=()) -> Vehicle:  # noqa: ANN001
    """In OFFBOARD at (0, 0, -2.5), a 9 m square fence stored, ``GF_ACTION = action``."""
    from test_mock_geofence import square

    v = Vehicle(CFG, faults=faults)
    assert v.params.set("GF_ACTION", encode_param(action, 6)) is not None
    v.fence_stored(square(4.5))
    v.arm(True)
    v.takeoff()
    v.update(5.0)
    stream(v, 5.0, 5.5, pos=(0.0, 0.0, -2.5))
    assert v.set_mode(Mode.OFFBOARD) is MavResult.ACCEPTED
    return v


@pytest.mark.parametrize(("action", "mode"), [(1, Mode.OFFBOARD), (2, Mode.HOLD), (5, Mode.LAND)])
def test_a_breach_of_the_estimate_takes_gf_action(action: int, mode: Mode) -> None:
    from gcs.mock.estimator import PositionJump

    jump = PositionJump(7.0, None, (0.0, 6.0, 0.0))  # 7 s after arming, 6 m east
    v = fenced(action, [jump])
    stream(v, 5.5, 6.9, pos=(0.0, 0.0, -2.5))
    assert v.mode is Mode.OFFBOARD and not v.gf_breaches
    stream(v, 6.9, 7.3, pos=(0.0, 0.0, -2.5))  # the setpoints keep coming
    assert v.mode is mode
    (breach,) = v.gf_breaches
    assert breach["kinds"] == ["fence"] and breach["action"] == action
    assert 7.0 <= breach["t_vehicle_s"] - v.first_armed_t_s <= 7.0 + 0.2 + CFG.physics.dt_s
    texts = [text for _, text in v.events]
    assert "Geofence: approaching or outside geofence" in texts and "Failsafe activated" in texts
    if action == 5:  # Land is taken again while outside; a mode change does not escape it
        assert v.set_mode(Mode.HOLD) is MavResult.ACCEPTED
        stream(v, v.t_s, v.t_s + 0.3, pos=(0.0, 0.0, -2.5))
        assert v.mode is Mode.LAND
    if (
        action == 2
    ):  # the operator may take over Hold, and the setpoints do not resume by themselves
        stream(v, v.t_s, v.t_s + 2.0, pos=(0.0, 0.0, -2.5))
        assert v.mode is Mode.HOLD
        assert v.set_mode(Mode.OFFBOARD) is MavResult.ACCEPTED
        stream(v, v.t_s, v.t_s + 0.3, pos=(0.0, 0.0, -2.5))
        assert v.mode is Mode.OFFBOARD and len(v.gf_breaches) == 1  # one breach, one action


def test_no_breach_action_without_gf_action_and_arming_is_refused_outside() -> None:
    from test_mock_geofence import square

    from gcs.mock.estimator import PositionJump

    v = fenced(0, [PositionJump(7.0, None, (0.0, 6.0, 0.0))])
    stream(v, 5.5, 8.0, pos=(0.0, 0.0, -2.5))
    assert v.mode is Mode.OFFBOARD and not v.gf_breaches  # GF_ACTION 0: no check at all
    w = Vehicle(CFG)
    w.fence_stored(square(4.5))
    assert w.armable
    w.home_ned_m = (0.0, 0.0, 0.0)
    w.physics.pos[1] = 6.0  # carried out of the fence on the ground
    w.update(0.3)
    assert not w.armable and w.arm(True) is MavResult.TEMPORARILY_REJECTED
    texts = [text for _, text in w.events]
    assert "Geofence: approaching or outside geofence" in texts
    assert "Arming denied: Resolve system health failures first" in texts


def test_estimator_faults_count_from_the_first_arming() -> None:
    from gcs.mock.estimator import PositionDrift

    drift = PositionDrift(1.0, 2.0, (0.0, 1.0, 0.0))
    v = Vehicle(CFG, faults=[drift])
    v.update(5.0)  # on the ground, disarmed: nothing yet, whatever the time
    assert drift.onset_s is None and v.physics.nav_pos == v.physics.pos
    v.arm(True)
    assert drift.onset_s == pytest.approx(v.t_s + 1.0)
    v.update(v.t_s + 2.0)
    assert drift.pos_err_m[1] == pytest.approx(1.0, abs=0.01)
    assert v.physics.nav_pos[1] == pytest.approx(v.physics.pos[1] + drift.pos_err_m[1])


def test_estimator_faults_are_passed_on_the_command_line() -> None:
    from gcs.mock.cli import estimator_faults

    faults = Faults(
        drift_start_s=1.0, drift_duration_s=None, drift_ned_m_s=(0.0, 3.0, 0.0),
        divergence_start_s=0.3, divergence_duration_s=4.0, divergence_ned_m_s2=(0.0, 0.0, 2.0),
        jump_at_s=9.0, jump_ned_m=(0.0, 6.0, 0.0),
    )  # fmt: skip
    args = faults_cli_args(faults)
    assert args == [
        "--drift", "1.0:inf:0.0:3.0:0.0", "--divergence", "0.3:4.0:0.0:0.0:2.0",
        "--jump", "9.0:0.0:6.0:0.0",
    ]  # fmt: skip
    options = dict(zip(args[::2], args[1::2], strict=True))
    back = estimator_faults(options["--drift"], options["--divergence"], options["--jump"])
    assert Faults(**back) == faults
    with pytest.raises(ValueError, match="jump needs both"):
        Faults(jump_at_s=1.0)
    with pytest.raises(ValueError, match="three finite numbers"):
        Faults(drift_start_s=1.0, drift_ned_m_s=(0.0, float("nan"), 0.0))
    with pytest.raises(ValueError, match="drift_duration_s"):
        Faults(drift_start_s=1.0, drift_duration_s=-1.0, drift_ned_m_s=(0.0, 1.0, 0.0))


def _indoor() -> Vehicle:
    from gcs.mock.config import load_mock_config

    return Vehicle(
        load_mock_config(Path(__file__).resolve().parents[1] / "profiles" / "mock-mocap.yaml")
    )


def _vision(v: Vehicle, t0: float, t1: float, north: bool = True) -> None:
    t = t0
    while t < t1:
        v.update(t)
        v.on_vision(t, (0.0, 0.0, 0.0), north)
        t += 0.02


def test_on_vision_only_arming_waits_for_px4s_delay_an_origin_and_a_north_heading() -> None:
    from gcs.mock.vehicle import EV_PREARM_DELAY_S

    v = _indoor()
    assert v.origin is None and int(v.params["EKF2_MAG_TYPE"]) == 5
    _vision(v, 0.0, 1.0)
    assert v.local_position_valid and v.navigation_problem() == "horizontal position unstable"
    assert v.arm(True) is MavResult.TEMPORARILY_REJECTED
    texts = [t for _, t in v.events]
    assert "Preflight Fail: horizontal position unstable" in texts
    assert "Arming denied: Resolve system health failures first" in texts
    _vision(v, 1.0, EV_PREARM_DELAY_S + 0.1)
    assert v.navigation_problem() == "No valid global position estimate" and not v.armable
    assert v.set_origin(47.0, 8.0, 400.0) and not v.set_origin(1.0, 1.0, 1.0)  # the first stays
    assert v.armable and v.arm(True) is MavResult.ACCEPTED
    assert v.global_position((0.0, 0.0, 0.0)) == pytest.approx((47.0, 8.0, 400.0))


def test_vision_in_a_relative_frame_never_aligns_the_heading_to_north() -> None:
    v = _indoor()
    v.set_origin(47.0, 8.0, 400.0)
    _vision(v, 0.0, 10.0, north=False)
    assert v.navigation_problem() == "No valid global position estimate"
    assert v.arm(True) is MavResult.TEMPORARILY_REJECTED


def test_with_gps_origin_and_heading_are_there_from_the_start() -> None:
    v = Vehicle(CFG)
    assert v.origin is not None and v.navigation_problem() is None and v.armable
