"""Input update of the smoother-based ILC: the quadratically optimal design of eq. (8).

The next trial input ``U_{j+1}`` minimises (paper, sec. III-B)::

    J = E^T We E + dU^T Wdu dU + U^T Wu U,
    E = F U - Yd + D_hat,   dU = U - U_j,

per axis (SISO), in learning coordinates (metres relative to the trajectory's start point, the
vehicle at rest there before the trial: zero initial state, ``u(-1) = 0``). ``We = we I``,
``Wdu = wdu I``, ``Wu = wu I``.

Relative degree ``r > 1`` (a delay of ``r - 1`` samples) is treated as in
:func:`gcs.core.model.controllable_slices`:

* the cost covers only the outputs ``y(r) .. y(N)``: ``y(1) .. y(r-1)`` cannot be influenced;
* the free inputs are ``u(0) .. u(N-r)``; the last ``r - 1`` inputs influence nothing within the
  trial and are pinned to the final reference ``yd(N)`` (the vehicle ends hovering at the end
  point). Their ``dU`` and ``U`` terms are constants of ``J`` and are included in the reported
  objective.

Formulation (linear in ``N``): the decision vector is ``z = [u(0) .. u(N-r), x(d+1) .. x(N)]``
with ``d`` the model's input delay; the dynamics ``x(k+1) = A x(k) + B u(k-d)`` are banded
equality constraints and the cost on the outputs is ``we (C x(k) - yd(k) + d_hat(k))^2``.
Without limits (or when the unconstrained optimum already satisfies them) the equality
constrained QP is solved through its KKT system, which is banded once its unknowns are put in
stage-wise order (the dynamics' multipliers of step ``t``, ``u(t)`` and ``x(d+1+t)`` together):
LAPACK's banded LU (``dgbtrf`` / ``dgbtrs``), linear in ``N``. With active limits the same QP
plus linear inequalities goes to Clarabel (``ZeroConeT`` for the dynamics,
``NonnegativeConeT`` for the limits) the first time; a kept :class:`InputUpdate` then starts
the next trial from the active set of the last one (an active-set iteration on the banded KKT
system, Clarabel again when it does not settle in a few rounds, its solver kept: only the
linear term is replaced). See ``docs/update.md``.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import clarabel
import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse as sp
import scipy.sparse.csgraph

from gcs.core.model import (
    DiscreteModel,
    controllable_slices,
    lifted_matrix,
    markov_parameters,
    relative_degree,
)
from gcs.core.robustness import RobustnessWeight, difference_matrix
from gcs.errors import TrajectoryError, UpdateInfeasible

__all__ = [
    "UpdateWeights",
    "SetpointLimits",
    "UpdateResult",
    "next_input",
    "InputUpdate",
    "unconstrained_update_operator",
    "reference_for_inputs",
]

#: A limit counts as satisfied by the unconstrained optimum (fast path) within this margin [m].
_FAST_PATH_TOL_M = 1e-9
#: An inequality counts as active when its slack is below this [m].
_ACTIVE_TOL_M = 1e-7
#: Feasibility pre-check margin [m] (intervals emptier than this are infeasible).
_FEAS_TOL_M = 1e-9
#: Active-set refinement rounds after Clarabel (each one banded KKT solve).
_POLISH_ROUNDS = 5
#: Rounds of the active-set solve started from the last trial's active set before Clarabel.
_WARM_ROUNDS = 8
#: An active-set round solves through the Schur complement of the unconstrained KKT matrix
#: (:class:`_Schur`) while at most this many limits are held with equality; more go to the
#: banded LU of the whole KKT system. The Schur complement is dense, its Cholesky
#: factorisation grows as the cube of the count, and above about a hundred rows OpenBLAS
#: spreads it over threads, which on a busy machine took 3-18 ms instead of 0.2-1.4 ms.
_SCHUR_MAX_ROWS = 96
#: Columns of the inverse KKT matrix a structure keeps for the Schur complement (each one
#: ``N`` floats); a round that would need more goes to the banded LU.
_SCHUR_MAX_COLUMNS = 512
#: The objective's simulation convolves directly up to this many samples, by FFT above.
_DIRECT_CONVOLVE = 512
#: Order of the KKT system's unknowns within one time step ``t`` (keys added to ``t`` before
#: the stable sort of :class:`_BandedLU`): the limits held at ``t``, the dynamics'
#: multipliers of step ``t``, the input ``u(t)``, the state ``x(d+1+t)``. Each then couples
#: only with near neighbours (a limit with ``u(t-1)`` and ``u(t)``, a multiplier with
#: ``x(d+t)``, ``u(t)`` and ``x(d+1+t)``): at N = 6000 with limits held the band is 4-5 wide
#: on each side, against 8-12 in the order input, state, multipliers, limits, and ``dgbtrf``'s
#: work grows as the square of that width.
_KEY_LIMIT, _KEY_DYNAMICS, _KEY_INPUT, _KEY_STATE = 0.0, 0.25, 0.5, 0.75


@dataclass(frozen=True)
class UpdateWeights:
    """Scalar weights of eq. (8): ``We = we I``, ``Wdu = wdu I``, ``Wu = wu I``.

    Defaults are the values of the paper's Table I.

    Parameters
    ----------
    we : float
        Weight on the predicted tracking error [1/m^2], ``> 0``.
    wdu : float
        Weight on the input change between trials [1/m^2], ``>= 0``.
    wu : float
        Weight on the input itself [1/m^2], ``>= 0``.
    """

    we: float = 1.0
    wdu: float = 0.01
    wu: float = 0.0

    def __post_init__(self) -> None:
        for name, lower_ok in (("we", False), ("wdu", True), ("wu", True)):
            value = getattr(self, name)
            try:
                v = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"UpdateWeights.{name} must be a number, got {value!r}") from None
            if not math.isfinite(v) or v < 0 or (v == 0 and not lower_ok):
                bound = ">= 0" if lower_ok else "> 0"
                raise ValueError(f"UpdateWeights.{name} must be finite and {bound}, got {value}")
            object.__setattr__(self, name, v)


@dataclass(frozen=True)
class SetpointLimits:
    """Limits on the setpoints of one axis, in learning coordinates. All optional.

    Parameters
    ----------
    u_min_m : float or None
        Lower edge of the arena box for this axis [m].
    u_max_m : float or None
        Upper edge of the arena box for this axis [m].
    max_step_m : float or None
        Bound on ``|u(k) - u(k-1)|`` per sample [m], with ``u(-1) = 0`` (vehicle at rest at
        the start point). Also applies between the last free input and the pinned tail.
    max_deviation_m : float or None
        Bound on ``|u(k) - yd_u(k)|`` [m], where ``yd_u`` is the reference aligned with the
        inputs (see :func:`reference_for_inputs`): the setpoint at ``k`` acts first on
        ``y(k + r)``, so ``yd_u(k) = yd(k + r)``, and ``yd_u(k) = yd(N)`` for the pinned tail.
    """

    u_min_m: float | None = None
    u_max_m: float | None = None
    max_step_m: float | None = None
    max_deviation_m: float | None = None

    def __post_init__(self) -> None:
        for name in ("u_min_m", "u_max_m", "max_step_m", "max_deviation_m"):
            value = getattr(self, name)
            if value is None:
                continue
            try:
                v = float(value)
            except (TypeError, ValueError):
                raise ValueError(
                    f"SetpointLimits.{name} must be a number or None, got {value!r}"
                ) from None
            if math.isnan(v):
                raise ValueError(f"SetpointLimits.{name} is NaN")
            if name in ("max_step_m", "max_deviation_m") and not v >= 0:
                raise ValueError(f"SetpointLimits.{name} must be >= 0, got {value}")
            object.__setattr__(self, name, v)
        if self.u_min_m is not None and self.u_max_m is not None and self.u_min_m > self.u_max_m:
            raise UpdateInfeasible(
                f"arena box is empty: u_min_m = {self.u_min_m:g} > u_max_m = {self.u_max_m:g}"
            )


@dataclass(frozen=True)
class UpdateResult:
    """Outcome of one input update (one axis).

    Parameters
    ----------
    u_m : ndarray, shape (N,)
        Next trial input ``u(0) .. u(N-1)`` [m], learning coordinates.
    status : str
        ``"solved"``, or Clarabel's status name when it is not ``Solved`` (``"AlmostSolved"``).
    objective : float
        Value of eq. (8) at ``u_m`` [dimensionless], the error term over ``y(r) .. y(N)``,
        the ``dU`` and ``U`` terms over all ``N`` inputs (the pinned tail included); computed
        from ``u_m`` by the same simulation for both methods.
    method : str
        ``"direct"`` (no limit active: one banded KKT solve), ``"clarabel"`` (limits active,
        Clarabel's interior point refined on its active set) or ``"active-set"`` (limits
        active, the last trial's active set refined by banded KKT solves until the KKT
        conditions hold; the same minimiser).
    active_constraints : int
        Number of inequality limits holding with equality (slack below 1e-7 m).
    """

    u_m: np.ndarray
    status: str
    objective: float
    method: str
    active_constraints: int


# ---------------------------------------------------------------------------------------------
# Problem data
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Problem:
    """Equality-constrained QP ``min 1/2 z'Pz + q'z  s.t.  G z = h`` of one axis."""

    n: int  # trial length N
    r: int  # relative degree
    m: int  # number of free inputs, N - r + 1
    y_final: float  # yd(N), value of the pinned tail
    P: sp.csc_matrix  # full symmetric
    q: np.ndarray
    G: sp.csc_matrix
    h: np.ndarray
    yd_u: np.ndarray  # reference aligned with the inputs, shape (N,)
    stage_z: np.ndarray  # stage (time step) of each entry of z, shape (nz,)
    stage_eq: np.ndarray  # stage of each row of G, shape (rows of G,)


def _check_vector(name: str, value: object, n: int | None, exc: type[Exception]) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 1:
        raise exc(f"{name} must be one-dimensional, got shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise exc(f"{name} must have {n} samples, got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        raise exc(f"{name} contains NaN or inf")
    return arr


def reference_for_inputs(yd_m: np.ndarray, r: int) -> np.ndarray:
    """Align the reference with the inputs: ``yd_u(k) = yd(k + r)``, the tail held at ``yd(N)``.

    Parameters
    ----------
    yd_m : ndarray, shape (N,)
        Reference ``yd(1) .. yd(N)`` [m] (Y-indexed).
    r : int
        Relative degree of the model (``>= 1``).

    Returns
    -------
    ndarray, shape (N,)
        ``yd_u(k)`` for ``k = 0 .. N-1`` [m] (U-indexed): ``yd_m[k + r - 1]`` for
        ``k <= N - r`` and ``yd_m[-1]`` for the ``r - 1`` pinned tail samples.
    """
    yd_m = np.asarray(yd_m, dtype=float)
    return np.concatenate([yd_m[r - 1 :], np.full(r - 1, yd_m[-1])])


class _Structure:
    """The parts of one axis's QP that do not change between trials (model, N, weights, yd).

    Built once per :class:`InputUpdate`: the banded dynamics ``G z = h``, the Hessian ``P``
    without the robustness term, its KKT factorisation (on first use), the Markov parameters
    for the objective. Each trial then only forms the linear term ``q``.
    """

    def __init__(self, model: DiscreteModel, yd_m: np.ndarray, weights: UpdateWeights) -> None:
        if not isinstance(model, DiscreteModel):
            raise TypeError(f"model must be a DiscreteModel, got {type(model).__name__}")
        if not isinstance(weights, UpdateWeights):
            raise TypeError(f"weights must be UpdateWeights, got {type(weights).__name__}")
        yd = _check_vector("yd_m", yd_m, None, TrajectoryError)
        N = yd.shape[0]
        if N == 0:
            raise TrajectoryError("yd_m is empty")
        controllable_slices(model, N)  # raises ModelError when the trial is shorter than r
        r = relative_degree(model)
        d = model.delay_samples
        nx = model.order
        m = N - r + 1
        T = N - d  # number of state blocks x(d+1) .. x(N)
        s = r - d - 1  # first state block whose output is in the cost
        A, B, C = model.A, model.B, model.C
        y_final = float(yd[-1])

        # Dynamics: x(d+1+t) - A x(d+t) - B u(t) = 0, t = 0 .. T-1 (x(d) = 0); u(t) pinned for
        # t >= m.
        GX = sp.kron(sp.eye(T), sp.eye(nx)) - sp.kron(sp.eye(T, k=-1), sp.csr_matrix(A))
        GU = sp.kron(sp.eye(T, m), sp.csr_matrix(-B))
        G = sp.hstack([GU, GX], format="csc")
        pinned = (np.arange(T) >= m).astype(float)
        h = np.kron(pinned * y_final, B[:, 0])

        # Cost: we (C x(k) - w(k))^2 for k = r..N, w = yd - d_hat; (wdu + wu) u^2 - 2 wdu u_prev u.
        mask = (np.arange(T) >= s).astype(float)
        ctc = C.T @ C
        self.PX = sp.kron(sp.diags(mask), sp.csr_matrix(2.0 * weights.we * ctc))
        self.PU = sp.eye(m) * (2.0 * (weights.wdu + weights.wu))
        self.P = sp.block_diag([self.PU, self.PX], format="csc")
        self.model, self.weights, self.yd, self.d, self.mask = model, weights, yd, d, mask
        self.n, self.r, self.m, self.y_final = N, r, m, y_final
        self.G, self.h = G, h
        self.yd_u = reference_for_inputs(yd, r)
        self.f = markov_parameters(model, N)
        # stage-wise order of the KKT system: the dynamics' row t, u(t) and x(d+1+t) together
        step = np.repeat(np.arange(T), nx)
        self.stage_eq = step + _KEY_DYNAMICS
        self.stage_z = np.concatenate([np.arange(m) + _KEY_INPUT, step + _KEY_STATE])
        self._kkt: tuple[_Triplets, _BandedLU] | None = None
        self._schur: _Schur | None = None
        self._dense: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def problem(
        self, d_hat_m: np.ndarray, u_prev_m: np.ndarray, robust: RobustnessWeight | None
    ) -> _Problem:
        """The QP of one trial: the fixed structure and this trial's linear term."""
        N, m = self.n, self.m
        dh = _check_vector("d_hat_m", d_hat_m, N, ValueError)
        up = _check_vector("u_prev_m", u_prev_m, N, ValueError)
        qU, qX = self.linear_terms(dh, up)
        P = self.P
        if robust is not None and robust.lam > 0:
            PR, qR = _robust_terms(robust, N, m, self.y_final)
            P, qU = sp.block_diag([self.PU + PR, self.PX], format="csc"), qU + qR
        q = np.concatenate([qU, qX])
        return _Problem(N, self.r, m, self.y_final, P, q, self.G, self.h, self.yd_u,
                        self.stage_z, self.stage_eq)  # fmt: skip

    def linear_terms(
        self, d_hat_m: np.ndarray, u_prev_m: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The linear term of eq. (8) without the robustness weight, of one trial (shape (N,))
        or of many (rows of shape (P, N)): its input part (..., m) and its state part
        (..., nz - m)."""
        we, wdu = self.weights.we, self.weights.wdu
        w = self.yd - d_hat_m
        qX = (-2.0 * we * (self.mask * w[..., self.d : self.n]))[..., None] * self.model.C[0]
        qU = -2.0 * wdu * u_prev_m[..., : self.m]
        return qU, qX.reshape(*qX.shape[:-2], -1)

    def kkt_base(self) -> _Triplets:
        """The KKT matrix ``[P G'; G 0]`` of the structure's own Hessian as triplets (the
        active-set method adds the limits held with equality to it)."""
        if self._kkt is None:
            self._kkt = _kkt_factor(self.P, self.G, self.stage_z, self.stage_eq)
        return self._kkt[0]

    def schur(self) -> _Schur:
        """The KKT system of the structure's own Hessian for the active-set rounds through the
        Schur complement (built on first use, its columns kept across trials)."""
        if self._schur is None:
            K = self.kkt_base()
            self._schur = _Schur(K, self._kkt[1], self.m)
        return self._schur

    def solve_direct(self, prob: _Problem) -> np.ndarray:
        """Unconstrained optimum (equality-constrained QP); the free inputs. The KKT matrix
        of the structure's own Hessian is factorised once."""
        if prob.P is not self.P:
            return _solve_direct(prob)
        if self._kkt is None:
            self._kkt = _kkt_factor(self.P, self.G, prob.stage_z, prob.stage_eq)
        z, _ = _kkt_solve_factored(*self._kkt, prob.q, prob.h, self.P.shape[0])
        return z[: prob.m]


def _build_problem(
    model: DiscreteModel,
    yd_m: np.ndarray,
    d_hat_m: np.ndarray,
    u_prev_m: np.ndarray,
    weights: UpdateWeights,
    robust: RobustnessWeight | None = None,
) -> _Problem:
    """The QP of one trial, structure and linear term built together."""
    return _Structure(model, yd_m, weights).problem(d_hat_m, u_prev_m, robust)


def _robust_terms(
    robust: RobustnessWeight, n: int, m: int, y_final: float
) -> tuple[sp.csc_matrix, np.ndarray]:
    """Hessian block and linear term of ``lam ||D (u - anchor)||^2`` on the free inputs.

    The pinned tail (``u = y_final``) is a constant of ``D u`` and moves to the offset.
    """
    if robust.anchor_m.shape != (n,):
        raise ValueError(
            f"robustness anchor_m must have {n} samples, got shape {robust.anchor_m.shape}"
        )
    D = difference_matrix(n, robust.order)
    Df = D[:, :m]
    offset = D @ robust.anchor_m - D[:, m:] @ np.full(n - m, y_final)
    return (2.0 * robust.lam * (Df.T @ Df)).tocsc(), -2.0 * robust.lam * (Df.T @ offset)


def _full_input(prob: _Problem, u_free: np.ndarray) -> np.ndarray:
    return np.concatenate([u_free, np.full(prob.r - 1, prob.y_final)])


#: A sparse square matrix as triplets ``(rows, cols, values)`` and its size: ``K[i, j] = v``.
_Triplets = tuple[np.ndarray, np.ndarray, np.ndarray, int]


def _matvec(K: _Triplets, x: np.ndarray) -> np.ndarray:
    i, j, v, n = K
    return np.bincount(i, weights=v * x[j], minlength=n)


class _BandedLU:
    """LU factorisation (LAPACK ``dgbtrf``, partial pivoting) of a square sparse matrix that is
    banded once its unknowns are put in stage-wise order: the KKT matrix of the update, whose
    variables and rows of time step ``t`` couple only with those of ``t - 1`` and ``t + 1``
    (and, with the robustness weight or a rate limit, a few steps further). Cost linear in N:
    the factorisation ``O(n kl (kl + ku))``, a solve ``O(n (kl + ku))``.

    Parameters
    ----------
    K : tuple (rows, cols, values, n)
        The matrix as triplets (no position twice).
    stage : ndarray, shape (n,)
        Stage (time step, plus its place within the step: :data:`_KEY_LIMIT` ...) of each
        unknown and row; the unknowns are ordered by it (stably).
    """

    def __init__(self, K: _Triplets, stage: np.ndarray) -> None:
        rows, cols, values, n = K
        order = np.argsort(stage, kind="stable")
        inv = np.empty(n, dtype=np.intp)
        inv[order] = np.arange(n)
        i, j = inv[rows], inv[cols]
        kl = int(np.max(i - j, initial=0))
        ku = int(np.max(j - i, initial=0))
        ab = np.zeros((2 * kl + ku + 1, n))
        ab[kl + ku + i - j, j] = values
        lu, piv, info = scipy.linalg.lapack.dgbtrf(ab, kl, ku, overwrite_ab=True)
        if info != 0:
            raise RuntimeError(f"banded LU of the input update's KKT matrix failed (info {info})")
        self.order, self.kl, self.ku, self._lu, self._piv = order, kl, ku, lu, piv

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``K^-1 rhs`` for ``rhs`` of shape (n,) or (n, k) (``k`` right-hand sides)."""
        x, info = scipy.linalg.lapack.dgbtrs(self._lu, self.kl, self.ku, rhs[self.order], self._piv)
        if info != 0:
            raise RuntimeError(f"banded solve of the input update's KKT system failed ({info})")
        out = np.empty_like(x)
        out[self.order] = x
        return out


def _kkt_triplets(P: sp.spmatrix, G: sp.spmatrix) -> _Triplets:
    """``[P G'; G 0]`` as triplets."""
    Pc, Gc = sp.coo_matrix(P), sp.coo_matrix(G)
    Pc.sum_duplicates()
    Gc.sum_duplicates()
    nz = P.shape[0]
    rows = np.concatenate([Pc.row, nz + Gc.row, Gc.col]).astype(np.intp)
    cols = np.concatenate([Pc.col, Gc.col, nz + Gc.row]).astype(np.intp)
    return rows, cols, np.concatenate([Pc.data, Gc.data, Gc.data]), nz + G.shape[0]


def _with_rows(K: _Triplets, A: sp.csr_matrix, act: np.ndarray) -> _Triplets:
    """``[K A_act'; A_act 0]``: the rows ``act`` of ``A`` (CSR, columns of the first block of
    ``K``) added as equality constraints, their multipliers after ``K``'s unknowns."""
    rows, cols, values, n = K
    idx = np.flatnonzero(act)
    count = np.diff(A.indptr)[idx]
    new = n + np.repeat(np.arange(idx.size), count)
    start = np.repeat(A.indptr[idx] - np.cumsum(count) + count, count)
    pos = start + np.arange(int(count.sum()))
    c, v = A.indices[pos].astype(np.intp), A.data[pos]
    return (np.concatenate([rows, new, c]), np.concatenate([cols, c, new]),
            np.concatenate([values, v, v]), n + idx.size)  # fmt: skip


def _kkt_factor(
    P: sp.csc_matrix, G: sp.csc_matrix, stage_z: np.ndarray, stage_rows: np.ndarray
) -> tuple[_Triplets, _BandedLU]:
    """The KKT matrix ``[P G'; G 0]`` and its banded LU in stage-wise order (``stage_z`` of
    the unknowns, ``stage_rows`` of the rows of ``G``)."""
    K = _kkt_triplets(P, G)
    return K, _BandedLU(K, np.concatenate([stage_z, stage_rows]))


def _kkt_solve_factored(
    K: _Triplets, lu: _BandedLU, q: np.ndarray, h: np.ndarray, nz: int
) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``K [z; nu] = [-q; h]`` with a factorised ``K``, plus one step of iterative
    refinement. Returns ``(z, nu)``; ``P z + q + G' nu = 0``."""
    rhs = np.concatenate([-q, h])
    sol = lu.solve(rhs)
    sol += lu.solve(rhs - _matvec(K, sol))
    if not np.all(np.isfinite(sol)):
        raise RuntimeError("KKT factorisation of the input update produced NaN")
    return sol[:nz], sol[nz:]


def _kkt_solve(
    P: sp.csc_matrix,
    q: np.ndarray,
    G: sp.csc_matrix,
    h: np.ndarray,
    stage_z: np.ndarray,
    stage_rows: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``min 1/2 z'Pz + q'z s.t. G z = h`` via ``[P G'; G 0] [z; nu] = [-q; h]``.

    Returns ``(z, nu)``; ``P z + q + G' nu = 0``.
    """
    return _kkt_solve_factored(*_kkt_factor(P, G, stage_z, stage_rows), q, h, P.shape[0])


def _solve_direct(prob: _Problem) -> np.ndarray:
    """Unconstrained optimum (equality-constrained QP); return the free inputs."""
    z, _ = _kkt_solve(prob.P, prob.q, prob.G, prob.h, prob.stage_z, prob.stage_eq)
    return z[: prob.m]


# ---------------------------------------------------------------------------------------------
# Limits
# ---------------------------------------------------------------------------------------------


def _intervals(
    prob: _Problem | _Structure, limits: SetpointLimits
) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample interval ``[lo, hi]`` from the box and the deviation bound, shape (N,)."""
    lo = np.full(prob.n, -np.inf)
    hi = np.full(prob.n, np.inf)
    if limits.u_min_m is not None:
        lo[:] = limits.u_min_m
    if limits.u_max_m is not None:
        hi[:] = limits.u_max_m
    if limits.max_deviation_m is not None:
        lo = np.maximum(lo, prob.yd_u - limits.max_deviation_m)
        hi = np.minimum(hi, prob.yd_u + limits.max_deviation_m)
    return lo, hi


def _violations(u: np.ndarray, prob: _Problem, limits: SetpointLimits, tol: float) -> int:
    """Number of limit rows whose slack is below ``tol`` (``tol < 0``: violated by ``-tol``)."""
    return int(_violations_batch(u[None, :], prob, limits, tol)[0])


def _violations_batch(
    u: np.ndarray, prob: _Problem | _Structure, limits: SetpointLimits, tol: float
) -> np.ndarray:
    """:func:`_violations` of every row of ``u`` (P, N): shape (P,) of int."""
    lo, hi = _intervals(prob, limits)
    count = np.sum(u - lo[None, : u.shape[1]] < tol, axis=1)
    count += np.sum(hi[None, : u.shape[1]] - u < tol, axis=1)
    if limits.max_step_m is not None:
        du = np.diff(u, axis=1, prepend=0.0)
        count += np.sum(limits.max_step_m - du < tol, axis=1)
        count += np.sum(limits.max_step_m + du < tol, axis=1)
    return count.astype(int)


def _check_feasible(prob: _Problem, limits: SetpointLimits) -> None:
    """Exact feasibility test of the limits (they form a chain in ``u``); raise if empty.

    The set of values ``u(k)`` reachable by a sequence satisfying every limit up to ``k`` is an
    interval, propagated forward: ``R(k) = I(k) & [R(k-1) - s, R(k-1) + s]``.
    """
    lo, hi = _intervals(prob, limits)
    tail = np.arange(prob.n) >= prob.m
    yT = prob.y_final
    if np.any(tail):
        if limits.u_min_m is not None and yT < limits.u_min_m - _FEAS_TOL_M:
            raise UpdateInfeasible(
                f"final reference yd[-1] = {yT:g} m (pinned hover point) is below "
                f"u_min_m = {limits.u_min_m:g} m"
            )
        if limits.u_max_m is not None and yT > limits.u_max_m + _FEAS_TOL_M:
            raise UpdateInfeasible(
                f"final reference yd[-1] = {yT:g} m (pinned hover point) is above "
                f"u_max_m = {limits.u_max_m:g} m"
            )
    lo = np.where(tail, yT, lo)
    hi = np.where(tail, yT, hi)
    empty = np.nonzero(lo > hi + _FEAS_TOL_M)[0]
    if empty.size:
        k = int(empty[0])
        raise UpdateInfeasible(
            f"arena box [{limits.u_min_m}, {limits.u_max_m}] m and max_deviation_m = "
            f"{limits.max_deviation_m:g} m leave no setpoint at sample {k} "
            f"(aligned reference {prob.yd_u[k]:g} m)"
        )
    step = limits.max_step_m
    if step is None:
        return
    a, b = 0.0, 0.0  # u(-1) = 0
    for k in range(prob.n):
        a2, b2 = max(lo[k], a - step), min(hi[k], b + step)
        if a2 > b2 + _FEAS_TOL_M:
            raise UpdateInfeasible(
                f"max_step_m = {step:g} m cannot reach the allowed setpoints "
                f"[{lo[k]:g}, {hi[k]:g}] m at sample {k} (reachable [{a - step:g}, {b + step:g}] m)"
            )
        a, b = a2, max(a2, b2)


def _inequalities(prob: _Problem, limits: SetpointLimits) -> tuple[sp.csc_matrix, np.ndarray]:
    """Rows ``A_in z <= b_in`` on the free inputs (state columns zero)."""
    m, nz = prob.m, prob.P.shape[0]
    lo, hi = _intervals(prob, limits)
    lo, hi = lo[:m], hi[:m]
    blocks: list[sp.spmatrix] = []
    rhs: list[np.ndarray] = []
    eye = sp.eye(m, nz, format="csr")
    up = np.isfinite(hi)
    if np.any(up):
        blocks.append(eye[up])
        rhs.append(hi[up])
    dn = np.isfinite(lo)
    if np.any(dn):
        blocks.append(-eye[dn])
        rhs.append(-lo[dn])
    if limits.max_step_m is not None:
        s = limits.max_step_m
        # D u = [u(0) - 0, u(1) - u(0), .., u(m-1) - u(m-2), (y_final - u(m-1)) if tail].
        D = sp.eye(m, nz, format="csr") - sp.eye(m, nz, k=-1, format="csr")
        off = np.zeros(m)
        if prob.r > 1:
            D = sp.vstack([D, -sp.eye(1, nz, k=m - 1, format="csr")], format="csr")
            off = np.append(off, prob.y_final)
        blocks += [D, -D]
        rhs += [s - off, s + off]
    if not blocks:
        return sp.csc_matrix((0, nz)), np.zeros(0)
    return sp.vstack(blocks, format="csc"), np.concatenate(rhs)


def _clarabel_settings() -> clarabel.DefaultSettings:
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    # data updates (a kept solver, a new linear term per trial) need both off; every limit row
    # has a finite bound, so the presolve had nothing to remove
    settings.presolve_enable = False
    settings.chordal_decomposition_enable = False
    settings.tol_gap_abs = 1e-10
    settings.tol_gap_rel = 1e-10
    settings.tol_feas = 1e-10
    settings.tol_ktratio = 1e-8
    settings.max_iter = 300
    return settings


class _ClarabelQP:
    """Clarabel's solver of one structure's QP with its limit rows, built once.

    Between trials (and between the plants of a batch) only the linear term ``q`` changes:
    the Hessian, the dynamics and the limit rows are the structure's. The first solve sets
    the solver up (equilibration, the symbolic factorisation of its KKT matrix); every later
    one replaces ``q`` (Clarabel's data update, presolve off) and solves again.

    Parameters
    ----------
    prob : _Problem
        The QP of a trial without the robustness weight (the structure's ``P``).
    rows : _Rows
        The limits' inequality rows.
    """

    def __init__(self, prob: _Problem, rows: _Rows) -> None:
        A = sp.vstack([prob.G, rows.A], format="csc")
        b = np.concatenate([prob.h, rows.b])
        cones = [clarabel.ZeroConeT(prob.G.shape[0]), clarabel.NonnegativeConeT(rows.b.size)]
        P = sp.triu(prob.P, format="csc")
        self._solver = clarabel.DefaultSolver(P, prob.q, A, b, cones, _clarabel_settings())
        self._q = prob.q

    def solve(self, q: np.ndarray) -> clarabel.DefaultSolution:
        """Clarabel's solution of the QP with the linear term ``q``, shape (nz,)."""
        if q is not self._q:
            self._solver.update(q=q)
            self._q = q
        return self._solver.solve()


def _solve_clarabel(
    prob: _Problem,
    limits: SetpointLimits | None,
    rows: _Rows | None = None,
    qp: _ClarabelQP | None = None,
    base: _Triplets | None = None,
    schur: tuple[_Schur, np.ndarray] | None = None,
) -> tuple[np.ndarray, str, clarabel.DefaultSolution]:
    """Solve the QP with the limits' inequalities (``rows``, default from ``limits``) by
    Clarabel (the kept solver ``qp`` when given: the QP without the robustness weight);
    return free inputs and status. ``base``, ``schur``: the KKT triplets of ``prob.P`` and
    ``prob.G`` when already built, the structure's Schur complement and the unconstrained
    optimum (for the polish, see :func:`_active_set`)."""
    nz = prob.P.shape[0]
    if rows is None:
        A_in, b_in = (_inequalities(prob, limits) if limits is not None
                      else (sp.csc_matrix((0, nz)), np.zeros(0)))  # fmt: skip
        rows = _rows_of(A_in, b_in, prob.m)
    if qp is not None:
        solution = qp.solve(prob.q)
    else:
        A = sp.vstack([prob.G, rows.A], format="csc")
        b = np.concatenate([prob.h, rows.b])
        cones = [clarabel.ZeroConeT(prob.G.shape[0])]
        if rows.b.size:
            cones.append(clarabel.NonnegativeConeT(rows.b.size))
        P = sp.triu(prob.P, format="csc")
        solution = clarabel.DefaultSolver(P, prob.q, A, b, cones, _clarabel_settings()).solve()
    status = str(solution.status)
    if status in ("PrimalInfeasible", "AlmostPrimalInfeasible"):
        raise UpdateInfeasible(f"Clarabel reports the setpoint limits infeasible ({status})")
    if status not in ("Solved", "AlmostSolved"):
        raise RuntimeError(f"Clarabel failed on the input update (status {status})")
    x = np.asarray(solution.x, dtype=float)
    if rows.b.size:
        x = _polish(prob, rows, x, solution, base, schur)
    return x[: prob.m], ("solved" if status == "Solved" else status), solution


@dataclass(frozen=True)
class _Rows:
    """The limits' inequality rows ``A z <= b`` and their place in the problem.

    Every row involves one input (a bound: an edge between ``u(t)`` and the fixed values) or
    two consecutive ones (a rate limit: an edge between ``u(t-1)`` and ``u(t)``); a set of
    rows held with equality is linearly independent exactly when these edges form a forest.
    """

    A: sp.csc_matrix  # (rows, nz)
    b: np.ndarray  # (rows,)
    csr: sp.csr_matrix  # A by rows, duplicates summed (the active-set method's row access)
    stage: np.ndarray  # latest input sample of each row, (rows,)
    ends: np.ndarray  # the two nodes of each row's edge, (rows, 2); node m is the fixed values
    coef: np.ndarray  # the row's coefficients on its two nodes, (rows, 2); 0 on node m

    def excess(self, u_free: np.ndarray) -> np.ndarray:
        """``A z - b`` for ``z`` whose free inputs are ``u_free`` (the states do not enter).

        Parameters
        ----------
        u_free : ndarray, shape (m,)
            The free inputs [m].

        Returns
        -------
        ndarray, shape (rows,)
            The rows' excess over their bounds [m] (positive: violated).
        """
        u = np.append(u_free, 0.0)  # node m, the fixed values, has coefficient 0
        return self.coef[:, 0] * u[self.ends[:, 0]] + self.coef[:, 1] * u[self.ends[:, 1]] - self.b


def _rows_of(A_in: sp.csc_matrix, b_in: np.ndarray, m: int) -> _Rows:
    csr = sp.csr_matrix(A_in)
    csr.sum_duplicates()
    count = np.diff(csr.indptr)
    if np.any((count < 1) | (count > 2)):
        raise ValueError("each limit row must involve one or two inputs")
    if csr.shape[0] == 0:
        empty = np.zeros(0, dtype=np.intp)
        return _Rows(sp.csc_matrix(A_in), np.zeros(0), csr, empty, np.zeros((0, 2), dtype=np.intp),
                     np.zeros((0, 2)))  # fmt: skip
    first = csr.indices[csr.indptr[:-1]]
    last = csr.indices[csr.indptr[1:] - 1]
    stage = np.maximum(first, last).astype(np.intp)
    ends = np.column_stack([np.minimum(first, last), np.where(count == 2, stage, m)])
    # indices are sorted (sum_duplicates): the first entry is the smaller node's
    two = count == 2
    coef = np.column_stack([csr.data[csr.indptr[:-1]],
                            np.where(two, csr.data[csr.indptr[1:] - 1], 0.0)])  # fmt: skip
    return _Rows(sp.csc_matrix(A_in), np.asarray(b_in, dtype=float), csr, stage, ends, coef)


def _independent(rows: _Rows, order: np.ndarray, m: int) -> np.ndarray:
    """Mask of the rows of ``order`` (taken in that order) whose edges do not close a cycle
    with those taken before: a linearly independent subset.

    Taking edges in a given order and keeping those that join two trees is Kruskal's
    algorithm with the order as the weights: the minimum spanning forest of the graph whose
    edge weights are the positions in ``order`` (distinct, so the forest is unique), computed
    by :func:`scipy.sparse.csgraph.minimum_spanning_tree`. Of edges joining the same two nodes
    only the first can be kept (a later one closes a cycle with it).
    """
    keep = np.zeros(rows.b.size, dtype=bool)
    if order.size == 0:
        return keep
    ends = rows.ends[order]
    if np.all(ends[:, 1] == m):
        # bounds only: every edge ends at the fixed values (a star), so the forest is the
        # first edge of each input
        _, first = np.unique(ends[:, 0], return_index=True)
        keep[order[first]] = True
        return keep
    lo, hi = ends.min(axis=1), ends.max(axis=1)
    _, first = np.unique(lo * (m + 1) + hi, return_index=True)
    weight = first + 1.0  # positions in order, from 1 (a zero would be no edge)
    graph = sp.csr_matrix((weight, (lo[first], hi[first])), shape=(m + 1, m + 1))
    tree = scipy.sparse.csgraph.minimum_spanning_tree(graph)
    keep[order[tree.data.astype(np.intp) - 1]] = True
    return keep


def _nonnegative_multipliers(
    rows: _Rows, act: np.ndarray, tight: np.ndarray, lam: np.ndarray, m: int
) -> bool:
    """Whether the limits held (``act``, multipliers ``lam``) and those met with equality but
    not held (``tight``: each closes a cycle with the held ones) admit non-negative multipliers
    with the same force on the inputs.

    At a degenerate vertex more limits meet than are independent, and the multipliers of the
    independent subset that happens to be held are only one of a family: ``lam + t c`` for every
    ``c`` with ``A' c = 0`` on these rows. The point is the minimiser when some member of the
    family is non-negative, which a non-negative least-squares fit of the held rows' force
    ``A_act' lam_act`` by the rows ``act | tight`` finds (to rounding) or rules out.
    """
    both = np.flatnonzero(act | tight)
    A = rows.csr[both][:, :m]
    force = A.T @ np.where(act[both], lam[both], 0.0)
    cols = np.flatnonzero(np.abs(A).sum(axis=0).A1 > 0)
    At = A[:, cols].toarray().T
    _, residual = scipy.optimize.nnls(At, force[cols])
    return bool(residual <= 1e-9 * max(1.0, float(np.max(np.abs(force)))))


def _most_negative_per_run(rows: _Rows, lam: np.ndarray, negative: np.ndarray) -> np.ndarray:
    """Mask of the row with the most negative multiplier in each run of consecutive samples
    among the ``negative`` rows."""
    neg = np.flatnonzero(negative)
    out = np.zeros(lam.size, dtype=bool)
    if neg.size == 0:
        return out
    neg = neg[np.argsort(rows.stage[neg], kind="stable")]
    run = np.concatenate([[0], np.cumsum(np.diff(rows.stage[neg]) > 1)])
    by_run = neg[np.lexsort((lam[neg], run))]  # by run, most negative first within a run
    first = np.concatenate([[True], np.diff(run[np.lexsort((lam[neg], run))]) != 0])
    out[by_run[first]] = True
    return out


class _Schur:
    """The unconstrained KKT system of a structure, for active-set rounds with few limits.

    Holding the limit rows ``act`` with equality adds them to the KKT matrix ``K`` (the
    structure's, factorised once): ``[K A'; A 0] [z; lam] = [k; b]``. By the Schur
    complement, ``z = z0 - W A' lam`` with ``z0 = K^-1 k`` the unconstrained optimum,
    ``W = K^-1`` and ``(A W A') lam = A z0 - b``. A limit row involves one or two inputs, so
    only the input rows and columns of ``W`` enter (the inverse of the reduced Hessian in the
    inputs, symmetric positive definite): a round costs a Cholesky factorisation of the small
    dense ``A W A'`` instead of a banded LU of the whole augmented KKT matrix. The columns of
    ``W`` are computed on first use, each by the factorised ``K`` (two banded solves, one of
    them iterative refinement), and kept (at most :data:`_SCHUR_MAX_COLUMNS`).

    Parameters
    ----------
    K : tuple (rows, cols, values, n)
        The structure's KKT matrix ``[P G'; G 0]`` as triplets.
    lu : _BandedLU
        Its factorisation.
    m : int
        Number of free inputs (the first ``m`` unknowns of ``K``).
    """

    def __init__(self, K: _Triplets, lu: _BandedLU, m: int) -> None:
        self._triplets, self._K = K, None  # K as CSR built on the first column asked
        self._lu, self._n, self.m = lu, K[3], m
        self._pos = np.full(m, -1, dtype=np.intp)  # column of each input in _w, -1: not yet
        self._w = np.empty((0, m))  # the kept columns of W's input block, one per row
        self._count = 0
        self._lock = threading.Lock()

    def _columns(self, inputs: np.ndarray) -> np.ndarray | None:
        """The columns of ``W``'s input block for ``inputs`` as rows, shape (inputs, m)
        (computing the missing ones), or None when they would exceed the budget. Under a
        lock: a column half written by another thread would give a wrong answer silently
        (the forks of an update are solved on one thread; their shared Clarabel solver
        refuses a second thread outright)."""
        with self._lock:
            return self._columns_locked(inputs)

    def _columns_locked(self, inputs: np.ndarray) -> np.ndarray | None:
        new = inputs[self._pos[inputs] < 0]
        if new.size:
            count = self._count + new.size
            if count > _SCHUR_MAX_COLUMNS:
                return None
            if count > self._w.shape[0]:
                grown = np.empty((min(max(2 * count, 32), _SCHUR_MAX_COLUMNS), self.m))
                grown[: self._count] = self._w[: self._count]
                self._w = grown
            if self._K is None:
                rows, cols, values, n = self._triplets
                self._K = sp.csr_matrix((values, (rows, cols)), shape=(n, n))
            # all at once, one right-hand side each (LAPACK and the sparse product treat the
            # columns alike: a column's bits do not depend on which others are asked with it)
            E = np.zeros((self._n, new.size))
            E[new, np.arange(new.size)] = 1.0
            X = self._lu.solve(E)
            X += self._lu.solve(E - self._K @ X)
            self._w[self._count : count] = X[: self.m].T
            self._pos[new] = np.arange(self._count, count)
            self._count = count
        return self._w[self._pos[inputs]]

    def solve(
        self, rows: _Rows, act: np.ndarray, u0: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The free inputs and the multipliers with the rows ``act`` held with equality.

        Parameters
        ----------
        rows : _Rows
            The limit rows.
        act : ndarray of int
            Indices of the rows held with equality (linearly independent).
        u0 : ndarray, shape (m,)
            Free inputs of the unconstrained optimum ``z0``.

        Returns
        -------
        (u, lam) or None
            ``u`` of shape (m,) and the multipliers of ``act`` (the convention of the KKT
            solve: non-negative at the minimiser); None when the columns of ``W`` needed
            exceed the budget or ``A W A'`` is not numerically positive definite.
        """
        if act.size == 0:
            return u0.copy(), np.zeros(0)
        ends, coef = rows.ends[act], rows.coef[act]
        inputs = np.unique(ends[coef != 0.0])  # the inputs involved (node m: coefficient 0)
        W_in = self._columns(inputs)  # (inputs, m): rows of W (symmetric) = its columns
        if W_in is None:
            return None
        # A restricted to the involved inputs: row k is c0[k] e(at0[k]) + c1[k] e(at1[k])
        at = np.searchsorted(inputs, ends)
        at[coef == 0.0] = 0  # node m (and nothing else) adds zero
        at0, at1, c0, c1 = at[:, 0], at[:, 1], coef[:, 0], coef[:, 1]
        two = bool(np.any(c1))
        W_ss = W_in[:, inputs]
        # S = A W A', gathered (each row of A has one or two entries)
        S = np.outer(c0, c0) * W_ss[np.ix_(at0, at0)]
        if two:
            cross = np.outer(c0, c1) * W_ss[np.ix_(at0, at1)]
            S += cross + cross.T + np.outer(c1, c1) * W_ss[np.ix_(at1, at1)]
        # LAPACK's Cholesky directly (scipy.linalg.cho_factor's checks cost more than it here)
        cho, info = scipy.linalg.lapack.dpotrf(S, lower=False, clean=False)
        if info != 0:  # not numerically positive definite
            return None
        b = rows.b[act]

        def cho_solve(rhs: np.ndarray) -> np.ndarray:
            x, _ = scipy.linalg.lapack.dpotrs(cho, rhs, lower=False)
            return x

        def rows_at(v: np.ndarray) -> np.ndarray:  # A v for v on the involved inputs
            return c0 * v[at0] + c1 * v[at1] if two else c0 * v[at0]

        def spread(lam: np.ndarray) -> np.ndarray:  # W A' lam on the free inputs
            g = np.bincount(at0, weights=c0 * lam, minlength=inputs.size)
            if two:
                g += np.bincount(at1, weights=c1 * lam, minlength=inputs.size)
            return g @ W_in

        lam = cho_solve(rows_at(u0[inputs]) - b)
        u = u0 - spread(lam)
        # one step of iterative refinement on the rows held
        dlam = cho_solve(rows_at(u[inputs]) - b)
        lam += dlam
        u -= spread(dlam)
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(lam))):
            return None
        return u, lam


def _active_set(
    prob: _Problem,
    rows: _Rows,
    act: np.ndarray,
    rounds: int,
    base: _Triplets | None = None,
    schur: tuple[_Schur, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The QP's minimiser from a guess of its active set, or None.

    The rows ``act`` (a linearly independent subset of them) become equalities and the
    equality-constrained QP is solved: through the Schur complement of the unconstrained
    KKT matrix (``schur``, while at most :data:`_SCHUR_MAX_ROWS` rows are held) or through
    the whole KKT system (banded in stage-wise order); then the violated rows are added (the
    most violated first, each while it keeps the set independent) and, of each run of
    consecutive samples whose rows have negative multipliers, the most negative dropped
    (dropping whole runs at once overshoots and can cycle), for at most ``rounds`` rounds. A
    point is returned (with its active set) only when it is primal feasible and its
    multipliers are non-negative: it then satisfies the KKT conditions of the full problem to
    rounding, and the problem being strictly convex, it is the minimiser.

    Parameters
    ----------
    prob : _Problem
        The trial's QP.
    rows : _Rows
        The limits' inequality rows.
    act : ndarray of bool, shape (rows,)
        The guess of the active set.
    rounds : int
        Most rounds (equality-constrained solves) before giving up.
    base : tuple (rows, cols, values, n) or None
        The KKT triplets of ``prob.P`` and ``prob.G`` when already built.
    schur : (_Schur, ndarray) or None
        The structure's unconstrained KKT system and the free inputs of the unconstrained
        optimum of this trial (only when ``prob.P`` is the structure's own Hessian).

    Returns
    -------
    (u, act) or None
        The free inputs of the minimiser, shape (m,), and its active set (bool, (rows,)).
    """
    n_eq, b_in, A_csr, m = prob.G.shape[0], rows.b, rows.csr, prob.m
    scale = max(1.0, float(np.max(np.abs(b_in), initial=0.0)))
    act = _independent(rows, np.flatnonzero(act), m)
    for _ in range(rounds):
        held = np.flatnonzero(act)
        found = None
        if schur is not None and held.size <= _SCHUR_MAX_ROWS:
            found = schur[0].solve(rows, held, schur[1])
        if found is not None:
            u, lam_held = found
            excess = rows.excess(u)
            residual = np.max(np.abs(excess[act]), initial=0.0)
        else:
            if base is None:  # the KKT system without the limits, built once
                base = _kkt_triplets(prob.P, prob.G)
            K = _with_rows(base, A_csr, act)
            h = np.concatenate([prob.h, b_in[act]])
            stage = np.concatenate([prob.stage_z, prob.stage_eq, rows.stage[act] + _KEY_LIMIT])
            try:
                z, nu = _kkt_solve_factored(K, _BandedLU(K, stage), prob.q, h, prob.P.shape[0])
            except (RuntimeError, ValueError):
                return None
            u, lam_held = z[:m], nu[n_eq:]
            excess = A_csr @ z - b_in
            residual = max(np.max(np.abs(prob.G @ z - prob.h), initial=0.0),
                           np.max(np.abs(excess[act]), initial=0.0))  # fmt: skip
        if residual > 1e-10 * scale:
            return None
        lam = np.zeros(act.size)
        lam[act] = lam_held
        lam_tol = 1e-9 * max(1.0, float(np.max(np.abs(lam), initial=0.0)))
        violated = excess > 1e-10 * scale
        negative = lam < -lam_tol
        if not violated.any() and not negative.any():
            return u, act
        if not violated.any():
            tight = ~act & (np.abs(excess) <= 1e-10 * scale)
            if tight.any() and _nonnegative_multipliers(rows, act, tight, lam, m):
                return u, act | tight
        new = np.flatnonzero(violated & ~act)
        new = new[np.argsort(-excess[new], kind="stable")]
        keep = act & ~_most_negative_per_run(rows, lam, negative)
        act = _independent(rows, np.concatenate([np.flatnonzero(keep), new]), m)
    return None


def _polish(
    prob: _Problem,
    rows: _Rows,
    x: np.ndarray,
    solution: clarabel.DefaultSolution,
    base: _Triplets | None = None,
    schur: tuple[_Schur, np.ndarray] | None = None,
) -> np.ndarray:
    """Refine Clarabel's answer on its active set (as OSQP's polishing does).

    The inequalities Clarabel finds active (dual above slack) start :func:`_active_set` for
    a few rounds; its point is kept when it satisfies the KKT conditions of the full problem
    to rounding, otherwise Clarabel's answer is returned (``base``, ``schur``: as there).
    """
    n_eq = prob.G.shape[0]
    s = np.asarray(solution.s, dtype=float)[n_eq:]
    zd = np.asarray(solution.z, dtype=float)[n_eq:]
    found = _active_set(prob, rows, zd > s, _POLISH_ROUNDS, base, schur)
    return x[: prob.m] if found is None else found[0]


# ---------------------------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------------------------


def _objective(
    f: np.ndarray,
    u: np.ndarray,
    yd: np.ndarray,
    dh: np.ndarray,
    up: np.ndarray,
    weights: UpdateWeights,
    r: int,
    robust: RobustnessWeight | None = None,
) -> float:
    from scipy.signal import oaconvolve  # on first use: a second to import

    # direct below a few hundred samples (microseconds; the FFT's set-up costs a millisecond)
    y = oaconvolve(f, u)[: u.size] if u.size > _DIRECT_CONVOLVE else np.convolve(f, u)[: u.size]
    e = (y - yd + dh)[r - 1 :]
    du = u - up
    value = float(weights.we * e @ e + weights.wdu * du @ du + weights.wu * u @ u)
    if robust is not None and robust.lam > 0:
        x = difference_matrix(u.size, robust.order) @ (u - robust.anchor_m)
        value += robust.lam * float(x @ x)
    return value


class _LimitData:
    """What the limits of one :class:`InputUpdate` need, built on the first trial with an
    active limit (the feasibility checked then) and shared with its forks: the inequality
    rows and Clarabel's kept solver of the QP without the robustness weight."""

    def __init__(self) -> None:
        self.rows: _Rows | None = None
        self.qp: _ClarabelQP | None = None


class InputUpdate:
    """Eq. (8) of one axis for a fixed model, reference, weights and limits; one call per trial.

    What does not change between trials is built once: the QP's banded structure, the
    banded LU of its KKT matrix, the Markov parameters, the limits' feasibility and their
    inequality rows. :meth:`solve` then costs one linear term and two banded triangular solves;
    when a limit is active, the first time one Clarabel solve, later a few banded KKT
    factorisations started from the last trial's active set (Clarabel when they do not
    settle). Clarabel's solver is kept too: a later solve replaces only its linear term. The
    minimiser is that of :func:`next_input` (strictly convex QP): equal to rounding when both
    find its active set (a fresh :func:`next_input` asks Clarabel).

    Parameters
    ----------
    model : DiscreteModel
        Closed-loop model "setpoint -> position" of this axis.
    yd_m : ndarray, shape (N,)
        Reference ``yd(1) .. yd(N)`` [m], learning coordinates (Y-indexed).
    weights : UpdateWeights
        Weights of eq. (8).
    limits : SetpointLimits or None
        Setpoint limits of this axis; None for none.

    Raises
    ------
    TrajectoryError
        ``yd_m`` has a bad shape or NaN/inf.
    ModelError
        The trial is shorter than the model's relative degree.
    """

    def __init__(
        self,
        model: DiscreteModel,
        yd_m: np.ndarray,
        weights: UpdateWeights,
        limits: SetpointLimits | None = None,
    ) -> None:
        self._s = _Structure(model, yd_m, weights)
        self.limits = limits
        # built on the first trial with an active limit, shared with the forks
        self._limit_data = _LimitData()
        self._active: np.ndarray | None = None  # the limits active at the last solution

    @property
    def model(self) -> DiscreteModel:
        """The model the structure was built for."""
        return self._s.model

    def solve(
        self,
        d_hat_m: np.ndarray,
        u_prev_m: np.ndarray,
        robustness: RobustnessWeight | None = None,
    ) -> UpdateResult:
        """Next trial input: minimiser of eq. (8) under the limits.

        Parameters
        ----------
        d_hat_m : ndarray, shape (N,)
            Disturbance estimate ``d_hat(1) .. d_hat(N)`` [m] (Y-indexed).
        u_prev_m : ndarray, shape (N,)
            Input of the last trial ``u_j(0) .. u_j(N-1)`` [m] (U-indexed).
        robustness : RobustnessWeight or None
            Zero-phase weight added to eq. (8) (see :func:`next_input`).

        Returns
        -------
        UpdateResult
            As :func:`next_input`.
        """
        s, limits = self._s, self.limits
        prob = s.problem(d_hat_m, u_prev_m, robustness)
        u0 = s.solve_direct(prob)
        u = _full_input(prob, u0)
        method, status = "direct", "solved"
        if limits is not None and _violations(u, prob, limits, -_FAST_PATH_TOL_M) > 0:
            shared = self._limit_data
            if shared.rows is None:
                _check_feasible(prob, limits)
                shared.rows = _rows_of(*_inequalities(prob, limits), prob.m)
            rows = shared.rows
            own = prob.P is s.P  # no robustness weight: the structure's KKT and Clarabel's QP
            base = s.kkt_base() if own else None
            schur = (s.schur(), u0) if own else None
            found = None
            if self._active is not None and self._active.size == rows.b.size:
                # the last trial's active set (or the replaced model's), refined
                found = _active_set(prob, rows, self._active, _WARM_ROUNDS, base, schur)
            if found is not None:
                u_free, self._active = found
                method = "active-set"
            else:
                if own and shared.qp is None:
                    shared.qp = _ClarabelQP(prob, rows)
                qp = shared.qp if own else None
                u_free, status, _ = _solve_clarabel(prob, limits, rows, qp, base, schur)
                method = "clarabel"
                z = np.zeros(prob.P.shape[0])
                z[: prob.m] = u_free
                scale = max(1.0, float(np.max(np.abs(rows.b), initial=0.0)))
                self._active = rows.A @ z > rows.b - _ACTIVE_TOL_M * scale
            u = _full_input(prob, u_free)
        active = 0 if limits is None else _violations(u, prob, limits, _ACTIVE_TOL_M)
        dh = np.asarray(d_hat_m, dtype=float)
        up = np.asarray(u_prev_m, dtype=float)
        objective = _objective(s.f, u, s.yd, dh, up, s.weights, prob.r, robustness)
        return UpdateResult(u, status, objective, method, active)

    def start_from(self, previous: InputUpdate) -> None:
        """Start the next constrained solve from ``previous``'s last active set.

        For the update of a refreshed model of the same axis: the limits are the same, so the
        limits active at the old model's answer are a good guess for the new one's (half of
        the constrained solves of a study with the model refresh were a new model's first).
        The guess is only a start: the answer is accepted only when it satisfies the KKT
        conditions of the new problem, else Clarabel solves it.

        Parameters
        ----------
        previous : InputUpdate
            The update this one replaces.
        """
        if previous.limits == self.limits and previous._active is not None:
            self._active = previous._active.copy()

    def fork(self) -> InputUpdate:
        """A new update of the same axis sharing this one's structure and factorisation, the
        limits' rows and Clarabel's kept solver, with its own memory of the last active set
        (one per plant of a batch).

        Returns
        -------
        InputUpdate
            The copy; solving with it never changes this one's answers (the kept solver's
            interior point depends on the first linear term it was built with only within
            Clarabel's tolerance, and is refined to the KKT point of the QP).
        """
        other = InputUpdate.__new__(InputUpdate)
        other.__dict__.update(self.__dict__)
        other._active = None
        return other

    def solve_unconstrained(
        self, d_hat_m: np.ndarray, u_prev_m: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The unconstrained optimum of eq. (8) for many trials at once (no robustness weight).

        One factorisation, every trial a column of one banded solve. A trial whose optimum
        satisfies the limits gets from :meth:`solve` this same input (method ``"direct"``, to
        rounding); the others need :meth:`solve` (a QP).

        Parameters
        ----------
        d_hat_m : ndarray, shape (P, N)
            Disturbance estimates [m] (Y-indexed), one row per trial.
        u_prev_m : ndarray, shape (P, N)
            Inputs of the last trials [m] (U-indexed).

        Returns
        -------
        u_m : ndarray, shape (P, N)
            Unconstrained optima [m], the pinned tail included.
        within : ndarray of bool, shape (P,)
            The optimum satisfies every limit (no QP needed).
        active : ndarray of int, shape (P,)
            Limits holding with equality at the optimum (as ``UpdateResult.active_constraints``).
        """
        s = self._s
        dh = np.atleast_2d(np.asarray(d_hat_m, dtype=float))
        up = np.atleast_2d(np.asarray(u_prev_m, dtype=float))
        for name, arr in (("d_hat_m", dh), ("u_prev_m", up)):
            if arr.shape[1:] != (s.n,):
                raise ValueError(f"{name} must have {s.n} samples per trial, got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} contains NaN or inf")
        q = np.hstack(s.linear_terms(dh, up))
        if s._kkt is None:
            s._kkt = _kkt_factor(s.P, s.G, s.stage_z, s.stage_eq)
        K, lu = s._kkt
        rows, cols, values, n = K
        rhs = np.concatenate([-q.T, np.repeat(s.h[:, None], dh.shape[0], axis=1)])
        sol = lu.solve(rhs)
        sol += lu.solve(rhs - sp.csr_matrix((values, (rows, cols)), shape=(n, n)) @ sol)
        if not np.all(np.isfinite(sol)):
            raise RuntimeError("KKT factorisation of the input update produced NaN")
        u = np.hstack([sol[: s.m].T, np.full((dh.shape[0], s.r - 1), s.y_final)])
        return (u, *self.check_limits(u))

    def check_limits(self, u_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Which inputs satisfy the limits, and how many limits each meets with equality.

        The tests of :meth:`solve`'s unconstrained optimum, for many inputs at once.

        Parameters
        ----------
        u_m : ndarray, shape (P, N)
            Inputs [m] (U-indexed), one row per trial.

        Returns
        -------
        within : ndarray of bool, shape (P,)
            Every limit satisfied (to 1e-9 m).
        active : ndarray of int, shape (P,)
            Limits holding with equality (to 1e-7 m), as ``UpdateResult.active_constraints``.
        """
        u = np.atleast_2d(np.asarray(u_m, dtype=float))
        if self.limits is None or self.limits == SetpointLimits():
            return np.ones(u.shape[0], dtype=bool), np.zeros(u.shape[0], dtype=int)
        within = _violations_batch(u, self._s, self.limits, -_FAST_PATH_TOL_M) == 0
        return within, _violations_batch(u, self._s, self.limits, _ACTIVE_TOL_M)

    def unconstrained_map(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The unconstrained optimum as a dense affine map of the trial's data.

        ``u_next = c + M @ (yd - d_hat) + L @ u_prev`` equals :meth:`solve`'s input wherever
        it satisfies the limits (to rounding): :func:`unconstrained_update_operator` for this
        update's model, length and weights, with the pinned tail's value folded into ``c``.
        Computed on first use and kept; ``O(N^2)`` memory, ``O(N^3)`` time once.

        Returns
        -------
        M : ndarray, shape (N, N)
            Acts on ``yd - d_hat`` (Y-indexed) [m/m].
        L : ndarray, shape (N, N)
            Acts on ``u_prev`` (U-indexed) [m/m].
        c : ndarray, shape (N,)
            Constant [m]: ``yd(N)`` on the pinned tail, 0 elsewhere.
        """
        s = self._s
        if s._dense is None:
            M, L, c = unconstrained_update_operator(s.model, s.n, s.weights)
            s._dense = (M, L, c * s.y_final)
        return s._dense


def next_input(
    model: DiscreteModel,
    yd_m: np.ndarray,
    d_hat_m: np.ndarray,
    u_prev_m: np.ndarray,
    weights: UpdateWeights,
    limits: SetpointLimits | None = None,
    robustness: RobustnessWeight | None = None,
) -> UpdateResult:
    """Next trial input: minimiser of eq. (8) under the setpoint limits (one axis, one call).

    The same as ``InputUpdate(model, yd_m, weights, limits).solve(d_hat_m, u_prev_m,
    robustness)``; a learner that runs many trials keeps the :class:`InputUpdate`.

    Parameters
    ----------
    model : DiscreteModel
        Closed-loop model "setpoint -> position" of this axis.
    yd_m : ndarray, shape (N,)
        Reference ``yd(1) .. yd(N)`` [m], learning coordinates (Y-indexed).
    d_hat_m : ndarray, shape (N,)
        Disturbance estimate ``d_hat(1) .. d_hat(N)`` [m] (Y-indexed), e.g. from the smoother.
    u_prev_m : ndarray, shape (N,)
        Input of the last trial ``u_j(0) .. u_j(N-1)`` [m] (U-indexed).
    weights : UpdateWeights
        Weights of eq. (8).
    limits : SetpointLimits or None
        Setpoint limits of this axis; None for none.
    robustness : RobustnessWeight or None
        Zero-phase weight ``lam ||D_p (U - U_anchor)||^2`` added to eq. (8) (the Q-filter of
        :mod:`gcs.core.robustness`); None (default) for eq. (8) as written.

    Returns
    -------
    UpdateResult
        ``u_m`` of shape (N,) [m]; the first ``N - r + 1`` entries optimised, the last
        ``r - 1`` equal to ``yd_m[-1]``.

    Raises
    ------
    UpdateInfeasible
        The limits admit no input sequence (the message names the limit).
    TrajectoryError
        ``yd_m`` has a bad shape or NaN/inf.
    ValueError
        ``d_hat_m`` or ``u_prev_m`` has a bad shape or NaN/inf.
    ModelError
        The trial is shorter than the model's relative degree.
    RuntimeError
        Clarabel failed numerically (status other than solved or infeasible).
    """
    return InputUpdate(model, yd_m, weights, limits).solve(d_hat_m, u_prev_m, robustness)


def unconstrained_update_operator(
    model: DiscreteModel, n: int, weights: UpdateWeights
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dense affine form of the unconstrained update, for batched studies (small ``n``).

    ``next_input(model, yd, d_hat, u_prev, weights).u_m == M @ (yd - d_hat) + L @ u_prev
    + c * yd[-1]``; for many trials stack them as columns: ``M @ (Yd - D) + L @ Up +
    np.outer(c, yd_final)``.

    Parameters
    ----------
    model : DiscreteModel
        Closed-loop model of the axis.
    n : int
        Trial length ``N`` [samples].
    weights : UpdateWeights
        Weights of eq. (8).

    Returns
    -------
    M : ndarray, shape (n, n)
        Acts on ``yd - d_hat`` (Y-indexed) [m/m]; columns ``0 .. r-2`` (the outputs that
        cannot be influenced) and rows ``n-r+1 ..`` (pinned tail) are zero.
    L : ndarray, shape (n, n)
        Acts on ``u_prev`` (U-indexed) [m/m]; non-zero only in the free block
        ``[:n-r+1, :n-r+1]`` and only when ``wdu > 0``.
    c : ndarray, shape (n,)
        Coefficient of ``yd[-1]``: 1 on the ``r - 1`` pinned tail samples, 0 elsewhere.

    Notes
    -----
    ``H = we Fc' Fc + (wdu + wu) I`` with ``Fc = F[r-1:, :n-r+1]`` (square, lower triangular,
    diagonal ``f_r != 0``); ``M[:m, r-1:] = H^-1 we Fc'``, ``L[:m, :m] = wdu H^-1``.
    Cost ``O(n^3)``: meant for ``n`` up to a few thousand.
    """
    if not isinstance(weights, UpdateWeights):
        raise TypeError(f"weights must be UpdateWeights, got {type(weights).__name__}")
    n = int(n)
    inputs, outputs = controllable_slices(model, n)
    m = inputs.stop
    r = n - m + 1
    F = lifted_matrix(model, n)
    Fc = F[outputs, inputs]
    H = weights.we * (Fc.T @ Fc) + (weights.wdu + weights.wu) * np.eye(m)
    cho = scipy.linalg.cho_factor(H)
    M = np.zeros((n, n))
    L = np.zeros((n, n))
    M[:m, r - 1 :] = scipy.linalg.cho_solve(cho, weights.we * Fc.T)
    if weights.wdu > 0:
        L[:m, :m] = scipy.linalg.cho_solve(cho, weights.wdu * np.eye(m))
    c = np.zeros(n)
    c[m:] = 1.0
    return M, L, c
