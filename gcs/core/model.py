"""Discrete LTI models of the closed loop "position setpoint -> measured position".

A :class:`DiscreteModel` is a SISO state-space model ``(A, B, C)`` sampled at ``dt_s`` with an
explicit integer input delay of ``delay_samples``::

    x(k+1) = A x(k) + B u(k - delay_samples)
    y(k)   = C x(k)

There is no direct feedthrough: a position loop cannot move the vehicle in the same sample it
receives a setpoint. The lifted form of the paper (eq. 4-5) maps ``U = [u(0) .. u(N-1)]`` to
``Y = [y(1) .. y(N)]`` through the lower-triangular Toeplitz matrix of Markov parameters
``f_k = C A^(k-1-delay) B``. When the relative degree ``r`` is above one the first ``r - 1``
outputs cannot be influenced and the last ``r - 1`` inputs influence nothing within the
trial; :func:`controllable_slices` names both ranges so that the estimator, the update and
the report treat them the same way.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from gcs.errors import ModelError

__all__ = [
    "DiscreteModel",
    "from_transfer_function",
    "from_state_space",
    "markov_parameters",
    "lifted_matrix",
    "simulate",
    "predicted_output",
    "relative_degree",
    "controllable_slices",
    "dc_gain",
    "frequency_response",
]


@dataclass(frozen=True)
class DiscreteModel:
    """SISO discrete state-space model with an explicit input delay.

    Parameters
    ----------
    A : ndarray, shape (n, n)
        State matrix.
    B : ndarray, shape (n, 1)
        Input matrix (input: position setpoint [m]).
    C : ndarray, shape (1, n)
        Output matrix (output: measured position [m]).
    dt_s : float
        Sample time [s].
    delay_samples : int
        Pure input delay in samples, applied before ``B``.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    dt_s: float
    delay_samples: int = 0

    def __post_init__(self) -> None:
        A = np.atleast_2d(np.asarray(self.A, dtype=float))
        n = A.shape[0]
        B = np.asarray(self.B, dtype=float).reshape(n, 1)
        C = np.asarray(self.C, dtype=float).reshape(1, n)
        if A.shape != (n, n):
            raise ModelError(f"A must be square, got shape {A.shape}")
        if not np.all(np.isfinite(A)) or not np.all(np.isfinite(B)) or not np.all(np.isfinite(C)):
            raise ModelError("model matrices contain NaN or inf")
        if not self.dt_s > 0:
            raise ModelError(f"dt_s must be positive, got {self.dt_s}")
        if self.delay_samples < 0:
            raise ModelError(f"delay_samples must be >= 0, got {self.delay_samples}")
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "B", B)
        object.__setattr__(self, "C", C)
        object.__setattr__(self, "delay_samples", int(self.delay_samples))

    @property
    def order(self) -> int:
        """Number of states of the core model (without delay states)."""
        return self.A.shape[0]

    @functools.cached_property
    def difference_equation(self) -> tuple[np.ndarray, np.ndarray]:
        """``(num, a)`` of :func:`simulate`'s difference equation (computed once per model).

        ``a`` the characteristic polynomial of ``A``, ``num`` the delay's zeros, then ``b``
        from the first ``n`` Markov parameters. Read-only arrays.
        """
        n = self.order
        a = np.real(np.poly(self.A))  # det(zI - A) = z^n + a_1 z^(n-1) + ..
        f = np.empty(n)  # Markov parameters without the delay
        x = self.B[:, 0].copy()
        for k in range(n):
            f[k] = self.C[0] @ x
            x = self.A @ x
        b = np.array([f[k] + a[1 : k + 1] @ f[k - 1 :: -1][:k] for k in range(n)])
        num = np.concatenate([np.zeros(self.delay_samples), b])
        num.flags.writeable = False
        a.flags.writeable = False
        return num, a

    def is_stable(self) -> bool:
        """True when all eigenvalues of ``A`` lie strictly inside the unit circle."""
        return bool(np.all(np.abs(np.linalg.eigvals(self.A)) < 1.0))

    def as_dict(self) -> dict:
        """The model as the profile's state-space form, plain floats (YAML and JSON ready).

        Returns
        -------
        dict
            ``{A, B, C, D, dt_s, delay_samples}`` with ``D = [[0.0]]`` (no feedthrough); the
            floats round-trip exactly through :func:`from_state_space`.
        """
        return {
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "D": [[0.0]],
            "dt_s": float(self.dt_s),
            "delay_samples": int(self.delay_samples),
        }


def frequency_response(model: DiscreteModel, omega_rad_s: np.ndarray) -> np.ndarray:
    """Frequency response ``F(e^{j w T})`` of a model, its delay included.

    Parameters
    ----------
    model : DiscreteModel
        The model (sample time ``T = model.dt_s``).
    omega_rad_s : ndarray, shape (K,)
        Frequencies [rad/s], ``0 <= w <= pi / T``.

    Returns
    -------
    ndarray of complex, shape (K,)
        ``C (zI - A)^-1 B z^-delay`` at ``z = e^{j w T}`` [m/m].
    """
    w = np.atleast_1d(np.asarray(omega_rad_s, dtype=float))
    z = np.exp(1j * w * model.dt_s)
    n = model.order
    out = np.empty(w.shape, dtype=complex)
    for i, zi in enumerate(z):
        out[i] = (model.C @ np.linalg.solve(zi * np.eye(n) - model.A, model.B))[0, 0]
    return out * z ** (-model.delay_samples)


def _controllable_form(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, ...]:
    """The controllable canonical form of a strictly proper ``num / den``: ``A`` (n, n),
    ``B`` (n, 1), ``C`` (1, n), the same arithmetic as ``scipy.signal.tf2ss`` (so bit for bit
    its matrices), without importing ``scipy.signal`` (a second or more, with ``scipy.stats``)
    where a study needs nothing else of it."""
    lead = den[0]
    den, num = den / lead, num / lead
    n = den.size - 1
    a = np.vstack([-den[1:][np.newaxis, :], np.eye(n - 1, n)])
    b = np.eye(n, 1)
    c = np.concatenate([np.zeros(n - num.size), num])[np.newaxis, :]
    return a, b, c


def from_transfer_function(
    num: list[float], den: list[float], delay_s: float, dt_s: float
) -> DiscreteModel:
    """Discretise ``G(s) = exp(-delay_s s) num(s) / den(s)`` with a zero-order hold.

    The zero-order hold is exact for the way setpoints are flown: each setpoint is held
    constant for one sample time. A delay that is a whole number of samples becomes
    ``delay_samples``; a fractional remainder ``tau`` is discretised exactly (modified
    z-transform, Astrom and Wittenmark, Computer-Controlled Systems, sec. 2.3) with one extra
    state holding the previous input.

    Parameters
    ----------
    num, den : list of float
        Polynomial coefficients in descending powers of ``s``; ``len(num) < len(den)``.
    delay_s : float
        Pure time delay [s], ``>= 0``.
    dt_s : float
        Sample time [s].

    Returns
    -------
    DiscreteModel
    """
    num = np.atleast_1d(np.asarray(num, dtype=float))
    den = np.atleast_1d(np.asarray(den, dtype=float))
    if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))):
        raise ModelError(f"num and den must be finite, got num={num.tolist()} den={den.tolist()}")
    num = np.trim_zeros(num, "f")
    den = np.trim_zeros(den, "f")
    if den.size == 0 or num.size == 0:
        raise ModelError("num and den must be non-empty and non-zero")
    if num.size >= den.size:
        raise ModelError("the transfer function must be strictly proper (len(num) < len(den))")
    with np.errstate(over="ignore"):
        scaled = np.concatenate([num, den]) / den[0]
    if not np.all(np.isfinite(scaled)):
        raise ModelError(
            f"num and den divided by den[0] = {den[0]:.3g} overflow: give them at a usable scale"
        )
    if delay_s < 0 or not np.isfinite(delay_s):
        raise ModelError(f"delay_s must be >= 0, got {delay_s}")
    if not (dt_s > 0 and np.isfinite(dt_s)):
        raise ModelError(f"dt_s must be positive and finite, got {dt_s}")
    Ac, Bc, Cc = _controllable_form(num, den)
    n_whole = int(np.floor(delay_s / dt_s + 1e-9))
    tau = delay_s - n_whole * dt_s
    if tau <= 1e-9 * dt_s:
        Ad, B0 = _zoh(Ac, Bc, dt_s)
        return DiscreteModel(Ad, B0, Cc, dt_s, n_whole)
    # Fractional delay: x(k+1) = Ad x(k) + G0 u(k-n) + G1 u(k-n-1), G0 over [0, dt - tau],
    # G1 = e^{A (dt - tau)} * integral over [0, tau]. Augment with z(k) = u(k-n-1).
    Ad, _ = _zoh(Ac, Bc, dt_s)
    e_late, g0 = _zoh(Ac, Bc, dt_s - tau)
    _, g_tau = _zoh(Ac, Bc, tau)
    g1 = e_late @ g_tau
    n = Ac.shape[0]
    A_aug = np.block([[Ad, g1], [np.zeros((1, n)), np.zeros((1, 1))]])
    B_aug = np.vstack([g0, np.ones((1, 1))])
    C_aug = np.hstack([Cc, np.zeros((1, 1))])
    return DiscreteModel(A_aug, B_aug, C_aug, dt_s, n_whole)


def from_state_space(
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    D: np.ndarray | float,
    dt_s: float,
    delay_samples: int = 0,
) -> DiscreteModel:
    """Build a :class:`DiscreteModel` from discrete ``A, B, C, D`` (e.g. identified).

    Parameters
    ----------
    A, B, C : array_like
        Discrete state-space matrices, shapes (n, n), (n, 1), (1, n).
    D : array_like, shape (1, 1), or float
        Direct feedthrough; must be zero (to 1e-9 relative to the Markov parameters), since the
        lifted map of the paper has none.
    dt_s : float
        Sample time [s].
    delay_samples : int
        Pure input delay [samples].

    Returns
    -------
    DiscreteModel
    """
    model = DiscreteModel(A, B, C, dt_s, delay_samples)
    d = float(np.asarray(D, dtype=float).reshape(-1)[0]) if np.size(D) else 0.0
    scale = max(float(np.max(np.abs(markov_parameters(model, 20)))), 1e-12)
    if abs(d) > 1e-9 * scale:
        raise ModelError(
            f"direct feedthrough D = {d:g} is not supported: identify with D = 0 (no_d)"
        )
    return model


def _zoh(Ac: np.ndarray, Bc: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(e^{A t}, integral_0^t e^{A s} ds B)`` via one matrix exponential."""
    n, m = Bc.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = Ac * t
    M[:n, n:] = Bc * t
    E = scipy.linalg.expm(M)
    return E[:n, :n], E[:n, n:]


def markov_parameters(model: DiscreteModel, n: int) -> np.ndarray:
    """Markov parameters ``f_1 .. f_n`` (eq. 2), the delay included.

    Parameters
    ----------
    model : DiscreteModel
    n : int
        How many parameters.

    Returns
    -------
    ndarray, shape (n,)
        ``f[k-1] = C A^(k-1-delay) B`` for ``k > delay``, zero otherwise.
    """
    f = np.zeros(n)
    x = model.B[:, 0].copy()
    c = model.C[0]
    for k in range(model.delay_samples, n):
        f[k] = c @ x
        x = model.A @ x
    return f


def lifted_matrix(model: DiscreteModel, n: int) -> np.ndarray:
    """Lower-triangular Toeplitz matrix ``F`` of eq. (5), ``Y = F U``.

    Parameters
    ----------
    model : DiscreteModel
    n : int
        Trial length in samples.

    Returns
    -------
    ndarray, shape (n, n)
        ``F[i, j] = f_(i-j+1)`` for ``i >= j``; ``Y[i] = y(i+1)``, ``U[j] = u(j)``.
    """
    f = markov_parameters(model, n)
    return scipy.linalg.toeplitz(f, np.zeros(n))


def simulate(model: DiscreteModel, u: np.ndarray) -> np.ndarray:
    """Simulate from rest: outputs ``y(1) .. y(N)`` for inputs ``u(0) .. u(N-1)``.

    The difference equation of the model's transfer function (``scipy.signal.lfilter``,
    compiled): ``z^-d (b_1 + .. + b_n z^-(n-1)) / (1 + a_1 z^-1 + .. + a_n z^-n)`` with ``a``
    the characteristic polynomial of ``A`` and ``b`` from the first ``n`` Markov parameters.

    Parameters
    ----------
    model : DiscreteModel
    u : ndarray, shape (N,) or (N, M)
        Input sequence(s); a second axis simulates M sequences at once.

    Returns
    -------
    ndarray, same shape as ``u``
    """
    u = np.asarray(u, dtype=float)
    num, a = model.difference_equation
    from scipy.signal import lfilter  # on first use: a second to import

    return lfilter(num, a, u, axis=0)


def predicted_output(model: DiscreteModel, u: np.ndarray, d_hat: np.ndarray) -> np.ndarray:
    """The outputs the lifted model ``Y = F U + D`` predicts for inputs ``u``.

    A learning step plans the next trial with this prediction: its measured positions against
    it show how well the model foresaw the vehicle (the step's own error, apart from noise).

    Parameters
    ----------
    model : DiscreteModel
    u : ndarray, shape (N,)
        Inputs u(0..N-1), learning coordinates (relative to the start point) [m].
    d_hat : ndarray, shape (N,)
        Disturbance d(1..N) in the same coordinates (a learning step's estimate) [m].

    Returns
    -------
    ndarray, shape (N,)
        Outputs y(1..N) [m].
    """
    u = np.asarray(u, dtype=float)
    d = np.asarray(d_hat, dtype=float)
    if u.ndim != 1 or u.shape != d.shape:
        raise ValueError(f"u and d_hat must be (N,) alike, got {u.shape} and {d.shape}")
    return simulate(model, u) + d


def relative_degree(model: DiscreteModel, rtol: float = 1e-9) -> int:
    """Index ``r`` of the first non-zero Markov parameter (``r >= 1``).

    Parameters
    ----------
    model : DiscreteModel
    rtol : float
        A Markov parameter counts as zero below ``rtol`` times the largest of the first
        ``delay + order + 1``.

    Returns
    -------
    int
    """
    m = model.delay_samples + model.order + 1
    f = markov_parameters(model, m)
    scale = float(np.max(np.abs(f)))
    if scale == 0.0:
        raise ModelError("the model's input has no effect on its output (all Markov parameters 0)")
    return int(np.argmax(np.abs(f) > rtol * scale)) + 1


def controllable_slices(model: DiscreteModel, n: int) -> tuple[slice, slice]:
    """Which inputs can act and which outputs can be influenced within an ``n``-sample trial.

    Parameters
    ----------
    model : DiscreteModel
    n : int
        Trial length in samples.

    Returns
    -------
    inputs : slice
        ``u(0) .. u(n - r)``: the inputs that influence some output of the trial.
    outputs : slice
        Indices into ``Y`` of ``y(r) .. y(n)``: the outputs some input influences.
    """
    r = relative_degree(model)
    if r > n:
        raise ModelError(f"trial of {n} samples is shorter than the model's delay ({r} samples)")
    return slice(0, n - r + 1), slice(r - 1, n)


def dc_gain(model: DiscreteModel) -> float:
    """Static gain ``C (I - A)^-1 B`` of a stable model.

    Parameters
    ----------
    model : DiscreteModel
        A stable model.

    Returns
    -------
    float
        Output change per unit input change in steady state [m/m].
    """
    n = model.order
    return float((model.C @ np.linalg.solve(np.eye(n) - model.A, model.B))[0, 0])
