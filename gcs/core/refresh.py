"""Model refresh between trials: correct the model from trials flown with different setpoints.

Two trials with different setpoints give ``Y_j - Y_(j-1) = F_true (U_j - U_(j-1)) + v_j -
v_(j-1)``: the repeatable disturbance cancels and what is left is the vehicle's response to the
input change (its linearisation around the flown path) plus non-repeatable error. The refresh
fits an output-error model of the same structure as the model in use to these pairs,

    dy(k) = z^-d B(z) / A(z) du(k),   B = b_1 z^-1 + .. + b_n z^-n,   A = 1 + a_1 z^-1 + ..,

with the input delay ``d`` kept from the model (explicit, not fitted) and the order ``n`` the
model's, by Levenberg-Marquardt on the simulation error (Ljung, System Identification,
sec. 10.1), started from the model in use. The candidate is accepted only when it explains
held-out data better than the model in use: two-fold cross-validation over blocks of time
(fit on the even blocks, score on the odd ones, and the other way round), the model in use
scored on the same samples. It must also be stable. Pairs whose predicted output change is
within the noise (signal-to-noise below ``min_snr``) carry no information and are not used; a
refresh is attempted only when the newest pair is informative. With a model of the
non-repeatable error's spectrum measured on flights of identical setpoints (:func:`fit_ar_noise`),
:func:`refresh_model` whitens the pairs first, so that a wander slower than the blocks does not
pass for a change of the vehicle.

How far the model moved is the largest relative change of its frequency response over the
band where the update inverts the model (``|F|^2 >= W_du / W_e``): ``max |F_new / F_old - 1|``.
That is the quantity that decides convergence of norm-optimal ILC, ``|1 - F_true / F| < 1``,
so a move of 0.3 means the old model was about 30 % off where learning acts.

The next trial judges a refresh once more, on data it has never seen: the refreshed model and
the one it replaced each predict that trial from the trials before it, and
:func:`prediction_loss_z` says whether the old one predicted significantly better (the
learning's take-back, ``refresh_takeback`` in :mod:`gcs.core.learning`).

Everything is vectorised over a leading batch axis; :func:`refresh_model` is the one-axis
entry point the learning step uses, :func:`refresh_models` the same for the plants of a batch.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
import scipy.fft

from gcs.core.model import DiscreteModel

T = TypeVar("T")

__all__ = [
    "RefreshSettings",
    "RefreshResult",
    "transfer_function",
    "model_from_transfer_function",
    "simulate_tf",
    "fit_output_error",
    "refresh_decision",
    "refresh_model",
    "refresh_models",
    "model_change",
    "ArNoise",
    "fit_ar_noise",
    "prediction_loss_z",
    "pooled_pairs",
    "anchor_pairs",
]


@dataclass(frozen=True)
class RefreshSettings:
    """How the model is refreshed.

    Parameters
    ----------
    min_snr : float
        A pair is used when ``mean (F dU)^2 >= min_snr * 2 r`` (its predicted output change
        above the noise of a difference of two flights).
    block_s : float
        Length of the cross-validation blocks [s], longer than the correlation time of the
        non-repeatable error; shortened so that a trial has at least 8 blocks.
    max_iter : int
        Levenberg-Marquardt iterations.
    stability_margin : float
        Largest pole radius accepted.
    delay_search : int
        The input delay is searched within this many samples of the current model's (the
        candidate with the smallest cross-validated error wins); 0 keeps it.
    max_move : float or None
        Where the learning has converged with the model in use (a plant's ``converged``), a
        candidate that moves the model by more than this (:func:`model_change`) is rejected:
        learning with a model converges only where the vehicle is within 100 % of it
        (``|1 - F_true / F| < 1``), so such a move contradicts what was flown (docs/
        learning-floor.md, section 5). None: no limit.
    min_gain_z : float
        How significant the candidate's held-out gain must be: the Diebold-Mariano statistic
        of the model in use's and the candidate's squared errors on the held-out samples
        (:func:`prediction_loss_z`, lags up to one block) at least this. 0 (default): any
        gain (a smaller held-out error), which is the statistic above 0; 1.645: a gain
        significant at the one-sided 5 % level.
    """

    min_snr: float = 1.0
    block_s: float = 1.0
    max_iter: int = 40
    stability_margin: float = 0.999
    delay_search: int = 2
    max_move: float | None = None
    min_gain_z: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.min_snr) and self.min_snr >= 0):
            raise ValueError(f"min_snr must be finite and >= 0, got {self.min_snr}")
        if not (np.isfinite(self.block_s) and self.block_s > 0):
            raise ValueError(f"block_s must be > 0, got {self.block_s}")
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")
        if not 0 < self.stability_margin <= 1:
            raise ValueError(f"stability_margin must lie in (0, 1], got {self.stability_margin}")
        if int(self.delay_search) != self.delay_search or self.delay_search < 0:
            raise ValueError(f"delay_search must be an integer >= 0, got {self.delay_search}")
        if self.max_move is not None and not (np.isfinite(self.max_move) and self.max_move > 0):
            raise ValueError(f"max_move must be > 0 or None, got {self.max_move}")
        if not (np.isfinite(self.min_gain_z) and self.min_gain_z >= 0):
            raise ValueError(f"min_gain_z must be finite and >= 0, got {self.min_gain_z}")


@dataclass(frozen=True)
class RefreshResult:
    """One refresh decision (one axis).

    Parameters
    ----------
    model : DiscreteModel
        The model to use from now on (the candidate when accepted, else the current one).
    accepted : bool
        Whether the candidate replaced the current model.
    reason : str
        Why, in words.
    moved : float
        ``max |F_candidate / F_current - 1|`` over the learning band (0 when not accepted or no
        candidate).
    candidate_moved : float
        The same for the candidate, accepted or not (NaN when none was fitted).
    cv_loss_current_m2 : float
        Mean square held-out error of the current model on the pairs [m^2] (NaN: not scored).
    cv_loss_candidate_m2 : float
        Mean square cross-validated error of the candidate [m^2] (NaN: not fitted).
    pairs : int
        Informative pairs used.
    snr : float
        Signal-to-noise of the newest pair (``mean (F dU)^2 / 2 r``).
    takeback_z : float
        With the learning's take-back: how much better the profile's model predicted the
        newest trial than the model in use (:func:`prediction_loss_z`); NaN when not judged
        (no take-back, or the model in use is the profile's).
    holdout_z : float
        With the learning's hold-out: how much better the model in use predicted the newest
        trial than the candidate fitted to the trials before it (:func:`prediction_loss_z`;
        below ``-1.645`` the candidate is adopted); NaN when not judged.
    gain_z : float
        With ``min_gain_z`` above 0: how significant the candidate's held-out gain over the
        model in use was (:func:`prediction_loss_z`); NaN when not judged (and then left out
        of :meth:`as_dict`).
    """

    model: DiscreteModel
    accepted: bool
    reason: str
    moved: float
    candidate_moved: float
    cv_loss_current_m2: float
    cv_loss_candidate_m2: float
    pairs: int
    snr: float
    takeback_z: float = float("nan")
    holdout_z: float = float("nan")
    gain_z: float = float("nan")

    def as_dict(self) -> dict:
        """JSON-ready dictionary (the model as its discrete state space).

        Returns
        -------
        dict
            Every field; ``gain_z`` only where it was judged, so that the records of the
            default refresh stay as they were.
        """
        judged = {} if np.isnan(self.gain_z) else {"gain_z": self.gain_z}
        return {
            "accepted": self.accepted,
            "reason": self.reason,
            "moved": self.moved,
            "candidate_moved": self.candidate_moved,
            "cv_loss_current_m2": self.cv_loss_current_m2,
            "cv_loss_candidate_m2": self.cv_loss_candidate_m2,
            "pairs": self.pairs,
            "snr": self.snr,
            "takeback_z": self.takeback_z,
            "holdout_z": self.holdout_z,
            **judged,
            "model": self.model.as_dict(),
        }


# ---------------------------------------------------------------------------------------------
# The non-repeatable error's spectrum: an autoregressive model that whitens it
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ArNoise:
    """An autoregressive model of one flight's non-repeatable error on one axis.

    ``v(k) + c_1 v(k-1) + .. + c_p v(k-p) = e(k)``, ``e`` white of variance
    ``innovation_var_m2``: the filter ``L(z) = 1 + c_1 z^-1 + .. + c_p z^-p`` whitens ``v``
    (and the difference of two flights' ``v``, whose spectrum has the same shape).

    Parameters
    ----------
    coefficients : tuple of float
        ``c_1 .. c_p`` (empty: white, ``p = 0``).
    innovation_var_m2 : float
        Variance of ``e`` [m^2].
    variance_m2 : float
        Variance of ``v`` itself [m^2].
    """

    coefficients: tuple[float, ...]
    innovation_var_m2: float
    variance_m2: float

    @property
    def order(self) -> int:
        """``p``."""
        return len(self.coefficients)

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """``L(z) x`` along the last axis, from rest.

        Parameters
        ----------
        x : ndarray, shape (..., N)
            Series on the trial grid [m].

        Returns
        -------
        ndarray, shape like ``x``
            The filtered series [m].
        """
        x = np.asarray(x, dtype=float)
        out = x.copy()
        for i, c in enumerate(self.coefficients, start=1):
            out[..., i:] += c * x[..., :-i]
        return out


def fit_ar_noise(series_m: np.ndarray, max_order: int) -> ArNoise:
    """Autoregressive model of a non-repeatable error from flights of identical setpoints.

    Yule-Walker equations on the autocovariance pooled over the series (Levinson-Durbin),
    the order chosen by the Bayesian information criterion
    ``N_total log(sigma_p^2) + p log(N_total)`` over ``p = 0 .. max_order`` (consistent: for
    white noise it settles on 0 as the data grow).

    Parameters
    ----------
    series_m : ndarray, shape (K, N)
        Independent realisations of the error (e.g. ``sqrt(K / (K - 1))`` times each flight's
        deviation from the mean of ``K`` flights of identical setpoints; for two flights their
        difference over ``sqrt 2``) [m].
    max_order : int
        Largest order tried [samples].

    Returns
    -------
    ArNoise
    """
    x = np.atleast_2d(np.asarray(series_m, dtype=float))
    if x.ndim != 2 or x.shape[1] < 4:
        raise ValueError(f"series_m must have shape (K, N) with N >= 4, got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("series_m contains NaN or inf")
    if int(max_order) != max_order or max_order < 0:
        raise ValueError(f"max_order must be an integer >= 0, got {max_order}")
    k, n = x.shape
    p_max = int(min(max_order, n // 4))
    xc = x - x.mean(axis=1, keepdims=True)
    # biased autocovariance (positive definite Toeplitz), pooled over the series
    acov = np.array([np.sum(xc[:, lag:] * xc[:, : n - lag]) for lag in range(p_max + 1)]) / (k * n)
    var = float(acov[0])
    if var <= 0.0:
        return ArNoise((), 0.0, 0.0)
    total = k * n
    best = (total * np.log(var), np.zeros(0), var)
    coef = np.zeros(0)
    err = var
    for p in range(1, p_max + 1):  # Levinson-Durbin: phi(p) from phi(p-1)
        refl = (acov[p] - coef @ acov[p - 1 : 0 : -1]) / err if p > 1 else acov[1] / err
        coef = np.concatenate([coef - refl * coef[::-1], [refl]])
        err *= 1.0 - refl * refl
        if err <= 0.0:
            break
        bic = total * np.log(err) + p * np.log(total)
        if bic < best[0]:
            best = (bic, coef.copy(), err)
    # v(k) = sum phi_i v(k-i) + e(k): L(z) = 1 - phi_1 z^-1 - ..
    return ArNoise(tuple(float(-c) for c in best[1]), float(best[2]), var)


# ---------------------------------------------------------------------------------------------
# Transfer functions
# ---------------------------------------------------------------------------------------------


def transfer_function(model: DiscreteModel) -> tuple[np.ndarray, np.ndarray]:
    """``(b, a)`` with ``F(z) = z^-d (b_1 z^-1 + .. + b_n z^-n) / (1 + a_1 z^-1 + .. + a_n z^-n)``.

    Parameters
    ----------
    model : DiscreteModel
        Model of order n (delay ``d = model.delay_samples``).

    Returns
    -------
    b : ndarray, shape (n,)
    a : ndarray, shape (n,)
        Denominator without its leading 1.
    """
    n = model.order
    a_full = np.real(np.poly(model.A))  # det(zI - A) = z^n + a_1 z^(n-1) + ..
    # Markov parameters f_1..f_n (no delay) satisfy f_k + sum_i a_i f_(k-i) = b_k
    f = np.empty(n)
    x = model.B[:, 0].copy()
    for k in range(n):
        f[k] = model.C[0] @ x
        x = model.A @ x
    b = np.array([f[k] + sum(a_full[i] * f[k - i] for i in range(1, k + 1)) for k in range(n)])
    return b, a_full[1:].copy()


def model_from_transfer_function(
    b: np.ndarray, a: np.ndarray, dt_s: float, delay_samples: int
) -> DiscreteModel:
    """Observable canonical state space of :func:`transfer_function`'s ``(b, a)``.

    Parameters
    ----------
    b : ndarray, shape (n,)
        Numerator ``b_1 .. b_n``.
    a : ndarray, shape (n,)
        Denominator ``a_1 .. a_n`` (leading 1 omitted).
    dt_s : float
        Sample time [s].
    delay_samples : int
        Input delay [samples].

    Returns
    -------
    DiscreteModel
    """
    b = np.asarray(b, dtype=float)
    a = np.asarray(a, dtype=float)
    if b.ndim != 1 or a.shape != b.shape or b.size == 0:
        raise ValueError(f"b and a must be 1-D of one length, got {b.shape} and {a.shape}")
    n = b.size
    A = np.zeros((n, n))
    A[:, 0] = -a
    A[: n - 1, 1:] = np.eye(n - 1)
    C = np.zeros((1, n))
    C[0, 0] = 1.0
    return DiscreteModel(A, b.reshape(n, 1), C, dt_s, delay_samples)


def _pole_radius(a: np.ndarray) -> np.ndarray:
    """Largest pole modulus of ``1 + a_1 z^-1 + .. + a_n z^-n`` per row, shape (M,)."""
    n = a.shape[-1]
    comp = np.zeros(a.shape[:-1] + (n, n))
    comp[..., 0, :] = -a
    comp[..., 1:, :-1] = np.eye(n - 1)
    with np.errstate(invalid="ignore"):
        radius = np.max(np.abs(np.linalg.eigvals(comp)), axis=-1) if n else np.zeros(len(a))
    return np.where(np.isfinite(radius), radius, np.inf)


def _impulse(b: np.ndarray, a: np.ndarray, delay: int, n_out: int) -> np.ndarray:
    """Impulse responses (M, n_out) of ``z^-delay (b_1 + b_2 z^-1 + ..) / A(z)``.

    The difference equation run on a unit impulse, vectorised over the rows (an unstable row
    grows, possibly to inf, and is refused by its loss).
    """
    m, n = b.shape
    h = np.zeros((m, n_out + n))  # column n + k holds h(k); the first n columns are h(<0) = 0
    coef = [a[:, i].copy() for i in range(n)]
    for k in range(delay, n_out):
        kk = k - delay  # b_(kk+1) multiplies the delayed impulse
        acc = b[:, kk].copy() if kk < n else np.zeros(m)
        for i in range(n):  # n is the model order: a handful of vector operations
            acc -= coef[i] * h[:, n + k - 1 - i]
        h[:, n + k] = acc
    return h[:, n:]


def _causal_conv(h: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``y(k) = sum_i h(i) u(k - i)`` along the last axis; h (M, N), u (M, ..., N)."""
    n = u.shape[-1]
    nfft = scipy.fft.next_fast_len(2 * n - 1, real=True)
    hh = h.reshape(h.shape[:1] + (1,) * (u.ndim - 2) + h.shape[1:])
    spec = scipy.fft.rfft(hh, nfft, axis=-1) * scipy.fft.rfft(u, nfft, axis=-1)
    return scipy.fft.irfft(spec, nfft, axis=-1)[..., :n]


def _iir(
    b: np.ndarray, a: np.ndarray, u: np.ndarray, delay: int | np.ndarray, rowwise: bool
) -> np.ndarray:
    """``y = z^-delay (b_1 + b_2 z^-1 + ..) / A u`` along the last axis; b, a (M, n).

    ``delay``: one for every row, or (``rowwise`` only) an array of one per row.

    ``rowwise``: the difference equation row by row in compiled code (``scipy.signal.lfilter``,
    tens of microseconds a row: the learner's refresh, one row); otherwise every row at once
    through its impulse response (a Python loop over the samples shared by the rows, then an
    FFT: the Monte Carlo study's many rows). The two agree to rounding.
    """
    m = b.shape[0]
    if not rowwise:
        return _causal_conv(_impulse(b, a, delay, u.shape[-1]), u)
    shape = u.shape if u.shape[0] == m else (m,) + u.shape[1:]
    out = np.empty(shape)
    per_row = np.ndim(delay) > 0  # a delay per row (the refresh's batched delay search)
    lead = None if per_row else np.zeros(delay)
    one = np.ones(1)
    from scipy.signal import lfilter  # on first use: a second to import

    for i in range(m):
        num = np.concatenate((np.zeros(int(delay[i])) if per_row else lead, b[i]))
        den = np.concatenate((one, a[i]))
        out[i] = lfilter(num, den, u[i] if u.shape[0] == m else u[0], axis=-1)
    return out


def simulate_tf(
    b: np.ndarray, a: np.ndarray, delay: int, u: np.ndarray, rowwise: bool = False
) -> np.ndarray:
    """Outputs ``y(1..N)`` from rest for inputs ``u(0..N-1)``, one model per batch row.

    Parameters
    ----------
    b, a : ndarray, shape (M, n)
        Numerators and denominators (see :func:`transfer_function`).
    delay : int
        Input delay [samples].
    u : ndarray, shape (M, ..., N)
        Inputs.
    rowwise : bool
        Simulate row by row with ``scipy.signal.lfilter`` (compiled; fast for a few rows);
        default: every row at once through its impulse response and an FFT (fast for many
        rows). The two agree to rounding.

    Returns
    -------
    ndarray, shape like ``u``
    """
    b, a, u = np.asarray(b, float), np.asarray(a, float), np.asarray(u, float)
    return _iir(b, a, u, int(delay), rowwise)


def _shift(x: np.ndarray, s: int) -> np.ndarray:
    if s == 0:
        return x
    out = np.zeros_like(x)
    out[..., s:] = x[..., :-s]
    return out


def _jacobian(
    b: np.ndarray, a: np.ndarray, delay: int | np.ndarray, du: np.ndarray, rowwise: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Simulation and its Jacobian with respect to ``(b, a)``: (M, P, N), (M, P, N, 2n).

    ``delay``: one for every row, or (``rowwise`` only) an array of one per row."""
    n = b.shape[-1]
    e1 = np.zeros_like(b)
    e1[:, 0] = 1.0
    w = _iir(e1, a, du, 0, rowwise)  # w = du / A: numerator 1, no delay
    # the columns written in place: d y / d b_(i+1) is w shifted by delay + i samples,
    # d y / d a_(i+1) is -s shifted by i + 1 (its leading samples -0.0, as -shift(s) has)
    jac = np.empty(du.shape + (2 * n,))
    y_hat = np.zeros_like(du)
    n_t = du.shape[-1]
    lead = (-1,) + (1,) * (du.ndim - 1)
    per_row = np.ndim(delay) > 0
    for i in range(n):
        col = jac[..., i]
        for r, d in enumerate(delay if per_row else (delay,)):
            k = min(int(d) + i, n_t)
            c, src = (col[r], w[r]) if per_row else (col, w)
            c[..., :k] = 0.0
            c[..., k:] = src[..., : n_t - k]
        y_hat = y_hat + b[:, i].reshape(lead) * col
    s = _iir(e1, a, y_hat, 0, rowwise)
    for i in range(n):
        k = min(i + 1, n_t)
        col = jac[..., n + i]
        col[..., :k] = -0.0
        np.negative(s[..., : n_t - k], out=col[..., k:])
    return y_hat, jac


def _quiet(func: Callable[..., T]) -> Callable[..., T]:
    """Run ``func`` with overflow ignored: an unstable candidate simulates to inf and its loss
    refuses it, which is the intended outcome, not a numerical accident."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> T:
        with np.errstate(over="ignore", invalid="ignore"):
            return func(*args, **kwargs)

    return wrapper


@_quiet
def fit_output_error(
    b0: np.ndarray,
    a0: np.ndarray,
    delay: int | np.ndarray,
    du: np.ndarray,
    dy: np.ndarray,
    mask: np.ndarray,
    max_iter: int = 40,
    rowwise: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Levenberg-Marquardt fit of ``dy = z^-d B/A du`` on the samples where ``mask`` is set.

    Parameters
    ----------
    b0, a0 : ndarray, shape (M, n)
        Starting models.
    delay : int or ndarray of int, shape (M,)
        Input delay [samples] (not fitted); with ``rowwise``, one per row may be given.
    du : ndarray, shape (M, P, N)
        Input changes of the pairs [m].
    dy : ndarray, shape (M, P, N)
        Output changes of the pairs [m].
    mask : ndarray of bool, shape (M, P, N)
        Samples (and pairs) that enter the loss.
    max_iter : int
        Iterations.
    rowwise : bool
        How the candidates are simulated (see :func:`simulate_tf`).

    Returns
    -------
    b, a : ndarray, shape (M, n)
        Fitted models.
    loss : ndarray, shape (M,)
        Sum of squared errors on the masked samples [m^2].
    """
    b, a = np.array(b0, dtype=float), np.array(a0, dtype=float)
    du, dy = np.asarray(du, float), np.asarray(dy, float)
    w = np.asarray(mask, float)
    n = b.shape[-1]

    per_row = np.ndim(delay) > 0
    if per_row and not rowwise:
        raise ValueError("a delay per row needs rowwise=True")
    delays = np.asarray(delay, dtype=int) if per_row else int(delay)

    def loss_of(bb: np.ndarray, aa: np.ndarray) -> np.ndarray:
        res = (_iir(bb, aa, du, delays, rowwise) - dy) * w
        out = _sse(res)
        return np.where(np.isfinite(out), out, np.inf)

    loss = loss_of(b, a)
    scale = _sse(dy * w)
    mu = np.full(b.shape[0], 1e-3)
    active = np.isfinite(loss)
    eye = np.eye(2 * n)
    every = slice(None)
    for _ in range(max_iter):
        count = int(np.count_nonzero(active))
        if count == 0:
            break
        # every row active (the learner's one row): views instead of copies, the same values
        rows = every if count == active.size else np.flatnonzero(active)
        ur, dr, wr, br, ar = du[rows], dy[rows], w[rows], b[rows], a[rows]
        dl = delays[rows] if per_row else delays
        y_hat, jac = _jacobian(br, ar, dl, ur, rowwise)
        res = ((y_hat - dr) * wr).reshape(count, -1)
        jw = (jac * wr[..., None]).reshape(count, -1, 2 * n)
        jtj = np.einsum("mki,mkj->mij", jw, jw)
        jtr = np.einsum("mki,mk->mi", jw, res)
        d = np.maximum(np.diagonal(jtj, axis1=-2, axis2=-1), 1e-300)
        mur, lossr = mu[rows], loss[rows]
        lhs = jtj + mur[:, None, None] * d[:, None, :] * eye
        step = -np.linalg.solve(lhs, jtr[..., None])[..., 0]
        bn, an = br + step[:, :n], ar + step[:, n:]
        res_new = (_iir(bn, an, ur, dl, rowwise) - dr) * wr
        new = _sse(res_new)
        new = np.where(np.isfinite(new), new, np.inf)
        better = new < lossr
        rel = np.where(better, (lossr - new) / np.maximum(lossr, 1e-300), 0.0)
        b[rows] = np.where(better[:, None], bn, br)
        a[rows] = np.where(better[:, None], an, ar)
        lossr = np.where(better, new, lossr)
        loss[rows] = lossr
        mur = np.where(better, mur / 3.0, mur * 4.0)
        mu[rows] = mur
        tiny = lossr <= 1e-24 * np.maximum(scale[rows], 1e-300)
        active[rows] = ~((better & (rel < 1e-9)) | (mur > 1e8) | tiny)
    return b, a, loss


def _sse(res: np.ndarray) -> np.ndarray:
    """Sum of squares over every axis but the first."""
    return np.sum(res * res, axis=tuple(range(1, res.ndim)))


def _stable(a: np.ndarray, margin: float) -> np.ndarray:
    return _pole_radius(a) < margin


def _freq(b: np.ndarray, a: np.ndarray, delay: int, omega: np.ndarray, dt_s: float) -> np.ndarray:
    """Frequency responses (M, K) of ``(b, a)`` at ``omega`` [rad/s]."""
    zinv = np.exp(-1j * omega * dt_s)
    powers = zinv[None, :] ** np.arange(1, b.shape[-1] + 1)[:, None]  # (n, K)
    return (b @ powers) / (1.0 + a @ powers) * zinv**delay


def pooled_pairs(
    u_m: np.ndarray, y_m: np.ndarray, moved: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of consecutive trials of different setpoints, each side the mean of its repeats.

    A run of consecutive flights of identical setpoints (trial 0 and its repeats, say) is one
    group; the pair where the setpoints change compares the mean of the group before with the
    mean of the group after, so its non-repeatable error has the variance ``r (1/n_a +
    1/n_b)`` instead of ``2 r``. Each pair is then scaled by ``c = sqrt(2 / (1/n_a +
    1/n_b))``, input and output alike (``c dy = F (c du) + c v``, the model linear): every
    scaled pair carries the noise of a difference of two single flights, ``2 r``, as the
    refresh assumes, and the least-squares fit weighs the pooled pairs by their precision.
    Where no group holds more than one flight, ``c = 1`` and the pairs are ``np.diff``'s.

    Parameters
    ----------
    u_m, y_m : ndarray, shape (K, T, N)
        Setpoints and positions of every trial of K plants, oldest first [m].
    moved : ndarray of bool, shape (K, T-1)
        Whether trial ``t + 1``'s setpoints differ from trial ``t``'s.

    Returns
    -------
    du_m, dy_m : ndarray, shape (K, T-1, N)
        At every ``t`` where ``moved``: the scaled change from the group ending at trial ``t``
        to the group starting at ``t + 1`` (input, output) [m]; zero elsewhere.
    """
    return _group_pairs(u_m, y_m, moved, anchor=False)


def anchor_pairs(
    u_m: np.ndarray, y_m: np.ndarray, moved: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of every group of identical setpoints against the first group (the anchor).

    As :func:`pooled_pairs`, but where the setpoints change the group starting there is
    compared with the first group (trial 0 and its repeats), not with the group before it:
    every pair sees the whole input change from trial 0, ``u_(t+1) - u_0``, which stays large
    once learning has converged, where a consecutive pair's change shrinks to the steps near
    the floor and its output change to the noise. The pairs share the anchor's mean, so their
    noises are correlated by ``(1/n_0) / (1/n_0 + 1/n_b)`` (a fifth for four flights of
    trial 0 against one); the fit takes them as independent. Scaled by ``c = sqrt(2 / (1/n_0
    + 1/n_b))`` as :func:`pooled_pairs` (the first pair is the same).

    Parameters
    ----------
    u_m, y_m : ndarray, shape (K, T, N)
        Setpoints and positions of every trial of K plants, oldest first [m].
    moved : ndarray of bool, shape (K, T-1)
        Whether trial ``t + 1``'s setpoints differ from trial ``t``'s.

    Returns
    -------
    du_m, dy_m : ndarray, shape (K, T-1, N)
        At every ``t`` where ``moved``: the scaled change from the first group to the group
        starting at ``t + 1`` (input, output) [m]; zero elsewhere.
    """
    return _group_pairs(u_m, y_m, moved, anchor=True)


def _group_pairs(
    u_m: np.ndarray, y_m: np.ndarray, moved: np.ndarray, anchor: bool
) -> tuple[np.ndarray, np.ndarray]:
    u = np.asarray(u_m, dtype=float)
    y = np.asarray(y_m, dtype=float)
    moved = np.asarray(moved, dtype=bool)
    du = np.zeros((u.shape[0], u.shape[1] - 1, u.shape[2]))
    dy = np.zeros_like(du)
    for k in range(u.shape[0]):
        group = np.concatenate(([0], np.cumsum(moved[k])))  # (T,): each trial's group
        count = np.bincount(group).astype(float)
        mean_y = np.zeros((count.size, y.shape[2]))
        np.add.at(mean_y, group, y[k])
        mean_y /= count[:, None]
        for t in np.flatnonzero(moved[k]):
            a, b = (0, group[t + 1]) if anchor else (group[t], group[t + 1])
            first = 0 if anchor else t  # any trial of group a: they share their setpoints
            c = np.sqrt(2.0 / (1.0 / count[a] + 1.0 / count[b]))
            du[k, t] = c * (u[k, t + 1] - u[k, first])
            dy[k, t] = c * (mean_y[b] - mean_y[a])
    return du, dy


def model_change(
    b_old: np.ndarray,
    a_old: np.ndarray,
    b_new: np.ndarray,
    a_new: np.ndarray,
    delay: int,
    dt_s: float,
    band_gain2: float,
    delay_new: int | None = None,
) -> np.ndarray:
    """Peak relative change ``max |F_new / F_old - 1|`` where ``|F_old|^2 >= band_gain2``.

    Parameters
    ----------
    b_old, a_old, b_new, a_new : ndarray, shape (M, n)
        The two models per batch row.
    delay : int
        Input delay of the old model [samples].
    dt_s : float
        Sample time [s].
    band_gain2 : float
        The band where the update inverts the model: ``|F_old|^2 >= W_du / W_e``.
    delay_new : int, optional
        Input delay of the new model [samples] (default: the old one's).

    Returns
    -------
    ndarray, shape (M,)
    """
    delay_new = delay if delay_new is None else delay_new
    omega = np.linspace(0.0, np.pi / dt_s, 400)
    f_old = _freq(np.atleast_2d(b_old), np.atleast_2d(a_old), delay, omega, dt_s)
    f_new = _freq(np.atleast_2d(b_new), np.atleast_2d(a_new), delay_new, omega, dt_s)
    band = np.abs(f_old) ** 2 >= band_gain2
    band[:, 0] = True  # DC always counts
    rel = np.abs(f_new / np.where(f_old == 0, 1.0, f_old) - 1.0)
    return np.max(np.where(band, rel, 0.0), axis=-1)


def prediction_loss_z(err_current_m: np.ndarray, err_other_m: np.ndarray, lag: int) -> np.ndarray:
    """How much better another model predicted one trial than the current one, in standard
    errors: the Diebold-Mariano statistic of the squared prediction errors.

    The loss differential ``g(k) = e_current(k)^2 - e_other(k)^2`` has mean zero when both
    predict equally well; its mean over the trial, divided by its standard error, is about
    standard normal then. The errors of one flight are correlated in time, so the variance of
    the mean is the Newey-West (Bartlett-weighted) long-run variance up to ``lag`` samples
    (Diebold and Mariano, J. Bus. Econ. Stat. 13(3), 1995; Newey and West, Econometrica
    55(3), 1987). Positive: the other model predicted better.

    Parameters
    ----------
    err_current_m, err_other_m : ndarray, shape (..., N)
        Prediction errors of the two models on the same samples [m].
    lag : int
        Largest autocovariance lag kept [samples], ``>= 0`` (about the errors' correlation
        time).

    Returns
    -------
    ndarray, shape (...)
        The statistic; 0 where the two losses are identical.
    """
    e1 = np.asarray(err_current_m, dtype=float)
    e2 = np.asarray(err_other_m, dtype=float)
    if e1.shape != e2.shape or e1.ndim < 1 or e1.shape[-1] < 2:
        raise ValueError(f"two error series (..., N >= 2) of one shape, got {e1.shape}, {e2.shape}")
    if int(lag) != lag or lag < 0:
        raise ValueError(f"lag must be an integer >= 0, got {lag}")
    g = e1 * e1 - e2 * e2
    n = g.shape[-1]
    mean = g.mean(axis=-1)
    c = g - mean[..., None]
    var = np.sum(c * c, axis=-1) / n
    for k in range(1, min(int(lag), n - 1) + 1):
        var = var + 2.0 * (1.0 - k / (lag + 1.0)) * np.sum(c[..., k:] * c[..., :-k], axis=-1) / n
    scale = np.sqrt(np.maximum(var, 0.0) / n)
    tiny = np.finfo(float).tiny
    return np.where(scale > tiny, mean / np.maximum(scale, tiny), 0.0)


@dataclass(frozen=True)
class _Batch:
    """Arrays of one batched refresh decision."""

    b: np.ndarray
    a: np.ndarray
    delay: np.ndarray
    accepted: np.ndarray
    reason: np.ndarray
    moved: np.ndarray
    candidate_moved: np.ndarray
    cv_current: np.ndarray
    cv_candidate: np.ndarray
    pairs: np.ndarray
    snr: np.ndarray
    gain_z: np.ndarray


def _fold_fits_each(
    br: np.ndarray,
    ar: np.ndarray,
    delays: list[int],
    du: np.ndarray,
    dy: np.ndarray,
    valid: np.ndarray,
    masks: list[np.ndarray],
    settings: RefreshSettings,
) -> tuple[
    list[np.ndarray],
    Callable[[int], tuple[np.ndarray, np.ndarray]],
    Callable[[int], np.ndarray],
]:
    """Cross-validated loss of each delay's candidate (two folds), the fit on every sample
    of one delay, and one delay's held-out errors (M, P, N), summed over the folds when asked:
    one delay and one fold at a time (the batch's many rows)."""
    cvs, folds = [], {}
    for d in delays:
        cv = np.zeros(br.shape[0])
        folds[d] = []
        for f in (0, 1):
            bf, af, _ = fit_output_error(br, ar, d, du, dy, masks[f], settings.max_iter)
            res = (simulate_tf(bf, af, d, du) - dy) * masks[1 - f]
            held = _sse(res)
            ok = _stable(af, settings.stability_margin) & np.isfinite(held)
            cv += np.where(ok, held, np.inf)
            folds[d].append(res)
        cvs.append(cv)

    def full(d: int) -> tuple[np.ndarray, np.ndarray]:
        every = np.broadcast_to(valid, du.shape)
        bd, ad, _ = fit_output_error(br, ar, d, du, dy, every, settings.max_iter)
        return bd, ad

    return cvs, full, lambda d: folds[d][0] + folds[d][1]


def _fold_fits(
    br: np.ndarray,
    ar: np.ndarray,
    delays: list[int],
    du: np.ndarray,
    dy: np.ndarray,
    valid: np.ndarray,
    masks: list[np.ndarray],
    settings: RefreshSettings,
) -> tuple[
    list[np.ndarray],
    Callable[[int], tuple[np.ndarray, np.ndarray]],
    Callable[[int], np.ndarray],
]:
    """:func:`_fold_fits_each` for a few rows (the learner's one), simulated row by row: every
    delay's and fold's fit in one Levenberg-Marquardt call (a row each, iterated as alone),
    then the fits on every sample of the delays that improve the loss in one more call."""
    m = br.shape[0]
    nd = len(delays)
    k = 2 * nd  # rows (delay, fold), each a copy of the m rows
    row_delay = np.repeat(np.asarray(delays, dtype=int), 2 * m)
    b0, a0 = np.tile(br, (k, 1)), np.tile(ar, (k, 1))
    u, y = np.tile(du, (k, 1, 1)), np.tile(dy, (k, 1, 1))
    fit_mask = np.concatenate([masks[0], masks[1]] * nd)
    held_mask = np.concatenate([masks[1], masks[0]] * nd)
    bf, af, _ = fit_output_error(b0, a0, row_delay, u, y, fit_mask, settings.max_iter, True)
    res = (_iir(bf, af, u, row_delay, True) - y) * held_mask
    held = _sse(res)
    ok = _stable(af, settings.stability_margin) & np.isfinite(held)
    term = np.where(ok, held, np.inf).reshape(nd, 2, m)
    per_fold = res.reshape(nd, 2, m, *du.shape[1:])  # a view: summed when a delay is asked
    cvs = []
    for i in range(nd):
        cv = np.zeros(m)
        cv += term[i, 0]
        cv += term[i, 1]
        cvs.append(cv)
    # the delays whose candidate improves on every earlier one for some row: fitted together
    best = np.full(m, np.inf)
    wanted = []
    for d, cv in zip(delays, cvs, strict=True):
        better = cv < best
        if np.any(better):
            wanted.append(d)
            best = np.where(better, cv, best)
    fitted: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    if wanted:
        kw = len(wanted)
        every = np.broadcast_to(valid, du.shape)
        bd, ad, _ = fit_output_error(
            np.tile(br, (kw, 1)), np.tile(ar, (kw, 1)), np.repeat(np.asarray(wanted), m),
            np.tile(du, (kw, 1, 1)), np.tile(dy, (kw, 1, 1)), np.tile(every, (kw, 1, 1)),
            settings.max_iter, True,
        )  # fmt: skip
        for i, d in enumerate(wanted):
            fitted[d] = (bd[i * m : (i + 1) * m], ad[i * m : (i + 1) * m])
    return cvs, fitted.__getitem__, lambda d: per_fold[list(delays).index(d)].sum(axis=0)


@_quiet
def refresh_decision(
    b: np.ndarray,
    a: np.ndarray,
    delay: int,
    dt_s: float,
    du: np.ndarray,
    dy: np.ndarray,
    noise_var_m2: np.ndarray,
    settings: RefreshSettings,
    band_gain2: float,
    rowwise: bool = False,
    converged: np.ndarray | None = None,
) -> _Batch:
    """Batched refresh: fit, cross-validate and accept or keep, per batch row.

    Parameters
    ----------
    b, a : ndarray, shape (M, n)
        Current models.
    delay : int
        Input delay [samples].
    dt_s : float
        Sample time [s].
    du, dy : ndarray, shape (M, P, N)
        Input and output changes of consecutive trials, oldest pair first [m].
    noise_var_m2 : ndarray, shape (M,)
        Per-sample variance of one flight's non-repeatable error ``r`` [m^2].
    settings : RefreshSettings
        Thresholds and iterations.
    band_gain2 : float
        Learning band for :func:`model_change` (``W_du / W_e``).
    rowwise : bool
        How the candidates are simulated (see :func:`simulate_tf`): row by row for the
        learner's one row, all rows at once (default) for the Monte Carlo study's many.
    converged : ndarray of bool, shape (M,), optional
        The rows whose learning has converged with the current model: there a candidate
        moving it by more than ``settings.max_move`` is rejected (default: none).

    Returns
    -------
    _Batch
        Fields of shape (M,) (models (M, n)).
    """
    b, a = np.atleast_2d(np.asarray(b, float)), np.atleast_2d(np.asarray(a, float))
    du, dy = np.asarray(du, float), np.asarray(dy, float)
    m_rows, n_pairs, n = du.shape
    r = np.broadcast_to(np.asarray(noise_var_m2, float), (m_rows,))
    pred = simulate_tf(b, a, delay, du, rowwise)
    snr_all = np.mean(pred * pred, axis=-1) / np.maximum(2.0 * r[:, None], 1e-300)
    use = snr_all >= settings.min_snr  # (M, P)
    newest = use[:, -1] if n_pairs else np.zeros(m_rows, bool)
    out_b, out_a = b.copy(), a.copy()
    nan = np.full(m_rows, np.nan)
    reason = np.where(newest, "", "skipped: the newest input change is within the noise")
    reason = reason.astype(object)
    result = _Batch(
        out_b, out_a, np.full(m_rows, delay), np.zeros(m_rows, bool), reason, np.zeros(m_rows),
        nan.copy(), nan.copy(), nan.copy(), use.sum(axis=-1),
        snr_all[:, -1] if n_pairs else nan.copy(), nan.copy(),
    )  # fmt: skip
    rows = np.flatnonzero(newest)
    if rows.size == 0:
        return result
    # at least 8 blocks, so that each fold sees every part of the trial
    block = max(1, min(int(round(settings.block_s / dt_s)), n // 8))
    fold = (np.arange(n) // block) % 2  # (N,)
    valid = use[rows][:, :, None]
    dur, dyr, br, ar = du[rows], dy[rows], b[rows], a[rows]
    masks = [valid & (fold == f)[None, None, :] for f in (0, 1)]
    res0 = (simulate_tf(br, ar, delay, dur, rowwise) - dyr) * valid
    cv_cur = _sse(res0)
    count = np.maximum(valid.sum(axis=(1, 2)) * n, 1)
    best_cv = np.full(rows.size, np.inf)
    best_d = np.full(rows.size, delay)
    bc, ac = br.copy(), ar.copy()
    delays = range(max(0, delay - settings.delay_search), delay + settings.delay_search + 1)
    fits = _fold_fits if rowwise else _fold_fits_each
    cvs, full, held_errors = fits(br, ar, list(delays), dur, dyr, valid, masks, settings)
    for d, cv in zip(delays, cvs, strict=True):
        better = cv < best_cv
        if not np.any(better):
            continue
        bd, ad = full(d)
        best_cv = np.where(better, cv, best_cv)
        best_d = np.where(better, d, best_d)
        bc = np.where(better[:, None], bd, bc)
        ac = np.where(better[:, None], ad, ac)
    stable = _stable(ac, settings.stability_margin)
    moved_c = np.array(
        [
            model_change(br[i], ar[i], bc[i], ac[i], delay, dt_s, band_gain2, int(best_d[i]))[0]
            for i in range(rows.size)
        ]
    )
    better = best_cv < cv_cur
    too_far = np.zeros(rows.size, dtype=bool)
    if settings.max_move is not None and converged is not None:
        too_far = np.asarray(converged, dtype=bool)[rows] & (moved_c > settings.max_move)
    gain_z = np.full(rows.size, np.nan)
    if settings.min_gain_z > 0:  # the chosen delay's held-out errors, each delay summed once
        held = {d: held_errors(d) for d in {int(best_d[i]) for i in np.flatnonzero(better)}}
        for i in np.flatnonzero(better):
            pairs = valid[i, :, 0]  # the informative pairs, back to back
            candidate = held[int(best_d[i])][i, pairs].ravel()
            gain_z[i] = prediction_loss_z(res0[i, pairs].ravel(), candidate, block)
    weak = better & (gain_z < settings.min_gain_z)  # NaN (not judged) is never weak
    accept = stable & better & ~too_far & ~weak
    result.cv_current[rows] = cv_cur / count
    result.cv_candidate[rows] = best_cv / count
    result.gain_z[rows] = gain_z
    result.candidate_moved[rows] = moved_c
    result.moved[rows] = np.where(accept, moved_c, 0.0)
    result.accepted[rows] = accept
    result.b[rows] = np.where(accept[:, None], bc, br)
    result.a[rows] = np.where(accept[:, None], ac, ar)
    result.delay[rows] = np.where(accept, best_d, delay)
    why = np.where(
        accept,
        "accepted: explains held-out data better",
        np.where(stable, "rejected: does not explain held-out data better", "rejected: unstable"),
    ).astype(object)
    for i in np.flatnonzero(stable & weak & ~too_far):
        why[i] = (
            f"rejected: explains held-out data better by z = {gain_z[i]:.2f}, below "
            f"{settings.min_gain_z:g}"
        )
    for i in np.flatnonzero(stable & better & too_far):
        why[i] = (
            f"rejected: moves the model {100 * moved_c[i]:.0f} % (limit "
            f"{100 * settings.max_move:.0f} %), which the learning's convergence with it "
            "contradicts"
        )
    for i in np.flatnonzero(accept & np.isfinite(gain_z)):
        why[i] = f"{why[i]} (z = {gain_z[i]:.2f} >= {settings.min_gain_z:g})"
    result.reason[rows] = why
    return result


def refresh_model(
    current: DiscreteModel,
    du_m: np.ndarray,
    dy_m: np.ndarray,
    noise_var_m2: float,
    settings: RefreshSettings,
    band_gain2: float,
    noise: ArNoise | None = None,
    converged: bool = False,
) -> RefreshResult:
    """Refresh one axis's model from consecutive trials (the learning step's entry point).

    With ``noise``, the pairs are whitened first: ``du`` and ``dy`` both filtered by the
    noise model's ``L(z)`` (``L (dy - F du) = L dy - F (L du)``, LTI filters from rest
    commute), so the fit minimises the whitened simulation error (maximum likelihood for
    Gaussian noise of that spectrum, a Box-Jenkins model with its noise part fixed), the
    cross-validation's blocks hold nearly independent residuals whatever the correlation
    time of the non-repeatable error, and the signal-to-noise gate compares the whitened
    predicted change with the innovation variance.

    Parameters
    ----------
    current : DiscreteModel
        Model in use.
    du_m : ndarray, shape (P, N)
        ``U_j - U_(j-1)`` of the pairs, oldest first [m] (U-indexed).
    dy_m : ndarray, shape (P, N)
        ``Y_j - Y_(j-1)`` of the same pairs [m] (Y-indexed, y(1..N)).
    noise_var_m2 : float
        Per-sample variance of one flight's non-repeatable error [m^2].
    settings : RefreshSettings
        Thresholds and iterations.
    band_gain2 : float
        ``W_du / W_e``: the learning band of :func:`model_change`.
    noise : ArNoise, optional
        The non-repeatable error's spectrum (:func:`fit_ar_noise`); default white, of
        variance ``noise_var_m2``; of order 0, white as well (``noise_var_m2`` kept).
    converged : bool
        The learning has converged with ``current`` (``settings.max_move`` applies).

    Returns
    -------
    RefreshResult
    """
    du = np.asarray(du_m, dtype=float)
    dy = np.asarray(dy_m, dtype=float)
    if du.ndim != 2 or du.shape != dy.shape:
        raise ValueError(f"du_m and dy_m must share one shape (P, N), got {du.shape}, {dy.shape}")
    return refresh_models(
        [current],
        du[None],
        dy[None],
        np.array([noise_var_m2]),
        settings,
        band_gain2,
        [noise],
        [converged],
    )[0]


def refresh_models(
    currents: Sequence[DiscreteModel],
    du_m: np.ndarray,
    dy_m: np.ndarray,
    noise_var_m2: np.ndarray,
    settings: RefreshSettings,
    band_gain2: float,
    noises: Sequence[ArNoise | None] | None = None,
    converged: Sequence[bool] | None = None,
) -> list[RefreshResult]:
    """:func:`refresh_model` of many plants at once, each its own (the learners of a batch).

    The plants of one input delay share one :func:`refresh_decision`, simulated row by row:
    every row iterates as it would alone, so each result equals its own
    :func:`refresh_model`'s.

    Parameters
    ----------
    currents : sequence of DiscreteModel
        Model in use of each plant (``K`` of them).
    du_m, dy_m : ndarray, shape (K, P, N)
        The pairs of each plant, as :func:`refresh_model` (the same number per plant) [m].
    noise_var_m2 : ndarray, shape (K,)
        Each plant's per-sample variance of one flight's non-repeatable error [m^2].
    settings : RefreshSettings
        Thresholds and iterations.
    band_gain2 : float
        ``W_du / W_e``.
    noises : sequence of ArNoise or None, optional
        Each plant's non-repeatable error spectrum (default: white).
    converged : sequence of bool, optional
        Whether each plant's learning has converged with its model (``settings.max_move``
        applies there); default: none has.

    Returns
    -------
    list of RefreshResult
        One per plant, in order.
    """
    du = np.array(du_m, dtype=float)
    dy = np.array(dy_m, dtype=float)
    r = np.array(noise_var_m2, dtype=float).reshape(len(currents))
    if du.ndim != 3 or du.shape != dy.shape or du.shape[0] != len(currents):
        raise ValueError(
            f"du_m and dy_m must share one shape ({len(currents)}, P, N), got {du.shape}, "
            f"{dy.shape}"
        )
    if not (np.all(np.isfinite(du)) and np.all(np.isfinite(dy))):
        raise ValueError("du_m or dy_m contains NaN or inf")
    for k, noise in enumerate(noises or ()):
        if noise is not None and noise.order > 0:
            du[k], dy[k], r[k] = noise.whiten(du[k]), noise.whiten(dy[k]), noise.innovation_var_m2
    nan = float("nan")
    if du.shape[1] == 0:
        return [
            RefreshResult(
                current,
                False,
                "no pair of trials with different setpoints",
                0.0,
                nan,
                nan,
                nan,
                0,
                nan,
            )  # fmt: skip
            for current in currents
        ]
    out: list[RefreshResult | None] = [None] * len(currents)
    ba = [transfer_function(current) for current in currents]
    for delay in sorted({c.delay_samples for c in currents}):
        rows = [k for k, c in enumerate(currents) if c.delay_samples == delay]
        dec = refresh_decision(
            np.array([ba[k][0] for k in rows]), np.array([ba[k][1] for k in rows]), delay,
            currents[rows[0]].dt_s, du[rows], dy[rows], r[rows], settings, band_gain2,
            rowwise=True, converged=None if converged is None else np.array(converged)[rows],
        )  # fmt: skip
        for i, k in enumerate(rows):
            model = currents[k]
            if dec.accepted[i]:
                model = model_from_transfer_function(
                    dec.b[i], dec.a[i], model.dt_s, int(dec.delay[i])
                )
            out[k] = RefreshResult(
                model=model,
                accepted=bool(dec.accepted[i]),
                reason=str(dec.reason[i]),
                moved=float(dec.moved[i]),
                candidate_moved=float(dec.candidate_moved[i]),
                cv_loss_current_m2=float(dec.cv_current[i]),
                cv_loss_candidate_m2=float(dec.cv_candidate[i]),
                pairs=int(dec.pairs[i]),
                snr=float(dec.snr[i]),
                gain_z=float(dec.gain_z[i]),
            )
    return out  # type: ignore[return-value]
