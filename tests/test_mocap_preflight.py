"""EKF2's vision settings judged for a flight on motion capture (pure)."""

from __future__ import annotations

import pytest

from gcs.flight.mocap.preflight import ekf2_findings, ev_noise_granted

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


@pytest.mark.parametrize(
    ("evp", "mode", "std", "granted"),
    [
        (0.1, 0, 0.005, 0.1),  # PX4's default: the parameter bounds the 5 mm sent from below
        (0.01, 0, 0.005, 0.01),  # PX4's smallest: 1 cm, whatever is sent
        (0.01, 0, 0.05, 0.05),  # a noisier mocap said so: the message's
        (0.02, 1, 0.005, 0.02),  # noise mode 1: the parameter alone
        (0.001, 1, 0.005, 0.01),  # ... never below 1 cm
    ],
)
def test_the_noise_ekf2_grants_a_pose_is_the_largest_bound(evp, mode, std, granted) -> None:
    params = {"EKF2_EVP_NOISE": evp, "EKF2_EV_NOISE_MD": mode}
    assert ev_noise_granted(params, std) == granted


def test_px4_s_default_vision_noise_warns_with_the_fix_only_when_gcs_forwards() -> None:
    default = {**INDOOR, "EKF2_EVP_NOISE": 0.1}
    warned = [f.text for f in ekf2_findings(default, True) if f.level == "warning"]
    assert len(warned) == 1 and warned[0].startswith("EKF2_EVP_NOISE = 0.1 m")
    assert "0.1 m noisy (gcs sends 0.005 m)" in warned[0] and "to 0.01" in warned[0]
    assert levels(default, forward=False) == ["info"]  # another bridge: its covariance unknown
    # within twice what gcs sends (at least 1 cm): nothing to say; unread: not judged
    for evp in (0.01, 0.02):
        assert levels({**INDOOR, "EKF2_EVP_NOISE": evp}) == ["info"]
    assert ev_noise_granted(INDOOR) is None and levels(INDOOR) == ["info"]
    # a mocap sent as 3 cm noisy: 0.05 m is within twice that, 0.07 m is not
    assert [f.level for f in ekf2_findings(default | {"EKF2_EVP_NOISE": 0.05}, True,
                                           position_std_m=0.03)] == ["info"]  # fmt: skip
    assert "warning" in [f.level for f in ekf2_findings(default | {"EKF2_EVP_NOISE": 0.07}, True,
                                                        position_std_m=0.03)]  # fmt: skip
