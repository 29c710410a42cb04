"""Tests of the refresh's pairs against the mean of flights of identical setpoints (the
learning's ``refresh_pool_repeats`` option) and against trial 0's flights (``refresh_anchor``;
the pairs themselves: tests/test_refresh.py)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from test_learning_takeback import BACK, PROFILE, REF, SETTINGS, N, history, scaled

from gcs.core.learning import refresh_axes
from gcs.core.model import simulate
from gcs.core.refresh import model_change, transfer_function

POOL = replace(BACK, refresh_takeback=False, refresh_pool_repeats=True)
PLAIN = replace(POOL, refresh_pool_repeats=False)


def test_without_repeats_the_refresh_is_the_one_without_the_option() -> None:
    u, y = history(11, trials=5)
    u, y = u[:, 1:], y[:, 1:]  # trial 0's repeat left out: every pair of different setpoints
    on = refresh_axes(SETTINGS, POOL, [SETTINGS.models[0]], u, y, [None], 0)[0]
    off = refresh_axes(SETTINGS, PLAIN, [SETTINGS.models[0]], u, y, [None], 0)[0]
    assert on.pairs == off.pairs == 3
    assert json.dumps(on.as_dict(), sort_keys=True) == json.dumps(off.as_dict(), sort_keys=True)


def test_the_first_pair_is_the_mean_of_trial_0s_flights_against_the_first_learned_trial() -> None:
    """Trial 0 flown twice, then j = 1: the pooled pair is the plain one with the base's noise
    halved, scaled by c = sqrt(2 / (1/2 + 1)); its predicted change, and so its signal-to-noise
    ratio against the same floor, is c^2 = 4/3 times the plain pair's."""
    u, y = history(12, trials=3)
    on = refresh_axes(SETTINGS, POOL, [SETTINGS.models[0]], u, y, [None], 0)[0]
    off = refresh_axes(SETTINGS, PLAIN, [SETTINGS.models[0]], u, y, [None], 0)[0]
    assert on.pairs == off.pairs == 1
    assert on.snr / off.snr == pytest.approx(4 / 3, rel=1e-12)


def _white_history(seed: int, repeats: int = 3, noise_m: float = 0.05):
    """Trial 0 flown ``repeats + 1`` times, then one changed trial (a smooth random step of
    0.3 m), by the profile's own model with white noise: any move of the refresh fits noise."""
    rng = np.random.default_rng(seed)
    yd = REF[1:, 0] - REF[0, 0]
    t = np.arange(1, N + 1) * PROFILE.t_ilc_s
    change = np.convolve(rng.standard_normal(N + 9), np.ones(10) / 10, "valid")
    change *= 0.3 / np.std(change)
    u = np.array([yd] * (repeats + 1) + [yd + change])
    y = np.array([simulate(SETTINGS.models[0], x) for x in u]) + 0.05 * np.sin(0.7 * t) ** 2
    return u[None], y[None] + noise_m * rng.standard_normal(y.shape)[None]


def test_pooling_the_repeats_fits_less_of_the_noise() -> None:
    """The vehicle is the profile's model: over 40 histories of four flights of trial 0 and
    one changed trial, the refresh's candidates (every one a fit to noise) move the model
    less with the pooled pair (noise 1.25 r, the pair scaled by c = 1.26 to 2 r) than with the
    last flight of trial 0 (2 r): the same noise fitted through an input c times larger
    (median over the seeds; about 1 / c expected)."""
    moved: dict[bool, list[float]] = {False: [], True: []}
    for seed in range(40):
        u, y = _white_history(seed)
        for mode in (PLAIN, POOL):
            result = refresh_axes(SETTINGS, mode, [SETTINGS.models[0]], u, y, [None], 0)[0]
            moved[mode.refresh_pool_repeats].append(result.candidate_moved)
    assert np.median(moved[True]) < np.median(moved[False]), moved


ANCHOR = replace(POOL, refresh_anchor=True)


def _converging_history(seed: int, plant, noise_m: float = 0.05):  # noqa: ANN001
    """Trial 0 flown four times, a large change (j = 1), then two small ones near the floor
    (j = 2, 3: a tenth of it each), by ``plant`` with white noise."""
    rng = np.random.default_rng(seed)
    yd = REF[1:, 0] - REF[0, 0]
    change = np.convolve(rng.standard_normal(N + 9), np.ones(10) / 10, "valid")
    change *= 0.3 / np.std(change)
    small = [np.convolve(rng.standard_normal(N + 9), np.ones(10) / 10, "valid") for _ in range(2)]
    u = [yd] * 4 + [yd + change]
    for s in small:
        u.append(u[-1] + 0.03 * s / np.std(s))
    u = np.array(u)
    y = np.array([simulate(plant, x) for x in u]) + noise_m * rng.standard_normal((len(u), N))
    return u[None], y[None]


def test_against_the_anchor_the_newest_pair_keeps_the_whole_change() -> None:
    """Near the floor a consecutive pair's input change is the small step, the anchor's the
    whole way from trial 0: its predicted change, and so its signal-to-noise ratio against
    the same floor, is far above the pooled consecutive pair's."""
    u, y = _converging_history(21, SETTINGS.models[0])
    on = refresh_axes(SETTINGS, ANCHOR, [SETTINGS.models[0]], u, y, [None], 0)[0]
    off = refresh_axes(SETTINGS, POOL, [SETTINGS.models[0]], u, y, [None], 0)[0]
    assert on.pairs == 3 and on.snr > 10 * off.snr, (on.snr, off.snr)


def test_against_the_anchor_a_converged_history_still_corrects_the_model() -> None:
    """The vehicle has 1.5 times the profile's gain (the profile 33 % off where learning
    acts). From four flights of trial 0, j = 1 and two small steps, over 20 seeds: the
    consecutive pairs' newest is within the noise, so the refresh is not attempted and the
    profile's model stays; against the anchor every pair is informative and the refreshed
    model comes to within a quarter of the vehicle (median; its distance computed here from
    the two transfer functions)."""
    truth = scaled(SETTINGS.models[0], 1.5)
    bt, at = transfer_function(truth)
    band = SETTINGS.weights.wdu / SETTINGS.weights.we
    off: dict[bool, list[float]] = {False: [], True: []}
    for seed in range(20):
        u, y = _converging_history(seed, truth)
        for mode in (POOL, ANCHOR):
            result = refresh_axes(SETTINGS, mode, [SETTINGS.models[0]], u, y, [None], 0)[0]
            b, a = transfer_function(result.model)
            off[mode.refresh_anchor].append(float(model_change(
                bt, at, b, a, truth.delay_samples, truth.dt_s, band, result.model.delay_samples
            )[0]))  # fmt: skip
            if not mode.refresh_anchor:
                assert result.model is SETTINGS.models[0] and not result.accepted
    assert min(off[False]) > 0.3 and np.median(off[True]) < 0.25, off
