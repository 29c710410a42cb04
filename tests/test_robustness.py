"""Tests of the robustness weight (Q-filter) of the input update (gcs.core.robustness)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.core.model import frequency_response, from_transfer_function, lifted_matrix
from gcs.core.robustness import (
    RobustnessWeight,
    crossover_frequency,
    difference_matrix,
    q_filter_response,
    repeat_cutoff,
    robustness_weight,
)
from gcs.core.update import SetpointLimits, UpdateWeights, next_input

EQ11 = from_transfer_function([0.08, 1.94], [1.0, 1.752, 2.01], 0.25, 0.05)
MSD = from_transfer_function([3.24], [1.0, 2.88, 3.24], 0.0, 0.01)


def test_difference_matrix() -> None:
    d = difference_matrix(6, 2).toarray()
    x = np.arange(6.0) ** 2
    # (D x)(k) = x(k) - 2 x(k-1) + x(k-2), x(-1) = x(-2) = 0
    np.testing.assert_allclose(d @ x, [0.0, 1.0, 2.0, 2.0, 2.0, 2.0])
    assert np.allclose(np.triu(d, 1), 0)


def test_frequency_response_matches_the_markov_parameters() -> None:
    w = np.array([0.0, 0.7, 2.5])
    f = np.fft.rfft(np.concatenate([[0.0], lifted_matrix(EQ11, 4000)[:, 0]]), 2**16)
    grid = 2 * np.pi * np.fft.rfftfreq(2**16, 0.05)
    for wi, fi in zip(w, frequency_response(EQ11, w), strict=True):
        k = np.argmin(np.abs(grid - wi))
        assert abs(fi - f[k]) < 2e-3
    assert frequency_response(EQ11, np.array([0.0]))[0].real == pytest.approx(1.94 / 2.01)


@settings(max_examples=25, deadline=None)
@given(cutoff=st.floats(0.5, 20.0), order=st.integers(1, 3))
def test_q_filter_is_zero_phase_passes_dc_and_halves_at_the_cutoff(cutoff: float, order: int):
    weight = robustness_weight(EQ11, cutoff, order, np.zeros(10))
    w = np.linspace(0.0, np.pi / EQ11.dt_s - 1e-6, 400)
    q = q_filter_response(EQ11, weight, w)
    assert np.isrealobj(q)  # zero phase: a real, non-negative gain at every frequency
    assert np.all((q >= 0) & (q <= 1))
    assert q[0] == 1.0
    assert q_filter_response(EQ11, weight, np.array([cutoff]))[0] == pytest.approx(0.5)
    assert q_filter_response(EQ11, weight, np.array([2 * cutoff]))[0] < 0.5 or 2 * cutoff > 62


def _dense_reference(model, yd, d_hat, u_prev, w: UpdateWeights, weight: RobustnessWeight):
    """Normal equations of eq. (8) + lam ||D (u - anchor)||^2 (relative degree 1)."""
    n = yd.size
    f = lifted_matrix(model, n)
    d = difference_matrix(n, weight.order).toarray()
    h = w.we * f.T @ f + (w.wdu + w.wu) * np.eye(n) + weight.lam * d.T @ d
    rhs = w.we * f.T @ (yd - d_hat) + w.wdu * u_prev + weight.lam * d.T @ d @ weight.anchor_m
    return scipy.linalg.solve(h, rhs)


def test_weighted_update_equals_its_normal_equations() -> None:
    n = 120
    rng = np.random.default_rng(0)
    t = np.arange(1, n + 1) * MSD.dt_s
    yd, d_hat = np.sin(2 * t), 0.1 * rng.standard_normal(n)
    u_prev, anchor = 0.1 * rng.standard_normal(n), np.sin(2 * t - 0.01)
    w = UpdateWeights(we=1.0, wdu=0.01, wu=0.0)
    weight = robustness_weight(MSD, 20.0, 2, anchor)
    res = next_input(MSD, yd, d_hat, u_prev, w, None, weight)
    ref = _dense_reference(MSD, yd, d_hat, u_prev, w, weight)
    np.testing.assert_allclose(res.u_m, ref, atol=1e-8)
    du, x = res.u_m - u_prev, difference_matrix(n, 2) @ (res.u_m - anchor)
    e = lifted_matrix(MSD, n) @ res.u_m - yd + d_hat
    assert res.objective == pytest.approx(e @ e + 0.01 * du @ du + weight.lam * x @ x, rel=1e-9)
    # lam = 0 is eq. (8) as written, to the bit
    zero = RobustnessWeight(0.0, 2, anchor)
    np.testing.assert_array_equal(
        next_input(MSD, yd, d_hat, u_prev, w, None, zero).u_m,
        next_input(MSD, yd, d_hat, u_prev, w).u_m,
    )


def test_in_a_long_trial_the_update_is_the_q_filtered_inverse() -> None:
    """wdu = 0, perfect model, anchor 0: U = Q applied to the exact inverse, in phase."""
    model = from_transfer_function([1.0], [1.0, 1.4, 1.0], 0.0, 0.05)
    n = 2000
    t = np.arange(n) * model.dt_s
    w = UpdateWeights(we=1.0, wdu=0.0, wu=0.0)
    weight = robustness_weight(model, 3.0, 2, np.zeros(n))
    taper = np.sin(np.pi * np.arange(n) / n) ** 4  # starts and ends at rest
    mid = slice(n // 4, 3 * n // 4)
    for omega in (0.05, 1.0, 3.0, 6.0):
        x = taper * np.sin(omega * t)  # the input that would remove the error exactly
        yd = lifted_matrix(model, n) @ x
        u = next_input(model, yd, np.zeros(n), np.zeros(n), w, None, weight).u_m
        # u = a x + b x_quadrature away from the ends: zero phase is b = 0, and a = Q(w)
        basis = np.column_stack([x[mid], (taper * np.cos(omega * t))[mid]])
        a, b = np.linalg.lstsq(basis, u[mid], rcond=None)[0]
        assert abs(b) < 1e-3
        assert a == pytest.approx(q_filter_response(model, weight, np.array([omega]))[0], abs=1e-3)


def test_weighted_update_keeps_the_limits() -> None:
    n = 200
    t = np.arange(1, n + 1) * EQ11.dt_s
    yd = 1.5 * np.sin(2.5 * t) * np.sin(np.pi * t / t[-1]) ** 2
    w = UpdateWeights()
    weight = robustness_weight(EQ11, 6.0, 2, np.zeros(n))
    limits = SetpointLimits(u_min_m=-1.0, u_max_m=1.0, max_step_m=0.2)
    res = next_input(EQ11, yd, np.zeros(n), np.zeros(n), w, limits, weight)
    assert res.method == "clarabel" and res.active_constraints > 0
    assert np.all(np.abs(res.u_m) <= 1.0 + 1e-7)
    assert np.all(np.abs(np.diff(np.concatenate([[0.0], res.u_m]))) <= 0.2 + 1e-7)


def test_weight_refusals() -> None:
    with pytest.raises(ValueError):
        robustness_weight(EQ11, 70.0, 2, np.zeros(5))  # above Nyquist (62.8 rad/s)
    with pytest.raises(ValueError):
        RobustnessWeight(-1.0, 2, np.zeros(5))
    with pytest.raises(ValueError):
        RobustnessWeight(1.0, 0, np.zeros(5))
    with pytest.raises(ValueError):
        RobustnessWeight(1.0, 2, np.zeros((5, 2)))


def test_crossover_frequency() -> None:
    w = np.linspace(0, 10, 11)
    rep = np.array([9, 9, 9, 9, 0.5, 0.1, 2.0, 0.1, 0.1, 0.1, 0.1])
    nonrep = np.full(11, 0.5)
    # tails from the top: at 3 rad/s rep 12 vs nonrep 4, at 4 rad/s 3.0 vs 3.5
    assert crossover_frequency(rep, nonrep, w) == 4.0
    assert crossover_frequency(rep * 100, nonrep, w) == 10.0
    assert crossover_frequency(rep * 0, nonrep, w) == 0.0
    with pytest.raises(ValueError):
        crossover_frequency(rep[:-1], nonrep, w)


def test_repeat_cutoff_finds_where_the_repeatable_error_ends() -> None:
    """Repeatable error below 2 rad/s, white non-repeatable noise: the cutoff lies near 2."""
    rng = np.random.default_rng(3)
    dt, n = 0.05, 2000
    t = np.arange(n) * dt
    rep = sum(np.sin(w * t + w) for w in (0.3, 0.8, 1.5, 1.9))
    flights = rep + 0.3 * rng.standard_normal((3, n))
    cutoff = repeat_cutoff(flights, dt)
    assert 1.9 <= cutoff <= 2.3
    with pytest.raises(ValueError):
        repeat_cutoff(flights[:1], dt)
