"""Tests of the batched Monte Carlo study (gcs.core.montecarlo)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gcs.core import montecarlo as mc
from gcs.core.estimators import kilc_init, kilc_update, rts_smoother
from gcs.core.learner import FOLD_MIN_PLANTS
from gcs.core.model import from_transfer_function, lifted_matrix, simulate
from gcs.core.update import UpdateWeights, next_input

SMALL = mc.MontecarloSettings(
    levels=(0.1,),
    plants=3,
    repeats=2,
    iterations=5,
    steady_from=3,
    steady_to=5,
    n_samples=60,
    seed=7,
)


def _msd(wn: float, zeta: float, dt: float):
    return from_transfer_function([wn * wn], [1.0, 2.0 * zeta * wn, wn * wn], 0.0, dt)


def _reference_norms(settings: mc.MontecarloSettings, level: float, algorithm: str) -> np.ndarray:
    """Trial-by-trial loop with the per-trial reference functions (no batching)."""
    n, dt = settings.n_samples, settings.t_ilc_s
    plants = mc.sample_plants(settings, level)
    p, r = plants.wn_rad_s.size, settings.repeats
    t_out = dt * np.arange(1, n + 1)
    yd = np.sin(settings.reference_omega_rad_s * t_out)
    d = settings.disturbance_amp_m * np.sin(t_out) ** 2
    u0 = np.sin(settings.reference_omega_rad_s * dt * np.arange(n))
    nominal = _msd(settings.wn_rad_s, settings.zeta, dt)
    f_nom = lifted_matrix(nominal, n)
    weights = UpdateWeights(we=settings.we, wdu=settings.wdu, wu=settings.wu)

    def update(d_hat, u):  # noqa: ANN001, ANN202
        return next_input(nominal, yd, d_hat, u, weights).u_m

    # the study's noise stream: one (P*R, N) draw per trial, trials in order
    rng = mc.noise_generator(settings, level)
    noise = [rng.standard_normal((p * r, n)) for _ in range(settings.iterations + 1)]
    norms = np.zeros((p, r, settings.iterations + 1))
    for i in range(p):
        plant = _msd(float(plants.wn_rad_s[i]), float(plants.zeta[i]), dt)
        for k in range(r):
            u = u0.copy()
            state = kilc_init(n, settings.kilc)
            for j in range(settings.iterations + 1):
                y_true = simulate(plant, u) + d
                y = y_true + settings.noise_std * noise[j][i * r + k]
                e = yd - (y if settings.error_signal == "measured" else y_true)
                norms[i, k, j] = np.linalg.norm(e)
                z = y - f_nom @ u
                if algorithm == "smoother":
                    d_hat = rts_smoother(z, settings.smoother).d_hat
                else:
                    state = kilc_update(state, z, settings.kilc)
                    d_hat = state.d_hat
                u = update(d_hat, u)
    return norms


@pytest.mark.parametrize("algorithm", mc.ALGORITHMS)
@pytest.mark.parametrize("signal", ["true", "measured"])
@pytest.mark.parametrize("plants", [3, FOLD_MIN_PLANTS // 2])  # 6 runs: banded; 16: folded
def test_batched_study_equals_per_trial_reference(algorithm: str, signal: str, plants: int) -> None:
    settings = dataclasses.replace(SMALL, error_signal=signal, plants=plants)
    batched = mc.error_norms(settings, 0.1, algorithm)
    reference = _reference_norms(settings, 0.1, algorithm)
    assert batched.shape == (plants, 2, 6)
    np.testing.assert_allclose(batched, reference, rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize(("wn", "zeta"), [(1.8, 0.8), (0.4, 0.1), (3.1, 1.7)])
def test_batched_plants_respond_as_their_models(wn: float, zeta: float) -> None:
    # The batch's plants (Markov parameters of all of them from one batched matrix
    # exponential) against each plant's own model, simulated trial by trial: around a
    # well-damped, a lightly damped and an over-damped nominal, 120 samples, no noise.
    settings = dataclasses.replace(
        SMALL, levels=(0.2,), wn_rad_s=wn, zeta=zeta, n_samples=120, noise_std=0.0
    )
    plants = mc.sample_plants(settings, 0.2)
    assert np.unique(plants.wn_rad_s).size == 3 and np.unique(plants.zeta).size == 3
    batched = mc.error_norms(settings, 0.2, "kilc")
    np.testing.assert_allclose(batched, _reference_norms(settings, 0.2, "kilc"), rtol=1e-10)


@pytest.mark.parametrize("algorithm", mc.ALGORITHMS)
def test_nominal_noise_free_learning_converges(algorithm: str) -> None:
    settings = mc.MontecarloSettings(
        levels=(0.0,), plants=2, repeats=1, iterations=30, n_samples=200, noise_std=0.0
    )
    norms = mc.error_norms(settings, 0.0, algorithm)
    e = norms[0, 0]
    np.testing.assert_allclose(norms[1, 0], e)  # every plant is the nominal one
    assert np.all(np.diff(e) <= 1e-12), "error norm must not increase"
    assert e[0] > 5.0
    assert e[-1] < 0.03 * e[0]
    # with an exact model and no noise the error keeps shrinking towards zero
    longer = dataclasses.replace(settings, iterations=300, steady_from=0, steady_to=300)
    e_long = mc.error_norms(longer, 0.0, algorithm)[0, 0]
    assert e_long[-1] < 0.5 * e[-1]


def test_first_learned_trial_differs_between_algorithms_but_trial_zero_does_not() -> None:
    a = mc.error_norms(SMALL, 0.1, "smoother")
    b = mc.error_norms(SMALL, 0.1, "kilc")
    np.testing.assert_array_equal(a[:, :, 0], b[:, :, 0])  # same plants, same noise, same U_0
    assert not np.allclose(a[:, :, 1], b[:, :, 1])


def test_deterministic_for_a_fixed_seed() -> None:
    rows1 = mc.run_study(SMALL)
    rows2 = mc.run_study(SMALL)
    assert rows1 == rows2
    other = mc.run_study(dataclasses.replace(SMALL, seed=8))
    assert other[0].first_mean != rows1[0].first_mean
    # a level's numbers do not depend on which other levels are run
    both = mc.run_study(dataclasses.replace(SMALL, levels=(0.05, 0.1)))
    assert both[2:] == rows1


def test_invalid_plant_rules() -> None:
    settings = mc.MontecarloSettings(
        levels=(1.0,), plants=200, repeats=1, iterations=2, steady_from=1, steady_to=2, seed=1
    )
    resampled = mc.sample_plants(settings, 1.0)
    assert resampled.wn_rad_s.size == 200
    assert np.all(resampled.wn_rad_s > 0) and np.all(resampled.zeta > 0)
    assert resampled.excluded > 0
    excl = mc.sample_plants(dataclasses.replace(settings, invalid_plant_rule="exclude"), 1.0)
    assert excl.wn_rad_s.size == 200 - excl.excluded
    assert np.all(excl.wn_rad_s > 0) and np.all(excl.zeta > 0)
    # the first draw is common to both rules: resampling only replaces the invalid draws
    assert np.isin(excl.wn_rad_s, resampled.wn_rad_s).all()
    assert excl.excluded <= resampled.excluded
    small = dataclasses.replace(settings, plants=20, n_samples=40, invalid_plant_rule="exclude")
    rows = mc.run_study(small)
    assert all(r.plants == 20 - r.excluded for r in rows)
    assert "excluded" in rows[0].excluded_rule
    assert (
        "resampled"
        in mc.run_study(dataclasses.replace(small, invalid_plant_rule="resample"))[0].excluded_rule
    )
    # at 5 % a negative parameter needs a 20-sigma draw
    assert mc.sample_plants(mc.MontecarloSettings(), 0.05).excluded == 0


def test_diverged_rule_counts_and_excludes() -> None:
    settings = dataclasses.replace(SMALL, plants=1, levels=(0.1,))
    norms = np.ones((2, 2, 6))
    norms[1, :, 1:] = 100.0  # plant 1 diverged
    row = mc.summarise(settings, norms, 0.1, "kilc", 0)
    assert row.diverged == 1 and row.plants == 2 and row.steady_mean == pytest.approx(50.5)
    excl = dataclasses.replace(settings, diverged_rule="exclude")
    row = mc.summarise(excl, norms, 0.1, "kilc", 0)
    assert row.diverged == 1 and row.plants == 1 and row.steady_mean == pytest.approx(1.0)


def test_the_rows_do_not_depend_on_the_threads_that_run_the_batches() -> None:
    settings = dataclasses.replace(SMALL, levels=(0.05, 0.1, 0.2))
    calls: list[tuple[int, int]] = []
    serial = mc.run_study(settings)
    threaded = mc.run_study(settings, lambda done, total: calls.append((done, total)), threads=3)
    assert threaded == serial  # every bit, rows in the order of the levels
    total = 3 * 2 * settings.iterations
    assert [c[0] for c in calls] == list(range(1, total + 1)) and calls[-1][1] == total
    with pytest.raises(ValueError, match="threads"):
        mc.run_study(settings, threads=0)


def test_result_structure_and_progress() -> None:
    settings = dataclasses.replace(SMALL, levels=(0.05, 0.2))
    calls: list[tuple[int, int]] = []
    rows = mc.run_study(settings, progress=lambda done, total: calls.append((done, total)))
    assert [(r.algorithm, r.uncertainty) for r in rows] == [
        ("smoother", 0.05),
        ("kilc", 0.05),
        ("smoother", 0.2),
        ("kilc", 0.2),
    ]
    total = 2 * 2 * settings.iterations
    assert calls[-1] == (total, total) and len(calls) == total
    assert [c[0] for c in calls] == list(range(1, total + 1))
    for r in rows:
        assert isinstance(r, mc.StudyRow)
        assert r.plants == 3 and r.excluded == 0
        assert np.isfinite([r.first_mean, r.first_std, r.steady_mean, r.steady_std]).all()
        assert r.first_std >= 0 and r.steady_std >= 0
        norms = mc.error_norms(settings, r.uncertainty, r.algorithm)
        per_plant = norms.mean(axis=1)
        assert r.first_mean == pytest.approx(per_plant[:, 1].mean())
        assert r.steady_mean == pytest.approx(per_plant[:, 3:6].mean())
    assert set(mc.PAPER_TABLES) == {(a, x) for a in mc.ALGORITHMS for x in (0.05, 0.1, 0.2, 0.4)}
    with pytest.raises(dataclasses.FrozenInstanceError):
        rows[0].first_mean = 0.0  # type: ignore[misc]


@pytest.mark.parametrize(
    "field, value",
    [
        ("plants", 0),
        ("noise_std", -1.0),
        ("error_signal", "noisy"),
        ("u0", "ramp"),
        ("invalid_plant_rule", "keep"),
        ("diverged_rule", "drop"),
        ("algorithms", ("ilc",)),
        ("steady_to", 99),
        ("first_iteration", 31),
        ("levels", (-0.1,)),
    ],
)
def test_settings_validation(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field.split("_")[0]):
        mc.MontecarloSettings(**{field: value})
