"""Predictor-Based Subspace Identification (PBSID-opt, VARX form) of a SISO closed loop.

Identifies ``position setpoint u [m] -> measured position y [m]`` along one axis as the
innovation model (no direct feedthrough, "no_d")::

    x(k+1) = A x(k) + B u(k - d) + K e(k)
    y(k)   = C x(k) + e(k)

from one or several experiments, following Chiuso (2007, "The role of vector autoregressive
modeling in predictor-based subspace identification", Automatica 43) and van der Veen, van
Wingerden, Bergamasco, Lovera and Verhaegen (2013, "Closed-loop subspace identification
methods: an overview", IET Control Theory Appl. 7). The steps (the PBSID toolbox's
``dordvarx -> dmodx -> dx2abcdk``, re-implemented from the papers):

1. **Delay.** Steps 2-5 are run on the data shifted by every candidate delay
   ``d = 0 .. max_delay`` (``us(k) = u(k - d)``) and scored with
   ``J(d) = N log(RSS / N) + 6 n``, RSS being the sum of squared one-step prediction errors
   ``e(k) = y(k) - C x(k)`` over the samples common to all shifts and ``n`` the order found
   for that shift (3n free parameters of a SISO innovation model). The *longest* ``d`` with
   ``J(d) <= min J + 10.8`` (the 99.9 % quantile of chi-square(1)) is kept, because the risk
   is asymmetric: a too long delay deletes a Markov parameter the core cannot recreate (J
   jumps by hundreds), whereas a too short one is almost absorbed by the zero and poles of the
   core (phase lead), so J is nearly flat below the true delay and its minimum wanders there.
   Reading the delay off the leading VARX input coefficients (a t-test) was tried first and
   rejected: with band-limited (held) inputs neighbouring lags are nearly collinear and the
   small first Markov parameter after the delay was not significant, so the delay came out
   one to three samples long. A first Markov parameter below the noise level is absorbed into
   the delay. Cost: ``max_delay + 1`` identifications (milliseconds each).
2. **VARX.** On the shifted data ``us(k) = u(k - d)``, ``y(k)`` is regressed on the past
   window ``Z(k) = [us(k-p), y(k-p), ..., us(k-1), y(k-1)]`` (least squares, optional
   Tikhonov penalty). Windows never straddle experiments. The coefficients estimate the
   predictor Markov parameters ``Xi_j = C Atilde^(j-1) [B K]``, ``Atilde = A - K C``.
3. **Gamma K.** The extended observability times controllability product of the predictor
   is formed from them, row ``i = 0 .. f-1`` being ``[0 (i blocks), Xi_p, ..., Xi_(i+1)]``
   (this neglects ``Atilde^p``: the past window must be long enough, see below).
4. **SVD and order.** ``Gamma K Z = U S V^T``; the order is the index of the largest gap of
   ``log10`` of the ``future`` singular values (floored at ``1e-12`` of the largest), i.e.
   ``n = argmax_i log10(s_i / s_(i+1))``, unless ``order`` is given. The state sequence is
   ``X = S_n^(1/2) V_n^T``.
5. **Matrices.** ``C`` from ``y(k) = C x(k) + e(k)`` (least squares, ``D = 0``), then
   ``[A B K]`` from ``x(k+1) = A x(k) + B us(k) + K e(k)`` with the residuals ``e``.

Because the regression is on the *predictor* (which is driven by measured ``u`` and ``y``),
noise that enters the feedback loop does not bias the estimate as ``past -> inf``, which is
why PBSID works on closed-loop data where N4SID/MOESP do not.

Caveats: the approximation ``Atilde^p ~ 0`` requires ``past`` samples to cover the slowest
predictor mode. With pure output (measurement) noise the Kalman gain is small and
``Atilde ~ A``, so ``past`` would have to cover the settling time of the plant itself
(0.957^p small, p ~ 60-100 at 20 Hz for the paper's loop); in practice the VARX fits the
best order-p predictor and the default p = 20 gives pole errors of about 1 % at 1 cm noise
(docs/identify.md). Long windows raise the variance; ``regularisation`` trades it for bias.
Excitation must be rich: PRBS, or a multisine reaching close to Nyquist (a band-limited
multisine leaves the input window matrix nearly singular at 20 Hz). The input block of the
regression is checked for rank, and the state sequence for noise amplification along nearly
collinear regressors (``MAX_STATE_GAIN``), which is how a band-limited reference under
feedback shows up.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from gcs.core.model import DiscreteModel, from_state_space
from gcs.errors import IdentificationError, ModelError

__all__ = [
    "IdentificationResult",
    "identify",
    "vaf",
    "nrmse_fit",
    "simulate_free",
    "simulate_predictor",
    "estimate_initial_state",
    "to_continuous_tf",
    "continuous_poles",
    "natural_frequency_damping",
]

#: Criterion slack (chi-square(1) 99.9 % quantile) within which the longest delay wins.
DELAY_TOLERANCE = 10.8
#: Minimum ratio of usable windows to VARX parameters.
SAMPLES_PER_PARAMETER = 4
#: Largest allowed ratio of the first singular value of Gamma K Z to sqrt(future) x RMS(y).
MAX_STATE_GAIN = 5.0
#: Smallest singular value ratio of the (normalised) input window matrix.
MIN_INPUT_CONDITION = 1e-7


@dataclass(frozen=True)
class IdentificationResult:
    """Outcome of :func:`identify`.

    Attributes
    ----------
    model : DiscreteModel
        ``(A, B, C, dt_s, delay_samples)``; ``A`` shape (n, n), ``B`` (n, 1), ``C`` (1, n).
        Input: position setpoint [m]; output: measured position [m].
    K : ndarray, shape (n, 1)
        Innovation (Kalman) gain of the innovation model, in the same state basis.
    singular_values : ndarray, shape (future,)
        Singular values of ``Gamma K Z`` divided by the square root of the number of windows
        (so they do not grow with the data length) [m].
    order : int
        Chosen model order n.
    delay_samples : int
        Estimated (or given) input delay [samples].
    past : int
        Past window p [samples].
    future : int
        Future window f [samples].
    """

    model: DiscreteModel
    K: np.ndarray
    singular_values: np.ndarray
    order: int
    delay_samples: int
    past: int
    future: int


# --------------------------------------------------------------------------------- checks


def _as_experiments(
    experiments: Sequence[tuple[np.ndarray, np.ndarray]],
) -> list[tuple[np.ndarray, np.ndarray]]:
    if (
        isinstance(experiments, tuple)
        and len(experiments) == 2
        and all(isinstance(a, np.ndarray) and a.ndim == 1 for a in experiments)
    ):
        experiments = [experiments]  # a single (u, y) pair
    if len(experiments) == 0:
        raise IdentificationError("no experiments given: pass a list of (u, y) pairs")
    out = []
    for i, pair in enumerate(experiments):
        if len(pair) != 2:
            raise IdentificationError(f"experiment {i} must be a (u, y) pair")
        u = np.asarray(pair[0], dtype=float)
        y = np.asarray(pair[1], dtype=float)
        if u.ndim != 1 or y.ndim != 1:
            raise IdentificationError(
                f"experiment {i}: u and y must be 1-D (one axis), got shapes {u.shape}, {y.shape}"
            )
        if u.shape != y.shape:
            raise IdentificationError(f"experiment {i}: u has {u.size} samples but y has {y.size}")
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
            name = "u" if not np.all(np.isfinite(u)) else "y"
            bad = int(np.argmax(~np.isfinite(u if name == "u" else y)))
            raise IdentificationError(
                f"experiment {i}: {name} contains NaN or inf (first at sample {bad})"
            )
        out.append((u, y))
    return out


def _check_windows(
    exps: list[tuple[np.ndarray, np.ndarray]], past: int, future: int, max_delay: int
) -> None:
    if int(past) != past or past < 1:
        raise IdentificationError(f"past must be an integer >= 1, got {past}")
    if int(future) != future or not 2 <= future <= past:
        raise IdentificationError(f"future must be an integer in [2, past={past}], got {future}")
    if int(max_delay) != max_delay or max_delay < 0:
        raise IdentificationError(f"max_delay must be an integer >= 0, got {max_delay}")
    per_exp = past + max_delay + 2
    n_params = 2 * past + max_delay
    need_windows = SAMPLES_PER_PARAMETER * n_params
    for i, (u, _) in enumerate(exps):
        if u.size < per_exp:
            raise IdentificationError(
                f"experiment {i} has {u.size} samples; windows past={past} and "
                f"max_delay={max_delay} need at least {per_exp} per experiment"
            )
    windows = sum(u.size - past - max_delay for u, _ in exps)
    if windows < need_windows:
        total = sum(u.size for u, _ in exps)
        missing = need_windows - windows
        raise IdentificationError(
            f"too little data: {total} samples give {windows} regression windows, but "
            f"{SAMPLES_PER_PARAMETER} x (2 past + max_delay) = {need_windows} are needed "
            f"(about {total + missing} samples in total)"
        )


def _check_excitation(exps: list[tuple[np.ndarray, np.ndarray]], lags: int, reg: float) -> None:
    scale = max(float(np.max(np.abs(u))) for u, _ in exps)
    spread = max(float(np.ptp(u)) for u, _ in exps)
    if scale == 0.0 or spread <= 1e-12 * scale:
        raise IdentificationError(
            "the input u is constant: excite the loop (PRBS or multisine on the setpoint)"
        )
    rows = [_lagged(u, lags, lags) for u, _ in exps if u.size > lags]
    U = np.vstack(rows)
    s = np.linalg.svd(U / np.sqrt(U.shape[0]), compute_uv=False)
    ratio = float(s[-1] / s[0])
    if ratio < MIN_INPUT_CONDITION and reg == 0.0:
        rank = int(np.sum(s > MIN_INPUT_CONDITION * s[0]))
        raise IdentificationError(
            f"the input is not persistently exciting of order {lags} (window rank {rank}, "
            f"smallest/largest singular value {ratio:.1e}): use PRBS or a multisine with more "
            f"lines, a shorter window, or regularisation > 0"
        )


# ----------------------------------------------------------------------------- regression


def _lagged(x: np.ndarray, lags: int, start: int) -> np.ndarray:
    """Rows ``k = start .. N-1`` of ``[x(k-lags), ..., x(k-1)]`` (oldest first)."""
    n = x.size
    cols = [x[start - lags + j : n - lags + j] for j in range(lags)]
    return np.column_stack(cols)


def _solve_ls(Phi: np.ndarray, target: np.ndarray, reg: float) -> np.ndarray:
    """Least squares ``target ~ Phi theta`` with penalty ``reg * mean(diag(Phi^T Phi))``."""
    if reg > 0.0:
        G = Phi.T @ Phi
        lam = reg * float(np.trace(G)) / G.shape[0]
        return scipy.linalg.solve(G + lam * np.eye(G.shape[0]), Phi.T @ target, assume_a="pos")
    theta, *_ = np.linalg.lstsq(Phi, target, rcond=None)
    return theta


def _varx(exps: list[tuple[np.ndarray, np.ndarray]], p: int, reg: float) -> np.ndarray:
    """VARX on (already shifted) data; coefficients Xi, shape (2p,), oldest lag first."""
    Zs, tgt = [], []
    for u, y in exps:
        Z = np.empty((u.size - p, 2 * p))
        Z[:, 0::2] = _lagged(u, p, p)
        Z[:, 1::2] = _lagged(y, p, p)
        Zs.append(Z)
        tgt.append(y[p:])
    return _solve_ls(np.vstack(Zs), np.concatenate(tgt), reg)


def _past_with_last(u: np.ndarray, y: np.ndarray, p: int) -> np.ndarray:
    """Windows for states ``x(p) .. x(N)`` (one more than the regression), shape (N-p+1, 2p)."""
    n = u.size
    Z = np.empty((n - p + 1, 2 * p))
    for j in range(p):
        Z[:, 2 * j] = u[j : n - p + j + 1]
        Z[:, 2 * j + 1] = y[j : n - p + j + 1]
    return Z


def _gamma_k(Xi: np.ndarray, p: int, f: int) -> np.ndarray:
    """Rows ``i = 0..f-1``: ``[0 (2i entries), Xi[0 : 2(p-i)]]``, shape (f, 2p)."""
    LK = np.zeros((f, 2 * p))
    for i in range(f):
        LK[i, 2 * i :] = Xi[: 2 * (p - i)]
    return LK


def _select_order(sv: np.ndarray) -> int:
    """Index of the largest gap of log10(sv) (floored at 1e-12 of the largest)."""
    s = np.maximum(sv, 1e-12 * sv[0])
    gaps = np.log10(s[:-1]) - np.log10(s[1:])
    if gaps.size == 0:
        return 1
    return int(np.argmax(gaps)) + 1


@dataclass(frozen=True)
class _Fit:
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    K: np.ndarray
    sv: np.ndarray
    n: int
    residuals: list[np.ndarray]  # per experiment, e(k) for shifted k = p .. N_i - d - 1


def _fit(
    shifted: list[tuple[np.ndarray, np.ndarray]],
    p: int,
    f: int,
    order: int | None,
    reg: float,
    y_scale: float,
) -> _Fit:
    """Steps 2-5 of the module docstring on delay-free (shifted) data."""
    Xi = _varx(shifted, p, reg)
    LK = _gamma_k(Xi, p, f)
    Zs = [_past_with_last(u, y, p) for u, y in shifted]
    M = LK @ np.vstack(Zs).T  # (f, windows)
    U_, S, _ = np.linalg.svd(M, full_matrices=False)
    sv = S / np.sqrt(M.shape[1])
    if sv[0] <= 1e-12 * y_scale:
        raise IdentificationError("the output does not respond to the input (Gamma K Z is zero)")
    # Row i of Gamma K Z is the prediction of y(k+i) from the past alone, so its RMS is of the
    # order of the output's; far larger values mean the VARX fitted noise along nearly
    # collinear regressor directions and the shift structure of Gamma K amplified it.
    y_rms = float(np.sqrt(np.mean(np.concatenate([y for _, y in shifted]) ** 2)))
    gain = float(sv[0] / (np.sqrt(f) * y_rms))
    if gain > MAX_STATE_GAIN:
        raise IdentificationError(
            f"the regression is ill-conditioned (state sequence {gain:.0f} x the output "
            f"level; past inputs and outputs nearly collinear, e.g. a band-limited reference "
            f"under feedback): excite with PRBS on the setpoint or set regularisation > 0"
        )
    n = _select_order(sv) if order is None else int(order)
    # State basis X = sv_n^(-1/2) U_n^T (Gamma K Z), i.e. S_n^(1/2) V_n^T up to the factor
    # windows^(1/4), so that the state scale does not depend on the record length.
    T = (U_[:, :n] / np.sqrt(np.maximum(sv[:n], 1e-300))).T
    Xs = [T @ (LK @ Z.T) for Z in Zs]  # each (n, N_i - p + 1): x(p) .. x(N_i)
    # C from y(k) = C x(k) + e(k), k = p .. N-1 (D = 0).
    Xc = np.hstack([X[:, :-1] for X in Xs])
    yc = np.concatenate([y[p:] for _, y in shifted])
    C = np.linalg.lstsq(Xc.T, yc, rcond=None)[0].reshape(1, n)
    # [A B K] from x(k+1) = A x(k) + B u(k) + K e(k), k = p .. N-1.
    regs, nxt, res = [], [], []
    for X, (u, y) in zip(Xs, shifted, strict=True):
        e = y[p:] - (C @ X[:, :-1])[0]
        res.append(e)
        regs.append(np.vstack([X[:, :-1], u[p:][None, :], e[None, :]]))
        nxt.append(X[:, 1:])
    theta = np.linalg.lstsq(np.hstack(regs).T, np.hstack(nxt).T, rcond=None)[0].T
    return _Fit(
        A=theta[:, :n],
        B=theta[:, n : n + 1],
        C=C,
        K=theta[:, n + 1 : n + 2],
        sv=sv,
        n=n,
        residuals=res,
    )


def _shift(
    exps: list[tuple[np.ndarray, np.ndarray]], d: int
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Delay-free data ``(u(k - d), y(k))`` for ``k = d .. N-1``."""
    return [(u[: u.size - d], y[d:]) for u, y in exps]


def _delay_criterion(fit: _Fit, d: int, p: int, max_delay: int, y_power: float) -> float:
    """AIC-like ``N log(RSS / N) + 6 n`` over original times ``k >= p + max_delay``."""
    skip = max_delay - d  # shifted index p + skip is original time p + max_delay
    e = np.concatenate([r[skip:] for r in fit.residuals])
    rss = float(e @ e)
    if not np.isfinite(rss):
        return np.inf
    # Floor at (1e-9 of the output) squared: exact (noise-free) fits tie instead of being
    # ranked by rounding errors, and the tie goes to the longer delay.
    floor = 1e-18 * e.size * y_power
    return e.size * np.log(max(rss, floor) / e.size) + 2.0 * 3 * fit.n


def identify(
    experiments: list[tuple[np.ndarray, np.ndarray]],
    dt_s: float,
    *,
    past: int = 20,
    future: int = 10,
    order: int | None = None,
    max_delay: int = 10,
    regularisation: float = 0.0,
    delay_samples: int | None = None,
) -> IdentificationResult:
    """Identify ``setpoint -> position`` with PBSID-opt (VARX, D = 0), delay included.

    Parameters
    ----------
    experiments : list of (u, y)
        One pair per experiment: ``u`` position setpoint [m] and ``y`` measured position [m],
        each shape (N_i,), ``u[k]`` the setpoint sent at sample k and ``y[k]`` the position
        measured at sample k. Data should be relative to an equilibrium (e.g. minus the initial
        setpoint); there is no offset term. Windows never straddle experiments. A single
        ``(u, y)`` tuple is accepted too.
    dt_s : float
        Sample time [s].
    past : int
        Past window p [samples]; must cover the slowest mode of ``A - K C`` (``Atilde^p ~ 0``).
    future : int
        Future window f [samples], ``2 <= f <= p``; the order is at most ``f - 1``.
    order : int or None
        Model order n; None chooses it at the largest log-gap of the singular values.
    max_delay : int
        Largest input delay searched [samples] (ignored when ``delay_samples`` is given).
    regularisation : float
        Dimensionless Tikhonov weight ``lambda``: the VARX minimises
        ``|y - Xi Z|^2 + lambda * mean(diag(Z Z^T)) * |Xi|^2``; 0 is plain least squares.
    delay_samples : int or None
        Known delay [samples]; None searches ``0 .. max_delay`` (module docstring, step 1).

    Returns
    -------
    IdentificationResult

    Raises
    ------
    IdentificationError
        NaN/inf, mismatched lengths, too little data for the windows, constant or
        non-exciting input, an output that does not respond, or an impossible order.
    """
    exps = _as_experiments(experiments)
    if not (np.isfinite(dt_s) and dt_s > 0):
        raise IdentificationError(f"dt_s must be positive and finite, got {dt_s}")
    if delay_samples is not None:
        if int(delay_samples) != delay_samples or delay_samples < 0:
            raise IdentificationError(f"delay_samples must be an integer >= 0, got {delay_samples}")
        candidates = [int(delay_samples)]
    else:
        if int(max_delay) != max_delay or max_delay < 0:
            raise IdentificationError(f"max_delay must be an integer >= 0, got {max_delay}")
        candidates = list(range(int(max_delay) + 1))
    d_max = max(candidates)
    _check_windows(exps, past, future, d_max)
    p, f = int(past), int(future)
    if order is not None and (int(order) != order or not 1 <= order < f):
        raise IdentificationError(
            f"order must be an integer in [1, future - 1 = {f - 1}], got {order}"
        )
    if not (np.isfinite(regularisation) and regularisation >= 0):
        raise IdentificationError(f"regularisation must be >= 0, got {regularisation}")
    _check_excitation(exps, p, regularisation)
    y_scale = max(float(np.max(np.abs(y))) for _, y in exps)
    if y_scale == 0.0 or max(float(np.ptp(y)) for _, y in exps) <= 1e-12 * y_scale:
        raise IdentificationError("the output y is constant: nothing to identify")

    fits = {d: _fit(_shift(exps, d), p, f, order, regularisation, y_scale) for d in candidates}
    y_power = float(np.mean(np.concatenate([y for _, y in exps]) ** 2))
    crit = {d: _delay_criterion(fit, d, p, d_max, y_power) for d, fit in fits.items()}
    best = min(crit.values())
    # Longest delay statistically indistinguishable from the best (see step 1).
    d = max(d for d, c in crit.items() if c <= best + DELAY_TOLERANCE)
    fit = fits[d]
    try:
        model = from_state_space(fit.A, fit.B, fit.C, 0.0, dt_s, d)
    except ModelError as exc:  # NaN/inf from a degenerate regression
        raise IdentificationError(f"identified matrices are unusable: {exc}") from exc
    return IdentificationResult(
        model=model,
        K=fit.K,
        singular_values=fit.sv,
        order=fit.n,
        delay_samples=d,
        past=p,
        future=f,
    )


# ------------------------------------------------------------------------------ validation


def _check_pair(y: np.ndarray, y_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    y = np.asarray(y, dtype=float).reshape(-1)
    y_hat = np.asarray(y_hat, dtype=float).reshape(-1)
    if y.shape != y_hat.shape:
        raise IdentificationError(f"y has {y.size} samples but y_hat has {y_hat.size}")
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(y_hat))):
        raise IdentificationError("y or y_hat contains NaN or inf")
    if y.size < 2:
        raise IdentificationError("need at least 2 samples to compare signals")
    return y, y_hat


def vaf(y: np.ndarray, y_hat: np.ndarray) -> float:
    """Variance accounted for, ``100 (1 - var(y - y_hat) / var(y))`` [%].

    Parameters
    ----------
    y : ndarray, shape (N,)
        Measured output [m].
    y_hat : ndarray, shape (N,)
        Model output [m].

    Returns
    -------
    float
        VAF [%]; 100 is a perfect fit, it can be negative.
    """
    y, y_hat = _check_pair(y, y_hat)
    var_y = float(np.var(y))
    if var_y == 0.0:
        raise IdentificationError("y is constant: VAF is undefined")
    return 100.0 * (1.0 - float(np.var(y - y_hat)) / var_y)


def nrmse_fit(y: np.ndarray, y_hat: np.ndarray) -> float:
    """Normalised-RMSE fit, ``100 (1 - |y - y_hat| / |y - mean(y)|)`` [%].

    Parameters
    ----------
    y : ndarray, shape (N,)
        Measured output [m].
    y_hat : ndarray, shape (N,)
        Model output [m].

    Returns
    -------
    float
        Fit [%] (MATLAB ``compare``); 100 is perfect, it can be negative.
    """
    y, y_hat = _check_pair(y, y_hat)
    den = float(np.linalg.norm(y - np.mean(y)))
    if den == 0.0:
        raise IdentificationError("y is constant: NRMSE fit is undefined")
    return 100.0 * (1.0 - float(np.linalg.norm(y - y_hat)) / den)


def _shift_input(u: np.ndarray, d: int) -> np.ndarray:
    us = np.zeros_like(u)
    if d < u.size:
        us[d:] = u[: u.size - d]
    return us


def simulate_free(model: DiscreteModel, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
    """Free-run (output-error) simulation aligned with the data: ``y_hat[k] = C x(k)``.

    Unlike :func:`gcs.core.model.simulate` (which returns ``y(1) .. y(N)``), this returns
    ``y(0) .. y(N-1)`` for ``x(0) = x0`` and ``u(k) = 0`` for ``k < 0``, the convention of
    :func:`identify`.

    Parameters
    ----------
    model : DiscreteModel
        Identified model.
    u : ndarray, shape (N,)
        Input (setpoint) [m].
    x0 : ndarray, shape (n,), optional
        Initial core state; zeros (rest) by default.

    Returns
    -------
    ndarray, shape (N,)
        Simulated output [m].
    """
    u = np.asarray(u, dtype=float).reshape(-1)
    us = _shift_input(u, model.delay_samples)
    x = np.zeros(model.order) if x0 is None else np.asarray(x0, dtype=float).reshape(-1)
    A, b, c = model.A, model.B[:, 0], model.C[0]
    out = np.empty(u.size)
    for k in range(u.size):
        out[k] = c @ x
        x = A @ x + b * us[k]
    return out


def simulate_predictor(
    result: IdentificationResult, u: np.ndarray, y: np.ndarray, x0: np.ndarray | None = None
) -> np.ndarray:
    """One-step-ahead prediction of the innovation model (uses measured ``y``).

    ``x(k+1) = (A - K C) x(k) + B u(k-d) + K y(k)``, ``y_hat[k] = C x(k)``.

    Parameters
    ----------
    result : IdentificationResult
        Output of :func:`identify` (model and K).
    u : ndarray, shape (N,)
        Input (setpoint) [m].
    y : ndarray, shape (N,)
        Measured output [m].
    x0 : ndarray, shape (n,), optional
        Initial core state; zeros by default.

    Returns
    -------
    ndarray, shape (N,)
        One-step predictions [m].
    """
    m = result.model
    u = np.asarray(u, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float).reshape(-1)
    if u.shape != y.shape:
        raise IdentificationError(f"u has {u.size} samples but y has {y.size}")
    us = _shift_input(u, m.delay_samples)
    K = result.K[:, 0]
    At = m.A - np.outer(K, m.C[0])
    x = np.zeros(m.order) if x0 is None else np.asarray(x0, dtype=float).reshape(-1)
    out = np.empty(u.size)
    for k in range(u.size):
        out[k] = m.C[0] @ x
        x = At @ x + m.B[:, 0] * us[k] + K * y[k]
    return out


def estimate_initial_state(model: DiscreteModel, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least-squares initial state ``x(0)`` for a free-run simulation (inputs before 0 = 0).

    Parameters
    ----------
    model : DiscreteModel
        Identified model.
    u : ndarray, shape (N,)
        Input (setpoint) [m].
    y : ndarray, shape (N,)
        Measured output [m].

    Returns
    -------
    ndarray, shape (n,)
        ``x0`` minimising ``|y - simulate_free(model, u, x0)|``.
    """
    y = np.asarray(y, dtype=float).reshape(-1)
    forced = simulate_free(model, u)
    n = model.order
    obs = np.empty((y.size, n))
    row = model.C[0].copy()
    for k in range(y.size):
        obs[k] = row
        row = row @ model.A
    x0, *_ = np.linalg.lstsq(obs, y - forced, rcond=None)
    return x0


# ------------------------------------------------------------------------ continuous view


def to_continuous_tf(model: DiscreteModel) -> tuple[np.ndarray, np.ndarray, float]:
    """Continuous transfer function of the core via the inverse Tustin (bilinear) map.

    ``z = (1 + s dt/2) / (1 - s dt/2)``, as the paper's footnote 6. The state-space inverse
    is ``Ac = (2/dt)(A+I)^-1 (A-I)``, ``Bc = (2/dt)(A+I)^-1 B``, ``Cc = 2 C (A+I)^-1``,
    ``Dc = -C (A+I)^-1 B``. A strictly proper discrete model (D = 0) maps to a biproper one: the
    discrete zero at infinity becomes a zero at ``s = +2/dt`` (an artefact of the map, far
    above the loop's bandwidth), so ``num`` has the degree of ``den`` with a small leading
    coefficient. The delay is reported separately.

    Parameters
    ----------
    model : DiscreteModel
        Discrete model; ``A`` must have no eigenvalue at -1.

    Returns
    -------
    num : ndarray, shape (n + 1,)
        Numerator coefficients in descending powers of s.
    den : ndarray, shape (n + 1,)
        Monic denominator coefficients in descending powers of s.
    delay_s : float
        ``delay_samples * dt_s`` [s].
    """
    n = model.order
    dt = model.dt_s
    ApI = model.A + np.eye(n)
    if np.min(np.abs(np.linalg.eigvals(ApI))) < 1e-9:
        raise ModelError("the model has a pole at z = -1: the Tustin inverse does not exist")
    inv = np.linalg.inv(ApI)
    Ac = (2.0 / dt) * inv @ (model.A - np.eye(n))
    Bc = (2.0 / dt) * inv @ model.B
    Cc = 2.0 * model.C @ inv
    Dc = -(model.C @ inv @ model.B)
    import scipy.signal

    num, den = scipy.signal.ss2tf(Ac, Bc, Cc, Dc)
    num = np.asarray(num, dtype=float).reshape(-1)
    den = np.asarray(den, dtype=float).reshape(-1)
    return num / den[0], den / den[0], model.delay_samples * dt


def continuous_poles(model: DiscreteModel) -> np.ndarray:
    """Continuous poles of the core via the inverse Tustin map ``s = (2/dt)(z-1)/(z+1)``.

    Parameters
    ----------
    model : DiscreteModel
        Discrete model.

    Returns
    -------
    ndarray, shape (n,), complex
        Poles [rad/s], sorted by increasing ``|Re|`` then imaginary part.
    """
    z = np.linalg.eigvals(model.A)
    if np.min(np.abs(z + 1)) < 1e-9:
        raise ModelError("the model has a pole at z = -1: the Tustin inverse does not exist")
    s = (2.0 / model.dt_s) * (z - 1) / (z + 1)
    return s[np.lexsort((s.imag, np.abs(s.real)))]


def natural_frequency_damping(model: DiscreteModel) -> tuple[float, float]:
    """Natural frequency and damping of the dominant continuous pole pair (Tustin).

    The dominant pair is the complex-conjugate pair with the smallest ``|Re(s)|`` (slowest
    decay). Without complex poles, the two slowest real poles ``s1, s2`` give
    ``wn = sqrt(s1 s2)`` and ``zeta = -(s1 + s2) / (2 wn) >= 1``.

    Parameters
    ----------
    model : DiscreteModel
        Discrete model of order >= 2.

    Returns
    -------
    wn_rad_s : float
        Natural frequency [rad/s].
    zeta : float
        Damping ratio [-].
    """
    if model.order < 2:
        raise ModelError(f"need at least two poles for a pole pair, the model has {model.order}")
    s = continuous_poles(model)
    cplx = s[np.abs(s.imag) > 1e-9 * np.maximum(1.0, np.abs(s))]
    if cplx.size:
        p = cplx[np.argmin(np.abs(cplx.real))]
        wn = float(np.abs(p))
        return wn, float(-p.real / wn)
    real = s.real[np.argsort(np.abs(s.real))][:2]
    wn = float(np.sqrt(real[0] * real[1]))
    return wn, float(-(real[0] + real[1]) / (2 * wn))
