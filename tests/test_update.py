"""Tests of gcs.core.update (input update of eq. 8), in the style of Clarabel's own tests:
status, solution and objective are checked against independently computed values."""

from __future__ import annotations

import clarabel
import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
import scipy.sparse as sp
from hypothesis import example, given, settings
from hypothesis import strategies as st

import gcs.core.update as update_module
from gcs.core.model import (
    DiscreteModel,
    from_transfer_function,
    lifted_matrix,
    relative_degree,
    simulate,
)
from gcs.core.update import (
    InputUpdate,
    SetpointLimits,
    UpdateResult,
    UpdateWeights,
    next_input,
    reference_for_inputs,
    unconstrained_update_operator,
)
from gcs.errors import (
    GcsError,
    ModelError,
    TrajectoryError,
    UpdateInfeasible,
)

# ---------------------------------------------------------------------------------------------
# helpers: independent reference solutions on the dense lifted (controllable) problem
# ---------------------------------------------------------------------------------------------


def random_stable_model(seed: int, delay: int, order: int, zero_cb: bool = False) -> DiscreteModel:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(order, order))
    A *= rng.uniform(0.2, 0.95) / max(np.max(np.abs(np.linalg.eigvals(A))), 1e-9)
    B = rng.normal(size=(order, 1))
    C = rng.normal(size=(1, order))
    if zero_cb and order >= 2:
        # Chain x2(k+1) = b x2(k) + x1(k): C B = 0, C A B = 1 (relative degree delay + 2).
        A = np.array([[rng.uniform(-0.9, 0.9), 0.0], [1.0, rng.uniform(-0.9, 0.9)]])
        B = np.array([[1.0], [0.0]])
        C = np.array([[0.0, 1.0]])
    return DiscreteModel(A, B, C, 0.05, delay)


def signals(seed: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed + 1000)
    t = np.arange(1, n + 1) / n
    yd = 2.0 * np.sin(2 * np.pi * t) + 0.5 * t
    d_hat = 0.1 * rng.normal(size=n)
    u_prev = yd + 0.2 * rng.normal(size=n)
    return yd, d_hat, u_prev


def dense_reference(model, yd, d_hat, u_prev, w: UpdateWeights) -> np.ndarray:
    """Normal equations of eq. (8) on the reduced problem (free inputs, influenced outputs)."""
    n = yd.size
    r = relative_degree(model)
    m = n - r + 1
    F = lifted_matrix(model, n)
    Fc = F[r - 1 :, :m]
    H = w.we * Fc.T @ Fc + (w.wdu + w.wu) * np.eye(m)
    g = w.we * Fc.T @ (yd - d_hat)[r - 1 :] + w.wdu * u_prev[:m]
    u = np.full(n, yd[-1])
    u[:m] = np.linalg.solve(H, g)
    return u


def objective_eq8(model, u, yd, d_hat, u_prev, w: UpdateWeights) -> float:
    """Eq. (8) from a time-domain simulation (independent of the lifted matrix)."""
    r = relative_degree(model)
    e = (simulate(model, u) - yd + d_hat)[r - 1 :]
    du = u - u_prev
    return float(w.we * e @ e + w.wdu * du @ du + w.wu * u @ u)


def dense_qp(model, yd, d_hat, u_prev, w: UpdateWeights):
    """Eq. (8) as ``min 1/2 x'Hx + q'x`` in the free inputs ``x = u(0) .. u(N-r)``, dense."""
    n = yd.size
    r = relative_degree(model)
    m = n - r + 1
    F = lifted_matrix(model, n)
    Fc = F[r - 1 :, :m]
    H = 2 * (w.we * Fc.T @ Fc + (w.wdu + w.wu) * np.eye(m))
    q = -2 * (w.we * Fc.T @ (yd - d_hat)[r - 1 :] + w.wdu * u_prev[:m])
    return H, q


def dense_limit_rows(yd, r: int, m: int, limits: SetpointLimits):
    """The limits as dense rows ``A x <= b`` on the free inputs (the pinned tail a constant)."""
    yd_u = np.concatenate([yd[r - 1 :], np.full(r - 1, yd[-1])])[:m]
    rows, rhs = [], []
    eye = np.eye(m)
    lo = np.full(m, -np.inf)
    hi = np.full(m, np.inf)
    if limits.u_min_m is not None:
        lo = np.maximum(lo, limits.u_min_m)
    if limits.u_max_m is not None:
        hi = np.minimum(hi, limits.u_max_m)
    if limits.max_deviation_m is not None:
        lo = np.maximum(lo, yd_u - limits.max_deviation_m)
        hi = np.minimum(hi, yd_u + limits.max_deviation_m)
    for k in range(m):
        if np.isfinite(hi[k]):
            rows.append(eye[k])
            rhs.append(hi[k])
        if np.isfinite(lo[k]):
            rows.append(-eye[k])
            rhs.append(-lo[k])
    if limits.max_step_m is not None:
        s = limits.max_step_m
        for k in range(m):
            row = eye[k] - (eye[k - 1] if k > 0 else 0.0)
            rows += [row, -row]
            rhs += [s, s]
        if r > 1:
            rows += [-eye[m - 1], eye[m - 1]]
            rhs += [s - yd[-1], s + yd[-1]]
    return np.array(rows).reshape(-1, m), np.array(rhs)


def dense_clarabel_qp(model, yd, d_hat, u_prev, w, limits: SetpointLimits):
    """Independent constrained solution: dense lifted QP in the free inputs, solved by Clarabel."""
    n = yd.size
    r = relative_degree(model)
    m = n - r + 1
    H, q = dense_qp(model, yd, d_hat, u_prev, w)
    A, b = dense_limit_rows(yd, r, m, limits)
    settings_ = clarabel.DefaultSettings()
    settings_.verbose = False
    settings_.tol_gap_abs = settings_.tol_gap_rel = settings_.tol_feas = 1e-10
    solver = clarabel.DefaultSolver(
        sp.triu(sp.csc_matrix(H), format="csc"),
        q,
        sp.csc_matrix(A),
        b,
        [clarabel.NonnegativeConeT(b.size)],
        settings_,
    )
    sol = solver.solve()
    u = np.full(n, yd[-1])
    u[:m] = np.asarray(sol.x)
    return sol.status, u


def kkt_violation(model, yd, d_hat, u_prev, w, limits: SetpointLimits, u) -> tuple[float, float]:
    """How far ``u`` is from satisfying the KKT conditions of the dense QP: (stationarity,
    infeasibility), each relative. Stationarity is the distance of the negative gradient from
    the cone of the active rows (non-negative least squares, so the multipliers are >= 0).
    The QP being strictly convex, a point with both near zero is its minimiser."""
    r = relative_degree(model)
    m = yd.size - r + 1
    H, q = dense_qp(model, yd, d_hat, u_prev, w)
    A, b = dense_limit_rows(yd, r, m, limits)
    x = u[:m]
    scale = max(1.0, float(np.max(np.abs(b), initial=0.0)))
    slack = b - A @ x
    active = slack <= 1e-7 * scale
    grad = H @ x + q
    if np.any(active):
        _, residual = scipy.optimize.nnls(A[active].T, -grad, maxiter=50 * m)
    else:  # (nnls aborts the process on a matrix without columns)
        residual = float(np.linalg.norm(grad))
    stationarity = residual / (np.linalg.norm(H @ x) + np.linalg.norm(q))
    return float(stationarity), max(0.0, -float(np.min(slack, initial=0.0)) / scale)


def binding_limits(u_free, yd, r: int) -> SetpointLimits:
    """A box and a rate limit that the unconstrained optimum ``u_free`` violates, feasible:
    the box holds the start (0) and the pinned end (``yd[-1]``), and the rate limit lets a
    ramp from one to the other through."""
    m = yd.size - r + 1
    x, y_final = u_free[:m], float(yd[-1])
    hi = max(float(np.quantile(x, 0.85)), y_final, 0.0)
    lo = min(float(np.quantile(x, 0.15)), y_final, 0.0)
    steps = np.abs(np.diff(np.concatenate([[0.0], x])))
    step = max(0.7 * float(steps.max()), 2.0 * abs(y_final) / (m + 1), 2.0 * (hi - lo) / m)
    return SetpointLimits(u_min_m=lo, u_max_m=hi, max_step_m=step)


def assert_within_limits(u, yd, r, limits: SetpointLimits, tol=1e-7):
    yd_u = reference_for_inputs(yd, r)
    if limits.u_min_m is not None:
        assert np.all(u >= limits.u_min_m - tol)
    if limits.u_max_m is not None:
        assert np.all(u <= limits.u_max_m + tol)
    if limits.max_deviation_m is not None:
        assert np.all(np.abs(u - yd_u) <= limits.max_deviation_m + tol)
    if limits.max_step_m is not None:
        assert np.all(np.abs(np.diff(np.concatenate([[0.0], u]))) <= limits.max_step_m + tol)


@pytest.fixture
def px4_model() -> DiscreteModel:
    # Eq. (11) of the paper at 20 Hz: delay 5 samples, relative degree 6.
    return from_transfer_function([0.08, 1.94], [1, 1.752, 2.01], 0.25, 0.05)


# ---------------------------------------------------------------------------------------------
# analytic optima
# ---------------------------------------------------------------------------------------------


def test_identity_plant_wdu_zero_gives_exact_inversion():
    # y(k+1) = u(k): F = I, relative degree 1. With Wdu = Wu = 0 the optimum is U = Yd - D.
    model = DiscreteModel(np.zeros((1, 1)), np.ones((1, 1)), np.ones((1, 1)), 0.1, 0)
    yd, d_hat, u_prev = signals(1, 30)
    res = next_input(model, yd, d_hat, u_prev, UpdateWeights(we=1.0, wdu=0.0, wu=0.0))
    assert isinstance(res, UpdateResult)
    assert res.status == "solved" and res.method == "direct"
    np.testing.assert_allclose(res.u_m, yd - d_hat, atol=1e-12)
    assert res.objective == pytest.approx(0.0, abs=1e-20)
    assert res.active_constraints == 0


def test_one_step_delay_plant_shifts_reference_and_pins_tail():
    # y(k+1) = u(k-1): relative degree 2, u(k) = yd(k+2) - d(k+2), u(N-1) pinned to yd(N).
    model = DiscreteModel(np.zeros((1, 1)), np.ones((1, 1)), np.ones((1, 1)), 0.1, 1)
    yd, d_hat, u_prev = signals(2, 25)
    res = next_input(model, yd, d_hat, u_prev, UpdateWeights(we=2.0, wdu=0.0, wu=0.0))
    np.testing.assert_allclose(res.u_m[:-1], (yd - d_hat)[1:], atol=1e-12)
    assert res.u_m[-1] == yd[-1]
    assert res.objective == pytest.approx(0.0, abs=1e-20)


def test_identity_plant_with_input_weights_closed_form():
    # F = I: J separates per sample, u = (we w + wdu u_prev) / (we + wdu + wu).
    model = DiscreteModel(np.zeros((1, 1)), np.ones((1, 1)), np.ones((1, 1)), 0.1, 0)
    yd, d_hat, u_prev = signals(3, 20)
    w = UpdateWeights(we=1.5, wdu=0.3, wu=0.2)
    res = next_input(model, yd, d_hat, u_prev, w)
    expected = (w.we * (yd - d_hat) + w.wdu * u_prev) / (w.we + w.wdu + w.wu)
    np.testing.assert_allclose(res.u_m, expected, atol=1e-12)
    assert res.objective == pytest.approx(objective_eq8(model, expected, yd, d_hat, u_prev, w))


def test_identity_plant_box_is_a_clip():
    # F = I, Wdu = Wu = 0, box only: the separable optimum is the clipped inversion.
    model = DiscreteModel(np.zeros((1, 1)), np.ones((1, 1)), np.ones((1, 1)), 0.1, 0)
    yd, d_hat, u_prev = signals(4, 40)
    w = UpdateWeights(we=1.0, wdu=0.0, wu=0.0)
    limits = SetpointLimits(u_min_m=-1.2, u_max_m=1.5)
    res = next_input(model, yd, d_hat, u_prev, w, limits)
    expected = np.clip(yd - d_hat, -1.2, 1.5)
    assert res.status == "solved" and res.method == "clarabel"
    np.testing.assert_allclose(res.u_m, expected, atol=1e-7)
    n_clipped = int(np.sum((yd - d_hat < -1.2) | (yd - d_hat > 1.5)))
    assert n_clipped > 0 and res.active_constraints == n_clipped
    e = expected - (yd - d_hat)
    assert res.objective == pytest.approx(float(e @ e), rel=1e-7)


# ---------------------------------------------------------------------------------------------
# agreement: direct KKT == Clarabel == dense normal equations == update operator
# ---------------------------------------------------------------------------------------------


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    delay=st.integers(0, 5),
    order=st.integers(1, 3),
    zero_cb=st.booleans(),
    n=st.integers(12, 40),
    we=st.floats(0.1, 10.0),
    wdu=st.floats(1e-3, 1.0),
    wu=st.sampled_from([0.0, 1e-3, 0.05]),
)
def test_direct_and_clarabel_equal_dense_solutions(seed, delay, order, zero_cb, n, we, wdu, wu):
    """Without limits the banded KKT solve is the dense normal equations' solution; with a box
    and a rate limit that bind, Clarabel's answer (refined on its active set) satisfies the
    KKT conditions of the dense constrained QP and is no worse than Clarabel on that dense QP
    (whose interior point stops at its tolerance, up to 1e-5 m from the minimiser here)."""
    model = random_stable_model(seed, delay, order, zero_cb)
    yd, d_hat, u_prev = signals(seed, n)
    w = UpdateWeights(we=we, wdu=wdu, wu=wu)
    res = next_input(model, yd, d_hat, u_prev, w)
    assert res.method == "direct" and res.status == "solved"
    # Dense normal equations on the controllable problem.
    np.testing.assert_allclose(res.u_m, dense_reference(model, yd, d_hat, u_prev, w), atol=1e-8)
    assert res.objective == pytest.approx(
        objective_eq8(model, res.u_m, yd, d_hat, u_prev, w), rel=1e-9, abs=1e-12
    )
    # Clarabel on the sparse QP, with limits that bind.
    r = relative_degree(model)
    limits = binding_limits(res.u_m, yd, r)
    con = next_input(model, yd, d_hat, u_prev, w, limits)
    assert con.method == "clarabel" and con.status == "solved" and con.active_constraints > 0
    assert_within_limits(con.u_m, yd, r, limits, tol=1e-9)
    assert np.all(con.u_m[n - r + 1 :] == yd[-1])
    stationarity, infeasibility = kkt_violation(model, yd, d_hat, u_prev, w, limits, con.u_m)
    assert stationarity < 1e-10 and infeasibility < 1e-10
    status, u_ref = dense_clarabel_qp(model, yd, d_hat, u_prev, w, limits)
    assert status == clarabel.SolverStatus.Solved
    ref_objective = objective_eq8(model, u_ref, yd, d_hat, u_prev, w)
    assert res.objective <= con.objective <= ref_objective * (1 + 1e-9)
    assert con.objective == pytest.approx(
        objective_eq8(model, con.u_m, yd, d_hat, u_prev, w), rel=1e-9, abs=1e-12
    )


@pytest.mark.parametrize("delay", [0, 3])
def test_update_operator_equals_next_input(delay):
    model = random_stable_model(7, delay, 2)
    n = 50
    w = UpdateWeights(we=1.0, wdu=0.05, wu=0.01)
    M, L, c = unconstrained_update_operator(model, n, w)
    assert M.shape == (n, n) and L.shape == (n, n) and c.shape == (n,)
    r = relative_degree(model)
    assert np.all(M[:, : r - 1] == 0) and np.all(M[n - r + 1 :] == 0)
    # Batched: three trials as columns.
    cols = [signals(s, n) for s in range(3)]
    Yd = np.stack([c_[0] for c_ in cols], axis=1)
    D = np.stack([c_[1] for c_ in cols], axis=1)
    Up = np.stack([c_[2] for c_ in cols], axis=1)
    batched = M @ (Yd - D) + L @ Up + np.outer(c, Yd[-1])
    for j in range(3):
        res = next_input(model, Yd[:, j], D[:, j], Up[:, j], w)
        np.testing.assert_allclose(batched[:, j], res.u_m, atol=1e-10)


def test_update_operator_without_wdu_has_zero_l(px4_model):
    M, L, c = unconstrained_update_operator(px4_model, 60, UpdateWeights(wdu=0.0, wu=0.01))
    assert not np.any(L)
    assert c.sum() == relative_degree(px4_model) - 1


# ---------------------------------------------------------------------------------------------
# relative degree: pinned tail, excluded head
# ---------------------------------------------------------------------------------------------


def test_pinned_tail_and_excluded_head(px4_model):
    n = 80
    r = relative_degree(px4_model)
    assert r == 6
    yd, d_hat, u_prev = signals(5, n)
    w = UpdateWeights()
    res = next_input(px4_model, yd, d_hat, u_prev, w)
    # Tail: last r - 1 inputs are the final reference exactly.
    assert np.all(res.u_m[n - r + 1 :] == yd[-1])
    # Head: y(1)..y(r-1) cannot be influenced, so their reference/disturbance change nothing.
    yd2, d2 = yd.copy(), d_hat.copy()
    yd2[: r - 1] += 3.0
    d2[: r - 1] -= 1.0
    res2 = next_input(px4_model, yd2, d2, u_prev, w)
    np.testing.assert_array_equal(res2.u_m, res.u_m)
    assert res2.objective == pytest.approx(res.objective, rel=1e-12)
    # The previous input's tail only shifts the objective by a constant.
    u_prev2 = u_prev.copy()
    u_prev2[n - r + 1 :] += 1.0
    res3 = next_input(px4_model, yd, d_hat, u_prev2, w)
    np.testing.assert_allclose(res3.u_m, res.u_m, atol=1e-12)


def test_zero_cb_model_excludes_extra_head_sample():
    model = random_stable_model(11, 2, 2, zero_cb=True)
    assert relative_degree(model) == 4
    yd, d_hat, u_prev = signals(6, 30)
    res = next_input(model, yd, d_hat, u_prev, UpdateWeights())
    np.testing.assert_allclose(res.u_m, dense_reference(model, yd, d_hat, u_prev, UpdateWeights()))
    assert np.all(res.u_m[-3:] == yd[-1])


# ---------------------------------------------------------------------------------------------
# constrained solutions
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "limits",
    [
        SetpointLimits(u_min_m=-1.6, u_max_m=1.7),
        SetpointLimits(max_step_m=0.25),
        SetpointLimits(max_deviation_m=0.15),
        SetpointLimits(u_min_m=-2.0, u_max_m=2.3, max_step_m=0.3, max_deviation_m=1.0),
    ],
)
def test_constrained_matches_dense_qp_and_respects_limits(px4_model, limits):
    n = 60
    yd, d_hat, u_prev = signals(8, n)
    w = UpdateWeights()
    free = next_input(px4_model, yd, d_hat, u_prev, w)
    res = next_input(px4_model, yd, d_hat, u_prev, w, limits)
    assert res.method == "clarabel" and res.status == "solved"
    assert res.active_constraints > 0
    r = relative_degree(px4_model)
    assert_within_limits(res.u_m, yd, r, limits)
    assert np.all(res.u_m[n - r + 1 :] == yd[-1])
    assert res.objective >= free.objective - 1e-9
    status, u_ref = dense_clarabel_qp(px4_model, yd, d_hat, u_prev, w, limits)
    assert status == clarabel.SolverStatus.Solved
    np.testing.assert_allclose(res.u_m, u_ref, atol=1e-6)
    assert res.objective == pytest.approx(
        objective_eq8(px4_model, u_ref, yd, d_hat, u_prev, w), rel=1e-7
    )


def test_inactive_limits_take_the_fast_path(px4_model):
    yd, d_hat, u_prev = signals(9, 50)
    w = UpdateWeights()
    free = next_input(px4_model, yd, d_hat, u_prev, w)
    limits = SetpointLimits(u_min_m=-50, u_max_m=50, max_step_m=20, max_deviation_m=30)
    res = next_input(px4_model, yd, d_hat, u_prev, w, limits)
    assert res.method == "direct" and res.active_constraints == 0
    np.testing.assert_array_equal(res.u_m, free.u_m)
    assert res.objective == free.objective


# ---------------------------------------------------------------------------------------------
# infeasible limits
# ---------------------------------------------------------------------------------------------


def test_box_excluding_final_reference_is_infeasible(px4_model):
    yd, d_hat, u_prev = signals(10, 40)  # yd[-1] = 0.5
    with pytest.raises(UpdateInfeasible, match="u_max_m"):
        next_input(px4_model, yd, d_hat, u_prev, UpdateWeights(), SetpointLimits(u_max_m=0.4))


def test_box_and_deviation_disjoint_is_infeasible(px4_model):
    yd, d_hat, u_prev = signals(10, 40)
    limits = SetpointLimits(u_min_m=-0.5, u_max_m=1.0, max_deviation_m=0.1)
    with pytest.raises(UpdateInfeasible, match="max_deviation_m") as info:
        next_input(px4_model, yd, d_hat, u_prev, UpdateWeights(), limits)
    assert isinstance(info.value, GcsError) and isinstance(info.value, ValueError)


def test_step_too_small_to_reach_reference_is_infeasible(px4_model):
    n = 40
    yd = np.full(n, 3.0)  # a 3 m jump from the start point, max 0.05 m per sample
    with pytest.raises(UpdateInfeasible, match="max_step_m"):
        next_input(
            px4_model,
            yd,
            np.zeros(n),
            np.zeros(n),
            UpdateWeights(),
            SetpointLimits(max_step_m=0.05),
        )


@pytest.mark.parametrize("fraction", [0.5, 0.999, 1.001, 2.0])
def test_infeasible_exactly_when_an_independent_solver_certifies_it(px4_model, fraction):
    # A 3 m jump from the start point in 36 steps (u(-1) = 0 .. the pinned u(35)): rate limits
    # just below and just above 3/36 m. UpdateInfeasible, naming the limit, exactly when
    # Clarabel on the dense QP certifies the limits infeasible; otherwise the minimiser.
    n = 40
    yd = np.full(n, 3.0)
    zero = np.zeros(n)
    w = UpdateWeights()
    m = n - relative_degree(px4_model) + 1
    limits = SetpointLimits(max_step_m=fraction * 3.0 / (m + 1))
    status, _ = dense_clarabel_qp(px4_model, yd, zero, zero, w, limits)
    if fraction < 1.0:
        assert status == clarabel.SolverStatus.PrimalInfeasible
        with pytest.raises(UpdateInfeasible, match="max_step_m = .* cannot reach"):
            next_input(px4_model, yd, zero, zero, w, limits)
    else:
        assert status == clarabel.SolverStatus.Solved
        res = next_input(px4_model, yd, zero, zero, w, limits)
        assert res.method == "clarabel" and res.active_constraints > 0
        stationarity, infeasibility = kkt_violation(px4_model, yd, zero, zero, w, limits, res.u_m)
        assert stationarity < 1e-10 and infeasibility < 1e-10


def test_empty_box_rejected_at_construction():
    with pytest.raises(UpdateInfeasible, match="u_min_m"):
        SetpointLimits(u_min_m=1.0, u_max_m=0.0)


# ---------------------------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs", [{"we": 0.0}, {"we": -1.0}, {"wdu": -0.1}, {"wu": float("nan")}, {"we": "x"}]
)
def test_bad_weights(kwargs):
    with pytest.raises(ValueError, match="UpdateWeights"):
        UpdateWeights(**kwargs)


@pytest.mark.parametrize(
    "kwargs", [{"max_step_m": -0.1}, {"max_deviation_m": -1.0}, {"u_min_m": float("nan")}]
)
def test_bad_limits(kwargs):
    with pytest.raises(ValueError, match="SetpointLimits"):
        SetpointLimits(**kwargs)


def test_bad_shapes_and_nan(px4_model):
    n = 30
    yd, d_hat, u_prev = signals(12, n)
    w = UpdateWeights()
    with pytest.raises(TrajectoryError, match="yd_m"):
        next_input(px4_model, yd.reshape(5, 6), d_hat, u_prev, w)
    with pytest.raises(ValueError, match="d_hat_m"):
        next_input(px4_model, yd, d_hat[:-1], u_prev, w)
    bad = u_prev.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="u_prev_m"):
        next_input(px4_model, yd, d_hat, bad, w)
    bad_yd = yd.copy()
    bad_yd[0] = np.inf
    with pytest.raises(ValueError, match="yd_m"):
        next_input(px4_model, bad_yd, d_hat, u_prev, w)
    with pytest.raises(ModelError):  # shorter than the relative degree (6)
        next_input(px4_model, yd[:4], d_hat[:4], u_prev[:4], w)


def test_reference_alignment():
    yd = np.arange(1.0, 8.0)  # yd(1)..yd(7)
    np.testing.assert_array_equal(reference_for_inputs(yd, 3), [3, 4, 5, 6, 7, 7, 7])
    np.testing.assert_array_equal(reference_for_inputs(yd, 1), yd)


def test_dense_reference_helper_is_correct():
    # Guard of the guard: the dense helper satisfies the optimality condition of eq. (8).
    model = random_stable_model(3, 1, 2)
    yd, d_hat, u_prev = signals(3, 20)
    w = UpdateWeights(we=1.0, wdu=0.1, wu=0.0)
    u = dense_reference(model, yd, d_hat, u_prev, w)
    r = relative_degree(model)
    m = 20 - r + 1
    F = lifted_matrix(model, 20)
    grad = w.we * F[r - 1 :, :m].T @ (F @ u - yd + d_hat)[r - 1 :] + w.wdu * (u - u_prev)[:m]
    assert np.max(np.abs(grad)) < 1e-10
    assert scipy.linalg.norm(u) > 0


def test_kkt_helper_tells_the_minimiser_from_other_feasible_points(px4_model):
    # Guard of the guard: the clipped unconstrained optimum is feasible but not the minimiser.
    n = 60
    yd, d_hat, u_prev = signals(8, n)
    w = UpdateWeights()
    limits = SetpointLimits(u_min_m=-1.6, u_max_m=1.7)
    free = next_input(px4_model, yd, d_hat, u_prev, w)
    clipped = np.clip(free.u_m, -1.6, 1.7)
    stationarity, infeasibility = kkt_violation(px4_model, yd, d_hat, u_prev, w, limits, clipped)
    assert infeasibility == 0.0 and stationarity > 1e-3
    _, infeasibility = kkt_violation(px4_model, yd, d_hat, u_prev, w, limits, clipped + 0.01)
    assert infeasibility > 1e-3
    res = next_input(px4_model, yd, d_hat, u_prev, w, limits)
    stationarity, infeasibility = kkt_violation(px4_model, yd, d_hat, u_prev, w, limits, res.u_m)
    assert stationarity < 1e-10 and infeasibility < 1e-10


# ---------------------------------------------------------------------------------------------
# structure: the banded KKT solve and the active set kept across trials
# ---------------------------------------------------------------------------------------------


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    delay=st.integers(0, 4),
    order=st.integers(1, 4),
    n=st.integers(8, 40),
)
# a degenerate vertex: the box's lower bound, four rate limits and the pinned end (at the box's
# upper bound) meet in a cycle, and the independent rows first held have negative multipliers
@example(seed=369, delay=1, order=3, n=9)
def test_kept_update_solves_on_its_active_set_to_the_exact_minimiser(seed, delay, order, n):
    """A kept update asked the trial it has just solved again takes its active set (the limits
    held with equality in the banded KKT system) and lands on the minimiser at once, to
    rounding: the KKT conditions of the dense QP hold far tighter than Clarabel's tolerance.
    The next trial, started from that active set, ends on its own minimiser too."""
    model = random_stable_model(seed, delay, order)
    yd, d_hat, u_prev = signals(seed, n)
    w = UpdateWeights(1.0, 0.01, 0.001)
    r = relative_degree(model)
    limits = binding_limits(next_input(model, yd, d_hat, u_prev, w).u_m, yd, r)
    kept = InputUpdate(model, yd, w, limits)
    first = kept.solve(d_hat, u_prev)
    again = kept.solve(d_hat, u_prev)
    assert first.method == "clarabel" and again.method == "active-set"
    assert again.active_constraints == first.active_constraints > 0
    scale = max(1.0, float(np.max(np.abs(first.u_m))))
    np.testing.assert_allclose(again.u_m, first.u_m, rtol=0, atol=1e-9 * scale)
    stationarity, infeasibility = kkt_violation(model, yd, d_hat, u_prev, w, limits, again.u_m)
    assert stationarity < 1e-10 and infeasibility < 1e-10
    # the next trial: the disturbance estimate moved, some limits let go and others bind
    d_next = d_hat + 0.3 * np.sin(np.linspace(0.0, 3.0, n) + seed)
    after = kept.solve(d_next, first.u_m)
    stationarity, infeasibility = kkt_violation(model, yd, d_next, first.u_m, w, limits, after.u_m)
    assert stationarity < 1e-10 and infeasibility < 1e-10


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), delay=st.integers(0, 3), order=st.integers(1, 3))
def test_a_refreshed_models_update_starts_from_the_old_ones_active_set(seed, delay, order):
    """The update of a refreshed model (the same axis, limits and reference) takes the old
    model's active set as its first guess: where it holds it needs no Clarabel, and whatever
    the guess its answer is the new problem's minimiser (the KKT conditions to rounding, and
    a fresh update's answer within Clarabel's tolerance)."""
    n = 30
    old = random_stable_model(seed, delay, order)
    yd, d_hat, u_prev = signals(seed, n)
    w = UpdateWeights(1.0, 0.01, 0.001)
    limits = binding_limits(next_input(old, yd, d_hat, u_prev, w).u_m, yd, relative_degree(old))
    before = InputUpdate(old, yd, w, limits)
    assert before.solve(d_hat, u_prev).active_constraints > 0
    # the same model again (a refresh that moved nothing): the guess is the answer
    same = InputUpdate(old, yd, w, limits)
    same.start_from(before)
    assert same.solve(d_hat, u_prev).method == "active-set"
    # a moved model: a guess only
    new = random_stable_model(seed + 1, delay, order)
    started = InputUpdate(new, yd, w, limits)
    started.start_from(before)
    res = started.solve(d_hat, u_prev)
    stationarity, infeasibility = kkt_violation(new, yd, d_hat, u_prev, w, limits, res.u_m)
    assert stationarity < 1e-10 and infeasibility < 1e-10
    fresh = InputUpdate(new, yd, w, limits).solve(d_hat, u_prev)
    scale = max(1.0, float(np.max(np.abs(fresh.u_m))))
    np.testing.assert_allclose(res.u_m, fresh.u_m, rtol=0, atol=1e-9 * scale)
    # other limits: no guess taken
    other = InputUpdate(old, yd, w, None)
    other.start_from(before)
    assert other.solve(d_hat, u_prev).method == "direct"


def test_degenerate_active_set_is_solved_without_clarabel():
    """More limits hold with equality than there are inputs: the reference climbs at the rate
    limit and the optimum rides the deviation bound above it, so at every sample the bound
    and the step into it are both active (``u(0)``: the bound and the step from the start
    point). The kept update drops the dependent rows and solves on the rest; the optimum is
    the bound itself (identity plant, ``Wdu = Wu = 0``: a clip of ``yd - d_hat``)."""
    model = DiscreteModel(np.zeros((1, 1)), np.ones((1, 1)), np.ones((1, 1)), 0.1, 0)
    n, step, dev = 30, 0.1, 0.3
    yd = step * np.arange(1, n + 1) - dev  # yd + dev climbs by exactly one step per sample
    d_hat = np.full(n, -1.0)  # yd - d_hat lies above the deviation bound everywhere
    u_prev = np.zeros(n)
    w = UpdateWeights(we=1.0, wdu=0.0, wu=0.0)
    limits = SetpointLimits(max_step_m=step, max_deviation_m=dev)
    kept = InputUpdate(model, yd, w, limits)
    methods = []
    for _ in range(3):
        res = kept.solve(d_hat, u_prev)
        methods.append(res.method)
        np.testing.assert_allclose(res.u_m, yd + dev, rtol=0, atol=1e-12)
        assert res.active_constraints == 2 * n  # every bound and every step
        stationarity, infeasibility = kkt_violation(model, yd, d_hat, u_prev, w, limits, res.u_m)
        assert stationarity < 1e-10 and infeasibility < 1e-10
    assert methods == ["clarabel", "active-set", "active-set"]


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 10_000), trials=st.integers(2, 4))
def test_kept_update_equals_a_fresh_clarabel_solve(seed, trials):
    """Trials whose disturbance estimates drift: the kept update (active set of the last trial,
    refined) and a fresh Clarabel solve give the same setpoints within Clarabel's tolerance."""
    model = from_transfer_function([0.08, 1.94], [1, 1.752, 2.01], 0.25, 0.05)
    n = 120
    yd, d_hat, u_prev = signals(seed, n)
    limits = SetpointLimits(-1.9, 2.0, 0.15, 0.5)
    w = UpdateWeights()
    kept = InputUpdate(model, yd, w, limits)
    rng = np.random.default_rng(seed)
    methods = []
    for _ in range(trials):
        a = kept.solve(d_hat, u_prev)
        b = next_input(model, yd, d_hat, u_prev, w, limits)
        methods.append(a.method)
        assert b.method == "clarabel"
        np.testing.assert_allclose(a.u_m, b.u_m, rtol=0, atol=1e-7)
        assert a.objective == pytest.approx(b.objective, rel=1e-9)
        assert_within_limits(a.u_m, yd, relative_degree(model), limits, tol=1e-9)
        u_prev = a.u_m
        d_hat = d_hat + 0.05 * np.cumsum(rng.normal(size=n)) / np.sqrt(n)
    assert methods[0] == "clarabel" and "active-set" in methods[1:]


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_clarabel_solver_is_built_once_and_given_each_new_linear_term(seed):
    """Clarabel's solver of a kept update is built once and shared with its forks (the plants
    of a batch): a fork with no active set yet solves by Clarabel with its own disturbance
    estimate through the same solver, only the linear term replaced, and lands on the same
    minimiser as a fresh solve with a solver of its own, to rounding (both satisfy the KKT
    conditions of the dense QP)."""
    model = from_transfer_function([0.08, 1.94], [1, 1.752, 2.01], 0.25, 0.05)
    n = 120
    yd, d_hat, u_prev = signals(seed, n)
    limits = SetpointLimits(-1.9, 2.0, 0.15, 0.5)
    w = UpdateWeights()
    built = []
    solver_class = clarabel.DefaultSolver

    def counting(*args, **kwargs):
        built.append(args)
        return solver_class(*args, **kwargs)

    kept = InputUpdate(model, yd, w, limits)
    rng = np.random.default_rng(seed)
    plants = []
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(clarabel, "DefaultSolver", counting)
        first = kept.solve(d_hat, u_prev)
        for _ in range(2):
            d_plant = d_hat + 0.2 * np.cumsum(rng.normal(size=n)) / np.sqrt(n)
            plants.append((d_plant, kept.fork().solve(d_plant, u_prev)))
    assert first.method == "clarabel" and len(built) == 1
    assert [res.method for _, res in plants] == ["clarabel", "clarabel"]
    for d_plant, res in plants:
        fresh = next_input(model, yd, d_plant, u_prev, w, limits)
        scale = max(1.0, float(np.max(np.abs(fresh.u_m))))
        np.testing.assert_allclose(res.u_m, fresh.u_m, rtol=0, atol=1e-9 * scale)
        stationarity, infeasibility = kkt_violation(model, yd, d_plant, u_prev, w, limits, res.u_m)
        assert stationarity < 1e-10 and infeasibility < 1e-10


# ---------------------------------------------------------------------------------------------
# the active-set rounds through the Schur complement of the unconstrained KKT matrix
# ---------------------------------------------------------------------------------------------


def counted_banded_lus(patch: pytest.MonkeyPatch) -> list[int]:
    """Count the banded LU factorisations (the structure's KKT matrix and whole augmented
    systems) built from now on; returns the list that grows by one per factorisation."""
    built: list[int] = []
    banded = update_module._BandedLU

    class Counting(banded):
        def __init__(self, K, stage):
            built.append(K[3])
            super().__init__(K, stage)

    patch.setattr(update_module, "_BandedLU", Counting)
    return built


def drifting_trials(seed: int, n: int, trials: int):
    """A model, its reference, binding limits (a box, a rate limit and a deviation bound; the
    box and rate limit alone when the deviation bound leaves them no setpoint) and ``trials``
    disturbance estimates that drift from trial to trial."""
    model = random_stable_model(seed, seed % 4, 1 + seed % 3)
    yd, d_hat, u_prev = signals(seed, n)
    w = UpdateWeights(1.0, 0.01, 0.001)
    r = relative_degree(model)
    box = binding_limits(next_input(model, yd, d_hat, u_prev, w).u_m, yd, r)
    deviation = 0.9 * float(np.max(np.abs(dense_reference(model, yd, d_hat, u_prev, w) - yd)))
    limits = SetpointLimits(box.u_min_m, box.u_max_m, box.max_step_m, max(deviation, 0.2))
    try:
        next_input(model, yd, d_hat, u_prev, w, limits)
    except UpdateInfeasible:
        limits = box
    rng = np.random.default_rng(seed)
    d = [d_hat]
    for _ in range(trials - 1):
        d.append(d[-1] + 0.1 * np.cumsum(rng.normal(size=n)) / np.sqrt(n))
    return model, yd, u_prev, w, limits, d


def solve_trials(model, yd, u_prev, w, limits, d, **constants):
    """Every trial of ``d`` through one kept update (``constants``: module constants set for
    the run); returns the results and the number of banded LU factorisations built."""
    with pytest.MonkeyPatch.context() as patch:
        for name, value in constants.items():
            patch.setattr(update_module, name, value)
        built = counted_banded_lus(patch)
        kept = InputUpdate(model, yd, w, limits)
        results, u = [], u_prev
        for d_hat in d:
            results.append(kept.solve(d_hat, u))
            u = results[-1].u_m
    return results, len(built)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(10, 40))
def test_schur_rounds_reach_the_banded_rounds_minimiser(seed, n):
    """The active-set rounds through the Schur complement of the structure's factorised KKT
    matrix (few limits held) and the rounds that factorise the whole augmented KKT system
    each trial (``_SCHUR_MAX_ROWS = 0``, the method before) land on the same minimiser,
    within 1e-9 m, every answer satisfying the KKT conditions of the dense QP and the limits;
    the Schur rounds factorise nothing but the structure's KKT matrix. With a budget of one
    kept column the rounds fall back to the banded ones, and still agree."""
    model, yd, u_prev, w, limits, d = drifting_trials(seed, n, 4)
    schur, built_schur = solve_trials(model, yd, u_prev, w, limits, d)
    banded, built_banded = solve_trials(model, yd, u_prev, w, limits, d, _SCHUR_MAX_ROWS=0)
    budget, _ = solve_trials(model, yd, u_prev, w, limits, d, _SCHUR_MAX_COLUMNS=1)
    assert built_schur == 1  # n <= 40: at most 2 m + 1 <= 81 rows held, below the limit
    constrained = [k for k, res in enumerate(banded) if res.method != "direct"]
    assert built_banded >= 1 + len(constrained)  # (Clarabel's polish included)
    r = relative_degree(model)
    u_prev_k = u_prev
    for k, (a, b, c) in enumerate(zip(schur, banded, budget, strict=True)):
        assert a.method == b.method == c.method
        assert a.active_constraints == b.active_constraints
        scale = max(1.0, float(np.max(np.abs(b.u_m))))
        np.testing.assert_allclose(a.u_m, b.u_m, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(c.u_m, b.u_m, rtol=0, atol=1e-9 * scale)
        assert_within_limits(a.u_m, yd, r, limits, tol=1e-9)
        stationarity, infeasibility = kkt_violation(model, yd, d[k], u_prev_k, w, limits, a.u_m)
        assert stationarity < 1e-10 and infeasibility < 1e-10
        u_prev_k = a.u_m


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_schur_rounds_are_deterministic_whatever_columns_were_kept_before(seed):
    """The columns of the inverse KKT matrix are kept by the structure and shared with its
    forks (the plants of a batch), so which ones exist when a trial is solved depends on
    what was solved before. An answer does not: two updates given the same trials give the
    same setpoints bit for bit, also when the second one's structure first served a fork
    with other disturbance estimates (other active limits, other columns computed)."""
    n = 40
    model, yd, u_prev, w, limits, d = drifting_trials(seed, n, 3)
    one = InputUpdate(model, yd, w, limits)
    two = InputUpdate(model, yd, w, limits)
    fork = two.fork()
    rng = np.random.default_rng(seed + 1)
    fork.solve(d[0] + 0.3 * rng.normal(size=n), u_prev)
    fork.solve(d[0] - 0.3 * rng.normal(size=n), u_prev)
    u_one = u_two = u_prev
    for d_hat in d:
        a, b = one.solve(d_hat, u_one), two.solve(d_hat, u_two)
        assert a.method == b.method
        assert np.array_equal(a.u_m, b.u_m)
        u_one, u_two = a.u_m, b.u_m
