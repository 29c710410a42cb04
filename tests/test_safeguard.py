"""Tests of the safeguard decision (gcs.core.safeguard)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from gcs.core.safeguard import SafeguardSettings, safeguard
from gcs.core.trajectory import Box

ARENA = Box((-3.0, 3.0), (-2.0, 2.5), (-3.0, 0.0))


def history(t: int, n: int = 20) -> np.ndarray:
    return np.stack([np.full((n, 2), 0.1 * j) for j in range(t)])


def test_continue_while_trials_improve() -> None:
    d = safeguard(np.array([0.9, 0.1, 0.05]), history(3), 0.005, ARENA, SafeguardSettings())
    assert d.action == "continue" and d.anchor_trial == 2 and d.step == 1.0
    np.testing.assert_array_equal(d.anchor_ne_m, history(3)[2])
    assert d.best_trial == 1


def test_revert_to_the_best_trial_with_a_smaller_step() -> None:
    e = np.array([0.9, 0.1, 0.03, 0.05])
    s = SafeguardSettings(k_sigma=2.0, step=0.4)
    d = safeguard(e, history(4), 0.005, ARENA, s)
    assert d.threshold_m == pytest.approx(0.03 + 2 * np.sqrt(2) * 0.005)
    assert d.action == "revert" and d.anchor_trial == 2 and d.step == 0.4
    np.testing.assert_array_equal(d.anchor_ne_m, history(4)[2])
    assert "trial 2" in d.reason and d.as_dict()["action"] == "revert"
    # within the scatter: continue
    calm = safeguard(np.array([0.9, 0.03, 0.037]), history(3), 0.005, ARENA, s)
    assert calm.action == "continue"


def test_single_trial_continues() -> None:
    d = safeguard(np.array([0.5]), history(1), 0.0, ARENA, SafeguardSettings())
    assert d.action == "continue" and d.anchor_trial == 0


def test_refusals() -> None:
    with pytest.raises(ValueError):
        safeguard(np.array([0.1, 0.2]), history(3), 0.01, ARENA, SafeguardSettings())
    with pytest.raises(ValueError):
        safeguard(np.array([0.1, np.nan]), history(2), 0.01, ARENA, SafeguardSettings())
    with pytest.raises(ValueError):
        safeguard(np.array([0.1]), history(1).transpose(0, 2, 1), 0.01, ARENA, SafeguardSettings())
    with pytest.raises(ValueError):
        SafeguardSettings(step=0.0)
    with pytest.raises(ValueError):
        SafeguardSettings(k_sigma=-1.0)


@settings(max_examples=60, deadline=None)
@given(
    e=arrays(float, st.integers(1, 6), elements=st.floats(0.0, 5.0)),
    data=st.data(),
    scatter=st.floats(0.0, 1.0),
)
def test_the_anchor_never_leaves_the_arena(e: np.ndarray, data, scatter: float) -> None:
    sp = data.draw(arrays(float, (e.size, 15, 2), elements=st.floats(-50.0, 50.0, allow_nan=False)))
    d = safeguard(e, sp, scatter, ARENA, SafeguardSettings())
    (n_lo, n_hi), (e_lo, e_hi), _ = ARENA.bounds()
    assert np.all((d.anchor_ne_m[:, 0] >= n_lo) & (d.anchor_ne_m[:, 0] <= n_hi))
    assert np.all((d.anchor_ne_m[:, 1] >= e_lo) & (d.anchor_ne_m[:, 1] <= e_hi))
    assert 0 <= d.anchor_trial < e.size and 0 < d.step <= 1
