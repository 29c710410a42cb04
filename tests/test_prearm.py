"""PX4's reasons for not arming, said in one line (pure part of gcs.flight.prearm); the global
origin gcs sets, against PX4 v1.16's rule for its altitude."""

from __future__ import annotations

import asyncio

from ekf2_origin import OriginRuleVehicle

from gcs.flight.prearm import LAB_ORIGIN, PrearmState, ensure_global_origin, refusal_text


def test_the_failing_checks_are_named_and_no_rc_is_not_a_reason() -> None:
    state = PrearmState(
        problems=["No manual control input", "Navigation error: No valid global position estimate"]
    )
    assert refusal_text(state) == "Navigation error: No valid global position estimate"


def test_without_check_reports_the_status_texts_about_arming_are_used() -> None:
    state = PrearmState(
        texts=["Takeoff detected", "Preflight Fail: horizontal position unstable"] * 2
    )
    assert refusal_text(state) == "Preflight Fail: horizontal position unstable"


def test_with_nothing_reported_it_says_so() -> None:
    assert "no reason reported" in refusal_text(PrearmState(problems=["No manual control input"]))


def test_the_origin_gcs_sets_before_ekf2_has_a_height_leaves_the_local_height() -> None:
    # an origin above 0 m taken then moves the local height by its altitude (the rule bites)
    early = OriginRuleVehicle(height_after_s=1.0)
    asyncio.run(ensure_global_origin(early, (*LAB_ORIGIN[:2], 488.0)))  # type: ignore[arg-type]
    assert early.shift_m == 488.0
    # gcs's own origin, taken at the same moment, does not
    vehicle = OriginRuleVehicle(height_after_s=1.0)
    origin, was_set = asyncio.run(ensure_global_origin(vehicle))  # type: ignore[arg-type]
    assert was_set and origin == LAB_ORIGIN and not vehicle.height_valid
    assert vehicle.shift_m == 0.0


def test_an_origin_the_vehicle_has_is_kept() -> None:
    kept = (47.0, 8.0, 430.0)
    vehicle = OriginRuleVehicle(height_after_s=0.0, origin=kept)
    origin, was_set = asyncio.run(ensure_global_origin(vehicle))  # type: ignore[arg-type]
    assert (origin, was_set) == (kept, False) and vehicle.origin == kept
