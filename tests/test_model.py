"""Tests of gcs.core.model against scipy's own discretisation and simulation routines."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.signal
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from gcs.core.model import (
    DiscreteModel,
    controllable_slices,
    dc_gain,
    frequency_response,
    from_state_space,
    from_transfer_function,
    lifted_matrix,
    markov_parameters,
    predicted_output,
    relative_degree,
    simulate,
)
from gcs.errors import GcsError, ModelError

pytestmark = pytest.mark.filterwarnings("ignore::scipy.signal.BadCoefficients")

NUM11 = [0.08, 1.94]
DEN11 = [1.0, 1.752, 2.01]
DT = 0.05


def scipy_delayed_response(num, den, dt, delay_samples, u):
    """y(1..N) of the ZOH discretisation (scipy) with the delay as leading zeros."""
    numd, dend, _ = scipy.signal.cont2discrete((num, den), dt, method="zoh")
    n = len(u)
    u_delayed = np.concatenate([np.zeros(delay_samples), u, [0.0]])[: n + 1]
    _, y = scipy.signal.dlsim((np.ravel(numd), dend, dt), u_delayed)
    return np.ravel(y)[1 : n + 1]


def dense_zoh_response(num, den, dt, delay_s, u, fine):
    """y(k dt), k = 1..N, of the continuous system driven by the delayed, held input.

    The continuous system is simulated on a grid of step ``dt / fine`` with the input held
    between grid points (``interp=False``), exact when ``delay_s`` is on that grid.
    """
    n = len(u)
    h = dt / fine
    shift = int(round(delay_s / h))
    assert abs(shift * h - delay_s) < 1e-12
    t = np.arange(n * fine + 1) * h
    idx = np.arange(len(t)) - shift  # fine-grid index of the undelayed input
    held = np.where(idx >= 0, u[np.clip(idx // fine, 0, n - 1)], 0.0)
    _, y, _ = scipy.signal.lsim((num, den), held, t, interp=False)
    return y[fine::fine]


# ------------------------------------------------------------------------------ eq. (11)


def test_eq11_lifted_matrix_reproduces_scipy_simulation():
    model = from_transfer_function(NUM11, DEN11, 0.25, DT)
    assert model.delay_samples == 5
    n = 120
    rng = np.random.default_rng(11)
    u = rng.normal(size=n)
    expected = scipy_delayed_response(NUM11, DEN11, DT, 5, u)
    F = lifted_matrix(model, n)
    np.testing.assert_allclose(F @ u, expected, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(simulate(model, u), expected, rtol=1e-9, atol=1e-11)


def test_eq11_lifted_matrix_is_lower_triangular_toeplitz_of_scipy_impulse_response():
    model = from_transfer_function(NUM11, DEN11, 0.25, DT)
    n = 40
    impulse = np.zeros(n)
    impulse[0] = 1.0
    h = scipy_delayed_response(NUM11, DEN11, DT, 5, impulse)
    F = lifted_matrix(model, n)
    for i in range(n):
        for j in range(n):
            expected = h[i - j] if i >= j else 0.0
            assert F[i, j] == pytest.approx(expected, rel=1e-9, abs=1e-13)


def test_eq11_step_response_settles_at_continuous_dc_gain():
    model = from_transfer_function(NUM11, DEN11, 0.25, DT)
    y = simulate(model, np.ones(600))
    assert y[-1] == pytest.approx(1.94 / 2.01, rel=1e-6)
    assert dc_gain(model) == pytest.approx(1.94 / 2.01, rel=1e-12)


# ------------------------------------------------------------------------------ properties

stable_2nd_order = st.tuples(
    st.floats(0.3, 6.0),  # natural frequency [rad/s]
    st.floats(0.2, 1.5),  # damping ratio
    st.floats(-0.5, 0.5),  # numerator s coefficient
    st.floats(0.2, 5.0),  # numerator constant
)


def _tf(params):
    wn, zeta, b1, b0 = params
    return [b1, b0], [1.0, 2.0 * zeta * wn, wn * wn]


@settings(max_examples=40, deadline=None)
@given(
    params=stable_2nd_order,
    delay_whole=st.integers(0, 6),
    delay_frac=st.sampled_from([0.0, 0.1, 0.25, 0.5, 0.8]),
    dt=st.sampled_from([0.01, 0.05, 0.1]),
    n=st.integers(1, 60),
    seed=st.integers(0, 2**31 - 1),
)
def test_lifted_matrix_equals_simulation(params, delay_whole, delay_frac, dt, n, seed):
    num, den = _tf(params)
    model = from_transfer_function(num, den, (delay_whole + delay_frac) * dt, dt)
    assert model.delay_samples == delay_whole
    u = np.random.default_rng(seed).normal(size=(n, 3))
    Y = simulate(model, u)
    F = lifted_matrix(model, n)
    np.testing.assert_allclose(F @ u, Y, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(simulate(model, u[:, 1]), Y[:, 1], rtol=1e-12, atol=1e-14)


@settings(max_examples=25, deadline=None)
@given(
    params=stable_2nd_order,
    delay_fine=st.integers(0, 60),  # delay in units of dt / 20
    n=st.integers(2, 40),
    seed=st.integers(0, 2**31 - 1),
)
def test_fractional_delay_matches_dense_continuous_simulation(params, delay_fine, n, seed):
    num, den = _tf(params)
    fine = 20
    delay_s = delay_fine * DT / fine
    u = np.random.default_rng(seed).normal(size=n)
    model = from_transfer_function(num, den, delay_s, DT)
    expected = dense_zoh_response(num, den, DT, delay_s, u, fine)
    np.testing.assert_allclose(simulate(model, u), expected, rtol=1e-7, atol=1e-9)


def test_fractional_delay_eq11_matches_dense_simulation_and_adds_one_state():
    delay_s = 0.27  # 5 samples + 0.4 of a sample
    model = from_transfer_function(NUM11, DEN11, delay_s, DT)
    assert model.delay_samples == 5
    assert model.order == 3
    u = np.sin(np.arange(100) * 0.2) + (np.arange(100) % 7 == 0)
    expected = dense_zoh_response(NUM11, DEN11, DT, delay_s, u, fine=50)
    np.testing.assert_allclose(simulate(model, u), expected, rtol=1e-8, atol=1e-10)
    # and it lies strictly between the two neighbouring whole-sample delays
    y5 = simulate(from_transfer_function(NUM11, DEN11, 0.25, DT), u)
    y6 = simulate(from_transfer_function(NUM11, DEN11, 0.30, DT), u)
    assert not np.allclose(simulate(model, u), y5, atol=1e-4)
    assert not np.allclose(simulate(model, u), y6, atol=1e-4)


def test_whole_sample_delay_has_no_extra_state():
    for delay_s in (0.0, 0.05, 0.25, 0.3):
        model = from_transfer_function(NUM11, DEN11, delay_s, DT)
        assert model.order == 2
        assert model.delay_samples == round(delay_s / DT)


# ------------------------------------------------------------------------------ Markov etc.


@pytest.mark.parametrize("delay_s", [0.0, 0.05, 0.25, 0.27, 0.4])
def test_markov_parameters_zero_during_delay_then_impulse_response(delay_s):
    model = from_transfer_function(NUM11, DEN11, delay_s, DT)
    d = int(np.floor(delay_s / DT + 1e-9))
    f = markov_parameters(model, 30)
    assert f.shape == (30,)
    assert np.all(f[:d] == 0.0)
    assert f[d] != 0.0
    # independent: f_k = C A^(k-1-d) B, by explicit matrix powers
    for k in range(d + 1, 31):
        expected = (model.C @ np.linalg.matrix_power(model.A, k - 1 - d) @ model.B).item()
        assert f[k - 1] == pytest.approx(expected, rel=1e-10, abs=1e-14)


def _double_integrator_shift(delay: int) -> DiscreteModel:
    """x1(k+1) = x2(k), x2(k+1) = u(k - delay), y = x1: CB = 0, CAB = 1."""
    return DiscreteModel(np.array([[0.0, 1.0], [0.0, 0.0]]), [0.0, 1.0], [1.0, 0.0], 0.1, delay)


def test_relative_degree_counts_delay_and_vanishing_cb():
    assert relative_degree(from_transfer_function(NUM11, DEN11, 0.25, DT)) == 6
    assert relative_degree(from_transfer_function(NUM11, DEN11, 0.0, DT)) == 1
    assert relative_degree(from_transfer_function(NUM11, DEN11, 0.27, DT)) == 6
    for delay in (0, 1, 4):
        assert relative_degree(_double_integrator_shift(delay)) == delay + 2


def test_relative_degree_of_model_without_effect_is_refused():
    model = DiscreteModel(np.eye(2) * 0.5, [1.0, 0.0], [0.0, 1.0], 0.1, 0)
    with pytest.raises(ModelError):
        relative_degree(model)


@pytest.mark.parametrize(
    "model",
    [
        from_transfer_function(NUM11, DEN11, 0.25, DT),
        from_transfer_function(NUM11, DEN11, 0.0, DT),
        _double_integrator_shift(3),
    ],
)
@pytest.mark.parametrize("n", [6, 7, 20])
def test_controllable_slices_match_nonzero_pattern_of_F(model, n):
    r = relative_degree(model)
    if n < r:
        pytest.skip("covered by the refusal test")
    inputs, outputs = controllable_slices(model, n)
    F = lifted_matrix(model, n)
    acting = np.flatnonzero(np.any(np.abs(F) > 1e-12, axis=0))
    reached = np.flatnonzero(np.any(np.abs(F) > 1e-12, axis=1))
    assert list(range(n)[inputs]) == list(acting)
    assert list(range(n)[outputs]) == list(reached)
    assert len(range(n)[inputs]) == len(range(n)[outputs]) == n - r + 1


def test_controllable_slices_refuse_trial_shorter_than_delay():
    model = from_transfer_function(NUM11, DEN11, 0.25, DT)  # r = 6
    assert controllable_slices(model, 6) == (slice(0, 1), slice(5, 6))
    for n in (1, 3, 5):
        with pytest.raises(ModelError, match="shorter"):
            controllable_slices(model, n)


def test_dc_gain_independent_of_delay_and_equal_to_markov_sum():
    for delay_s in (0.0, 0.25, 0.27):
        model = from_transfer_function(NUM11, DEN11, delay_s, DT)
        assert dc_gain(model) == pytest.approx(1.94 / 2.01, rel=1e-10)
        assert np.sum(markov_parameters(model, 2000)) == pytest.approx(1.94 / 2.01, rel=1e-9)
    first_order = DiscreteModel([[0.8]], [0.5], [2.0], 0.1, 2)
    assert dc_gain(first_order) == pytest.approx(2.0 * 0.5 / (1.0 - 0.8))


# ------------------------------------------------------------------------------ state space


def test_from_state_space_accepts_zero_d_and_matches_discrete_model():
    A = np.array([[0.9, 0.1], [0.0, 0.7]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[1.0, 0.0]])
    for D in (0.0, [[0.0]], np.zeros((1, 1)), 1e-14):
        model = from_state_space(A, B, C, D, 0.05, 3)
        assert model.delay_samples == 3
        np.testing.assert_array_equal(model.A, A)
        u = np.arange(10.0)
        y = simulate(model, u)
        # independent loop
        x = np.zeros(2)
        expected = []
        for k in range(10):
            x = A @ x + (B[:, 0] * u[k - 3] if k >= 3 else 0.0)
            expected.append(C[0] @ x)
        np.testing.assert_allclose(y, expected, rtol=1e-12)


@pytest.mark.parametrize("D", [0.1, [[1e-3]], -2.0])
def test_from_state_space_refuses_direct_feedthrough(D):
    with pytest.raises(ModelError, match="feedthrough"):
        from_state_space([[0.5]], [[1.0]], [[1.0]], D, 0.05)


# ------------------------------------------------------------------------------ refusals


@pytest.mark.parametrize(
    "num, den, delay_s, dt_s",
    [
        ([1.0, 2.0, 3.0], [1.0, 2.0, 3.0], 0.0, 0.05),  # biproper
        ([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0], 0.0, 0.05),  # improper
        ([0.0, 0.0], [1.0, 2.0], 0.0, 0.05),  # zero numerator
        ([1.0], [0.0, 0.0], 0.0, 0.05),  # zero denominator
        ([float("nan"), 1.0], [1.0, 2.0, 3.0], 0.0, 0.05),
        ([1.0], [1.0, float("inf"), 3.0], 0.0, 0.05),
        ([1.0], [1.0, 2.0, 3.0], -0.05, 0.05),
        ([1.0], [1.0, 2.0, 3.0], float("nan"), 0.05),
        ([1.0], [1.0, 2.0, 3.0], float("inf"), 0.05),
        ([1.0], [1.0, 2.0, 3.0], 0.1, 0.0),
        ([1.0], [1.0, 2.0, 3.0], 0.1, -0.05),
        ([1.0], [1.0, 2.0, 3.0], 0.1, float("nan")),
    ],
)
def test_bad_transfer_functions_raise_model_error(num, den, delay_s, dt_s):
    with pytest.raises(ModelError) as info:
        from_transfer_function(num, den, delay_s, dt_s)
    assert isinstance(info.value, ValueError)
    assert isinstance(info.value, GcsError)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"A": [[0.5, 0.1]], "B": [1.0], "C": [1.0]},  # not square
        {"A": [[np.nan]], "B": [1.0], "C": [1.0]},
        {"A": [[0.5]], "B": [np.inf], "C": [1.0]},
        {"A": [[0.5]], "B": [1.0], "C": [1.0], "dt_s": 0.0},
        {"A": [[0.5]], "B": [1.0], "C": [1.0], "delay_samples": -1},
    ],
)
def test_bad_discrete_models_raise_model_error(kwargs):
    args = {"dt_s": 0.1, **kwargs}
    with pytest.raises(ModelError) as info:
        DiscreteModel(**args)
    assert isinstance(info.value, ValueError)


def test_discrete_model_is_frozen_and_stability_flag():
    model = from_transfer_function(NUM11, DEN11, 0.25, DT)
    assert model.is_stable()
    with pytest.raises(AttributeError):
        model.dt_s = 0.1  # type: ignore[misc]
    assert not DiscreteModel([[1.0]], [1.0], [1.0], 0.1).is_stable()


def test_as_dict_round_trips_exactly_through_yaml_and_json():
    import json

    import yaml

    model = from_transfer_function([0.09, 2.2], [1.0, 1.6, 2.3], 0.27, 0.05)
    data = model.as_dict()
    assert set(data) == {"A", "B", "C", "D", "dt_s", "delay_samples"} and data["D"] == [[0.0]]
    for text in (yaml.safe_dump(data), json.dumps(data)):
        back = yaml.safe_load(text)
        again = from_state_space(back["A"], back["B"], back["C"], back["D"], back["dt_s"],
                                 back["delay_samples"])  # fmt: skip
        for name in ("A", "B", "C"):
            assert np.array_equal(getattr(again, name), getattr(model, name))
        assert (again.dt_s, again.delay_samples) == (model.dt_s, model.delay_samples)


def test_frequency_response_is_the_transfer_function_on_the_unit_circle():
    dt = 0.05
    model = from_transfer_function([2.56], [1.0, 1.76, 2.56], 0.1, dt)
    w = np.array([0.0, 1.0, 5.0, 20.0])
    system = scipy.signal.cont2discrete(([2.56], [1.0, 1.76, 2.56]), dt, method="zoh")
    _, h = scipy.signal.freqz(np.ravel(system[0]), system[1], worN=w * dt)
    expected = h * np.exp(-1j * w * dt * 2)  # the whole-sample delay of 0.1 s
    np.testing.assert_allclose(frequency_response(model, w), expected, rtol=1e-9, atol=1e-12)


coefficient = st.floats(0.1, 10.0) | st.floats(-10.0, -0.1)


@settings(deadline=None)
@given(
    st.lists(coefficient, min_size=1, max_size=3),
    st.lists(coefficient, min_size=2, max_size=4),
    st.integers(0, 3),
)
def test_a_transfer_function_is_scipys_state_space_held_bit_for_bit(
    num: list[float], den: list[float], delay: int
) -> None:
    """The model of ``num / den`` is scipy.signal.tf2ss's canonical form under the zero-order
    hold (one matrix exponential of the augmented matrix), every bit: gcs builds that form
    itself, to spare a study the import of scipy.signal."""
    num_a, den_a = np.array(num), np.array(den)
    assume(num_a.size < den_a.size)
    ac, bc, cc, _ = scipy.signal.tf2ss(num_a, den_a)
    n = ac.shape[0]
    m = np.zeros((n + 1, n + 1))
    m[:n, :n], m[:n, n:] = ac * DT, bc * DT
    e = scipy.linalg.expm(m)
    model = from_transfer_function(num_a, den_a, delay * DT, DT)
    assert model.delay_samples == delay
    np.testing.assert_array_equal(model.A, e[:n, :n])
    np.testing.assert_array_equal(model.B, e[:n, n:])
    np.testing.assert_array_equal(model.C, cc)


def test_the_predicted_output_is_the_lifted_form_with_the_disturbance() -> None:
    """``Y = F U + D`` (eq. 5) with F built from the Markov parameters, not the difference
    equation the function runs."""
    model = from_transfer_function(NUM11, DEN11, 0.25, DT)
    rng = np.random.default_rng(3)
    u, d = rng.normal(size=120), rng.normal(size=120)
    f = scipy.linalg.toeplitz(markov_parameters(model, 120), np.zeros(120))
    np.testing.assert_allclose(predicted_output(model, u, d), f @ u + d, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="u and d_hat"):
        predicted_output(model, u, d[:-1])
