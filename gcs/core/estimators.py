"""Estimators of the repetitive disturbance ``D`` in ``Y = F U + D``.

Two methods, both fed with the lifted residual ``z = Y_j - F U_j`` of one trial:

* :func:`rts_smoother` - the paper's Algorithm 1: a fixed-interval Rauch-Tung-Striebel
  smoother running along the *time* axis of one trial on the random-walk model
  ``d(k+1) = d(k) + w(k)``, ``z(k) = d(k) + mu(k)``, ``w ~ N(0, Q)``, ``mu ~ N(0, R)``.
* :func:`kilc_update` - the baseline K-ILC of Degen and Schoellig (CDC 2014): a Kalman filter
  along the *iteration* axis on ``D_(j+1) = D_j + w_j``, ``z_j = D_j + mu_j``, whose estimate
  and covariance carry over from trial to trial.

Indexing of Algorithm 1. The paper writes the forward pass as ``d_f(k+1) = d_f(k) +
K(k) [y(k) - d_f(k) - F u(k)]``: the quantity it calls ``d_f(k+1)`` is the filtered estimate
of ``d(k)`` after measurement ``k``, which for a random walk is also the prediction of
``d(k+1)``. We index every quantity by the sample it estimates (``d_filt[k]`` = estimate of
``d(k)`` given ``z(1..k)``) and initialise the backward pass with the filtered estimate of the
last sample, which uses every measurement; this is the standard RTS recursion (Crassidis and
Junkins, Optimal Estimation of Dynamic Systems, ch. 5) that Algorithm 1 specialises.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.linalg

__all__ = [
    "SmootherSettings",
    "KilcSettings",
    "SmootherResult",
    "KilcState",
    "rts_smoother",
    "smoother_operator",
    "kilc_init",
    "kilc_update",
    "kilc_gains",
]


@dataclass(frozen=True)
class SmootherSettings:
    """Parameters of Algorithm 1 (Table I, "Proposed").

    Parameters
    ----------
    q : float
        Variance of the random-walk increment ``w(k)`` [m^2 per sample].
    r : float
        Variance of the measurement noise ``mu(k)`` [m^2].
    p0 : float
        Variance of the initial estimate ``d_f(0)`` [m^2].
    d0 : float
        Initial estimate ``d_f(0)`` [m].
    """

    q: float = 0.1
    r: float = 0.01
    p0: float = 0.1
    d0: float = 0.0

    def __post_init__(self) -> None:
        _check_variances(q=self.q, r=self.r, p0=self.p0)


@dataclass(frozen=True)
class KilcSettings:
    """Parameters of the iteration-domain Kalman filter (Table I, "K-ILC": scalars times I).

    Parameters
    ----------
    q : float
        Variance of the trial-to-trial change of each ``d(k)`` [m^2 per trial].
    r : float
        Variance of the measurement noise [m^2].
    p0 : float
        Variance of the initial estimate [m^2].
    d0 : float
        Initial estimate of every ``d(k)`` [m].
    """

    q: float = 0.1
    r: float = 0.01
    p0: float = 0.1
    d0: float = 0.0

    def __post_init__(self) -> None:
        _check_variances(q=self.q, r=self.r, p0=self.p0)


def _check_variances(**values: float) -> None:
    for name, value in values.items():
        if not np.isfinite(value) or value < 0:
            raise ValueError(f"{name} must be a finite variance >= 0, got {value}")
    if values["r"] <= 0:
        raise ValueError(f"r must be > 0, got {values['r']}")


@dataclass(frozen=True)
class SmootherResult:
    """Output of :func:`rts_smoother`.

    Parameters
    ----------
    d_hat : ndarray, shape (N,) or (N, M)
        Smoothed disturbance ``d(1) .. d(N)`` [m].
    p : ndarray, shape (N,)
        Smoothed error variance [m^2] (the same for every column of a batch).
    d_filt : ndarray, shape like ``d_hat``
        Forward (filtered) estimates [m].
    """

    d_hat: np.ndarray
    p: np.ndarray
    d_filt: np.ndarray


@functools.lru_cache(maxsize=32)
def _forward_variances(n: int, q: float, r: float, p0: float) -> tuple[np.ndarray, np.ndarray]:
    """Prior and posterior variances of the forward filter; they do not depend on data
    (kept for the next trial: read-only arrays)."""
    p_prior = np.empty(n)
    p_post = np.empty(n)
    p = p0
    for k in range(n):
        p_prior[k] = p
        p_post[k] = p * r / (p + r)
        p = p_post[k] + q
    p_prior.flags.writeable = False
    p_post.flags.writeable = False
    return p_prior, p_post


def rts_smoother(z: np.ndarray, settings: SmootherSettings) -> SmootherResult:
    """Smooth one trial's residual ``z = y - F u`` with Algorithm 1 (RTS).

    Parameters
    ----------
    z : ndarray, shape (N,) or (N, M)
        Residual ``y(k) - (F u)(k)`` for ``k = 1..N`` [m]; a second axis smooths M trials at
        once (they share the gains, which depend only on ``settings`` and ``N``).
    settings : SmootherSettings
        ``q``, ``r``, ``p0`` and the initial estimate ``d0``.

    Returns
    -------
    SmootherResult
    """
    z = np.asarray(z, dtype=float)
    if z.ndim not in (1, 2) or z.shape[0] == 0:
        raise ValueError(f"z must have shape (N,) or (N, M) with N > 0, got {z.shape}")
    if not np.all(np.isfinite(z)):
        raise ValueError("z contains NaN or inf")
    n = z.shape[0]
    q, r = settings.q, settings.r
    p_prior, p_post = _forward_variances(n, q, r, settings.p0)
    gain = p_prior / (p_prior + r)
    # The two passes are first-order recursions with time-varying coefficients of modulus at
    # most 1: bidiagonal systems, solved by LAPACK (no pivoting happens: |coefficient| <= 1).
    # forward: d(k) - (1 - K(k)) d(k-1) = K(k) z(k), d(-1) = d0
    zz = z if z.ndim == 2 else z[:, None]
    rhs = gain[:, None] * zz
    rhs[0] += (1.0 - gain[0]) * settings.d0
    ab = np.ones((2, n))
    ab[1, :-1] = -(1.0 - gain[1:])
    d_filt = scipy.linalg.solve_banded((1, 0), ab, rhs, check_finite=False)
    # backward: d_hat(k) - g(k) d_hat(k+1) = (1 - g(k)) d_filt(k), d_hat(N-1) = d_filt(N-1)
    p_next = p_post[:-1] + q
    # P+(k) / P-(k+1); with p0 = q = 0 the estimate is exact and the gain is moot
    g = np.divide(p_post[:-1], p_next, out=np.zeros(n - 1), where=p_next > 0)
    # random walk: the prediction of d(k+1) is the filtered d(k)
    ab = np.ones((2, n))
    ab[0, 1:] = -g
    rhs = np.empty_like(d_filt)
    rhs[:-1] = (1.0 - g)[:, None] * d_filt[:-1]
    rhs[-1] = d_filt[-1]
    # smoothed variance: p_s(k) - g^2 p_s(k+1) = P+(k) - g^2 P-(k+1), p_s(N-1) = P+(N-1)
    ab_p = ab.copy()
    ab_p[0, 1:] = -g * g
    rhs_p = np.append(p_post[:-1] - g * g * p_next, p_post[-1])
    d_hat = scipy.linalg.solve_banded((0, 1), ab, rhs, check_finite=False)
    p_s = scipy.linalg.solve_banded((0, 1), ab_p, rhs_p, check_finite=False)
    if z.ndim == 1:
        d_filt, d_hat = d_filt[:, 0], d_hat[:, 0]
    return SmootherResult(d_hat=d_hat, p=p_s, d_filt=d_filt)


def smoother_operator(n: int, settings: SmootherSettings) -> tuple[np.ndarray, np.ndarray]:
    """The smoother as an affine map ``d_hat = S @ z + s0 * d0``.

    The gains of Algorithm 1 depend only on ``q, r, p0`` and ``N``, so the smoother is a
    fixed linear operator: batch studies apply it to many trials with one matrix product.

    Parameters
    ----------
    n : int
        Trial length N in samples.
    settings : SmootherSettings
        Filter parameters; ``settings.d0`` is ignored (it enters through ``s0``).

    Returns
    -------
    S : ndarray, shape (N, N)
    s0 : ndarray, shape (N,)
        Response of the smoothed estimate to the initial estimate ``d0``.
    """
    base = SmootherSettings(q=settings.q, r=settings.r, p0=settings.p0, d0=0.0)
    S = rts_smoother(np.eye(n), base).d_hat
    unit = SmootherSettings(q=settings.q, r=settings.r, p0=settings.p0, d0=1.0)
    s0 = rts_smoother(np.zeros(n), unit).d_hat
    return S, s0


@dataclass(frozen=True)
class KilcState:
    """State of the iteration-domain Kalman filter between trials.

    Parameters
    ----------
    d_hat : ndarray, shape (N,)
        Estimate of ``D`` after the last trial it was updated with [m].
    p : float
        Its error variance (every covariance of Table I is a scalar times I, so it stays one).
    trials : int
        Number of trials the filter has been updated with.
    """

    d_hat: np.ndarray
    p: float
    trials: int = 0


def kilc_init(n: int, settings: KilcSettings) -> KilcState:
    """Prior of the K-ILC filter before the first trial.

    Parameters
    ----------
    n : int
        Trial length N in samples.
    settings : KilcSettings
        ``p0`` and ``d0`` give the prior.

    Returns
    -------
    KilcState
    """
    return KilcState(d_hat=np.full(n, settings.d0, dtype=float), p=float(settings.p0), trials=0)


def kilc_update(state: KilcState, z: np.ndarray, settings: KilcSettings) -> KilcState:
    """One K-ILC measurement update with a trial's residual ``z = Y_j - F U_j``.

    The prior for trial j is the previous posterior propagated through the random walk
    (``P- = P+ + Q``); the first update uses ``P(0)`` itself as its prior.

    Parameters
    ----------
    state : KilcState
        Filter state after the previous trial (or :func:`kilc_init`).
    z : ndarray, shape (N,) or (N, M)
        Residual of the trial [m]; a batch of M independent filters shares ``p``.
    settings : KilcSettings
        ``q`` and ``r``.

    Returns
    -------
    KilcState
    """
    z = np.asarray(z, dtype=float)
    if z.shape[0] != np.shape(state.d_hat)[0]:
        raise ValueError(f"z has {z.shape[0]} samples, the filter state {len(state.d_hat)}")
    if not np.all(np.isfinite(z)):
        raise ValueError("z contains NaN or inf")
    p_prior = state.p if state.trials == 0 else state.p + settings.q
    gain = p_prior / (p_prior + settings.r)
    d_hat = state.d_hat + gain * (z - state.d_hat)
    return KilcState(d_hat=d_hat, p=(1.0 - gain) * p_prior, trials=state.trials + 1)


def kilc_gains(settings: KilcSettings, trials: int) -> np.ndarray:
    """Kalman gains of the first ``trials`` K-ILC updates (they do not depend on data).

    Parameters
    ----------
    settings : KilcSettings
        ``q``, ``r``, ``p0``.
    trials : int
        How many gains.

    Returns
    -------
    ndarray, shape (trials,)
    """
    gains = np.empty(trials)
    p = settings.p0
    for j in range(trials):
        gains[j] = p / (p + settings.r)
        p = (1.0 - gains[j]) * p + settings.q
    return gains
