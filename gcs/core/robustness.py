"""Robustness of the input update: a zero-phase, frequency-dependent weight (the ILC Q-filter).

Norm-optimal ILC inverts the model wherever the weight on the input change is small next to
``|F|^2``. Where the model's gain is small (above the closed loop's bandwidth) that inverts
noise and model error: setpoints grow from trial to trial while the error does not shrink.
The usual cure is a Q-filter that stops learning above a cutoff. Here it is a weight inside
the QP of :mod:`gcs.core.update`, so that the arena and the setpoint limits stay exact::

    J_rob = lam || D_p (U - U_anchor) ||^2,

``D_p`` the p-th order backward difference (``u(-1) = .. = u(-p)`` equal to the anchor: the
vehicle hovers at the start point before the trial) and ``U_anchor`` the setpoints of the
first trial (the reference). ``|D_p(e^{j w T})|^2 = (2 sin(w T / 2))^(2 p)`` is zero at DC and
rises as ``w^(2p)``: the weight leaves the low frequencies free and pins the high-frequency
content of the learned correction ``U - U_anchor``. For a long trial, away from its ends, the
fixed point of the unconstrained update is the anchor plus the model inverse filtered by

    Q(w) = we |F(w)|^2 / (we |F(w)|^2 + lam |D_p(w)|^2),

which is real (zero phase), 1 at DC and falls as ``w^-(2p + 2 n_rel)`` beyond the cutoff.
``lam`` is set so that ``Q(w_c) = 1/2`` at the cutoff ``w_c`` for the model in use
(:func:`robustness_weight`). How the cutoff is chosen is in ``docs/learning-floor.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np
import scipy.sparse as sp

from gcs.core.model import DiscreteModel, frequency_response

__all__ = [
    "RobustnessWeight",
    "difference_matrix",
    "robustness_weight",
    "q_filter_response",
    "crossover_frequency",
    "repeat_cutoff",
]


@dataclass(frozen=True)
class RobustnessWeight:
    """The weight ``lam || D_p (U - U_anchor) ||^2`` added to eq. (8), one axis.

    Parameters
    ----------
    lam : float
        Weight ``lam`` [1/m^2], ``>= 0`` (0: no weight).
    order : int
        Order ``p`` of the backward difference, ``>= 1``.
    anchor_m : ndarray, shape (N,)
        ``U_anchor``: setpoints u(0..N-1) the high frequencies are held to, learning
        coordinates [m] (U-indexed).
    cutoff_rad_s : float
        Frequency where ``Q = 1/2`` for the model ``lam`` was computed with [rad/s]
        (informational).
    """

    lam: float
    order: int
    anchor_m: np.ndarray
    cutoff_rad_s: float = float("nan")

    def __post_init__(self) -> None:
        anchor = np.asarray(self.anchor_m, dtype=float)
        if anchor.ndim != 1 or not np.all(np.isfinite(anchor)):
            raise ValueError(f"anchor_m must be a finite 1-D array, got shape {anchor.shape}")
        if not (np.isfinite(self.lam) and self.lam >= 0):
            raise ValueError(f"lam must be finite and >= 0, got {self.lam}")
        if int(self.order) != self.order or self.order < 1:
            raise ValueError(f"order must be an integer >= 1, got {self.order}")
        object.__setattr__(self, "anchor_m", anchor)
        object.__setattr__(self, "order", int(self.order))
        object.__setattr__(self, "lam", float(self.lam))


def difference_matrix(n: int, order: int) -> sp.csr_matrix:
    """Backward difference of order ``p`` as a banded lower-triangular matrix.

    ``(D x)(k) = sum_i (-1)^i C(p, i) x(k - i)`` for ``k = 0..n-1``, with ``x(-1) = .. = 0``.

    Parameters
    ----------
    n : int
        Length of the sequence [samples].
    order : int
        ``p >= 1``.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, n)
    """
    diags = [(-1) ** i * comb(order, i) * np.ones(n - i) for i in range(min(order, n - 1) + 1)]
    return sp.diags(diags, [-i for i in range(len(diags))], shape=(n, n), format="csr")


def _difference_gain2(omega_rad_s: np.ndarray, dt_s: float, order: int) -> np.ndarray:
    return (2.0 * np.sin(0.5 * np.asarray(omega_rad_s) * dt_s)) ** (2 * order)


def robustness_weight(
    model: DiscreteModel,
    cutoff_rad_s: float,
    order: int,
    anchor_m: np.ndarray,
    we: float = 1.0,
) -> RobustnessWeight:
    """The weight whose Q-filter passes one half at ``cutoff_rad_s`` for ``model``.

    ``lam = we |F(w_c)|^2 / (2 sin(w_c T / 2))^(2p)``.

    Parameters
    ----------
    model : DiscreteModel
        Model used by the update.
    cutoff_rad_s : float
        Cutoff ``w_c`` [rad/s], ``0 < w_c < pi / T``.
    order : int
        Difference order ``p``.
    anchor_m : ndarray, shape (N,)
        Setpoints the high frequencies are held to, learning coordinates [m].
    we : float
        Weight on the predicted error in eq. (8).

    Returns
    -------
    RobustnessWeight
    """
    nyquist = np.pi / model.dt_s
    if not (np.isfinite(cutoff_rad_s) and 0 < cutoff_rad_s < nyquist):
        raise ValueError(f"cutoff_rad_s must lie in (0, {nyquist:g}) rad/s, got {cutoff_rad_s}")
    gain2 = abs(frequency_response(model, np.array([cutoff_rad_s]))[0]) ** 2
    lam = we * gain2 / _difference_gain2(cutoff_rad_s, model.dt_s, order)
    return RobustnessWeight(float(lam), order, anchor_m, float(cutoff_rad_s))


def q_filter_response(
    model: DiscreteModel, weight: RobustnessWeight, omega_rad_s: np.ndarray, we: float = 1.0
) -> np.ndarray:
    """Asymptotic (long-trial) filter ``Q(w)`` the weight applies to the learned correction.

    Parameters
    ----------
    model : DiscreteModel
        Model used by the update.
    weight : RobustnessWeight
        The weight.
    omega_rad_s : ndarray, shape (K,)
        Frequencies [rad/s].
    we : float
        Weight on the predicted error in eq. (8).

    Returns
    -------
    ndarray, shape (K,)
        Real values in [0, 1]; 1 at DC.
    """
    f2 = we * np.abs(frequency_response(model, omega_rad_s)) ** 2
    d2 = weight.lam * _difference_gain2(omega_rad_s, model.dt_s, weight.order)
    return f2 / (f2 + d2)


def crossover_frequency(
    repeatable_psd: np.ndarray, nonrepeatable_psd: np.ndarray, omega_rad_s: np.ndarray
) -> float:
    """Lowest frequency above which the repeatable error no longer outweighs the non-repeatable.

    Both spectra are summed from the top down: ``R(w)`` and ``V(w)`` are the repeatable and
    the non-repeatable error power at frequencies at or above ``w``. From the returned
    frequency up ``R <= V``: learning there would remove no more than it injects (the
    estimate of one trial carries one flight's non-repeatable error). Summing the tails, and
    taking the first crossing from below, makes the answer robust to the scatter of single
    periodogram bins (which decides the comparison near Nyquist).

    Parameters
    ----------
    repeatable_psd : ndarray, shape (K,)
        Spectrum of the repeatable part of the error [m^2 s].
    nonrepeatable_psd : ndarray, shape (K,)
        Spectrum of one flight's non-repeatable error [m^2 s].
    omega_rad_s : ndarray, shape (K,)
        Increasing, evenly spaced frequencies [rad/s].

    Returns
    -------
    float
        The smallest grid frequency ``w`` with ``R(w) <= V(w)`` [rad/s]; the last grid
        frequency when there is none.
    """
    rep = np.asarray(repeatable_psd, dtype=float)
    nonrep = np.asarray(nonrepeatable_psd, dtype=float)
    w = np.asarray(omega_rad_s, dtype=float)
    if not (rep.shape == nonrep.shape == w.shape) or w.ndim != 1 or w.size < 2:
        raise ValueError("repeatable_psd, nonrepeatable_psd and omega_rad_s must share one shape")
    tail_rep = np.cumsum(rep[::-1])[::-1]
    tail_nonrep = np.cumsum(nonrep[::-1])[::-1]
    below = np.flatnonzero(tail_rep <= tail_nonrep)
    return float(w[below[0]]) if below.size else float(w[-1])


def repeat_cutoff(error_m: np.ndarray, dt_s: float) -> float:
    """Data-driven cutoff from K >= 2 flights of identical setpoints (one axis).

    The repeatable error is their mean, the non-repeatable error of one flight the scaled
    deviation from it (:mod:`gcs.core.floor`); the repeatable periodogram is corrected for
    the non-repeatable share left in a mean of K flights, and the two are compared by
    :func:`crossover_frequency`.

    Parameters
    ----------
    error_m : ndarray, shape (K, N)
        Tracking errors ``yd - y`` of the flights [m].
    dt_s : float
        Sample time [s].

    Returns
    -------
    float
        Cutoff [rad/s].
    """
    e = np.asarray(error_m, dtype=float)
    if e.ndim != 2 or e.shape[0] < 2 or e.shape[1] < 8:
        raise ValueError(f"error_m must have shape (K >= 2, N >= 8), got {e.shape}")
    k, n = e.shape
    mean = e.mean(axis=0)
    dev = np.sqrt(k / (k - 1)) * (e - mean)
    scale = dt_s / n
    nonrep = scale * np.mean(np.abs(np.fft.rfft(dev, axis=-1)) ** 2, axis=0)
    rep = scale * np.abs(np.fft.rfft(mean)) ** 2 - nonrep / k
    omega = 2.0 * np.pi * np.fft.rfftfreq(n, dt_s)
    return crossover_frequency(rep[1:], nonrep[1:], omega[1:])
