"""Tests of the repeatability floor (gcs.core.floor)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.core.floor import (
    Floor,
    FloorDrift,
    FloorVerdict,
    first_flights,
    floor_drift,
    floor_flights,
    floor_from_difference,
    floor_from_flights,
    floor_verdicts,
    integrated_autocorrelation,
    prediction_noise_ratio,
)


def ou_noise(rng: np.random.Generator, shape: tuple[int, ...], rho: float) -> np.ndarray:
    """AR(1) series along axis -2 with unit marginal variance (correlated in time)."""
    x = np.empty(shape)
    x[..., 0, :] = rng.standard_normal(shape[:-2] + shape[-1:])
    for k in range(1, shape[-2]):
        x[..., k, :] = rho * x[..., k - 1, :] + np.sqrt(1 - rho**2) * rng.standard_normal(
            shape[:-2] + shape[-1:]
        )
    return x


def test_two_flights_floor_is_the_difference_over_sqrt_two() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 300, 2))
    f = floor_from_flights(np.array([a, b]))
    d = (a - b) / np.sqrt(2)
    assert f.epos_m == pytest.approx(np.mean(np.hypot(d[:, 0], d[:, 1])), rel=1e-12)
    assert f.rms_m == pytest.approx(np.sqrt(np.mean(np.sum(d**2, axis=1))), rel=1e-12)
    assert f.axis_rms_m[0] == pytest.approx(np.sqrt(np.mean(d[:, 0] ** 2)), rel=1e-12)
    assert f.axis_mean_abs_m[1] == pytest.approx(np.mean(np.abs(d[:, 1])), rel=1e-12)
    assert f.flights == 2 and f.source == "repeat"
    g = floor_from_difference(a - b)
    assert g.epos_m == pytest.approx(f.epos_m, rel=1e-12)
    assert g.scatter_m == pytest.approx(f.scatter_m, rel=1e-12)


def test_the_floor_is_unbiased_for_anisotropic_correlated_gaussian_noise() -> None:
    """E|delta| equals a single flight's E|v|, whatever the covariance and correlation."""
    rng = np.random.default_rng(1)
    sig = np.array([0.03, 0.01])  # anisotropic [m]
    v = ou_noise(rng, (400, 6, 250, 2), 0.9) * sig  # 400 campaigns of 6 flights
    truth = np.mean(np.hypot(v[..., 0], v[..., 1]))  # E|v| of one flight
    pairs = np.mean([floor_from_flights(v[i, :2]).epos_m for i in range(400)])
    sixes = np.mean([floor_from_flights(v[i]).epos_m for i in range(400)])
    assert pairs == pytest.approx(truth, rel=0.02)
    assert sixes == pytest.approx(truth, rel=0.02)


def test_scatter_is_the_spread_of_a_single_flights_epos() -> None:
    rng = np.random.default_rng(2)
    v = ou_noise(rng, (600, 2, 280, 2), 0.95) * 0.02
    epos_single = np.mean(np.hypot(v[:, 0, :, 0], v[:, 0, :, 1]), axis=1)
    truth = np.std(epos_single)
    estimated = np.median([floor_from_flights(v[i]).scatter_m for i in range(600)])
    # a within-trial estimate of a long-run variance is biased low on short series;
    # the s^2 tau / (N - tau) form keeps it within 25 % here (docs/learning-floor.md)
    assert estimated == pytest.approx(truth, rel=0.25)


def test_the_spread_between_three_or_more_flights_is_a_single_flights_scatter() -> None:
    rng = np.random.default_rng(3)
    v = ou_noise(rng, (1500, 4, 280, 2), 0.95) * 0.02
    truth = np.var(np.mean(np.hypot(v[:, 0, :, 0], v[:, 0, :, 1]), axis=1))
    for k in (3, 4):
        floors = [floor_from_flights(v[i, :k]) for i in range(v.shape[0])]
        between = np.array([f.scatter_between_m for f in floors])
        # the variance, not the sd, is what the estimate is unbiased for
        assert np.mean(between**2) == pytest.approx(truth, rel=0.1), k
        assert all(f.scatter_m == max(f.scatter_within_m, f.scatter_between_m) for f in floors)
    pair = floor_from_flights(v[0, :2])
    assert pair.scatter_between_m is None and pair.scatter_m == pair.scatter_within_m


def test_a_wander_slower_than_a_trial_is_seen_only_between_flights() -> None:
    """The lab on firmware: a slow swing of the vehicle, of an amplitude that differs from
    flight to flight, over a trial that holds two of its periods. Within one trial the
    scatter comes out far below the true spread of e_pos; measured between four flights it
    does not."""
    rng = np.random.default_rng(4)
    t = np.arange(280) * 0.05  # a 14 s trial
    campaigns, k = 1500, 4
    amplitude = 0.1 * rng.lognormal(0.0, 0.5, size=(campaigns, k, 1, 2))  # [m]
    phase = rng.uniform(0, 2 * np.pi, size=(campaigns, k, 1, 2))
    v = amplitude * np.sin(2 * np.pi * t[:, None] / 6.0 + phase)  # a 6 s period
    v = v + 0.01 * rng.standard_normal(v.shape)
    truth = np.std(np.mean(np.hypot(v[:, 0, :, 0], v[:, 0, :, 1]), axis=1))
    floors = [floor_from_flights(v[i]) for i in range(campaigns)]
    within = np.median([f.scatter_within_m for f in floors])
    scatter = np.median([f.scatter_m for f in floors])
    assert within < 0.5 * truth
    assert scatter == pytest.approx(truth, rel=0.3)


def test_integrated_autocorrelation() -> None:
    rng = np.random.default_rng(3)
    white = rng.standard_normal(20000)
    assert integrated_autocorrelation(white) == pytest.approx(1.0, abs=0.1)
    ar = ou_noise(rng, (20000, 1), 0.8)[:, 0]
    assert integrated_autocorrelation(ar) == pytest.approx((1 + 0.8) / (1 - 0.8), rel=0.15)
    assert integrated_autocorrelation(np.ones(50)) == 1.0


@pytest.mark.parametrize(
    "bad",
    [np.zeros((2, 2, 300)), np.zeros((1, 300, 2)), np.zeros((2, 3, 2)), np.zeros((300, 2))],
)
def test_wrong_orientation_or_too_few_flights_refused(bad: np.ndarray) -> None:
    with pytest.raises(ValueError):
        floor_from_flights(bad)


def test_nan_refused() -> None:
    x = np.zeros((2, 50, 2))
    x[1, 3, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        floor_from_flights(x)


def test_floor_flights_are_trial_0_and_its_repeats_only() -> None:
    a, b = np.zeros((40, 2)), np.ones((40, 2))
    assert floor_flights(np.array([a, a + 1e-12, a, b, a, b])) == [0, 1, 2]  # not 4: flown later
    assert floor_flights(np.array([a, b, a, a])) == []  # no repeat right after trial 0
    assert floor_flights(np.array([a, a + 1e-3])) == []  # not identical
    assert floor_flights(np.array([a])) == []
    with pytest.raises(ValueError):
        floor_flights(np.zeros((3, 2, 40)).transpose(0, 2, 1)[..., :1])


def _floor(epos: float, scatter: float, flights: int = 2) -> Floor:
    return Floor(epos, epos, (epos, epos), (epos, epos), scatter, 10.0, flights)


def test_verdicts_at_floor_and_converged() -> None:
    f = _floor(0.02, 0.004)  # sigma_d = 0.004 sqrt(2)
    e = np.array([0.9, 0.1, 0.05, 0.03, 0.024, 0.021, 0.04])
    v = floor_verdicts(e, f)
    assert [x.at_floor for x in v] == [False, False, False, True, True, True, False]
    # converged: two at the floor in a row and their mean within one scatter of the floor
    assert [x.converged for x in v] == [False, False, False, False, False, True, False]
    assert v[3].z == pytest.approx((0.03 - 0.02) / (0.004 * np.sqrt(2)))
    assert v[4].ratio == pytest.approx(1.2)


def test_converged_pairs_learned_trials_only() -> None:
    """Where the floor is high (GPS), trial 0 and its repeats can be at it: they never make a
    pair, and a flight of earlier setpoints (--again) between two learned trials is skipped."""
    f = _floor(0.4, 0.05, flights=3)
    a, b, c, d = (np.full((20, 2), x) for x in (0.0, 1.0, 2.0, 3.0))
    # trials 0-2: the reference and its repeats, all at the floor; 3: learned, at it
    e = np.array([0.40, 0.41, 0.39, 0.40])
    v = floor_verdicts(e, f, setpoints_ne_m=np.array([a, a, a, b]))
    assert all(x.at_floor for x in v)
    assert not any(x.converged for x in v)
    # then trial 4 learned at the floor: converged with trial 3, its learned predecessor
    e = np.array([0.40, 0.41, 0.39, 0.40, 0.42])
    v = floor_verdicts(e, f, setpoints_ne_m=np.array([a, a, a, b, c]))
    assert [x.converged for x in v] == [False] * 4 + [True]
    # an --again of trial 3 between two learned trials: trial 6 pairs with 4, not with 5
    e = np.array([0.40, 0.41, 0.39, 0.40, 0.42, 0.41, 0.40])
    sp = np.array([a, a, a, b, c, b, d])
    v = floor_verdicts(e, f, setpoints_ne_m=sp)
    assert v[5].repeat_of == 3 and not v[5].converged
    assert v[6].converged
    # the learned predecessor above the floor: no pair, though the --again before is at it
    e = np.array([0.40, 0.41, 0.39, 0.40, 0.90, 0.41, 0.40])
    assert not floor_verdicts(e, f, setpoints_ne_m=sp)[6].converged


def test_verdicts_with_many_flights_use_a_tighter_floor() -> None:
    e = np.array([0.031, 0.031])
    loose = floor_verdicts(e, _floor(0.02, 0.004, flights=2))
    tight = floor_verdicts(e, _floor(0.02, 0.004, flights=9))
    assert loose[0].z < tight[0].z


@settings(max_examples=40, deadline=None)
@given(
    shift=st.floats(-5, 5),
    scale=st.floats(0.01, 100.0),
    seed=st.integers(0, 10_000),
)
def test_floor_is_translation_invariant_and_scales(shift: float, scale: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    y = rng.normal(size=(3, 60, 2))
    f = floor_from_flights(y)
    g = floor_from_flights(scale * y + shift)
    assert g.epos_m == pytest.approx(scale * f.epos_m, rel=1e-9)
    assert g.scatter_m == pytest.approx(scale * f.scatter_m, rel=1e-6)
    assert g.effective_samples == pytest.approx(f.effective_samples, rel=1e-6)


def verdict_row(at: list[bool], epos: list[float]) -> tuple:
    return tuple(
        FloorVerdict(j, e, e / 0.02, 0.0 if a else 3.0, a, False)
        for j, (a, e) in enumerate(zip(at, epos, strict=True))
    )


def test_a_run_that_left_the_floor_it_reached_drifts() -> None:
    at = [False, False, True, True, False, False]
    epos = [0.9, 0.3, 0.021, 0.019, 0.05, 0.07]
    assert floor_drift(verdict_row(at, epos)) == FloorDrift(2, 3, (4, 5))
    assert floor_drift(verdict_row(at[:5], epos[:5])) is None  # one above: the scatter
    assert floor_drift(verdict_row(at[:5], epos[:5]), newest=1) == FloorDrift(2, 3, (4,))
    assert floor_drift(verdict_row([False] * 6, epos)) is None  # never reached: no drift
    assert floor_drift(verdict_row([*at, True], [*epos, 0.02])) is None  # back at the floor


def test_a_flight_of_setpoints_flown_before_is_never_one_of_the_trials_above() -> None:
    """Trial 1 repeats trial 0 (the floor's repeat): the same setpoints flying above the
    floor is their scatter, not learning leaving it. Seen on firmware over GPS: trial 0 at
    the floor, its repeat and the first learned trial above; a drift needs two learned."""
    rng = np.random.default_rng(3)
    sp = rng.normal(size=(5, 20, 2))
    sp[1] = sp[0]
    sp[4] = sp[0]  # gcs fly --again 0
    assert first_flights(sp) == (0, 0, 2, 3, 0)
    f = Floor(0.385, 0.4, (0.3, 0.3), (0.3, 0.3), 0.08, 20.0, 2, "repeat")
    epos = np.array([0.524, 0.658, 0.676, 0.70, 0.30])
    v = floor_verdicts(epos, f, 2.0, sp)
    assert [x.repeat_of for x in v] == [None, 0, None, None, 0]
    assert [x.at_floor for x in v] == [True, False, False, False, True]
    assert floor_drift(v[:3]) is None  # the repeat does not count: one learned trial above
    assert floor_drift(v[:4]) == FloorDrift(0, 0, (2, 3))  # two learned trials above
    assert floor_drift(v) == FloorDrift(0, 0, (2, 3))  # --again 0 at the floor: learning's are not
    assert floor_drift(floor_verdicts(epos[:3], f, 2.0)) == FloorDrift(0, 0, (1, 2))  # blind


@given(st.lists(st.tuples(st.booleans(), st.floats(0.001, 1.0)), min_size=0, max_size=12))
def test_drift_is_the_newest_two_above_after_one_at_the_floor(rows) -> None:
    at = [a for a, _ in rows]
    epos = [e for _, e in rows]
    drift = floor_drift(verdict_row(at, epos))
    n = len(rows)
    reached = [j for j in range(n - 2) if at[j]]
    expected = n >= 3 and not at[-1] and not at[-2] and bool(reached)
    assert (drift is not None) == expected
    if drift is not None:
        assert drift.reached_trial == reached[0] and drift.above == (n - 2, n - 1)
        assert epos[drift.best_trial] == min(epos[j] for j in reached)
        assert at[drift.best_trial]


@pytest.mark.parametrize("weights", [[1.0], [0.5, 0.5], [0.08, 0.08, 0.08, 0.32, 0.43]])
def test_the_distance_from_a_right_prediction_is_the_floor_times_the_noise_ratio(weights):
    """Simulated: a flight's anisotropic Gaussian noise minus the estimate's (the weighted mean
    of earlier flights' noise, independent draws of the same process): its mean horizontal
    distance against one flight's."""
    rng = np.random.default_rng(11)
    scale = np.array([0.12, 0.05])  # anisotropic north/east [m]
    v = rng.standard_normal((len(weights) + 1, 200_000, 2)) * scale
    miss = v[0] - np.tensordot(np.asarray(weights), v[1:], axes=1)
    ratio = np.hypot(*miss.T).mean() / np.hypot(*v[0].T).mean()
    assert ratio == pytest.approx(prediction_noise_ratio(np.asarray(weights)), rel=0.01)


@given(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=12))
def test_the_noise_ratio_lies_between_one_and_the_newest_trial_alone(weights) -> None:
    """Weights of an estimate sum to at most 1: the ratio is 1 without noise in the estimate
    and sqrt(2) at most (all the weight on one trial)."""
    w = np.asarray(weights)
    w = w / max(1.0, w.sum())
    assert 1.0 <= prediction_noise_ratio(w) <= np.sqrt(2.0) + 1e-12


def test_the_noise_ratio_refuses_weights_that_are_not_a_finite_vector() -> None:
    with pytest.raises(ValueError, match="finite"):
        prediction_noise_ratio(np.array([0.5, np.nan]))
