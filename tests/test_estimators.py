"""Tests of gcs.core.estimators: RTS smoother against the batch MAP solution, K-ILC by hand."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.core.estimators import (
    KilcSettings,
    KilcState,
    SmootherSettings,
    kilc_gains,
    kilc_init,
    kilc_update,
    rts_smoother,
    smoother_operator,
)


def batch_map(z: np.ndarray, q: float, r: float, p0: float, d0: float):
    """argmin sum (z-d)^2/r + sum (d(k+1)-d(k))^2/q + (d(1)-d0)^2/p0, and diag of H^-1.

    The normal equations are tridiagonal: H d = z/r + e1 d0/p0.
    """
    n = len(z)
    diff = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n))
    e1 = np.zeros(n)
    e1[0] = 1.0
    H = sp.identity(n) / r + (diff.T @ diff) / q + sp.diags(e1 / p0)
    rhs = z / r + e1 * d0 / p0
    H = sp.csc_matrix(H)
    d = spla.spsolve(H, rhs)
    cov = np.linalg.inv(H.toarray())
    return np.atleast_1d(d), np.diag(cov)


def scalar_kalman_filter(z, q, r, p0, d0):
    """Textbook scalar filter on the random walk; returns estimates and posterior variances."""
    d, p_prior = d0, p0
    est, var = [], []
    for zk in z:
        k = p_prior / (p_prior + r)
        d = d + k * (zk - d)
        p_post = (1 - k) * p_prior
        est.append(d)
        var.append(p_post)
        p_prior = p_post + q
    return np.array(est), np.array(var)


variance = st.floats(1e-4, 10.0)


@settings(max_examples=60, deadline=None)
@given(
    q=variance,
    r=variance,
    p0=variance,
    d0=st.floats(-2.0, 2.0),
    n=st.integers(1, 80),
    seed=st.integers(0, 2**31 - 1),
)
def test_rts_smoother_equals_batch_map(q, r, p0, d0, n, seed):
    z = np.random.default_rng(seed).normal(0.3, 1.0, n)
    result = rts_smoother(z, SmootherSettings(q=q, r=r, p0=p0, d0=d0))
    d_map, var_map = batch_map(z, q, r, p0, d0)
    scale = 1.0 + np.max(np.abs(z)) + abs(d0)
    np.testing.assert_allclose(result.d_hat, d_map, rtol=1e-7, atol=1e-8 * scale)
    np.testing.assert_allclose(result.p, var_map, rtol=1e-6, atol=1e-12)
    d_filt, p_filt = scalar_kalman_filter(z, q, r, p0, d0)
    np.testing.assert_allclose(result.d_filt, d_filt, rtol=1e-9, atol=1e-12 * scale)
    # smoothing never increases the variance; the last sample is not smoothed
    assert np.all(result.p <= p_filt * (1 + 1e-9) + 1e-15)
    assert result.d_hat[-1] == pytest.approx(result.d_filt[-1])


def test_table_one_settings_equal_batch_map():
    s = SmootherSettings()  # Table I: q = 0.1, r = 0.01, p0 = 0.1, d0 = 0
    assert (s.q, s.r, s.p0, s.d0) == (0.1, 0.01, 0.1, 0.0)
    z = np.sin(np.linspace(0, 6, 200)) + np.random.default_rng(3).normal(0, 0.1, 200)
    d_map, _ = batch_map(z, 0.1, 0.01, 0.1, 0.0)
    np.testing.assert_allclose(rts_smoother(z, s).d_hat, d_map, rtol=1e-9, atol=1e-10)


def test_constant_disturbance_is_recovered_far_below_noise():
    rng = np.random.default_rng(7)
    sigma, d_true, n = 0.1, 0.37, 3000
    z = d_true + rng.normal(0.0, sigma, n)
    result = rts_smoother(z, SmootherSettings(q=1e-7, r=sigma**2, p0=1.0, d0=0.0))
    err = result.d_hat - d_true
    assert np.sqrt(np.mean(err**2)) < 0.1 * sigma
    assert np.max(np.abs(err)) < 0.25 * sigma
    # the raw measurements are of course not that good
    assert np.sqrt(np.mean((z - d_true) ** 2)) > 0.9 * sigma


def test_smoothed_variance_below_filtered_and_symmetric_in_the_middle():
    n = 101
    res = rts_smoother(np.zeros(n), SmootherSettings(q=0.01, r=0.1, p0=1e6))
    _, p_filt = scalar_kalman_filter(np.zeros(n), 0.01, 0.1, 1e6, 0.0)
    assert np.all(res.p <= p_filt + 1e-15)
    assert np.all(res.p[:-1] < p_filt[:-1])
    # with a diffuse prior the smoother's variances are time-symmetric
    np.testing.assert_allclose(res.p, res.p[::-1], rtol=1e-4)


def test_zero_prior_variance_and_zero_q_keep_the_initial_estimate():
    z = np.random.default_rng(1).normal(size=30)
    res = rts_smoother(z, SmootherSettings(q=0.0, r=0.01, p0=0.0, d0=0.25))
    np.testing.assert_allclose(res.d_hat, 0.25)
    np.testing.assert_allclose(res.p, 0.0)


@settings(max_examples=20, deadline=None)
@given(
    q=variance,
    r=variance,
    p0=variance,
    d0=st.floats(-2.0, 2.0),
    n=st.integers(1, 40),
    m=st.integers(1, 5),
    seed=st.integers(0, 2**31 - 1),
)
def test_smoother_operator_and_batch_equal_the_function(q, r, p0, d0, n, m, seed):
    s = SmootherSettings(q=q, r=r, p0=p0, d0=d0)
    Z = np.random.default_rng(seed).normal(size=(n, m))
    S, s0 = smoother_operator(n, s)
    assert S.shape == (n, n) and s0.shape == (n,)
    batch = rts_smoother(Z, s)
    assert batch.d_hat.shape == (n, m)
    for c in range(m):
        single = rts_smoother(Z[:, c], s)
        np.testing.assert_allclose(batch.d_hat[:, c], single.d_hat, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(batch.d_filt[:, c], single.d_filt, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(batch.p, single.p)
        np.testing.assert_allclose(S @ Z[:, c] + s0 * d0, single.d_hat, rtol=1e-9, atol=1e-11)


def test_smoother_operator_rows_sum_with_s0_to_one():
    # a constant input equal to d0 is a fixed point: S 1 + s0 = 1
    S, s0 = smoother_operator(50, SmootherSettings(q=0.05, r=0.02, p0=0.3))
    np.testing.assert_allclose(S.sum(axis=1) + s0, 1.0, rtol=1e-12)


# ------------------------------------------------------------------------------ K-ILC


def test_kilc_gains_table_one_by_hand():
    q, r, p0 = Fraction(1, 10), Fraction(1, 100), Fraction(1, 10)
    expected = []
    p = p0
    for _ in range(6):
        k = p / (p + r)
        expected.append(k)
        p = (1 - k) * p + q
    assert expected[0] == Fraction(10, 11)  # 0.1 / 0.11
    gains = kilc_gains(KilcSettings(q=0.1, r=0.01, p0=0.1), 6)
    np.testing.assert_allclose(gains, [float(k) for k in expected], rtol=1e-13)
    assert gains[0] == pytest.approx(0.1 / 0.11, rel=1e-15)
    # second gain: P- = 0.1 * 0.01 / 0.11 + 0.1
    p_minus = 0.1 * 0.01 / 0.11 + 0.1
    assert gains[1] == pytest.approx(p_minus / (p_minus + 0.01), rel=1e-13)


@settings(max_examples=30, deadline=None)
@given(
    q=variance,
    r=variance,
    p0=variance,
    d0=st.floats(-1.0, 1.0),
    trials=st.integers(1, 6),
    n=st.integers(1, 20),
    seed=st.integers(0, 2**31 - 1),
)
def test_kilc_update_equals_hand_written_kalman_filter(q, r, p0, d0, trials, n, seed):
    s = KilcSettings(q=q, r=r, p0=p0, d0=d0)
    zs = np.random.default_rng(seed).normal(size=(trials, n))
    state = kilc_init(n, s)
    np.testing.assert_array_equal(state.d_hat, np.full(n, d0))
    assert state.p == p0 and state.trials == 0
    # per sample k, the iteration-domain filter is a scalar filter over trials
    expected = np.empty((trials, n))
    expected_p = None
    for k in range(n):
        est, var = scalar_kalman_filter(zs[:, k], q, r, p0, d0)
        expected[:, k] = est
        expected_p = var
    gains = kilc_gains(s, trials)
    for j in range(trials):
        previous = state
        state = kilc_update(state, zs[j], s)
        assert state.trials == j + 1
        np.testing.assert_allclose(state.d_hat, expected[j], rtol=1e-10, atol=1e-12)
        assert state.p == pytest.approx(expected_p[j], rel=1e-10)
        np.testing.assert_allclose(
            state.d_hat, previous.d_hat + gains[j] * (zs[j] - previous.d_hat), rtol=1e-12
        )


def test_kilc_state_carries_over_and_is_not_reset():
    s = KilcSettings()
    z = np.full(4, 1.0)
    s1 = kilc_update(kilc_init(4, s), z, s)
    s2 = kilc_update(s1, z, s)
    # a restart from a state rebuilt from the stored estimate gives the same result
    rebuilt = KilcState(d_hat=s1.d_hat.copy(), p=s1.p, trials=s1.trials)
    np.testing.assert_array_equal(kilc_update(rebuilt, z, s).d_hat, s2.d_hat)
    # a fresh prior would give a different answer (the second prior is P+ + Q, not P0)
    fresh = kilc_update(KilcState(d_hat=s1.d_hat.copy(), p=s.p0, trials=0), z, s)
    assert not np.allclose(fresh.d_hat, s2.d_hat)


def test_kilc_batch_columns_are_independent_filters():
    s = KilcSettings(q=0.05, r=0.02, p0=0.3)
    Z = np.random.default_rng(2).normal(size=(3, 6, 4))
    batch = KilcState(d_hat=np.zeros((6, 4)), p=s.p0)
    singles = [kilc_init(6, s) for _ in range(4)]
    for j in range(3):
        batch = kilc_update(batch, Z[j], s)
        singles = [kilc_update(st_, Z[j][:, c], s) for c, st_ in enumerate(singles)]
    for c in range(4):
        np.testing.assert_allclose(batch.d_hat[:, c], singles[c].d_hat, rtol=1e-13)
        assert batch.p == pytest.approx(singles[c].p)


# ------------------------------------------------------------------------------ refusals


@pytest.mark.parametrize("cls", [SmootherSettings, KilcSettings])
@pytest.mark.parametrize(
    "kwargs",
    [
        {"q": -0.1},
        {"r": 0.0},
        {"r": -1.0},
        {"p0": -1e-3},
        {"q": float("nan")},
        {"r": float("inf")},
        {"p0": float("nan")},
    ],
)
def test_invalid_settings_raise_value_error(cls, kwargs):
    with pytest.raises(ValueError):
        cls(**kwargs)


@pytest.mark.parametrize(
    "z",
    [np.array([]), np.zeros((2, 2, 2)), np.array([0.0, np.nan]), np.array([np.inf, 1.0])],
)
def test_rts_smoother_refuses_bad_residuals(z):
    with pytest.raises(ValueError):
        rts_smoother(z, SmootherSettings())


def test_kilc_update_refuses_wrong_length_and_nan():
    s = KilcSettings()
    state = kilc_init(5, s)
    with pytest.raises(ValueError, match="samples"):
        kilc_update(state, np.zeros(4), s)
    with pytest.raises(ValueError, match="NaN"):
        kilc_update(state, np.array([0, 0, np.nan, 0, 0]), s)
