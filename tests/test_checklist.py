"""The real-vehicle checklist: every row judged ok, warn or refuse, with the fix named."""

from __future__ import annotations

import pytest

from gcs.flight.checklist import checklist, checklist_lines, judge, refusal
from gcs.flight.mocap.preflight import ekf2_findings

GOOD_GPS = {
    "EKF2_GPS_CTRL": 7, "EKF2_HGT_REF": 1, "EKF2_EV_CTRL": 0, "NAV_DLL_ACT": 3,
    "COM_OBL_RC_ACT": 4, "COM_OF_LOSS_T": 1.0, "COM_RC_IN_MODE": 0, "COM_RC_OVERRIDE": 3,
    "GF_ACTION": 5,
}  # fmt: skip
GOOD_MOCAP = GOOD_GPS | {
    "EKF2_GPS_CTRL": 0, "EKF2_HGT_REF": 3, "EKF2_EV_CTRL": 15, "EKF2_EV_DELAY": 5.0,
    "EKF2_MAG_TYPE": 5, "EKF2_BARO_CTRL": 1, "EKF2_EVP_NOISE": 0.01,
}  # fmt: skip


@pytest.mark.parametrize(("navigation", "params"), [("gps", GOOD_GPS), ("mocap", GOOD_MOCAP)])
def test_the_advised_values_are_all_ok(navigation, params) -> None:
    verdicts = judge(params, navigation)
    assert [v.param for v in verdicts] == [i.param for i in checklist(navigation)]
    assert {v.level for v in verdicts} == {"ok"} and refusal(verdicts) is None
    for item in checklist(navigation):
        assert item.advised and item.why  # every row says what and why


def test_px4_defaults_warn_on_link_loss_offboard_loss_and_takeover() -> None:
    # PX4 v1.16's defaults: NAV_DLL_ACT 0, COM_OBL_RC_ACT 0, COM_RC_IN_MODE 3, COM_RC_OVERRIDE 1
    defaults = GOOD_GPS | {"NAV_DLL_ACT": 0, "COM_OBL_RC_ACT": 0, "COM_RC_OVERRIDE": 1}
    levels = {v.param: v.level for v in judge(defaults, "gps")}
    assert levels["NAV_DLL_ACT"] == levels["COM_OBL_RC_ACT"] == "warn"
    assert levels["COM_RC_OVERRIDE"] == "warn" and levels["COM_RC_IN_MODE"] == "ok"


def test_px4_defaults_on_mocap_warn_as_the_flight_s_own_check_does() -> None:
    # PX4 v1.16's EKF2_EVP_NOISE 0.1 m; the barometer turned off as some labs do
    defaults = GOOD_MOCAP | {"EKF2_EVP_NOISE": 0.1, "EKF2_BARO_CTRL": 0}
    rows = {v.param: v for v in judge(defaults, "mocap")}
    assert rows["EKF2_EVP_NOISE"].level == rows["EKF2_BARO_CTRL"].level == "warn"
    assert "set EKF2_EVP_NOISE to 0.01" in rows["EKF2_EVP_NOISE"].note
    assert "EKF2_BARO_CTRL 1" in rows["EKF2_BARO_CTRL"].note
    flight = {f.text for f in ekf2_findings(defaults, forward=True) if f.level == "warning"}
    assert {rows["EKF2_EVP_NOISE"].note, rows["EKF2_BARO_CTRL"].note} <= flight  # one source


def test_vision_not_fused_with_mocap_is_refused_with_the_fix() -> None:
    verdicts = judge(GOOD_MOCAP | {"EKF2_EV_CTRL": 0}, "mocap")
    row = next(v for v in verdicts if v.param == "EKF2_EV_CTRL")
    assert row.level == "refuse" and "set EKF2_EV_CTRL to 15" in row.note
    assert "EKF2_EV_CTRL" in refusal(verdicts)
    # the same judgement as the flight's own pre-flight check: one source
    findings = ekf2_findings({n: GOOD_MOCAP[n] for n in ("EKF2_HGT_REF", "EKF2_GPS_CTRL",
                             "EKF2_EV_DELAY")} | {"EKF2_EV_CTRL": 0}, forward=True)  # fmt: skip
    assert any(f.level == "refuse" and f.text == row.note for f in findings)


def test_gps_flight_without_gps_is_refused_and_unread_params_warn() -> None:
    verdicts = judge({"EKF2_GPS_CTRL": 0}, "gps")
    assert verdicts[0].level == "refuse" and "set EKF2_GPS_CTRL to 7" in verdicts[0].note
    unread = [v for v in verdicts if v.found is None]
    assert unread and all(v.level == "warn" and "could not read" in v.note for v in unread)
    lines = checklist_lines(verdicts)
    assert lines[0].startswith("refuse EKF2_GPS_CTRL: found 0, advised 7")
    assert any(line.startswith("warn   NAV_DLL_ACT: found not read") for line in lines)


def test_an_unknown_navigation_is_refused() -> None:
    with pytest.raises(ValueError, match="gps, mocap"):
        checklist("optical flow")
