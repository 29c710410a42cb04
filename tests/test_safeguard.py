"""Tests of the safeguard decision (gcs.core.safeguard)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from gcs.core.safeguard import SafeguardSettings, feasible_step, safeguard
from gcs.core.trajectory import Box
from gcs.core.update import SetpointLimits, reference_for_inputs

ARENA = Box((-3.0, 3.0), (-2.0, 2.5), (-3.0, 0.0))


def history(t: int, n: int = 20) -> np.ndarray:
    return np.stack([np.full((n, 2), 0.1 * j) for j in range(t)])


def test_continue_while_trials_improve() -> None:
    d = safeguard(np.array([0.9, 0.1, 0.05]), history(3), 0.005, ARENA, SafeguardSettings())
    assert d.action == "continue" and d.anchor_trial == 2 and d.step == 1.0
    np.testing.assert_array_equal(d.anchor_ne_m, history(3)[2])
    # the best so far is the newest; it was compared with the best earlier one
    assert d.best_trial == 2 and d.best_epos_m == 0.05
    assert d.compared_trial == 1 and d.compared_epos_m == 0.1


def test_revert_to_the_best_trial_with_a_smaller_step() -> None:
    e = np.array([0.9, 0.1, 0.03, 0.05])
    s = SafeguardSettings(k_sigma=2.0, step=0.4)
    d = safeguard(e, history(4), 0.005, ARENA, s)
    assert d.threshold_m == pytest.approx(0.03 + 2 * np.sqrt(2) * 0.005)
    assert d.action == "revert" and d.anchor_trial == 2 and d.step == 0.4
    np.testing.assert_array_equal(d.anchor_ne_m, history(4)[2])
    assert "trial 2" in d.reason and d.as_dict()["action"] == "revert"
    assert d.best_trial == d.compared_trial == 2
    # within the scatter: continue
    calm = safeguard(np.array([0.9, 0.03, 0.037]), history(3), 0.005, ARENA, s)
    assert calm.action == "continue"


def test_a_repeat_of_the_best_trials_setpoints_is_never_called_worse() -> None:
    # trial 3 flew trial 0's setpoints again and came out above the threshold (a floor
    # measured from repeats scatters so): falling back to the same setpoints would only halve
    # the next step
    sp = np.concatenate([np.repeat(history(1), 4, axis=0), history(2)[1:]])
    e = np.array([0.780, 0.848, 0.938, 0.901, 0.607])
    d = safeguard(e[:4], sp[:4], 0.0283, ARENA, SafeguardSettings())
    assert d.threshold_m == pytest.approx(0.780 + 3 * np.sqrt(2) * 0.0283)
    assert e[3] > d.threshold_m
    assert d.action == "continue" and d.step == 1.0 and d.anchor_trial == 3
    assert "setpoints of trial 0 again" in d.reason
    # a learned trial as far above the same best trial is called worse
    learned = safeguard(
        np.append(e[:3], 0.901), sp[[0, 1, 2, 4]], 0.0283, ARENA, SafeguardSettings()
    )
    assert learned.action == "revert" and learned.anchor_trial == 0 and learned.step == 0.5


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


LIMITS = SetpointLimits(u_min_m=-3.0, u_max_m=3.0, max_step_m=0.5, max_deviation_m=1.0)


def violations(u: np.ndarray, yd_u: np.ndarray, lim: SetpointLimits, tol: float = 1e-7) -> int:
    """How many of the axis's limits ``u`` breaks (box, deviation, step from u(-1) = 0)."""
    steps = np.abs(np.diff(np.concatenate([[0.0], u])))
    return int(
        np.sum(u < lim.u_min_m - tol)
        + np.sum(u > lim.u_max_m + tol)
        + np.sum(np.abs(u - yd_u) > lim.max_deviation_m + tol)
        + np.sum(steps > lim.max_step_m + tol)
    )


def test_feasible_step_keeps_the_step_asked_when_the_anchor_keeps_the_limits() -> None:
    yd = np.linspace(0.0, 2.0, 30)
    anchor, target = yd + 0.5, yd - 0.5
    assert feasible_step(anchor, target, yd, LIMITS, 0.5) == 0.5


def test_feasible_step_after_a_refresh_changed_the_delay() -> None:
    # the best trial kept the deviation bound of a model of relative degree 8; the model in
    # use has relative degree 2, so on the ramp the same setpoints lie 1.5 m from today's
    # aligned reference: half a step from them would break the 1 m bound, the step found not
    lim = SetpointLimits(u_min_m=-3.0, u_max_m=3.0, max_step_m=1.0, max_deviation_m=1.0)
    yd = np.concatenate([0.1 * np.arange(1, 31), np.full(30, 3.0)])
    old, new = reference_for_inputs(yd, 8), reference_for_inputs(yd, 2)
    ramp_in = np.minimum(0.1 * np.arange(yd.size), 1.0)
    anchor = np.minimum(old + 0.9 * ramp_in, 3.0)
    target = np.minimum(new + 0.8 * ramp_in, 3.0)
    assert violations(anchor, old, lim) == 0 and violations(target, new, lim) == 0
    assert violations(anchor + 0.5 * (target - anchor), new, lim) > 0
    s = feasible_step(anchor, target, new, lim, 0.5)
    assert s == pytest.approx((1.5 - 1.0) / (1.5 - 0.8), abs=1e-6)  # 1.5 - 0.7 s <= 1
    assert violations(anchor + s * (target - anchor), new, lim) == 0


@settings(max_examples=60, deadline=None)
@given(
    st.integers(min_value=2, max_value=40),
    st.floats(min_value=0.05, max_value=1.0),
    st.integers(min_value=0, max_value=2**31 - 1),
)
def test_feasible_step_always_keeps_the_limits(n: int, step: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    yd = np.cumsum(rng.uniform(-0.3, 0.3, n))
    # a target inside every limit: near the reference, small steps, inside the box
    target = np.cumsum(np.clip(np.diff(np.concatenate([[0.0], yd])), -0.45, 0.45))
    target = np.clip(target, -3.0, 3.0)
    if violations(target, yd, LIMITS) > 0:
        yd = target.copy()  # then the reference itself is the target's
    anchor = target + rng.uniform(-2.0, 2.0, n)
    s = feasible_step(anchor, target, yd, LIMITS, step)
    assert step <= s <= 1.0
    assert violations(anchor + s * (target - anchor), yd, LIMITS) == 0


def test_feasible_step_refuses_arrays_of_other_shapes() -> None:
    with pytest.raises(ValueError, match="1-D of one length"):
        feasible_step(np.zeros(3), np.zeros(4), np.zeros(3), LIMITS, 0.5)
