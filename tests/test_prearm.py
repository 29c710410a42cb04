"""PX4's reasons for not arming, said in one line (pure part of gcs.flight.prearm)."""

from __future__ import annotations

from gcs.flight.prearm import PrearmState, refusal_text


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
