"""What gcs says before take-off: the link-loss action and the navigation source."""

from __future__ import annotations

import pytest

from gcs.flight.preflight import NAV_DLL_ACT_NAMES, link_loss_warnings, navigation_source


@pytest.mark.parametrize("action", [0, 1])
def test_an_action_that_leaves_the_vehicle_hovering_is_one_warning(action: int) -> None:
    (line,) = link_loss_warnings({"NAV_DLL_ACT": action})
    assert f"NAV_DLL_ACT = {action} ({NAV_DLL_ACT_NAMES[action]})" in line
    assert "hovers in Hold" in line and "3 (Land)" in line
    assert "\n" not in line


@pytest.mark.parametrize("action", [2, 3, 5, 6])
def test_an_action_that_ends_the_flight_needs_no_warning(action: int) -> None:
    assert link_loss_warnings({"NAV_DLL_ACT": action}) == []


def test_no_answer_and_unknown_values_are_said() -> None:
    assert "could not read NAV_DLL_ACT" in link_loss_warnings({"NAV_DLL_ACT": None})[0]
    assert "could not read" in link_loss_warnings({})[0]
    assert "not a PX4 data-link-loss action" in link_loss_warnings({"NAV_DLL_ACT": 4})[0]


def nav(gps: int | None, ev: int | None, hgt: int | None = 1):  # type: ignore[no-untyped-def]
    return navigation_source({"EKF2_GPS_CTRL": gps, "EKF2_EV_CTRL": ev, "EKF2_HGT_REF": hgt})


def test_px4_defaults_as_captured_are_gps() -> None:
    source = nav(7, 0, 1)  # the SIH capture: EKF2_GPS_CTRL 7, EKF2_HGT_REF 1; EV_CTRL default 0
    assert source.gps and not source.vision and source.name == "GPS"
    assert source.height == "GPS" and not source.warning
    assert source.text.startswith("navigation: GPS (EKF2_GPS_CTRL 7 (position, altitude, ")
    assert "EKF2_EV_CTRL 0 (off)" in source.text and "wanders by decimetres" in source.text
    assert "\n" not in source.text


def test_motion_capture_setup_is_vision_and_both_is_both() -> None:
    vision = nav(0, 15, 3)  # shared/data/px4-sitl's vision runs
    assert vision.name == "vision" and vision.height == "vision" and not vision.warning
    assert "EKF2_EV_CTRL 15 (position, height, velocity, yaw)" in vision.text
    assert "wander" not in vision.text
    assert nav(7, 11, 0).name == "GPS + vision" and nav(7, 11, 0).height == "barometer"
    assert nav(4, 0).gps  # velocity aiding alone counts as GPS


def test_nothing_or_unknown_is_a_warning() -> None:
    none = nav(2, 8)  # GPS altitude and vision yaw only: nothing holds the horizontal position
    assert none.name == "none" and none.warning and "expect it to drift" in none.text
    unknown = nav(7, None)  # PX4 before v1.14 has no EKF2_EV_CTRL
    assert unknown.name == "unknown" and unknown.warning
    assert "could not read EKF2_EV_CTRL" in unknown.text
    assert navigation_source({}).name == "unknown"
    assert "unknown (7)" in nav(7, 0, 7).text
