"""Tests of the noise model from data (gcs.core.noise_model)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.core.estimators import SmootherSettings, rts_smoother
from gcs.core.noise_model import (
    IterationNoise,
    drift_scale,
    estimate_disturbance,
    fit_iteration_noise,
    fit_time_noise,
    iteration_filter,
    rts_smooth,
)


def iteration_history(
    rng: np.random.Generator, q0: float, kappa: float, r: float, m: np.ndarray, shape: tuple
) -> np.ndarray:
    """z_j = D_j + v_j with D_j = D_(j-1) + w_j, w_j ~ N(0, q0 [m_j > 0] + kappa m_j)."""
    d = np.cumsum(rng.standard_normal(shape[:-2] + (shape[-1],)), axis=-1) * 0.01
    zs = [d]
    for mj in m:
        q = (q0 if mj > 0 else 0.0) + kappa * mj
        d = d + np.sqrt(q) * rng.standard_normal(d.shape)
        zs.append(d)
    return np.stack(zs, axis=-2) + np.sqrt(r) * rng.standard_normal(shape)


M_SCALES = np.array([1.0, 0.3, 0.1, 0.03, 0.01, 0.003, 0.001])


def standard_errors(q0: float, kappa: float, r: float, m: np.ndarray, n: int) -> np.ndarray:
    """Asymptotic standard errors of (q0, kappa, r): the inverse Fisher information of the
    restricted likelihood of the trial differences, n independent samples (computed here
    from its definition, independently of the module)."""
    j = m.size
    t = 2 * np.eye(j) - np.eye(j, k=1) - np.eye(j, k=-1)
    mats = [np.diag((m > 0).astype(float)), np.diag(m), t]
    sigma = q0 * mats[0] + kappa * mats[1] + r * t
    v = np.linalg.inv(sigma)
    info = np.array([[0.5 * n * np.trace(v @ a @ v @ b) for b in mats] for a in mats])
    return np.sqrt(np.diag(np.linalg.inv(info)))


@settings(max_examples=15, deadline=None)
@given(
    q0=st.sampled_from([1e-5, 1e-4, 1e-3]),
    kappa=st.sampled_from([0.01, 0.1]),
    r=st.sampled_from([1e-4, 1e-3]),
    seed=st.integers(0, 1000),
)
def test_ml_recovers_known_iteration_variances(q0: float, kappa: float, r: float, seed: int):
    """8 trials x 5000 samples: every parameter within 4.5 asymptotic standard errors."""
    rng = np.random.default_rng(seed)
    z = iteration_history(rng, q0, kappa, r, M_SCALES, (8, 5000))
    est = fit_iteration_noise(z, M_SCALES)
    assert est.identified
    se = standard_errors(q0, kappa, r, M_SCALES, 5000)
    got = np.array([float(est.q0_m2), float(est.kappa), float(est.r_m2)])
    assert np.all(np.abs(got - [q0, kappa, r]) <= 4.5 * se), (got, se)


def test_ml_is_batched_over_problems() -> None:
    rng = np.random.default_rng(5)
    z = iteration_history(rng, 1e-4, 0.05, 4e-4, M_SCALES, (3, 8, 1500))
    batch = fit_iteration_noise(z, np.broadcast_to(M_SCALES, (3, 7)))
    for i in range(3):
        one = fit_iteration_noise(z[i], M_SCALES)
        assert float(one.r_m2) == pytest.approx(float(batch.r_m2[i]), rel=1e-6)
        assert float(one.kappa) == pytest.approx(float(batch.kappa[i]), rel=1e-5, abs=1e-12)


def test_a_repeat_alone_measures_r() -> None:
    rng = np.random.default_rng(6)
    z = iteration_history(rng, 0.0, 0.0, 2e-4, np.array([0.0]), (2, 5000))
    est = fit_iteration_noise(z, np.array([0.0]))
    assert not est.identified
    assert float(est.r_m2) == pytest.approx(2e-4, rel=0.05)
    assert float(est.q0_m2) == 0.0 and float(est.kappa) == 0.0


def test_one_moved_pair_keeps_r_at_its_bound() -> None:
    rng = np.random.default_rng(7)
    z = iteration_history(rng, 0.0, 0.1, 1e-4, np.array([0.5]), (2, 5000))
    est = fit_iteration_noise(z, np.array([0.5]), r_min_m2=1e-4)
    assert float(est.r_m2) == pytest.approx(1e-4)
    assert float(est.kappa) * 0.5 + 2e-4 == pytest.approx(np.mean(np.diff(z, axis=0) ** 2))


def test_without_offset_q0_is_zero() -> None:
    rng = np.random.default_rng(8)
    z = iteration_history(rng, 1e-3, 0.05, 4e-4, M_SCALES, (8, 2000))
    assert float(fit_iteration_noise(z, M_SCALES, drift_offset=False).q0_m2) == 0.0


def test_shapes_refused() -> None:
    with pytest.raises(ValueError):
        fit_iteration_noise(np.zeros((3, 100)), np.zeros(3))  # m has T entries, not T-1
    with pytest.raises(ValueError):
        fit_iteration_noise(np.zeros((3, 2)), np.zeros(2))  # N < 4
    with pytest.raises(ValueError):
        fit_time_noise(np.zeros(100))
    bad = np.zeros((2, 50))
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        fit_time_noise(bad)


@settings(max_examples=15, deadline=None)
@given(
    log_q=st.floats(-6, -4),
    log_r=st.floats(-5, -3),
    seed=st.integers(0, 1000),
)
def test_ml_recovers_known_time_variances(log_q: float, log_r: float, seed: int):
    """Random walk + white noise, 5 series of 4000 samples, q / r in [1e-3, 10].

    One realisation: within 50 % (the standard deviation of the estimate is up to 15 % of q
    at q / r = 1e-3 and 12 % of r at q / r = 10, measured over 40 seeds).
    """
    q, r = 10.0**log_q, 10.0**log_r
    est = fit_time_noise(time_history(np.random.default_rng(seed), q, r, (5, 4000)))
    assert float(est.q_m2) == pytest.approx(q, rel=0.5)
    assert float(est.r_m2) == pytest.approx(r, rel=0.5)


def time_history(rng: np.random.Generator, q: float, r: float, shape: tuple) -> np.ndarray:
    d = np.cumsum(np.sqrt(q) * rng.standard_normal(shape), axis=-1)
    return d + np.sqrt(r) * rng.standard_normal(shape)


@pytest.mark.parametrize(("q", "r"), [(1e-6, 1e-3), (1e-4, 1e-5)])
def test_time_ml_is_unbiased(q: float, r: float) -> None:
    """Mean over 40 realisations within 5 %."""
    z = time_history(np.random.default_rng(13), q, r, (40, 5, 4000))
    est = fit_time_noise(z)
    assert np.mean(est.q_m2) == pytest.approx(q, rel=0.05)
    assert np.mean(est.r_m2) == pytest.approx(r, rel=0.05)


def test_rts_smooth_is_algorithm_one_with_a_diffuse_start() -> None:
    rng = np.random.default_rng(9)
    z = np.cumsum(rng.standard_normal(200)) * 0.01 + 0.02 * rng.standard_normal(200)
    ref = rts_smoother(z, SmootherSettings(q=1e-4, r=4e-4, p0=1e9, d0=0.0))
    d, p = rts_smooth(z, 1e-4, 4e-4)
    np.testing.assert_allclose(d, ref.d_hat, atol=1e-9)
    np.testing.assert_allclose(p, ref.p, rtol=1e-6)
    # per-series and per-sample variances
    dd, _ = rts_smooth(np.stack([z, z]), np.array([1e-4, 1e-2]), np.array([4e-4, 4e-4]))
    np.testing.assert_allclose(dd[0], d, atol=1e-12)
    d2, _ = rts_smooth(z, 1e-4, np.full(200, 4e-4))
    np.testing.assert_allclose(d2, d, atol=1e-12)
    with pytest.raises(ValueError):
        rts_smooth(z, -1.0, 1.0)


def test_iteration_filter_weights() -> None:
    rng = np.random.default_rng(10)
    z = rng.standard_normal((5, 30))
    m = np.ones(4)
    none = IterationNoise(np.array(0.0), np.array(0.0), np.array(1.0), np.array(0.0), True)
    avg = iteration_filter(z, m, none)
    np.testing.assert_allclose(avg.d_hat_m, z.mean(axis=0), atol=1e-12)
    np.testing.assert_allclose(avg.weights, 0.2, atol=1e-12)
    fast = IterationNoise(np.array(1e9), np.array(0.0), np.array(1.0), np.array(0.0), True)
    last = iteration_filter(z, m, fast)
    np.testing.assert_allclose(last.d_hat_m, z[-1], atol=1e-8)
    mixed = IterationNoise(np.array(0.3), np.array(0.2), np.array(1.0), np.array(0.0), True)
    est = iteration_filter(z, m, mixed)
    assert est.weights.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(est.weights @ z, est.d_hat_m, atol=1e-12)
    # a repeat (m = 0) gets no drift: two flights of the same input are averaged
    rep = iteration_filter(z[:2], np.zeros(1), fast)
    np.testing.assert_allclose(rep.d_hat_m, z[:2].mean(axis=0), atol=1e-12)


def test_estimate_with_one_trial_is_the_smoothed_residual() -> None:
    rng = np.random.default_rng(11)
    z = np.cumsum(rng.standard_normal((1, 300)), axis=-1) * 0.01 + 0.01 * rng.standard_normal(
        (1, 300)
    )
    est = estimate_disturbance(z, np.zeros(0), smooth_in_time=True)
    tn = fit_time_noise(z)
    d, _ = rts_smooth(z[0], tn.q_m2, tn.r_m2)
    np.testing.assert_allclose(est.d_hat_m, d, atol=1e-12)
    raw = estimate_disturbance(z, np.zeros(0), smooth_in_time=False)
    np.testing.assert_allclose(raw.d_hat_m, z[0], atol=0)


def test_estimate_averages_repeatable_disturbance_toward_the_truth() -> None:
    """Eight trials of the same input: the estimate beats the newest residual by ~sqrt(8)."""
    rng = np.random.default_rng(12)
    t = np.linspace(0, 10, 400)
    truth = 0.1 * np.sin(t)
    v = np.stack([0.02 * rng.standard_normal(400) for _ in range(8)])
    z = truth + v
    est = estimate_disturbance(z, np.zeros(7), smooth_in_time=False)
    err_new = np.sqrt(np.mean((est.d_hat_m - truth) ** 2))
    err_last = np.sqrt(np.mean((z[-1] - truth) ** 2))
    assert err_new < 0.45 * err_last


def test_drift_scale_is_the_mean_square_predicted_change() -> None:
    x = np.array([[[0.0, 3.0, 4.0, 0.0]], [[1.0, 1.0, 1.0, 1.0]]])  # (2, 1, 4)
    np.testing.assert_allclose(drift_scale(x), [[25.0 / 4.0], [1.0]])
    with pytest.raises(ValueError):
        drift_scale(np.ones(4))
