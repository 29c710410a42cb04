"""Tests of the refresh judged on the newest trial before it is used (gcs.core.learning.
holdout_axes, and the learning's ``refresh_holdout`` option)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from test_learning_takeback import (
    BACK,
    PROFILE,
    REF,
    SETTINGS,
    history,
    planned_estimate,
    scaled,
)

from gcs.api import Learner
from gcs.core.learning import TAKEBACK_Z, holdout_axes, refresh_axes
from gcs.core.model import simulate
from gcs.core.refresh import RefreshResult, prediction_loss_z

HOLD = replace(BACK, refresh_takeback=False, refresh_holdout=True)


def stiff_history(seed: int, trials: int = 5):
    """``history`` flown by a vehicle of 1.6 times the profile's gain (north)."""
    u, y = history(seed, trials)
    truth = scaled(SETTINGS.models[0], 1.6)
    return u, y + simulate(truth, u[0].T).T[None] - simulate(SETTINGS.models[0], u[0].T).T[None]


def candidate(model, accepted: bool = True) -> RefreshResult:  # noqa: ANN001
    """A refresh's result proposing ``model``."""
    return RefreshResult(model, accepted, "accepted: explains held-out data better", 2.0, 2.0,
                         1e-3, 1e-4, 2, 10.0)  # fmt: skip


def test_a_refresh_the_newest_trial_confirms_is_the_refresh_of_the_trials_before_it() -> None:
    """On a vehicle the profile's model gets wrong: the refresh fitted to trials 0..T-2, bit
    for bit as the option off makes it from them, adopted, its judgement recorded."""
    u, y = stiff_history(6)
    on = refresh_axes(SETTINGS, HOLD, [SETTINGS.models[0]], u, y, [None], 0)[0]
    alone = refresh_axes(SETTINGS, replace(HOLD, refresh_holdout=False), [SETTINGS.models[0]],
                         u[:, :-1], y[:, :-1], [None], 0)[0]  # fmt: skip
    assert alone.accepted and on.accepted and on.holdout_z < -TAKEBACK_Z
    assert on.reason.startswith(alone.reason + "; adopted: predicted trial 4")
    assert np.isnan(alone.holdout_z)
    mine, theirs = on.as_dict(), alone.as_dict()
    for key in ("reason", "holdout_z"):
        mine.pop(key), theirs.pop(key)
    assert json.dumps(mine, sort_keys=True) == json.dumps(theirs, sort_keys=True)


def test_a_candidate_the_newest_trial_contradicts_is_not_used() -> None:
    """A candidate of three times the gain, on trials flown by the profile's own model: the
    model in use stays, the candidate's move in the words, nothing recorded as moved."""
    u, y = history(7)
    prior = SETTINGS.models[0]
    out = holdout_axes(SETTINGS, HOLD, [prior], [candidate(scaled(prior, 3.0))], u, y)[0]
    assert not out.accepted and out.model is prior and out.moved == 0.0
    assert out.holdout_z > TAKEBACK_Z  # the model in use predicted it far better
    assert out.reason.startswith("fitted to trials 0-2, moved 200 %, not adopted")
    assert out.candidate_moved == 2.0


def test_the_judgement_is_of_the_predictions_a_learning_step_would_have_made() -> None:
    """Each model's error is that of a Learner's own plan from the trials before the newest;
    the statistic is theirs, the candidate's errors first."""
    u, y = stiff_history(8, trials=4)
    truth, prior = scaled(SETTINGS.models[0], 1.6), SETTINGS.models[0]
    errors = [simulate(m, u[0, -1]) + planned_estimate(m, u, y) - y[0, -1] for m in (truth, prior)]
    out = holdout_axes(SETTINGS, HOLD, [prior], [candidate(truth)], u, y)[0]
    lag = round(HOLD.refresh_block_s / PROFILE.t_ilc_s)
    assert out.holdout_z == pytest.approx(prediction_loss_z(*errors, lag), rel=1e-9)
    assert out.accepted and out.model is truth


def test_what_was_not_accepted_or_was_taken_back_is_not_judged() -> None:
    u, y = history(9)
    prior = SETTINGS.models[0]
    kept = candidate(prior, accepted=False)
    back = replace(candidate(prior), reason="taken back: the profile's model predicted ...")
    assert holdout_axes(SETTINGS, HOLD, [prior, prior], [kept, back], u, y) == [kept, back]


def test_the_first_step_after_the_repeats_has_nothing_to_fit() -> None:
    """Trial 0, its repeat and one learned trial: no pair of different setpoints before the
    newest, so nothing is refreshed, whatever the newest says."""
    u, y = stiff_history(10, trials=3)
    out = refresh_axes(SETTINGS, HOLD, [SETTINGS.models[0]], u, y, [None], 0)[0]
    assert not out.accepted and out.reason == "no pair of trials with different setpoints"
    two = refresh_axes(SETTINGS, HOLD, [SETTINGS.models[0]], u[:, :2], y[:, :2], [None], 0)[0]
    assert not two.accepted and np.isnan(two.holdout_z)


def test_a_learner_flies_only_models_a_trial_has_confirmed() -> None:
    """A Learner on a vehicle of 1.6 times the profile's gain on both axes: it adopts
    refreshed models, each confirmed by the trial after the ones it was fitted to, and plans
    every step with the model its record names."""
    rng = np.random.default_rng(11)
    truth = [scaled(m, 1.6) for m in SETTINGS.models]
    n, t = REF.shape[0] - 1, np.arange(1, REF.shape[0]) * PROFILE.t_ilc_s
    learner = Learner(SETTINGS, REF, replace(HOLD, refresh_minmax_step=False), repeats=1)
    u, adopted = REF[:-1].copy(), 0
    for _ in range(7):
        y = np.column_stack(
            [REF[0, a] + simulate(truth[a], u[:, a] - REF[0, a]) + 0.05 * np.sin(0.7 * t + a) ** 2
             + 0.003 * rng.standard_normal(n) for a in range(2)]
        )  # fmt: skip
        u = learner.step(u, y)
        if learner.decisions is None:
            continue
        for a, ax in enumerate(learner.decisions.axes):
            if ax.refresh is not None and ax.refresh.accepted:
                assert ax.refresh.holdout_z < -TAKEBACK_Z
                adopted += 1
            assert learner.models[a] is (ax.refresh.model if ax.refresh else learner.models[a])
    assert adopted >= 2  # both axes, at least once
