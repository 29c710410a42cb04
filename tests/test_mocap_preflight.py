"""EKF2's vision settings judged for a flight on motion capture (pure)."""

from __future__ import annotations

from gcs.flight.mocap.preflight import ekf2_findings

INDOOR = {"EKF2_EV_CTRL": 15, "EKF2_HGT_REF": 3, "EKF2_GPS_CTRL": 0, "EKF2_EV_DELAY": 5.0}


def levels(params: dict, forward: bool = True) -> list[str]:
    return [f.level for f in ekf2_findings(params, forward)]


def test_an_indoor_vision_setup_is_only_reported() -> None:
    findings = ekf2_findings(INDOOR, True)
    assert [f.level for f in findings] == ["info"]
    assert "EV_CTRL 15" in findings[0].text and "EV_DELAY 5 ms" in findings[0].text


def test_vision_not_fused_is_refused_when_gcs_forwards_and_warned_otherwise() -> None:
    params = dict(INDOOR, EKF2_EV_CTRL=0)
    assert "refuse" in levels(params, True)
    assert "refuse" not in levels(params, False) and "warning" in levels(params, False)
    text = [f.text for f in ekf2_findings(params, True) if f.level == "refuse"][0]
    assert "EKF2_EV_CTRL" in text and "15" in text  # the fix is named


def test_gps_height_reference_without_gps_is_refused_naming_vision() -> None:
    findings = ekf2_findings(dict(INDOOR, EKF2_HGT_REF=1), True)
    refused = [f.text for f in findings if f.level == "refuse"]
    assert refused and "EKF2_HGT_REF to 3" in refused[0]
    # with GPS fused the GPS height is consistent (only GPS alongside vision is a warning)
    assert levels(dict(INDOOR, EKF2_HGT_REF=1, EKF2_GPS_CTRL=7)) == ["info", "warning"]


def test_vision_height_reference_needs_the_height_bit() -> None:
    assert "refuse" in levels(dict(INDOOR, EKF2_EV_CTRL=1))


def test_barometer_gps_alongside_and_a_long_delay_are_warnings() -> None:
    assert levels(dict(INDOOR, EKF2_HGT_REF=0)) == ["info", "warning"]
    assert levels(dict(INDOOR, EKF2_GPS_CTRL=7)) == ["info", "warning"]
    assert levels(dict(INDOOR, EKF2_EV_DELAY=175.0)) == ["info", "warning"]


def test_unreadable_parameters_are_named() -> None:
    findings = ekf2_findings({"EKF2_EV_CTRL": 15}, True)
    assert any("EKF2_HGT_REF" in f.text and f.level == "warning" for f in findings)


def test_odometry_without_a_heading_source_is_refused_naming_the_message() -> None:
    no_mag = {**INDOOR, "EKF2_MAG_TYPE": 5}
    findings = ekf2_findings(no_mag, True, "odometry")
    refused = [f.text for f in findings if f.level == "refuse"]
    assert len(refused) == 1 and "vision_position_estimate" in refused[0]
    assert [f.level for f in ekf2_findings(no_mag, True, "vision_position_estimate")] == ["info"]
    with_mag = {**INDOOR, "EKF2_MAG_TYPE": 0}
    assert [f.level for f in ekf2_findings(with_mag, True, "odometry")] == ["info"]
    gps_heading = {**no_mag, "EKF2_GPS_CTRL": 8}
    assert "refuse" not in [f.level for f in ekf2_findings(gps_heading, True, "odometry")]
    assert "refuse" not in [f.level for f in ekf2_findings(no_mag, False, "odometry")]


def test_no_barometer_without_gps_is_a_warning_naming_the_landing() -> None:
    found = ekf2_findings({**INDOOR, "EKF2_BARO_CTRL": 0}, True)
    warned = [f.text for f in found if f.level == "warning"]
    assert len(warned) == 1 and "EKF2_BARO_CTRL 1" in warned[0] and "landing" in warned[0]
    assert [f.level for f in ekf2_findings({**INDOOR, "EKF2_BARO_CTRL": 1}, True)] == ["info"]
