"""The campaign's pure checks (the flights themselves are in tests/test_flight_e2e.py)."""

from __future__ import annotations

import math

import pytest

from gcs.errors import VehicleError
from gcs.flight.campaign import check_battery


def test_enough_charge_an_unreported_level_or_no_limit_pass() -> None:
    check_battery(30.0, 30.0, "trial 1")
    check_battery(math.nan, 30.0, "taking off")
    check_battery(-1.0, 30.0, "taking off")  # MAVLink's "not reported"
    check_battery(0.0, 0.0, "trial 1")


def test_too_little_charge_is_one_line_naming_level_setting_and_remedy() -> None:
    with pytest.raises(VehicleError) as info:
        check_battery(29.4, 30.0, "trial 3")
    message = str(info.value)
    assert message.startswith("battery at 29 % before trial 3")
    assert "flight.min_battery_pct (30 %)" in message and "--resume" in message
    assert "\n" not in message
