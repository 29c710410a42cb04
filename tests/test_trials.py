"""Tests of a run's trial arithmetic (gcs.core.trials)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gcs.core.trials import iteration_of, repeat_of, setpoint_deviation, trial_errors


@pytest.mark.parametrize(
    ("trial", "repeats", "iteration", "repeated"),
    [(0, 0, 0, None), (3, 0, 3, None), (0, 1, 0, None), (1, 1, 0, 0), (2, 1, 1, None),
     (2, 2, 0, 0), (5, 2, 3, None)],
)  # fmt: skip
def test_iteration_and_repeat_of_a_trial(trial, repeats, iteration, repeated) -> None:
    assert iteration_of(trial, repeats) == iteration
    assert repeat_of(trial, repeats) == repeated


def test_setpoint_deviation_is_horizontal_and_not_aligned_by_the_delay() -> None:
    ref = np.zeros((4, 3))
    sp = np.array([[3.0, 4.0, -9.0], [0.0, 0.0, 5.0], [0.0, 1.0, 0.0]])  # down ignored
    rms, largest = setpoint_deviation(sp, ref)
    assert largest == 5.0
    assert rms == pytest.approx(np.sqrt((25.0 + 0.0 + 1.0) / 3))


def test_trial_errors_are_eq_10_and_the_largest_over_k_1_to_n() -> None:
    ref = np.zeros((3, 3))
    pos = np.array([[100.0, 0.0, 0.0], [0.3, 0.4, 7.0], [0.0, -1.0, 0.0]])  # row 0 not counted
    e, m = trial_errors(SimpleNamespace(ref_ned_m=ref, pos_ned_m=pos))
    assert e == pytest.approx((0.5 + 1.0) / 2) and m == pytest.approx(1.0)
