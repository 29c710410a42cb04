"""Noise model from the recorded trials, and the disturbance estimate that uses every trial.

Per axis, trial ``j`` has the residual ``z_j = Y_j - F U_j`` (``F`` the model in use). Two
random-walk models describe it, the same two the paper's estimators assume, but with their
variances estimated from the data instead of taken from Table I:

* **Across iterations** (K-ILC's model): ``z_j = D_j + v_j``, ``D_j = D_(j-1) + w_j`` with
  ``v_j ~ N(0, r)`` the non-repeatable error of one flight and ``w_j ~ N(0, q_j)`` the change
  of the disturbance between trials. The disturbance moves when the input moves, because the
  model is not exact (``(F_true - F) dU`` lands in the residual), so
  ``q_j = q0 + kappa m_j`` with ``m_j = mean_k (F (U_j - U_(j-1)))(k)^2`` the model's predicted
  output change [m^2] and ``kappa`` the relative model error variance. ``(q0, kappa, r)`` are
  maximum-likelihood estimates from the residual differences ``z_j - z_(j-1)`` (restricted
  likelihood: the unknown ``D_0`` drops out), samples treated as replicates (a composite
  likelihood: consistent for the per-sample variances, whatever the correlation in time).
  Fisher scoring solves it in closed form steps because the covariance is linear in the
  parameters. A Kalman filter along the iteration axis with these variances then weighs every
  trial so far: at steady state (small input changes, ``q_j -> q0``) it averages many trials
  and the estimate's error shrinks below one flight's non-repeatable error.
* **In time** (Algorithm 1's model): ``z(k) = d(k) + mu(k)``, ``d(k+1) = d(k) + omega(k)``,
  ``omega ~ N(0, q_time)``, ``mu ~ N(0, r_white)``. Maximum likelihood by Whittle's
  frequency-domain approximation (asymptotically equivalent to the exact likelihood; the
  differenced model is an MA(1) with spectrum ``q + 2 r (1 - cos w)``), the ratio ``q / r`` on a
  grid with ``r`` concentrated out. The white part ``r_white`` is certainly non-repeatable, so
  it bounds ``r`` from below; after the iteration filter the white part of the estimate has
  variance ``r_eff = r_white sum_i a_i^2`` (``a_i`` the filter's weights on the trials), which
  the RTS smoother in time is given.

Shapes: residual histories are ``(..., T, N)``, trials ``j = 0..T-1`` along the second-to-last
axis and time ``k = 1..N`` along the last; leading axes are independent problems (axes, Monte
Carlo runs), each with its own parameters. Everything is in metres. The maths and the evidence
are in ``docs/learning-floor.md``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

__all__ = [
    "TimeNoise",
    "IterationNoise",
    "IterationEstimate",
    "fit_time_noise",
    "fit_iteration_noise",
    "iteration_filter",
    "rts_smooth",
    "drift_scale",
    "DisturbanceEstimate",
    "estimate_disturbance",
]

#: log10 of the ratio q_time / r_white searched by :func:`fit_time_noise`.
_LOG_RATIO_GRID = np.arange(-8.0, 8.0001, 0.05)
#: Fisher-scoring iterations and relative tolerance on the parameters.
_SCORING_ITER = 60
_SCORING_TOL = 1e-6


@dataclass(frozen=True)
class TimeNoise:
    """Random walk plus white noise in time, per problem.

    Parameters
    ----------
    q_m2 : ndarray, shape (...)
        Variance of the random-walk increment per sample [m^2].
    r_m2 : ndarray, shape (...)
        Variance of the white measurement noise [m^2].
    """

    q_m2: np.ndarray
    r_m2: np.ndarray


@dataclass(frozen=True)
class IterationNoise:
    """Random walk along the iteration axis, per problem.

    Parameters
    ----------
    q0_m2 : ndarray, shape (...)
        Drift variance per trial independent of the input change [m^2].
    kappa : ndarray, shape (...)
        Drift variance per unit of predicted output change ``m_j`` (relative model error
        variance) [-].
    r_m2 : ndarray, shape (...)
        Variance of one flight's non-repeatable error per sample [m^2].
    loglik : ndarray, shape (...)
        Restricted log-likelihood per sample at the estimate (comparable between fits of the
        same data only).
    identified : ndarray of bool, shape (...)
        False when the history has fewer than two residual differences: then ``r`` is its
        lower bound and the whole difference is drift (the newest trial dominates).
    """

    q0_m2: np.ndarray
    kappa: np.ndarray
    r_m2: np.ndarray
    loglik: np.ndarray
    identified: np.ndarray


@dataclass(frozen=True)
class IterationEstimate:
    """Output of :func:`iteration_filter`.

    Parameters
    ----------
    d_hat_m : ndarray, shape (..., N)
        Estimate of the disturbance of the newest trial [m].
    p_m2 : ndarray, shape (...)
        Its error variance per sample [m^2].
    weights : ndarray, shape (..., T)
        ``d_hat = sum_j weights[j] z_j``; they sum to 1.
    """

    d_hat_m: np.ndarray
    p_m2: np.ndarray
    weights: np.ndarray


def _check_history(z: np.ndarray) -> np.ndarray:
    z = np.asarray(z, dtype=float)
    if z.ndim < 2 or z.shape[-1] < 4 or z.shape[-2] < 1:
        raise ValueError(
            f"residual history must have shape (..., T, N) with T >= 1 trials and N >= 4 "
            f"samples, got {z.shape}"
        )
    if not np.all(np.isfinite(z)):
        raise ValueError("residual history contains NaN or inf")
    return z


def drift_scale(predicted_change_m: np.ndarray) -> np.ndarray:
    """``m_j``: mean square of the model's predicted output change between trials.

    Parameters
    ----------
    predicted_change_m : ndarray, shape (..., T-1, N)
        ``F (U_j - U_(j-1))`` for ``j = 1..T-1`` [m].

    Returns
    -------
    ndarray, shape (..., T-1)
        [m^2]
    """
    x = np.asarray(predicted_change_m, dtype=float)
    if x.ndim < 2:
        raise ValueError(f"predicted_change_m must have shape (..., T-1, N), got {x.shape}")
    return np.mean(x * x, axis=-1)


# ---------------------------------------------------------------------------------------------
# In time: Whittle likelihood of the differenced local-level model
# ---------------------------------------------------------------------------------------------


def _tapered_periodogram(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (over the trial axis) Hann-tapered periodogram of the differenced series."""
    x = np.diff(z, axis=-1)  # (..., T, N-1)
    n = x.shape[-1]
    h = np.hanning(n + 2)[1:-1]
    spec = np.fft.rfft(x * h, axis=-1)
    per = (spec.real**2 + spec.imag**2) / np.sum(h * h)  # E = spectral density of x
    per = per.mean(axis=-2)  # (..., F)
    omega = 2.0 * np.pi * np.arange(per.shape[-1]) / n
    keep = (omega > 0) & (omega < np.pi)
    return per[..., keep], omega[keep]


@functools.lru_cache(maxsize=16)
def _whittle_grid(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What :func:`fit_time_noise`'s grid search needs apart from the data, for series of
    ``n`` samples (kept: read-only arrays): the ratios ``q / r`` (G,), ``1 / shape`` (G, F)
    and the mean over frequencies of ``log shape`` (G,)."""
    omega = 2.0 * np.pi * np.arange((n - 1) // 2 + 1) / (n - 1)  # the periodogram's
    omega = omega[(omega > 0) & (omega < np.pi)]
    base = 2.0 * (1.0 - np.cos(omega))  # spectrum of mu(k) - mu(k-1) per unit r
    ratios = 10.0**_LOG_RATIO_GRID  # (G,)
    shape = ratios[:, None] + base[None, :]  # (G, F)
    out = (ratios, 1.0 / shape, np.mean(np.log(shape), axis=1))
    for arr in out:
        arr.flags.writeable = False
    return out


def fit_time_noise(z: np.ndarray) -> TimeNoise:
    """Maximum-likelihood ``(q_time, r_white)`` of the random walk plus white noise in time.

    The parameters are shared by the trials of one problem (axis ``-2``).

    Parameters
    ----------
    z : ndarray, shape (..., T, N)
        Residual histories [m].

    Returns
    -------
    TimeNoise
        Arrays of shape ``z.shape[:-2]``.
    """
    z = _check_history(z)
    per, omega = _tapered_periodogram(z)  # (..., F), (F,)
    ratios, inv_shape, mean_log_shape = _whittle_grid(z.shape[-1])
    # r concentrated out: r_hat = mean(I / shape); -loglik / F = log r_hat + mean log shape
    r_hat = np.einsum("...f,gf->...g", per, inv_shape) / omega.size  # (..., G)
    nll = np.log(np.maximum(r_hat, 1e-300)) + mean_log_shape
    best = np.argmin(nll, axis=-1)
    r = np.take_along_axis(r_hat, best[..., None], axis=-1)[..., 0]
    return TimeNoise(q_m2=ratios[best] * r, r_m2=r)


def rts_smooth(z: np.ndarray, q_m2: np.ndarray, r_m2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RTS smoother of the random walk in time, with its own ``(q, r)`` per series.

    The same recursion as Algorithm 1 (:func:`gcs.core.estimators.rts_smoother`) with a
    diffuse start (the first sample initialises the estimate), vectorised over series whose
    variances differ.

    Parameters
    ----------
    z : ndarray, shape (..., N)
        Series to smooth [m].
    q_m2 : ndarray, shape (...)
        Random-walk increment variance per sample [m^2], ``>= 0``.
    r_m2 : ndarray, shape (...) or (..., N)
        Measurement noise variance [m^2], ``> 0``; per sample when it has the shape of ``z``.

    Returns
    -------
    d_hat : ndarray, shape (..., N)
        Smoothed series [m].
    p : ndarray, shape (..., N)
        Smoothed error variance [m^2].
    """
    z = np.asarray(z, dtype=float)
    q = np.broadcast_to(np.asarray(q_m2, dtype=float), z.shape[:-1])
    r_in = np.asarray(r_m2, dtype=float)
    r = np.broadcast_to(r_in if r_in.shape == z.shape else r_in[..., None], z.shape)
    if np.any(~np.isfinite(q)) or np.any(q < 0) or np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise ValueError("rts_smooth needs finite q >= 0 and r > 0")
    if z[..., 0].size <= _SCALAR_SERIES:
        # a few series (the learner's one): the same recursion on Python floats, one series
        # at a time, a hundred times faster than numpy's per-sample calls and equal to them
        # bit for bit (IEEE double, the same operations in the same order)
        d_hat = np.empty_like(z)
        p_s = np.empty(z.shape)
        for i in np.ndindex(z.shape[:-1]):
            d_hat[i], p_s[i] = _rts_series(z[i].tolist(), float(q[i]), r[i].tolist())
        return d_hat, p_s
    n = z.shape[-1]
    d_filt = np.empty_like(z)
    p_post = np.empty(z.shape)
    d = z[..., 0].copy()
    p = r[..., 0].copy()
    d_filt[..., 0], p_post[..., 0] = d, p
    for k in range(1, n):
        p_prior = p + q
        g = p_prior / (p_prior + r[..., k])
        d = d + g * (z[..., k] - d)
        p = (1.0 - g) * p_prior
        d_filt[..., k], p_post[..., k] = d, p
    d_hat = np.empty_like(z)
    p_s = np.empty(z.shape)
    d_hat[..., -1], p_s[..., -1] = d_filt[..., -1], p_post[..., -1]
    for k in range(n - 2, -1, -1):
        p_next = p_post[..., k] + q
        g = np.divide(p_post[..., k], p_next, out=np.zeros_like(p_next), where=p_next > 0)
        d_hat[..., k] = d_filt[..., k] + g * (d_hat[..., k + 1] - d_filt[..., k])
        p_s[..., k] = p_post[..., k] + g * g * (p_s[..., k + 1] - p_next)
    return d_hat, p_s


#: Up to this many series, :func:`rts_smooth` runs its recursion on Python floats.
_SCALAR_SERIES = 8


def _rts_series(z: list[float], q: float, r: list[float]) -> tuple[list[float], list[float]]:
    """:func:`rts_smooth`'s recursion for one series, on Python floats."""
    n = len(z)
    d, p = z[0], r[0]
    d_filt, p_post = [d] * n, [p] * n
    for k in range(1, n):
        p_prior = p + q
        g = p_prior / (p_prior + r[k])
        d = d + g * (z[k] - d)
        p = (1.0 - g) * p_prior
        d_filt[k], p_post[k] = d, p
    d_hat, p_s = d_filt.copy(), p_post.copy()
    for k in range(n - 2, -1, -1):
        pk = p_post[k]
        p_next = pk + q
        g = pk / p_next if p_next > 0 else 0.0
        dk = d_filt[k]
        d_hat[k] = dk + g * (d_hat[k + 1] - dk)
        p_s[k] = pk + g * g * (p_s[k + 1] - p_next)
    return d_hat, p_s


# ---------------------------------------------------------------------------------------------
# Across iterations: restricted likelihood of the residual differences, Fisher scoring
# ---------------------------------------------------------------------------------------------


def _second_difference(j: int) -> np.ndarray:
    """Covariance of ``v_j - v_(j-1)``, j = 1..J, per unit r: tridiagonal (-1, 2, -1)."""
    return 2.0 * np.eye(j) - np.eye(j, k=1) - np.eye(j, k=-1)


def _restricted_loglik(sigma: np.ndarray, s: np.ndarray) -> np.ndarray:
    sign, logdet = np.linalg.slogdet(sigma)
    tr = np.trace(np.linalg.solve(sigma, s), axis1=-2, axis2=-1)
    ll = -0.5 * (logdet + tr)
    return np.where(sign > 0, ll, -np.inf)


def _sigma(
    theta: np.ndarray, m: np.ndarray, t: np.ndarray, parts: tuple | None = None
) -> np.ndarray:
    """The covariance of the residual differences; ``parts``: :func:`_sigma_parts` of
    ``(m, t)`` when already computed."""
    d_moved, d_m = _sigma_parts(m, t) if parts is None else parts
    return (
        theta[..., 0, None, None] * d_moved
        + theta[..., 1, None, None] * d_m
        + theta[..., 2, None, None] * t
    )


def _sigma_parts(m: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``diag(m > 0)`` and ``diag(m)``, the covariance's parts that do not depend on theta."""
    eye = np.eye(t.shape[0])
    moved = (m > 0).astype(float)
    return moved[..., :, None] * eye, m[..., :, None] * eye


_EYE3 = np.eye(3)


def _scoring_step(
    theta: np.ndarray,
    m: np.ndarray,
    t: np.ndarray,
    s: np.ndarray,
    lower: np.ndarray,
    drift_offset: bool = True,
    parts: tuple | None = None,
) -> np.ndarray:
    """One Fisher-scoring step ``theta <- I^-1 b`` with the lower bounds kept (active set)."""
    inv = np.linalg.inv(_sigma(theta, m, t, parts))  # V = Sigma^-1
    # A_0 = diag(moved), A_1 = diag(m), A_2 = T. With W = V o V, G = V T V, Q = V S V:
    # tr(V diag(x) V diag(y)) = y' W x,  tr(V diag(x) V T) = x' diag(G),  tr(V T V T) = sum G o T,
    # b_a = tr(A_a Q): x' diag(Q) for a diagonal A_a, sum Q o T for T.
    diag_vecs = [(m > 0).astype(float), m]
    w = inv * inv
    g = inv @ t @ inv
    q = inv @ s @ inv
    g_diag = np.diagonal(g, axis1=-2, axis2=-1)
    q_diag = np.diagonal(q, axis1=-2, axis2=-1)
    info = np.empty(theta.shape + (3,))
    b = np.empty(theta.shape)
    for i, x in enumerate(diag_vecs):
        b[..., i] = np.sum(x * q_diag, axis=-1)
        info[..., i, 2] = info[..., 2, i] = np.sum(x * g_diag, axis=-1)
        for k, y in enumerate(diag_vecs):
            info[..., i, k] = np.einsum("...i,...ij,...j->...", y, w, x)
    info[..., 2, 2] = np.sum(g * t, axis=(-2, -1))
    b[..., 2] = np.sum(q * t, axis=(-2, -1))
    free = np.ones(theta.shape, dtype=bool)
    if not drift_offset:
        free[..., 0] = False  # q0 pinned at its bound 0
    new = theta.copy()
    for _ in range(3):  # active set: pin parameters that want to cross their bound
        fixed_val = np.where(free, 0.0, lower)
        rhs = b - np.einsum("...ac,...c->...a", info, fixed_val)
        reduced = np.where(free[..., :, None] & free[..., None, :], info, 0.0)
        reduced = reduced + np.where(free, 0.0, 1.0)[..., :, None] * _EYE3
        scale = np.maximum(np.abs(np.diagonal(reduced, axis1=-2, axis2=-1)), 1e-300)
        reduced = reduced + 1e-10 * scale[..., :, None] * _EYE3  # unidentified directions
        sol = np.linalg.solve(reduced, np.where(free, rhs, 0.0)[..., None])[..., 0]
        new = np.where(free, sol, lower)
        crossing = free & (new < lower)
        if not np.any(crossing):
            break
        free &= ~crossing
    return np.maximum(new, lower)


def fit_iteration_noise(
    z: np.ndarray, m: np.ndarray, r_min_m2: np.ndarray | float = 0.0, drift_offset: bool = True
) -> IterationNoise:
    """Maximum-likelihood ``(q0, kappa, r)`` of the random walk across iterations.

    Parameters
    ----------
    z : ndarray, shape (..., T, N)
        Residual histories ``z_j = Y_j - F U_j`` of trials j = 0..T-1 [m].
    m : ndarray, shape (..., T-1)
        Drift scales ``m_j`` (:func:`drift_scale`) [m^2].
    r_min_m2 : ndarray or float, shape (...)
        Lower bound of ``r``: the white measurement noise variance (:func:`fit_time_noise`)
        [m^2].
    drift_offset : bool
        Estimate ``q0``, the part of the drift that does not scale with the predicted output
        change (nonlinear and time-varying effects of a changed path); it applies only to
        trials whose input changed. False fixes ``q0 = 0``.

    Returns
    -------
    IterationNoise
        Arrays of shape ``z.shape[:-2]``.
    """
    z = _check_history(z)
    batch = z.shape[:-2]
    n_diff = z.shape[-2] - 1
    m = np.asarray(m, dtype=float)
    if m.shape != batch + (n_diff,):
        raise ValueError(f"m must have shape {batch + (n_diff,)}, got {m.shape}")
    if np.any(~np.isfinite(m)) or np.any(m < 0):
        raise ValueError("m must be finite and >= 0")
    r_min = np.broadcast_to(np.asarray(r_min_m2, dtype=float), batch).copy()
    if np.any(~np.isfinite(r_min)) or np.any(r_min < 0):
        raise ValueError("r_min_m2 must be finite and >= 0")
    if n_diff == 0:
        zero = np.zeros(batch)
        r0 = np.maximum(r_min, 1e-30)
        return IterationNoise(zero, zero.copy(), r0, zero.copy(), np.zeros(batch, bool))
    dz = np.diff(z, axis=-2)  # (..., J, N)
    s = np.einsum("...in,...jn->...ij", dz, dz) / z.shape[-1]
    diag = np.diagonal(s, axis1=-2, axis2=-1)  # (..., J)
    # r > 0 keeps the covariance positive definite even for noiseless data
    r_min = np.maximum(r_min, 1e-12 * np.mean(diag, axis=-1) + 1e-30)
    if n_diff == 1:
        # one difference identifies q_1 + 2 r only. A repeat (no input change) measures the
        # non-repeatable error: all of it is r. Otherwise r stays at its lower bound and the
        # rest is drift caused by the input change (the newest trial dominates the estimate).
        moved = m[..., 0] > 0
        r = np.where(moved, r_min, np.maximum(0.5 * diag[..., 0], r_min))
        q1 = np.maximum(diag[..., 0] - 2.0 * r, 0.0)
        kappa = np.where(moved, q1 / np.where(moved, m[..., 0], 1.0), 0.0)
        q0 = np.zeros(batch)
        theta = np.stack([q0, kappa, r], axis=-1)
        ll = _restricted_loglik(_sigma(theta, m, _second_difference(1)), s)
        return IterationNoise(q0, kappa, r, ll, np.zeros(batch, bool))
    t = _second_difference(n_diff)
    theta = _initial_theta(s, m, r_min)
    lower = np.stack([np.zeros(batch), np.zeros(batch), r_min], axis=-1)
    if not drift_offset:
        theta[..., 0] = 0.0
    parts = _sigma_parts(m, t)
    ll = _restricted_loglik(_sigma(theta, m, t, parts), s)
    finished = np.zeros(batch, dtype=bool)  # a problem stops where it would stop alone
    for _ in range(_SCORING_ITER):
        cand = _scoring_step(theta, m, t, s, lower, drift_offset, parts)
        step = cand - theta
        ll_new = _restricted_loglik(_sigma(cand, m, t, parts), s)
        for _ in range(8):  # step halving where the likelihood went down
            worse = ~(ll_new >= ll - 1e-12 * np.abs(ll))
            if not np.any(worse):
                break
            step = np.where(worse[..., None], 0.5 * step, step)
            cand = np.maximum(theta + step, lower)
            ll_new = _restricted_loglik(_sigma(cand, m, t, parts), s)
        worse = ~(ll_new >= ll - 1e-12 * np.abs(ll))
        keep = worse | finished
        cand = np.where(keep[..., None], theta, cand)
        ll_new = np.where(keep, ll, ll_new)
        scale = np.maximum(np.abs(theta), 1e-30)
        done = np.max(np.abs(cand - theta) / (scale + np.abs(cand)), axis=-1) < _SCORING_TOL
        theta, ll = cand, ll_new
        finished |= done
        if np.all(finished):
            break
    return IterationNoise(
        theta[..., 0], theta[..., 1], theta[..., 2], ll, np.ones(batch, dtype=bool)
    )


def _initial_theta(s: np.ndarray, m: np.ndarray, r_min: np.ndarray) -> np.ndarray:
    """Moment estimates: ``-cov(dz_j, dz_(j+1)) = r``, ``var(dz_j) = q_j + 2 r``."""
    diag = np.diagonal(s, axis1=-2, axis2=-1)
    lag1 = -np.mean(np.diagonal(s, offset=1, axis1=-2, axis2=-1), axis=-1)
    r = np.maximum(lag1, r_min)
    r = np.where(r > 0, r, np.maximum(np.mean(diag, axis=-1) * 0.25, 1e-30))
    q = np.maximum(diag - 2.0 * r[..., None], 0.0)
    mm = np.sum(m * m, axis=-1)
    kappa = np.where(mm > 0, np.sum(q * m, axis=-1) / np.where(mm > 0, mm, 1.0), 0.0)
    q0 = np.maximum(np.mean(q - kappa[..., None] * m, axis=-1), 0.0)
    # start slightly inside the feasible set so that no parameter begins on its bound
    tiny = 1e-3 * np.maximum(np.mean(diag, axis=-1), 1e-30)
    return np.stack([q0 + tiny, kappa + 1e-3, np.maximum(r, r_min + tiny)], axis=-1)


def iteration_filter(z: np.ndarray, m: np.ndarray, noise: IterationNoise) -> IterationEstimate:
    """Kalman filter along the iteration axis with ``q_j = q0 [m_j > 0] + kappa m_j`` and ``r``.

    The first trial initialises the estimate (diffuse prior): ``d_hat = z_0``, variance ``r``.
    All covariances are scalars times the identity, so the gains are the same for every
    sample: the estimate is a weighted mean of the trials' residuals.

    Parameters
    ----------
    z : ndarray, shape (..., T, N)
        Residual histories [m].
    m : ndarray, shape (..., T-1)
        Drift scales [m^2]; ``q0`` applies to trials with ``m_j > 0``.
    noise : IterationNoise
        The variances (arrays of shape ``z.shape[:-2]``).

    Returns
    -------
    IterationEstimate
    """
    z = _check_history(z)
    n_trials = z.shape[-2]
    r = np.asarray(noise.r_m2, dtype=float)
    if np.any(r <= 0):
        raise ValueError("iteration_filter needs r > 0")
    d = z[..., 0, :].copy()
    p = np.array(r, dtype=float, copy=True)
    weights = np.zeros(z.shape[:-1])
    weights[..., 0] = 1.0
    for j in range(1, n_trials):
        mj = m[..., j - 1]
        p_prior = p + np.where(mj > 0, noise.q0_m2, 0.0) + noise.kappa * mj
        g = p_prior / (p_prior + r)
        d = d + g[..., None] * (z[..., j, :] - d)
        p = (1.0 - g) * p_prior
        weights[..., :j] *= (1.0 - g)[..., None]
        weights[..., j] = g
    return IterationEstimate(d_hat_m=d, p_m2=p, weights=weights)


@dataclass(frozen=True)
class DisturbanceEstimate:
    """Output of :func:`estimate_disturbance`.

    Parameters
    ----------
    d_hat_m : ndarray, shape (..., N)
        Estimated disturbance of the newest trial [m].
    p_m2 : ndarray, shape (..., N)
        Its error variance [m^2] (iteration filter alone: the filter's scalar, repeated).
    time : TimeNoise
        Time-domain noise model (shape ``(...)``).
    iteration : IterationNoise
        Iteration-domain noise model (shape ``(...)``).
    weights : ndarray, shape (..., T)
        Weight of each trial in the iteration estimate.
    r_eff_m2 : ndarray, shape (...)
        White-noise variance left in the iteration estimate, given to the smoother [m^2].
    """

    d_hat_m: np.ndarray
    p_m2: np.ndarray
    time: TimeNoise
    iteration: IterationNoise
    weights: np.ndarray
    r_eff_m2: np.ndarray


def estimate_disturbance(
    z: np.ndarray, m: np.ndarray, smooth_in_time: bool, drift_offset: bool = True
) -> DisturbanceEstimate:
    """The data-driven estimate: noise models by maximum likelihood, then the filters.

    Parameters
    ----------
    z : ndarray, shape (..., T, N)
        Residual histories ``z_j = Y_j - F U_j`` [m].
    m : ndarray, shape (..., T-1)
        Drift scales (:func:`drift_scale`) [m^2].
    smooth_in_time : bool
        Follow the iteration filter with the RTS smoother in time (the smoother's path);
        False: the iteration filter alone (K-ILC's path).
    drift_offset : bool
        Estimate ``q0`` (see :func:`fit_iteration_noise`).

    Returns
    -------
    DisturbanceEstimate
    """
    z = _check_history(z)
    time_noise = fit_time_noise(z)
    noise = fit_iteration_noise(z, m, time_noise.r_m2, drift_offset)
    est = iteration_filter(z, m, noise)
    r_eff = time_noise.r_m2 * np.sum(est.weights**2, axis=-1)
    if smooth_in_time:
        # a white-noise variance of zero makes the smoother the identity; keep it positive
        r_eff = np.maximum(r_eff, 1e-12 * np.var(est.d_hat_m, axis=-1) + 1e-30)
        d_hat, p = rts_smooth(est.d_hat_m, time_noise.q_m2, r_eff)
    else:
        d_hat = est.d_hat_m
        p = np.broadcast_to(np.asarray(est.p_m2)[..., None], d_hat.shape).copy()
    return DisturbanceEstimate(d_hat, p, time_noise, noise, est.weights, r_eff)
