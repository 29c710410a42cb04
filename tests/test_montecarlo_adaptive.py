"""Tests of the Monte Carlo study with the options beyond the paper (gcs.core.montecarlo)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gcs.core import montecarlo as mc
from gcs.core.learner import Learner
from gcs.core.learning import AdaptiveSettings, LearnerSettings
from gcs.core.model import from_transfer_function, simulate
from gcs.core.update import UpdateWeights

# three runs: an odd number, so the last vehicle flies the last run on both axes
SMALL = mc.MontecarloSettings(
    levels=(0.3,), plants=3, repeats=1, iterations=4, steady_from=3, steady_to=4, n_samples=150
)
OPTIONS = AdaptiveSettings(noise="data", refresh=True)


def mass_spring_damper(wn: float, zeta: float, dt_s: float):  # noqa: ANN201
    return from_transfer_function([wn * wn], [1.0, 2.0 * zeta * wn, wn * wn], 0.0, dt_s)


def a_learner_per_run(settings: mc.MontecarloSettings, level: float, adaptive: AdaptiveSettings):  # noqa: ANN201
    """Each run alone: its own Learner, flown on north and east alike (the options learn the
    axes apart), its plant simulated by the model's difference equation. Error norms
    (P, R, J+1) and whether the run's model was refreshed (P, R)."""
    n, dt = settings.n_samples, settings.t_ilc_s
    plants = mc.sample_plants(settings, level)
    p, r = plants.wn_rad_s.size, settings.repeats
    t_out, t_in = dt * np.arange(1, n + 1), dt * np.arange(n)
    amp, omega = settings.reference_amp_m, settings.reference_omega_rad_s
    yd = amp * np.sin(omega * t_out)
    d = settings.disturbance_amp_m * np.sin(settings.disturbance_omega_rad_s * t_out) ** 2
    rng = mc.noise_generator(settings, level)
    noise = [rng.standard_normal((p * r, n)) for _ in range(settings.iterations + 1)]
    nominal = mass_spring_damper(settings.wn_rad_s, settings.zeta, dt)
    learner_settings = LearnerSettings(
        models=(nominal, nominal), weights=UpdateWeights(settings.we, settings.wdu, settings.wu)
    )
    ref = np.column_stack([np.concatenate([[0.0], yd])] * 2)
    norms = np.zeros((p, r, settings.iterations + 1))
    refreshed = np.zeros((p, r), dtype=bool)
    for i in range(p):
        plant = mass_spring_damper(float(plants.wn_rad_s[i]), float(plants.zeta[i]), dt)
        for k in range(r):
            learner = Learner(learner_settings, ref, adaptive)
            u = np.column_stack([amp * np.sin(omega * t_in)] * 2)
            for j in range(settings.iterations + 1):
                y_true = simulate(plant, u[:, 0]) + d
                norms[i, k, j] = np.linalg.norm(yd - y_true)
                y = y_true + settings.noise_std * noise[j][i * r + k]
                if j < settings.iterations:
                    u = learner.step(u, np.column_stack([y, y]))
            refreshed[i, k] = learner.models[0] is not nominal
    return norms, refreshed


@pytest.mark.parametrize(
    "adaptive",
    [OPTIONS, replace(OPTIONS, refresh=False, robustness_cutoff_rad_s=15.0)],
    ids=["refresh", "robustness"],
)
def test_the_study_s_runs_equal_a_learner_per_run(adaptive: AdaptiveSettings) -> None:
    batched, refreshed = mc.adaptive_error_norms(SMALL, 0.3, "smoother", adaptive)
    expected, expected_refreshed = a_learner_per_run(SMALL, 0.3, adaptive)
    assert batched.shape == (3, 1, SMALL.iterations + 1)
    np.testing.assert_allclose(batched, expected, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(refreshed, expected_refreshed)
    if adaptive.refresh:  # some runs refreshed: the runs of their own models are compared too
        assert refreshed.any()
    else:
        assert not refreshed.any()


def test_trial_zero_is_the_papers_and_learning_converges() -> None:
    paper = mc.error_norms(SMALL, 0.3, "smoother")
    new, _ = mc.adaptive_error_norms(SMALL, 0.3, "smoother", OPTIONS)
    np.testing.assert_array_equal(new[:, :, 0], paper[:, :, 0])  # same plants, same noise
    assert np.all(new[:, :, -1] < 0.2 * new[:, :, 0])


def test_compare_study_rows_and_comparison() -> None:
    settings = replace(SMALL, levels=(0.05, 0.4), repeats=2)
    done = []
    rows, comparison = mc.compare_study(settings, OPTIONS, progress=lambda d, t: done.append(t))
    assert [r.algorithm for r in rows] == ["smoother+adaptive"] * 2
    assert [c.uncertainty for c in comparison] == [0.05, 0.4]
    assert done and done[-1] == 2 * settings.iterations
    for c in comparison:
        paper = mc.error_norms(settings, c.uncertainty, "smoother")
        new, refreshed = mc.adaptive_error_norms(settings, c.uncertainty, "smoother", OPTIONS)
        assert c.paper_mean_2_5 == pytest.approx(paper[:, :, 2:6].mean())
        assert c.new_mean_2_5 == pytest.approx(new[:, :, 2:6].mean())
        assert c.change_pct == pytest.approx(100 * (c.new_mean_2_5 / c.paper_mean_2_5 - 1))
        assert c.refreshed_pct == pytest.approx(100 * refreshed.mean())
        assert c.seconds >= 0 and c.plants == 3


def test_refusals() -> None:
    with pytest.raises(ValueError, match="safeguard.*arena"):
        mc.adaptive_error_norms(SMALL, 0.3, "smoother", replace(OPTIONS, safeguard=True))
    mc.check_adaptive_size(SMALL, memory_bytes=1e9)
    with pytest.raises(ValueError, match="every trial .* GB"):
        mc.check_adaptive_size(SMALL, memory_bytes=1e5)
