"""PBSID-opt identification on synthetic open- and closed-loop data with known truth."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gcs.core.excitation import multisine, prbs
from gcs.core.model import DiscreteModel, from_transfer_function, markov_parameters, simulate
from gcs.core.pbsid import (
    IdentificationResult,
    continuous_poles,
    estimate_initial_state,
    identify,
    natural_frequency_damping,
    nrmse_fit,
    simulate_free,
    simulate_predictor,
    to_continuous_tf,
    vaf,
)
from gcs.errors import IdentificationError

DT = 0.05
PAPER = from_transfer_function([0.08, 1.94], [1, 1.752, 2.01], 0.25, DT)  # eq. (11)
LIGHT = from_transfer_function([6.25], [1, 1.5, 6.25], 0.10, DT)  # wn 2.5, zeta 0.3
NOISE_M = 0.01  # measurement noise std [m]
POLE_TOL = 0.02


# ------------------------------------------------------------------------------- helpers


def run_open_loop(
    plant: DiscreteModel, u: np.ndarray, noise_m: float, seed: int, x0=None
) -> np.ndarray:
    """y(k) = C x(k) + v(k), x(k+1) = A x(k) + B u(k-d); at rest before k = 0."""
    rng = np.random.default_rng(seed)
    y = simulate_free(plant, u, x0)
    return y + noise_m * rng.standard_normal(u.size)


def run_closed_loop(
    plant: DiscreteModel,
    r: np.ndarray,
    noise_m: float,
    dist: float,
    seed: int,
    kp: float,
    ki: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """PI controller u = kp e + ki dt sum(e), e = r - (y + v); input disturbance w.

    The measurement noise v is fed back, so u is correlated with it: the classic setting in
    which open-loop subspace methods (N4SID, MOESP) are biased. Returns (u, y_measured, v).
    """
    rng = np.random.default_rng(seed)
    v = noise_m * rng.standard_normal(r.size)
    w = dist * rng.standard_normal(r.size)
    x = np.zeros(plant.order)
    d = plant.delay_samples
    u = np.zeros(r.size)
    ym = np.zeros(r.size)
    integral = 0.0
    for k in range(r.size):
        ym[k] = plant.C[0] @ x + v[k]
        err = r[k] - ym[k]
        integral += ki * DT * err
        u[k] = kp * err + integral
        x = plant.A @ x + plant.B[:, 0] * ((u[k - d] if k >= d else 0.0) + w[k])
    return u, ym, v


def pole_error(model: DiscreteModel, truth: DiscreteModel) -> float:
    """Largest relative distance of a true continuous pole to the nearest identified one."""
    got = continuous_poles(model)
    return max(float(np.min(np.abs(got - s)) / abs(s)) for s in continuous_poles(truth))


@cache
def open_loop_case(name: str) -> tuple[IdentificationResult, np.ndarray, np.ndarray]:
    plant = {"paper": PAPER, "light": LIGHT}[name]
    u = prbs(3000, DT, 0.5, 2.0, seed=1)
    y = run_open_loop(plant, u, NOISE_M, seed=2)
    uv = multisine(1600, DT, 0.5, 0.02, 2.0, seed=3)
    yv = run_open_loop(plant, uv, NOISE_M, seed=4)
    return identify([(u, y)], DT), uv, yv


CL_GAINS = {"paper": (PAPER, 0.6, 0.4), "light": (LIGHT, 0.3, 0.5)}


@cache
def closed_loop_case(name: str) -> tuple[IdentificationResult, np.ndarray, np.ndarray]:
    plant, kp, ki = CL_GAINS[name]
    r = prbs(4000, DT, 0.5, 2.0, seed=11)
    u, y, _ = run_closed_loop(plant, r, NOISE_M, 0.05, seed=12, kp=kp, ki=ki)
    # Validation band of a flown trajectory; above ~0.5 Hz the closed loop attenuates the
    # reference so much that the output is mostly noise and disturbance.
    rv = multisine(2000, DT, 0.5, 0.02, 0.5, seed=13)
    uv, yv, _ = run_closed_loop(plant, rv, NOISE_M, 0.05, seed=14, kp=kp, ki=ki)
    return identify([(u, y)], DT), uv, yv


# ------------------------------------------------------------------------ accuracy cases


@pytest.mark.parametrize("name", ["paper", "light"])
def test_open_loop_poles_delay_and_validation_vaf(name: str) -> None:
    truth = {"paper": PAPER, "light": LIGHT}[name]
    res, uv, yv = open_loop_case(name)
    assert res.order == 2
    assert res.delay_samples == truth.delay_samples
    assert res.model.delay_samples == truth.delay_samples
    assert pole_error(res.model, truth) < POLE_TOL
    assert vaf(yv, simulate_free(res.model, uv)) > 95.0
    assert vaf(yv, simulate_free(res.model, uv)) > vaf(yv, simulate_free(truth, uv)) - 0.5


@pytest.mark.parametrize("name", ["paper", "light"])
def test_closed_loop_poles_delay_and_validation_vaf(name: str) -> None:
    truth = CL_GAINS[name][0]
    res, uv, yv = closed_loop_case(name)
    assert res.order == 2
    assert res.delay_samples == truth.delay_samples
    assert pole_error(res.model, truth) < POLE_TOL
    assert vaf(yv, simulate_free(res.model, uv)) > 95.0
    # as good as the truth itself on the same noisy data (noise sets the ceiling)
    assert vaf(yv, simulate_free(res.model, uv)) > vaf(yv, simulate_free(truth, uv)) - 0.5
    assert res.model.is_stable()


def _fir_least_squares(u: np.ndarray, y: np.ndarray, taps: int) -> np.ndarray:
    """Naive open-loop estimate: y(k) ~ sum_j h_j u(k-j), consistent only if u is independent
    of the output noise."""
    Phi = np.column_stack(
        [np.concatenate([np.zeros(j), u[: u.size - j]]) for j in range(1, taps + 1)]
    )
    return np.linalg.lstsq(Phi[taps:], y[taps:], rcond=None)[0]


def test_strong_noise_feedback_biases_open_loop_estimate_but_not_pbsid() -> None:
    """Weak reference, strong disturbance and sensor noise fed back by the PI controller: the
    FIR least-squares estimate (open-loop consistent) loses two thirds of the static gain,
    PBSID (delay given: at this SNR the estimate of the delay is not reliable) stays close."""
    r = prbs(4000, DT, 0.1, 2.0, seed=104)
    u, y, v = run_closed_loop(PAPER, r, 0.03, 0.3, seed=204, kp=1.0, ki=0.6)
    true_dc = float(markov_parameters(PAPER, 300).sum())
    # open-loop control experiment: same excitation level, same noise, FIR is fine there
    y_ol = run_open_loop(PAPER, u, 0.03, seed=205)
    assert abs(_fir_least_squares(u, y_ol, 150).sum() / true_dc - 1) < 0.1
    fir_dc = float(_fir_least_squares(u, y, 150).sum())
    assert abs(fir_dc / true_dc - 1) > 0.3
    res = identify([(u, y)], DT, delay_samples=5)
    f_hat = markov_parameters(res.model, 300)
    assert abs(f_hat.sum() / true_dc - 1) < 0.15
    f_true = markov_parameters(PAPER, 300)
    assert np.linalg.norm(f_hat - f_true) < 0.15 * np.linalg.norm(f_true)
    assert pole_error(res.model, PAPER) < 0.06


def test_identified_paper_model_matches_footnote_6() -> None:
    """wn ~ 1.4 rad/s, zeta ~ 0.6 and the static gain of eq. (11), from identified data."""
    res, _, _ = closed_loop_case("paper")
    wn, zeta = natural_frequency_damping(res.model)
    wn_true, zeta_true = np.sqrt(2.01), 1.752 / (2 * np.sqrt(2.01))
    assert wn == pytest.approx(wn_true, rel=0.02)
    assert zeta == pytest.approx(zeta_true, rel=0.03)
    num, den, delay_s = to_continuous_tf(res.model)
    assert delay_s == pytest.approx(0.25)
    assert num[-1] / den[-1] == pytest.approx(1.94 / 2.01, rel=0.02)


def test_multi_experiment_concatenation() -> None:
    """Three short experiments with different excitations and initial offsets identify the model;
    one of them alone is not enough for the same accuracy."""
    rng_seeds = [(21, 22), (23, 24), (25, 26)]
    exps = []
    for i, (s_u, s_y) in enumerate(rng_seeds):
        u = prbs(1200, DT, 0.5, 2.0, seed=s_u)
        x0 = np.array([0.3, -0.2]) * (i + 1)  # different initial states: a jump between records
        exps.append((u, run_open_loop(PAPER, u, NOISE_M, seed=s_y, x0=x0)))
    res = identify(exps, DT)
    assert res.delay_samples == PAPER.delay_samples
    assert pole_error(res.model, PAPER) < POLE_TOL
    uv = multisine(1600, DT, 0.5, 0.02, 2.0, seed=27)
    yv = run_open_loop(PAPER, uv, NOISE_M, seed=28)
    assert vaf(yv, simulate_free(res.model, uv)) > 95.0


def test_windows_do_not_straddle_experiments() -> None:
    """Noise-free data from two records with very different initial states are identified
    exactly; gluing them into one record (a window across the joint) is not."""
    u1 = prbs(500, DT, 0.5, 10.0, seed=31)
    u2 = prbs(500, DT, 0.5, 10.0, seed=32)
    y1 = run_open_loop(PAPER, u1, 0.0, seed=0)
    y2 = run_open_loop(PAPER, u2, 0.0, seed=0, x0=np.array([5.0, -4.0]))
    split = identify([(u1, y1), (u2, y2)], DT, order=2)
    glued = identify([(np.concatenate([u1, u2]), np.concatenate([y1, y2]))], DT, order=2)
    f_true = markov_parameters(PAPER, 60)
    err_split = np.max(np.abs(markov_parameters(split.model, 60) - f_true))
    err_glued = np.max(np.abs(markov_parameters(glued.model, 60) - f_true))
    assert err_split < 1e-6 * np.max(np.abs(f_true))
    assert err_glued > 100 * err_split


def test_single_tuple_is_accepted() -> None:
    u = prbs(800, DT, 0.5, 10.0, seed=41)
    y = run_open_loop(PAPER, u, 0.0, seed=0)
    res = identify((u, y), DT)
    assert res.order == 2 and res.delay_samples == 5


def test_given_order_delay_and_regularisation() -> None:
    u = prbs(3000, DT, 0.5, 2.0, seed=1)
    y = run_open_loop(PAPER, u, NOISE_M, seed=2)
    res = identify([(u, y)], DT, order=3, delay_samples=5, regularisation=1e-6, past=30)
    assert res.order == 3 and res.model.order == 3 and res.K.shape == (3, 1)
    assert res.delay_samples == 5 and res.past == 30 and res.future == 10
    assert res.singular_values.shape == (10,)
    # An over-parameterised model still validates (the third state is nearly unobservable).
    uv = multisine(1600, DT, 0.5, 0.02, 2.0, seed=3)
    yv = run_open_loop(PAPER, uv, NOISE_M, seed=4)
    assert vaf(yv, simulate_free(res.model, uv)) > 95.0


def test_singular_values_show_the_order_gap() -> None:
    res, _, _ = open_loop_case("paper")
    sv = res.singular_values
    assert np.all(np.diff(sv) <= 0)
    gaps = np.log10(sv[:-1] / sv[1:])
    assert int(np.argmax(gaps)) + 1 == res.order == 2


# ------------------------------------------------------------------ exact recovery (PBT)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    wn=st.floats(0.5, 5.0),
    zeta=st.floats(0.15, 1.5),
    gain=st.floats(0.3, 3.0),
    delay=st.integers(0, 4),
    seed=st.integers(0, 2**16),
)
def test_noise_free_second_order_system_is_recovered_exactly(
    wn: float, zeta: float, gain: float, delay: int, seed: int
) -> None:
    truth = from_transfer_function([gain * wn**2], [1, 2 * zeta * wn, wn**2], delay * DT, DT)
    u = prbs(700, DT, 1.0, 10.0, seed=seed)  # clocked every sample: white-like
    y = run_open_loop(truth, u, 0.0, seed=0)
    res = identify([(u, y)], DT, max_delay=6)
    assert res.order == 2
    assert res.delay_samples == delay
    f_true = markov_parameters(truth, 80)
    f_hat = markov_parameters(res.model, 80)
    assert np.max(np.abs(f_hat - f_true)) < 1e-6 * np.max(np.abs(f_true))
    assert pole_error(res.model, truth) < 1e-5


# -------------------------------------------------------------------- validation helpers


def test_simulate_free_matches_model_simulate_shifted_by_one() -> None:
    u = prbs(200, DT, 0.5, 2.0, seed=5)
    assert np.allclose(simulate_free(PAPER, u)[1:], simulate(PAPER, u)[:-1])
    assert simulate_free(PAPER, u)[0] == 0.0


def test_predictor_beats_free_run_on_disturbed_data() -> None:
    res, uv, yv = closed_loop_case("light")
    pred = vaf(yv, simulate_predictor(res, uv, yv))
    free = vaf(yv, simulate_free(res.model, uv))
    assert pred > free


def test_initial_state_estimate_removes_the_transient() -> None:
    u = prbs(600, DT, 0.5, 2.0, seed=6)
    y = run_open_loop(PAPER, u, 0.0, seed=0, x0=np.array([0.8, -0.5]))
    x0 = estimate_initial_state(PAPER, u, y)
    assert vaf(y, simulate_free(PAPER, u, x0)) > 99.999
    assert vaf(y, simulate_free(PAPER, u)) < 99.0


def test_vaf_and_fit_values() -> None:
    y = np.sin(np.linspace(0, 10, 200))
    assert vaf(y, y) == pytest.approx(100.0)
    assert nrmse_fit(y, y) == pytest.approx(100.0)
    assert vaf(y, np.full_like(y, y.mean())) == pytest.approx(0.0)
    assert nrmse_fit(y, np.full_like(y, y.mean())) == pytest.approx(0.0)
    assert vaf(y, 0.5 * y) == pytest.approx(75.0)
    assert nrmse_fit(y, 0.5 * y) < 100.0
    with pytest.raises(IdentificationError, match="samples"):
        vaf(y, y[:-1])
    with pytest.raises(IdentificationError, match="constant"):
        vaf(np.ones(10), np.ones(10))


def test_tustin_of_the_true_model_recovers_eq_11() -> None:
    num, den, delay_s = to_continuous_tf(PAPER)
    assert delay_s == pytest.approx(0.25)
    assert den == pytest.approx([1.0, 1.752, 2.01], rel=2e-3)
    assert num[-1] / den[-1] == pytest.approx(1.94 / 2.01, rel=1e-9)  # Tustin keeps DC gain
    # The strictly proper discrete model maps to a zero near s = +2/dt (Tustin artefact).
    zeros = np.roots(num)
    assert np.min(np.abs(zeros - 2 / DT)) < 0.1 * 2 / DT
    wn, zeta = natural_frequency_damping(PAPER)
    assert wn == pytest.approx(np.sqrt(2.01), rel=1e-3)
    assert zeta == pytest.approx(1.752 / (2 * np.sqrt(2.01)), rel=1e-3)


def test_natural_frequency_of_overdamped_pair() -> None:
    model = from_transfer_function([2.0], [1, 3.0, 2.0], 0.0, DT)  # poles -1, -2
    wn, zeta = natural_frequency_damping(model)
    assert wn == pytest.approx(np.sqrt(2.0), rel=1e-3)
    assert zeta == pytest.approx(3.0 / (2 * np.sqrt(2.0)), rel=1e-3)


# --------------------------------------------------------------------------- bad inputs


def _good(n: int = 800) -> tuple[np.ndarray, np.ndarray]:
    u = prbs(n, DT, 0.5, 5.0, seed=7)
    return u, run_open_loop(PAPER, u, NOISE_M, seed=8)


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda u, y: [(np.where(np.arange(u.size) == 50, np.nan, u), y)], "u contains NaN"),
        (lambda u, y: [(u, np.where(np.arange(y.size) == 9, np.inf, y))], "sample 9"),
        (lambda u, y: [(u, y[:-3])], "u has 800 samples but y has 797"),
        (lambda u, y: [(u[:25], y[:25])], "need at least 32 per experiment"),
        (lambda u, y: [(u[:150], y[:150])], r"about \d+ samples in total"),
        (lambda u, y: [(np.full_like(u, 0.3), y)], "constant"),
        (
            lambda u, y: [(np.sin(0.3 * np.arange(u.size)), y)],
            "not persistently exciting of order 20",
        ),
        (lambda u, y: [(u, np.zeros_like(y))], "output y is constant"),
        (lambda u, y: [], "no experiments"),
        (lambda u, y: [(u[:, None], y[:, None])], "1-D"),
        (lambda u, y: [(u, y, u)], r"\(u, y\) pair"),
    ],
    ids=[
        "nan",
        "inf",
        "lengths",
        "too-short-experiment",
        "too-little-data",
        "constant-input",
        "sinusoid-input",
        "zero-output",
        "empty",
        "2-d",
        "triple",
    ],
)
def test_bad_data_raises_identification_error(mutate, match: str) -> None:
    u, y = _good()
    with pytest.raises(IdentificationError, match=match):
        identify(mutate(u, y), DT)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"dt_s": 0.0}, "dt_s"),
        ({"future": 25}, "future"),
        ({"future": 1}, "future"),
        ({"past": 0}, "past"),
        ({"order": 10}, "order"),
        ({"order": 0}, "order"),
        ({"max_delay": -1}, "max_delay"),
        ({"delay_samples": -2}, "delay_samples"),
        ({"regularisation": -1.0}, "regularisation"),
    ],
)
def test_bad_settings_raise_identification_error(kwargs: dict, match: str) -> None:
    u, y = _good()
    args = {"dt_s": DT, **kwargs}
    dt = args.pop("dt_s")
    with pytest.raises(IdentificationError, match=match):
        identify([(u, y)], dt, **args)


def test_band_limited_reference_under_feedback_is_refused() -> None:
    """u(k) + kp y_m(k) = kp r(k) + integral: with a reference below 0.5 Hz the past inputs and
    outputs are collinear at high frequency, the VARX fits noise there and Gamma K amplifies it
    (pole errors of 80 % unchecked). Refused unless regularised."""
    plant, kp, ki = CL_GAINS["paper"]
    r = multisine(4000, DT, 0.5, 0.02, 0.5, seed=11)
    u, y, _ = run_closed_loop(plant, r, NOISE_M, 0.05, seed=12, kp=kp, ki=ki)
    with pytest.raises(IdentificationError, match="ill-conditioned.*PRBS"):
        identify([(u, y)], DT)
    res = identify([(u, y)], DT, regularisation=1e-3, order=2, delay_samples=5)
    assert res.model.order == 2  # runs; accuracy is poor (about 6 %), hence the refusal


def test_identification_error_is_a_value_error() -> None:
    with pytest.raises(ValueError):
        identify([], DT)
