"""Tests of the take-back of a refreshed model (gcs.core.learning.takeback_axes, and the
learning's ``refresh_takeback`` option)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from synthetic import SHORT, profile

from gcs.api import Learner, learner_settings
from gcs.core.learner import Trial
from gcs.core.learning import (
    TAKEBACK_Z,
    AdaptiveSettings,
    refresh_axes,
    takeback_axes,
)
from gcs.core.model import DiscreteModel, simulate
from gcs.core.refresh import prediction_loss_z
from gcs.core.trajectory import sample_eight
from gcs.io.config import trajectory_from_dict

PROFILE = profile()
SETTINGS = learner_settings(PROFILE, "smoother")
REF = sample_eight(trajectory_from_dict(SHORT).shape, PROFILE.t_ilc_s).pos_ned_m[:, :2]
N = REF.shape[0] - 1
BACK = AdaptiveSettings(noise="data", refresh=True, safeguard=True, refresh_takeback=True)


def scaled(model: DiscreteModel, gain: float) -> DiscreteModel:
    """The model with its static gain times ``gain``: a refresh that went wrong."""
    return replace(model, B=model.B * gain)


def history(seed: int, trials: int = 4, noise_m: float = 0.005):
    """Setpoints and positions (1, T, N) of one axis (north), learning coordinates: trial 0,
    its repeat, then trials of changed setpoints, flown by the profile's own model plus a
    repeatable disturbance and noise correlated in time."""
    rng = np.random.default_rng(seed)
    yd = REF[1:, 0] - REF[0, 0]
    t = np.arange(1, N + 1) * PROFILE.t_ilc_s
    plant = SETTINGS.models[0]
    u, y = [], []
    for j in range(trials):
        change = 0.0 if j < 2 else 0.15 * (j - 1) * np.sin(2.1 * t + j)
        sp = yd + change
        gust = np.convolve(rng.standard_normal(N), np.ones(10) / 10, "same") * noise_m * 3
        u.append(sp)
        y.append(simulate(plant, sp) + 0.05 * np.sin(0.7 * t) ** 2 + gust)
    return np.array(u)[None], np.array(y)[None]


def test_a_refresh_the_newest_trial_contradicts_is_taken_back_to_the_profiles_model() -> None:
    u, y = history(1)
    wrong = scaled(SETTINGS.models[0], 3.0)
    z, results = takeback_axes(SETTINGS, BACK, [wrong], u, y, 0)
    assert z[0] > TAKEBACK_Z
    back = results[0]
    assert back is not None and back.accepted and back.model is SETTINGS.models[0]
    assert back.reason.startswith("taken back: the profile's model predicted trial 3 better")
    assert back.takeback_z == z[0]
    assert back.cv_loss_candidate_m2 < back.cv_loss_current_m2
    assert back.moved > 0.5  # the gain of 3 undone: |1/3 - 1| at DC


def test_a_model_that_predicts_better_than_the_profiles_stays() -> None:
    """The trials flown by a vehicle of 1.6 times the gain the profile says: the refreshed
    model that knows it predicts better, and is kept (z well below zero)."""
    u, y = history(2)
    truth = scaled(SETTINGS.models[0], 1.6)
    y = y + simulate(truth, u[0].T).T[None] - simulate(SETTINGS.models[0], u[0].T).T[None]
    z, results = takeback_axes(SETTINGS, BACK, [truth], u, y, 0)
    assert z[0] < -TAKEBACK_Z
    assert results == [None]


def test_the_profiles_own_model_is_not_judged() -> None:
    u, y = history(3)
    same = replace(SETTINGS.models[0])  # an equal copy, as a resumed run loads it
    uu, yy = np.repeat(u, 2, 0), np.repeat(y, 2, 0)
    z, results = takeback_axes(SETTINGS, BACK, [SETTINGS.models[0], same], uu, yy, 0)
    assert np.all(np.isnan(z)) and results == [None, None]


def planned_estimate(model: DiscreteModel, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The estimate (N,) of north a Learner made from trials 0..T-2 with ``model`` in use:
    the one the step that planned the newest trial predicted it with."""
    zero = np.zeros_like(u[0])
    u2, y2 = np.stack([u[0], zero], -1) + REF[0], np.stack([y[0], zero], -1) + REF[0]
    learner = Learner(
        SETTINGS, REF, AdaptiveSettings(noise="data", safeguard=True), repeats=1,
        models=(model, SETTINGS.models[1]), history=[Trial(u2[j], y2[j]) for j in range(2)],
    )  # fmt: skip
    for j in range(2, u.shape[1] - 1):
        learner.step(u2[j], y2[j])
    return learner.last.d_hat_m[:, 0]


def test_the_judgement_is_of_the_predictions_the_learning_steps_made() -> None:
    """Each model's error is that of a Learner's own plan from the trials before the newest:
    its estimate and the setpoints flown next; z is their statistic."""
    u, y = history(4)
    wrong, prior = scaled(SETTINGS.models[0], 3.0), SETTINGS.models[0]
    errors = [simulate(m, u[0, -1]) + planned_estimate(m, u, y) - y[0, -1] for m in (wrong, prior)]
    back = takeback_axes(SETTINGS, BACK, [wrong], u, y, 0)[1][0]
    assert back.cv_loss_current_m2 == pytest.approx(np.mean(errors[0] ** 2), rel=1e-9)
    assert back.cv_loss_candidate_m2 == pytest.approx(np.mean(errors[1] ** 2), rel=1e-9)
    lag = round(BACK.refresh_block_s / PROFILE.t_ilc_s)
    assert back.takeback_z == pytest.approx(prediction_loss_z(*errors, lag), rel=1e-9)


def test_refresh_axes_takes_back_or_refreshes_as_without_the_option() -> None:
    """Taken back: the take-back's result. Kept: the refresh's own decision, bit for bit,
    with the judgement recorded."""
    u, y = history(5)
    truth = scaled(SETTINGS.models[0], 1.6)  # the second plant's vehicle, its model in use
    stiff = y + simulate(truth, u[0].T).T[None] - simulate(SETTINGS.models[0], u[0].T).T[None]
    models = [scaled(SETTINGS.models[0], 3.0), truth]
    uu, yy = np.repeat(u, 2, 0), np.concatenate([y, stiff])
    on = refresh_axes(SETTINGS, BACK, models, uu, yy, [None, None], 0)
    off_settings = replace(BACK, refresh_takeback=False)
    off = refresh_axes(SETTINGS, off_settings, models, uu, yy, [None, None], 0)
    assert on[0].reason.startswith("taken back") and on[0].model is SETTINGS.models[0]
    assert not off[0].reason.startswith("taken back")
    assert np.isnan(off[1].takeback_z) and np.isfinite(on[1].takeback_z)
    kept, alone = on[1].as_dict(), off[1].as_dict()
    kept.pop("takeback_z"), alone.pop("takeback_z")
    assert json.dumps(kept, sort_keys=True) == json.dumps(alone, sort_keys=True)
