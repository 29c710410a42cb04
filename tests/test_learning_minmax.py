"""Tests of the step that both models expect to help (gcs.core.safeguard.minmax_step,
gcs.core.learning.minmax_steps, and the learning's ``refresh_minmax_step`` option)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from synthetic import SHORT, profile

from gcs.api import Learner, learner_settings
from gcs.core.learner import Trial
from gcs.core.learning import AdaptiveSettings, data_estimates, minmax_steps
from gcs.core.model import DiscreteModel, lifted_matrix, simulate
from gcs.core.safeguard import minmax_step
from gcs.core.trajectory import sample_eight
from gcs.io.config import trajectory_from_dict

PROFILE = profile()
SETTINGS = learner_settings(PROFILE, "smoother")
REF = sample_eight(trajectory_from_dict(SHORT).shape, PROFILE.t_ilc_s).pos_ned_m[:, :2]
N = REF.shape[0] - 1
CAUTIOUS = AdaptiveSettings(noise="data", refresh=True, safeguard=True, refresh_minmax_step=True)


def worst_on_grid(e0: np.ndarray, g: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The larger of the models' squared errors at each step of ``s``, summed directly."""
    residual = e0[None, :, :] - s[:, None, None] * g[None, :, :]  # (steps, models, samples)
    return np.sum(residual**2, axis=2).max(axis=1)


@settings(max_examples=200, deadline=None)
@given(
    st.integers(1, 3).flatmap(
        lambda m: st.tuples(
            arrays(float, (m, 6), elements=st.floats(-2, 2)),
            arrays(float, (m, 6), elements=st.floats(-2, 2)),
        )
    )
)
def test_the_step_is_the_grids_best_worst_case(pair: tuple[np.ndarray, np.ndarray]) -> None:
    e0, g = pair
    s = minmax_step(e0, g)
    assert 0.0 <= s <= 1.0
    grid = np.linspace(0.0, 1.0, 2001)
    best = worst_on_grid(e0, g, grid).min()
    assert worst_on_grid(e0, g, np.array([s]))[0] <= best + 1e-9 * (1.0 + best)


def test_models_that_agree_take_the_whole_step_and_an_overshoot_is_shared() -> None:
    """One model whose error the step removes: all of it. A second that sees the same step
    as twice as large: ``|1 - s| = |1 - 2 s|`` at s = 2/3. One that sees it as half: the
    whole step still lowers both."""
    e = np.sin(np.arange(8.0))[None]
    assert minmax_step(e, e) == 1.0
    assert minmax_step(np.vstack([e, e]), np.vstack([e, 2 * e])) == pytest.approx(2 / 3)
    assert minmax_step(np.vstack([e, e]), np.vstack([e, 0.5 * e])) == 1.0
    with pytest.raises(ValueError, match="one shape"):
        minmax_step(e, np.vstack([e, e]))


def scaled(model: DiscreteModel, gain: float) -> DiscreteModel:
    """The model with its static gain times ``gain``."""
    return replace(model, B=model.B * gain)


def history(seed: int, trials: int = 4) -> list[Trial]:
    """Trials flown by the profile's models: trial 0, its repeat, then changed setpoints;
    a repeatable disturbance and noise (absolute coordinates, north and east)."""
    rng = np.random.default_rng(seed)
    t = np.arange(1, N + 1) * PROFILE.t_ilc_s
    out = []
    for j in range(trials):
        change = 0.15 * max(j - 1, 0) * np.sin(2.1 * t + j)
        sp = REF[1:] + change[:, None]
        y = np.column_stack(
            [simulate(m, sp[:, a] - REF[0, a]) for a, m in enumerate(SETTINGS.models)]
        )
        y = y + REF[0] + 0.08 * np.sin(0.7 * t)[:, None] ** 2 + 0.004 * rng.standard_normal((N, 2))
        out.append(Trial(sp, y))
    return out


def test_the_fraction_is_the_worst_case_of_the_two_models_predictions() -> None:
    """Against predictions made here: each model's estimate (data_estimates), its simulated
    response to a fraction of the step, and the worse of the two on a fine grid."""
    trials = history(1)
    u = np.array([tr.u_m[:, 0] for tr in trials])[None] - REF[0, 0]
    y = np.array([tr.y_m[:, 0] for tr in trials])[None] - REF[0, 0]
    yd = REF[1:, 0] - REF[0, 0]
    prior, refreshed = SETTINGS.models[0], scaled(SETTINGS.models[0], 0.4)
    anchor = u[:, -1]
    d = [data_estimates(SETTINGS, CAUTIOUS, [m], u, y)[0][0] for m in (prior, refreshed)]
    # the step that removes the refreshed model's predicted error (least squares)
    f = lifted_matrix(refreshed, N)
    error = yd - f @ anchor[0] - d[1]
    target = anchor + np.linalg.lstsq(f, error, rcond=None)[0][None]
    s = minmax_steps(SETTINGS, CAUTIOUS, [refreshed], 0, u, y, d[1][None], yd, anchor,
                     target)[0]  # fmt: skip

    def worst(x: float) -> float:
        step = anchor[0] + x * (target[0] - anchor[0])
        pairs = zip((prior, refreshed), d, strict=True)
        return max(float(np.sum((yd - simulate(m, step) - dm) ** 2)) for m, dm in pairs)

    grid = np.linspace(0, 1, 4001)
    assert 0 < s < 1
    assert worst(s) <= min(worst(x) for x in grid) * (1 + 1e-9)
    same = minmax_steps(SETTINGS, CAUTIOUS, [replace(prior)], 0, u, y, d[0][None], yd,
                        anchor, target)  # fmt: skip
    assert same.tolist() == [1.0]  # the profile's own model: nothing to share


def test_a_learner_takes_that_fraction_of_the_update_it_would_take_without_the_option() -> None:
    """With a model in use that sees the vehicle as 0.4 times as stiff, the learner's step is
    the same update as without the option, from the same anchor, cut to the fraction it
    records; with the profile's models nothing changes."""
    trials = history(2)
    models = (scaled(SETTINGS.models[0], 0.4), SETTINGS.models[1])
    off = replace(CAUTIOUS, refresh=False, safeguard=False, refresh_minmax_step=False)
    on = replace(off, refresh_minmax_step=True)
    plans = {}
    for name, adaptive in (("off", off), ("on", on)):
        learner = Learner(SETTINGS, REF, adaptive, repeats=1, models=models, history=trials[:-1])
        plans[name] = (learner.step(trials[-1].u_m, trials[-1].y_m), learner.last.record)
    (u_off, rec_off), (u_on, rec_on) = plans["off"], plans["on"]
    north, east = rec_on.axes
    assert 0 < north.minmax_step < 1 and east.minmax_step == 1.0
    anchor = trials[-1].u_m[:, 0]
    np.testing.assert_allclose(
        u_on[:, 0], anchor + north.step * (u_off[:, 0] - anchor), rtol=0, atol=1e-12
    )
    assert north.step == pytest.approx(north.minmax_step)
    np.testing.assert_array_equal(u_on[:, 1], u_off[:, 1])
    assert [ax.minmax_step for ax in rec_off.axes] == [1.0, 1.0]
