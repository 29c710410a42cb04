"""Tests of the model refresh between trials (gcs.core.refresh)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.signal
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.core.model import from_transfer_function, markov_parameters, simulate
from gcs.core.refresh import (
    ArNoise,
    RefreshSettings,
    anchor_pairs,
    fit_ar_noise,
    fit_output_error,
    model_change,
    model_from_transfer_function,
    pooled_pairs,
    prediction_loss_z,
    refresh_model,
    simulate_tf,
    transfer_function,
)

EQ11 = from_transfer_function([0.08, 1.94], [1.0, 1.752, 2.01], 0.25, 0.05)


def loop(wn: float, zeta: float, gain: float, delay_s: float, dt: float = 0.05):
    k = gain * wn * wn
    return from_transfer_function([k], [1.0, 2 * zeta * wn, wn * wn], delay_s, dt)


def excitation(seed: int, pairs: int = 2, n: int = 280) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.standard_normal((pairs, n)), axis=1) * 0.05


@pytest.mark.parametrize("model", [EQ11, loop(1.3, 0.7, 1.0, 0.0), loop(2.0, 0.4, 0.9, 0.1)])
def test_transfer_function_round_trip(model) -> None:
    b, a = transfer_function(model)
    back = model_from_transfer_function(b, a, model.dt_s, model.delay_samples)
    np.testing.assert_allclose(
        markov_parameters(back, 80), markov_parameters(model, 80), atol=1e-12
    )
    u = excitation(0, 3)
    np.testing.assert_allclose(
        simulate_tf(b[None], a[None], model.delay_samples, u[None])[0],
        simulate(model, u.T).T,
        atol=1e-10,
    )


@settings(max_examples=10, deadline=None)
@given(
    wn=st.floats(0.8, 2.5),
    zeta=st.floats(0.3, 1.2),
    gain=st.floats(0.7, 1.3),
    seed=st.integers(0, 1000),
)
def test_refresh_recovers_a_known_plant_from_noiseless_data(wn, zeta, gain, seed) -> None:
    true = loop(wn, zeta, gain, 0.25)
    du = excitation(seed)
    dy = simulate(true, du.T).T
    res = refresh_model(EQ11, du, dy, 1e-8, RefreshSettings(delay_search=0), 0.01)
    assert res.accepted, res.reason
    assert res.model.delay_samples == true.delay_samples
    assert res.model.is_stable()
    scale = np.max(np.abs(markov_parameters(true, 200)))
    err = np.max(np.abs(markov_parameters(res.model, 200) - markov_parameters(true, 200)))
    assert err <= 1e-6 * scale
    # how far it moved: the peak relative change over the learning band, here vs the truth
    b0, a0 = transfer_function(EQ11)
    bt, at = transfer_function(true)
    expected = model_change(b0[None], a0[None], bt[None], at[None], 5, 0.05, 0.01)[0]
    assert res.moved == pytest.approx(expected, rel=1e-4)


def test_refresh_finds_the_delay() -> None:
    true = loop(1.5, 0.6, 1.0, 0.15)  # 3 samples, the model has 5
    du = excitation(3)
    res = refresh_model(EQ11, du, simulate(true, du.T).T, 1e-8, RefreshSettings(), 0.01)
    assert res.accepted and res.model.delay_samples == 3
    kept = refresh_model(
        EQ11, du, simulate(true, du.T).T, 1e-8, RefreshSettings(delay_search=0), 0.01
    )
    assert kept.model.delay_samples == 5


def test_refresh_rejects_a_candidate_no_better_on_held_out_data() -> None:
    """The current model is the truth: a fit to noise must not replace it."""
    rng = np.random.default_rng(4)
    du = excitation(4)
    dy = simulate(EQ11, du.T).T + 0.01 * rng.standard_normal(du.shape)
    res = refresh_model(EQ11, du, dy, 1e-4 / 2, RefreshSettings(), 0.01)
    assert not res.accepted and res.model is EQ11
    assert "held-out" in res.reason
    assert res.cv_loss_candidate_m2 >= res.cv_loss_current_m2
    assert res.moved == 0.0 and res.candidate_moved > 0


def test_refresh_skips_a_pair_within_the_noise() -> None:
    du = excitation(5) * 1e-3
    dy = simulate(loop(1.2, 0.8, 1.0, 0.25), du.T).T
    res = refresh_model(EQ11, du, dy, 1e-2, RefreshSettings(), 0.01)
    assert not res.accepted and res.reason.startswith("skipped")
    assert res.snr < 1.0


def test_refresh_without_pairs() -> None:
    res = refresh_model(EQ11, np.zeros((0, 50)), np.zeros((0, 50)), 1e-4, RefreshSettings(), 0.01)
    assert not res.accepted and res.pairs == 0


def test_refresh_refuses_bad_shapes() -> None:
    with pytest.raises(ValueError):
        refresh_model(EQ11, np.zeros((2, 50)), np.zeros((2, 49)), 1e-4, RefreshSettings(), 0.01)
    bad = np.zeros((1, 50))
    bad[0, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        refresh_model(EQ11, bad, np.zeros((1, 50)), 1e-4, RefreshSettings(), 0.01)
    with pytest.raises(ValueError):
        RefreshSettings(delay_search=-1)


def test_model_change_measures_relative_change() -> None:
    b, a = transfer_function(EQ11)
    assert model_change(b[None], a[None], b[None], a[None], 5, 0.05, 0.01)[0] == pytest.approx(
        0, abs=1e-12
    )
    moved = model_change(b[None], a[None], 1.1 * b[None], a[None], 5, 0.05, 0.01)[0]
    assert moved == pytest.approx(0.1, rel=1e-9)
    # one sample more delay: |e^{-j w T} - 1| peaks at 2 where the band reaches Nyquist
    later = model_change(b[None], a[None], b[None], a[None], 5, 0.05, 0.0, delay_new=6)[0]
    assert later == pytest.approx(2.0, rel=1e-3)


def test_fit_output_error_is_batched() -> None:
    true = loop(1.6, 0.5, 1.0, 0.25)
    b0, a0 = transfer_function(EQ11)
    du = np.stack([excitation(6), excitation(7)])
    dy = np.stack([simulate(true, du[0].T).T, simulate(EQ11, du[1].T).T])
    b, a, loss = fit_output_error(
        np.stack([b0, b0]), np.stack([a0, a0]), 5, du, dy, np.ones(du.shape, bool)
    )
    bt, at = transfer_function(true)
    np.testing.assert_allclose(b[0], bt, rtol=1e-6)
    np.testing.assert_allclose(a[1], a0, rtol=1e-9)
    assert np.all(loss < 1e-18)


def _dlsim(b: np.ndarray, a: np.ndarray, delay: int, u: np.ndarray) -> np.ndarray:
    """``z^-delay (b_1 + b_2 z^-1 + ..) / A`` by scipy.signal.dlsim (an independent state-space
    simulation of the same transfer function), one input sequence."""
    den = np.concatenate([[1.0], a])
    num = np.concatenate([b, [0.0]])  # b_1 + b_2 z^-1 + .. over 1 + a_1 z^-1 + ..
    _, y = scipy.signal.dlsim((num, den, 1.0), u)
    return np.concatenate([np.zeros(delay), y[: u.size - delay, 0]])


def _stable_tf(seed: int, order: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    poles = rng.uniform(0.2, 0.95, order) * np.exp(1j * rng.uniform(-1.0, 1.0, order))
    poles = np.concatenate([poles[: order // 2], np.conj(poles[: order // 2])])
    poles = np.concatenate([poles, rng.uniform(-0.9, 0.95, order - poles.size)])
    return rng.normal(size=order), np.real(np.poly(poles))[1:]


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), order=st.integers(1, 4), delay=st.integers(0, 6))
def test_simulate_tf_equals_dlsim_row_by_row_and_batched(seed, order, delay) -> None:
    """Row by row (compiled difference equation) and all rows at once (impulse responses and
    an FFT) both reproduce scipy.signal.dlsim of the same transfer function."""
    b, a = _stable_tf(seed, order)
    u = excitation(seed, 2, 120)
    expected = np.array([_dlsim(b, a, delay, row) for row in u])
    scale = np.max(np.abs(expected))
    bb, ab = np.stack([b, 0.5 * b]), np.stack([a, a])
    for rowwise in (True, False):
        got = simulate_tf(bb, ab, delay, np.stack([u, u]), rowwise)
        np.testing.assert_allclose(got[0], expected, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(got[1], 0.5 * expected, rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("delay", [0, 5])
def test_fit_recovers_a_known_iir_that_dlsim_confirms(delay) -> None:
    """Noiseless pairs of a known IIR: the fit started from another model reproduces the data
    (checked by dlsim of the fitted coefficients) and recovers the coefficients, whether the
    candidates are simulated row by row or all rows at once."""
    b_true, a_true = np.array([0.02, 0.015]), np.array([-1.6, 0.68])
    du = excitation(11, 3)
    dy = np.array([_dlsim(b_true, a_true, delay, row) for row in du])
    b0, a0 = np.array([[0.03, 0.01]]), np.array([[-1.5, 0.6]])
    mask = np.ones(du.shape, dtype=bool)
    b, a, loss = fit_output_error(b0, a0, delay, du[None], dy[None], mask[None], rowwise=True)
    fitted = np.array([_dlsim(b[0], a[0], delay, row) for row in du])
    np.testing.assert_allclose(fitted, dy, rtol=0, atol=1e-8 * np.max(np.abs(dy)))
    np.testing.assert_allclose(np.concatenate([b[0], a[0]]), np.concatenate([b_true, a_true]),
                               rtol=1e-6, atol=1e-9)  # fmt: skip
    assert loss[0] <= 1e-12 * np.sum(dy * dy)
    bb, ab, _ = fit_output_error(b0, a0, delay, du[None], dy[None], mask[None], rowwise=False)
    np.testing.assert_allclose(bb[0], b[0], rtol=1e-7)
    np.testing.assert_allclose(ab[0], a[0], rtol=1e-7)


# ---------------------------------------------------------------------------------------------
# The non-repeatable error's spectrum: fit_ar_noise, and the refresh on whitened pairs
# ---------------------------------------------------------------------------------------------


def _ar_series(coef: np.ndarray, sigma: float, shape: tuple[int, int], seed: int) -> np.ndarray:
    """``v(k) = sum phi_i v(k-i) + e(k)`` by scipy.signal.lfilter, a burn-in dropped."""
    rng = np.random.default_rng(seed)
    e = sigma * rng.standard_normal((shape[0], shape[1] + 500))
    return scipy.signal.lfilter([1.0], np.concatenate([[1.0], -coef]), e, axis=1)[:, 500:]


def test_fit_ar_noise_recovers_a_known_ar2_process() -> None:
    phi = np.array([1.5, -0.7])  # poles 0.84 at +-27 deg: a slow, oscillating wander
    x = _ar_series(phi, 0.01, (8, 2000), 1)
    noise = fit_ar_noise(x, 20)
    assert noise.order == 2
    np.testing.assert_allclose(noise.coefficients, -phi, atol=0.02)
    assert noise.innovation_var_m2 == pytest.approx(1e-4, rel=0.05)
    assert noise.variance_m2 == pytest.approx(np.mean(np.var(x, axis=1)), rel=1e-12)


def test_fit_ar_noise_is_the_yule_walker_solution_of_its_order() -> None:
    """The Levinson-Durbin recursion against scipy's Toeplitz solver on the same pooled
    autocovariance, and its innovation variance against ``r_0 - phi . r_(1..p)``."""
    x = _ar_series(np.array([0.9, -0.2, 0.1]), 0.02, (3, 280), 2)
    noise = fit_ar_noise(x, 20)
    p = noise.order
    assert p >= 1
    xc = x - x.mean(axis=1, keepdims=True)
    r = np.array([np.sum(xc[:, k:] * xc[:, : x.shape[1] - k]) for k in range(p + 1)]) / x.size
    phi = scipy.linalg.solve_toeplitz(r[:p], r[1 : p + 1])
    np.testing.assert_allclose(noise.coefficients, -phi, rtol=1e-9, atol=1e-12)
    assert noise.innovation_var_m2 == pytest.approx(r[0] - phi @ r[1 : p + 1], rel=1e-9)


def test_fit_ar_noise_keeps_white_noise_white() -> None:
    rng = np.random.default_rng(3)
    noise = fit_ar_noise(0.1 * rng.standard_normal((2, 280)), 20)
    assert noise.order == 0 and noise.coefficients == ()
    assert noise.innovation_var_m2 == noise.variance_m2
    assert noise.variance_m2 == pytest.approx(0.01, rel=0.15)


def test_fit_ar_noise_refuses_bad_input() -> None:
    with pytest.raises(ValueError):
        fit_ar_noise(np.zeros((2, 3)), 5)
    with pytest.raises(ValueError, match="NaN"):
        fit_ar_noise(np.full((1, 50), np.nan), 5)
    with pytest.raises(ValueError):
        fit_ar_noise(np.zeros((1, 50)), -1)


def test_whiten_is_the_fir_filter_of_the_ar_polynomial() -> None:
    noise = ArNoise((-1.2, 0.5, 0.1), 1.0, 2.0)
    x = excitation(8, 3)
    np.testing.assert_allclose(
        noise.whiten(x), scipy.signal.lfilter([1.0, -1.2, 0.5, 0.1], [1.0], x, axis=-1),
        rtol=0, atol=1e-15,
    )  # fmt: skip


def test_refresh_on_whitened_pairs_recovers_a_known_plant() -> None:
    """Noiseless pairs: whitening both sides keeps the true plant the exact fit."""
    true = loop(1.5, 0.6, 1.1, 0.25)
    du = excitation(9)
    dy = simulate(true, du.T).T
    noise = ArNoise((-1.5, 0.7), 1e-8, 1e-6)
    res = refresh_model(EQ11, du, dy, 1e-6, RefreshSettings(delay_search=0), 0.01, noise)
    assert res.accepted, res.reason
    scale = np.max(np.abs(markov_parameters(true, 200)))
    err = np.max(np.abs(markov_parameters(res.model, 200) - markov_parameters(true, 200)))
    assert err <= 1e-6 * scale
    # the SNR is the whitened predicted change over the innovation variance
    pred = simulate(EQ11, noise.whiten(du).T).T
    assert res.snr == pytest.approx(np.mean(pred[-1] ** 2) / 2e-8, rel=1e-9)


def test_refresh_with_a_white_noise_model_is_the_refresh_without() -> None:
    du = excitation(10)
    dy = simulate(loop(1.4, 0.7, 1.0, 0.25), du.T).T + 0.01 * np.random.default_rng(
        10
    ).standard_normal(du.shape)
    plain = refresh_model(EQ11, du, dy, 1e-4, RefreshSettings(), 0.01)
    white = refresh_model(EQ11, du, dy, 1e-4, RefreshSettings(), 0.01, ArNoise((), 5.0, 5.0))
    assert white.accepted == plain.accepted and white.snr == plain.snr
    assert white.cv_loss_candidate_m2 == plain.cv_loss_candidate_m2


def test_whitening_refuses_fits_to_a_slow_wander() -> None:
    """The model in use is the truth and the pairs' noise a slow wander (an AR(2) of 0.1 m
    with a period of about 5 s at 0.05 s): without its spectrum the cross-validation over
    1 s blocks accepts fits to the wander; with the spectrum, measured on independent flights
    (as the repeats of trial 0 give it), it accepts fewer and moves less."""
    phi = np.array([1.94, -0.9425])  # poles 0.97 at +-3.6 deg
    moved_plain, moved_white = [], []
    for seed in range(12):
        du = excitation(100 + seed, 1)
        v = _ar_series(phi, 1.0, (5, 280), 200 + seed)
        v *= 0.1 / np.std(v)
        dy = simulate(EQ11, du.T).T + (v[0] - v[1])[None]
        noise = fit_ar_noise(v[2:], 20)  # other flights: the repeats
        r = noise.variance_m2
        plain = refresh_model(EQ11, du, dy, r, RefreshSettings(min_snr=0.0), 0.01)
        white = refresh_model(EQ11, du, dy, r, RefreshSettings(min_snr=0.0), 0.01, noise)
        moved_plain.append(plain.moved)
        moved_white.append(white.moved)
    plain_n, white_n = np.count_nonzero(moved_plain), np.count_nonzero(moved_white)
    assert white_n < plain_n, (moved_plain, moved_white)
    assert np.median(moved_white) < np.median(moved_plain)


def test_a_move_the_convergence_contradicts_is_rejected_only_where_learning_converged() -> None:
    """``max_move``: where the learning has converged with the model in use, a candidate that
    moves it by more than the limit is rejected; elsewhere the same candidate is accepted."""
    true = loop(2.2, 0.5, 1.3, 0.25)  # far from EQ11: a large move
    du = excitation(6)
    dy = simulate(true, du.T).T
    free = refresh_model(EQ11, du, dy, 1e-8, RefreshSettings(delay_search=0), 0.01)
    assert free.accepted and free.moved > 0.2
    limit = RefreshSettings(delay_search=0, max_move=free.moved / 2)
    refused = refresh_model(EQ11, du, dy, 1e-8, limit, 0.01, converged=True)
    assert not refused.accepted and refused.model is EQ11 and refused.moved == 0.0
    assert refused.candidate_moved == pytest.approx(free.moved)
    assert refused.reason.startswith("rejected: moves the model") and "limit" in refused.reason
    kept = refresh_model(EQ11, du, dy, 1e-8, limit, 0.01, converged=False)
    assert kept.accepted and kept.moved == pytest.approx(free.moved)
    within = RefreshSettings(delay_search=0, max_move=2 * free.moved)
    assert refresh_model(EQ11, du, dy, 1e-8, within, 0.01, converged=True).accepted


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_max_move_must_be_positive_and_finite(bad: float) -> None:
    with pytest.raises(ValueError, match="max_move"):
        RefreshSettings(max_move=bad)


# ------------------------------------------------------------------ min_gain_z


def _wander_pairs(seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    """One pair on the profile's own model (EQ11 is the truth) with a slow wander: every
    candidate fits noise. Returns du, dy and one flight's noise variance."""
    du = excitation(300 + seed, 1)
    v = _ar_series(np.array([1.94, -0.9425]), 1.0, (2, 280), 400 + seed)
    v *= 0.1 / np.std(v)
    return du, simulate(EQ11, du.T).T + (v[0] - v[1])[None], 0.01


def _same(m1, m2) -> bool:
    return m1.delay_samples == m2.delay_samples and all(
        np.array_equal(getattr(m1, k), getattr(m2, k)) for k in "ABC"
    )


def test_a_gain_short_of_min_gain_z_is_refused_and_says_so() -> None:
    """On a slow wander the plain refresh accepts fits to noise; with ``min_gain_z`` 1.645
    it accepts only those whose held-out gain is that significant, the same candidates, and
    says of the others how significant they were."""
    strict = RefreshSettings(min_snr=0.0, min_gain_z=1.645)
    plain_n = strict_n = 0
    for seed in range(16):
        du, dy, r = _wander_pairs(seed)
        plain = refresh_model(EQ11, du, dy, r, RefreshSettings(min_snr=0.0), 0.01)
        res = refresh_model(EQ11, du, dy, r, strict, 0.01)
        assert np.isnan(plain.gain_z) and "gain_z" not in plain.as_dict()
        plain_n += plain.accepted
        strict_n += res.accepted
        if not plain.accepted:  # no gain, or unstable: the same refusal
            assert not res.accepted and res.reason == plain.reason
            continue
        assert res.as_dict()["gain_z"] == res.gain_z
        assert res.cv_loss_candidate_m2 == plain.cv_loss_candidate_m2
        if res.accepted:
            assert res.gain_z >= 1.645 and res.reason.endswith(f"(z = {res.gain_z:.2f} >= 1.645)")
            assert _same(res.model, plain.model)
        else:
            assert 0 < res.gain_z < 1.645 and res.model is EQ11 and res.moved == 0.0
            assert (
                res.reason
                == f"rejected: explains held-out data better by z = {res.gain_z:.2f}, below 1.645"
            )  # noqa: E501
    assert 0 < strict_n < plain_n, (strict_n, plain_n)


def test_gain_z_is_the_statistic_of_the_folds_held_out_errors() -> None:
    """``gain_z`` against the two folds' fits made here: each fold's candidate from
    :func:`fit_output_error` on alternate 1 s blocks, its errors on the other blocks, and
    :func:`prediction_loss_z` of the model in use's errors against them (lags up to a block)."""
    du, dy, r = _wander_pairs(3)
    settings = RefreshSettings(min_snr=0.0, delay_search=0, min_gain_z=1e-9)
    res = refresh_model(EQ11, du, dy, r, settings, 0.01)
    assert np.isfinite(res.gain_z)
    b, a = transfer_function(EQ11)
    block = 20  # 1 s at 0.05 s
    fold = (np.arange(du.shape[1]) // block) % 2
    held = np.zeros(du.shape[1])
    for f in (0, 1):
        mask = np.broadcast_to(fold == f, du.shape)[None]
        bf, af, _ = fit_output_error(b[None], a[None], 5, du[None], dy[None], mask, 40, True)
        pred = simulate_tf(bf, af, 5, du[None], True)[0, 0]
        held = np.where(fold == 1 - f, pred - dy[0], held)
    current = simulate(EQ11, du.T).T[0] - dy[0]
    assert res.gain_z == pytest.approx(float(prediction_loss_z(current, held, block)), rel=1e-6)


def test_a_large_true_move_clears_min_gain_z() -> None:
    """A vehicle far from the model in use, a little white noise: the gain is significant
    and the candidate is the one the plain refresh accepts."""
    true = loop(2.2, 0.5, 1.3, 0.25)
    rng = np.random.default_rng(8)
    du = excitation(6)
    dy = simulate(true, du.T).T + 0.005 * rng.standard_normal(du.shape)
    plain = refresh_model(EQ11, du, dy, 2.5e-5, RefreshSettings(), 0.01)
    strict = refresh_model(EQ11, du, dy, 2.5e-5, RefreshSettings(min_gain_z=1.645), 0.01)
    assert plain.accepted and strict.accepted and strict.gain_z > 1.645
    assert _same(strict.model, plain.model) and strict.moved == plain.moved


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf")])
def test_min_gain_z_must_be_finite_and_not_negative(bad: float) -> None:
    with pytest.raises(ValueError, match="min_gain_z"):
        RefreshSettings(min_gain_z=bad)


# ------------------------------------------------------------------ prediction_loss_z


def test_prediction_loss_z_without_lags_is_the_t_statistic_of_the_loss_differential() -> None:
    rng = np.random.default_rng(3)
    e1, e2 = rng.normal(0, 1.2, 300), rng.normal(0, 1.0, 300)
    g = e1**2 - e2**2
    n = g.size
    t = scipy.stats.ttest_1samp(g, 0.0).statistic  # variance with n - 1
    assert prediction_loss_z(e1, e2, 0) == pytest.approx(t * np.sqrt(n / (n - 1)), rel=1e-12)


@pytest.mark.parametrize("lag", [1, 5, 20])
def test_prediction_loss_z_is_the_bartlett_long_run_variance_as_a_quadratic_form(lag) -> None:
    rng = np.random.default_rng(lag)
    e1 = np.convolve(rng.standard_normal(240), np.ones(8) / 8, "same")
    e2 = np.convolve(rng.standard_normal(240), np.ones(8) / 8, "same")
    g = e1**2 - e2**2
    n = g.size
    c = g - g.mean()
    gap = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    weights = np.clip(1.0 - gap / (lag + 1.0), 0.0, None)  # Bartlett's kernel
    long_run = c @ weights @ c / n
    assert prediction_loss_z(e1, e2, lag) == pytest.approx(g.mean() / np.sqrt(long_run / n))


def test_prediction_loss_z_is_antisymmetric_zero_for_equal_losses_and_batched() -> None:
    rng = np.random.default_rng(5)
    e1, e2 = rng.standard_normal((2, 3, 100))
    z = prediction_loss_z(e1, e2, 4)
    assert z.shape == (3,)
    np.testing.assert_allclose(prediction_loss_z(e2, e1, 4), -z, rtol=1e-12)
    for k in range(3):
        assert z[k] == prediction_loss_z(e1[k], e2[k], 4)
    assert prediction_loss_z(e1[0], -e1[0], 4) == 0.0  # the same squares
    assert prediction_loss_z(2 * e1[0], e1[0], 4) > 0  # the other predicted better


def test_prediction_loss_z_is_about_standard_normal_when_both_predict_alike() -> None:
    """Correlated errors of equal variance, the lag their correlation time: the one-sided 5 %
    point is exceeded in about 5 % of the trials (binomial 99.9 % bounds over 2000)."""
    rng = np.random.default_rng(11)
    kernel = np.ones(10) / np.sqrt(10)
    draws = rng.standard_normal((2, 2000, 280 + 9))
    e = np.apply_along_axis(lambda x: np.convolve(x, kernel, "valid"), -1, draws)
    z = prediction_loss_z(e[0], e[1], 20)
    share = np.mean(z > scipy.stats.norm.ppf(0.95))
    low, high = scipy.stats.binom.interval(0.999, 2000, 0.05)
    assert low / 2000 - 0.02 <= share <= high / 2000 + 0.02
    assert abs(np.median(z)) < 0.1


@pytest.mark.parametrize(
    "e1, e2, lag, match",
    [
        (np.zeros(5), np.zeros(6), 1, "one shape"),
        (np.zeros(1), np.zeros(1), 1, "N >= 2"),
        (np.zeros(5), np.zeros(5), -1, "lag"),
        (np.zeros(5), np.zeros(5), 1.5, "lag"),
    ],
)
def test_prediction_loss_z_refusals(e1, e2, lag, match) -> None:
    with pytest.raises(ValueError, match=match):
        prediction_loss_z(e1, e2, lag)


def _moved(u: np.ndarray) -> np.ndarray:
    return np.max(np.abs(np.diff(u, axis=1)), axis=2) > 1e-9


def test_pooled_pairs_without_repeats_are_the_differences_bit_for_bit() -> None:
    rng = np.random.default_rng(3)
    u, y = rng.standard_normal((2, 5, 40)), rng.standard_normal((2, 5, 40))
    du, dy = pooled_pairs(u, y, _moved(u))
    assert np.array_equal(du, np.diff(u, axis=1)) and np.array_equal(dy, np.diff(y, axis=1))


def test_pooled_pairs_compare_the_means_of_the_repeats_scaled_to_two_flights_noise() -> None:
    """Trials 0-3 identical, then 4, then 5 twice: the pairs (0-3 | 4) and (4 | 5, 6), each
    the difference of the groups' means times sqrt(2 / (1/n_a + 1/n_b)), computed here
    from the groups directly."""
    rng = np.random.default_rng(4)
    base, step, step2 = rng.standard_normal((3, 30))
    u = np.array([base] * 4 + [base + step] + [base + step + step2] * 2)[None]
    y = rng.standard_normal((1, 7, 30))
    du, dy = pooled_pairs(u, y, _moved(u))
    c1, c2 = np.sqrt(2 / (1 / 4 + 1)), np.sqrt(2 / (1 + 1 / 2))
    np.testing.assert_allclose(du[0, 3], c1 * step, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(dy[0, 3], c1 * (y[0, 4] - y[0, :4].mean(axis=0)), rtol=1e-13)
    np.testing.assert_allclose(du[0, 4], c2 * step2, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(dy[0, 4], c2 * (y[0, 5:].mean(axis=0) - y[0, 4]), rtol=1e-13)
    assert not np.any(du[0, [0, 1, 2, 5]]) and not np.any(dy[0, [0, 1, 2, 5]])


@given(st.integers(1, 5), st.integers(1, 4), st.integers(0, 10_000))
@settings(max_examples=25, deadline=None)
def test_pooled_pairs_keep_the_model_and_carry_two_flights_noise(n_a, n_b, seed) -> None:
    """A linear plant with a repeatable disturbance: the noiseless pooled pair obeys the model
    exactly (``c dy = F (c du)``), and with white noise of variance r per flight its error has
    the variance 2 r (over 40000 samples, within 5 %: seven of the estimate's standard errors)."""
    rng = np.random.default_rng(seed)
    n = 40_000
    u0, u1 = rng.standard_normal((2, n)) * 0.1
    d = rng.standard_normal(n)  # repeatable
    u = np.array([u0] * n_a + [u1] * n_b)[None]
    clean = np.array([simulate(EQ11, x[:, None])[:, 0] + d for x in u[0]])[None]
    du, dy = pooled_pairs(u, clean, _moved(u))
    t = n_a - 1
    np.testing.assert_allclose(dy[0, t], simulate(EQ11, du[0, t][:, None])[:, 0], atol=1e-12)
    r = 0.04
    _, noisy = pooled_pairs(u, clean + np.sqrt(r) * rng.standard_normal(clean.shape), _moved(u))
    assert np.var(noisy[0, t] - dy[0, t]) == pytest.approx(2 * r, rel=0.05)


def test_anchor_pairs_compare_every_group_with_trial_0s_flights() -> None:
    """Trials 0-3 identical, then 4, then 5 twice: the pairs (0-3 | 4) and (0-3 | 5, 6), each
    the difference of the groups' means times sqrt(2 / (1/n_0 + 1/n_b)), computed here from
    the groups directly; the first is the pooled pair."""
    rng = np.random.default_rng(5)
    base, step, step2 = rng.standard_normal((3, 30))
    u = np.array([base] * 4 + [base + step] + [base + step + step2] * 2)[None]
    y = rng.standard_normal((1, 7, 30))
    du, dy = anchor_pairs(u, y, _moved(u))
    anchor = y[0, :4].mean(axis=0)
    c1, c2 = np.sqrt(2 / (1 / 4 + 1)), np.sqrt(2 / (1 / 4 + 1 / 2))
    np.testing.assert_allclose(du[0, 3], c1 * step, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(dy[0, 3], c1 * (y[0, 4] - anchor), rtol=1e-13)
    np.testing.assert_allclose(du[0, 4], c2 * (step + step2), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(dy[0, 4], c2 * (y[0, 5:].mean(axis=0) - anchor), rtol=1e-13)
    assert not np.any(du[0, [0, 1, 2, 5]]) and not np.any(dy[0, [0, 1, 2, 5]])
    pooled = pooled_pairs(u, y, _moved(u))
    assert np.array_equal(du[0, 3], pooled[0][0, 3]) and np.array_equal(dy[0, 3], pooled[1][0, 3])


@given(st.lists(st.integers(1, 3), min_size=2, max_size=5), st.integers(0, 10_000))
@settings(max_examples=25, deadline=None)
def test_anchor_pairs_keep_the_model_for_any_groups(sizes: list[int], seed: int) -> None:
    """Groups of 1-3 flights of random setpoints, a linear plant and a repeatable disturbance:
    every noiseless anchor pair obeys the model exactly (``c dy = F (c du)``)."""
    rng = np.random.default_rng(seed)
    inputs = rng.standard_normal((len(sizes), 60)) * 0.1
    u = np.array([x for x, n in zip(inputs, sizes, strict=True) for _ in range(n)])[None]
    d = rng.standard_normal(60)
    y = np.array([simulate(EQ11, x[:, None])[:, 0] + d for x in u[0]])[None]
    moved = _moved(u)
    du, dy = anchor_pairs(u, y, moved)
    for t in np.flatnonzero(moved[0]):
        np.testing.assert_allclose(dy[0, t], simulate(EQ11, du[0, t][:, None])[:, 0], atol=1e-12)
