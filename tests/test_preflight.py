"""link_loss_warnings: what a lost link would make the vehicle do, said before take-off."""

from __future__ import annotations

import pytest

from gcs.flight.preflight import NAV_DLL_ACT_NAMES, link_loss_warnings


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
