"""Tests of the Monte Carlo study with the options beyond the paper (gcs.core.montecarlo)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gcs.core import montecarlo as mc
from gcs.core.learning import AdaptiveSettings
from gcs.core.model import from_transfer_function, simulate
from gcs.core.noise_model import drift_scale, estimate_disturbance
from gcs.core.refresh import refresh_model
from gcs.core.robustness import robustness_weight
from gcs.core.update import UpdateWeights, next_input

SMALL = mc.MontecarloSettings(
    levels=(0.3,), plants=2, repeats=2, iterations=4, steady_from=3, steady_to=4, n_samples=150
)
OPTIONS = AdaptiveSettings(noise="data", refresh=True)


def _estimate(model, uh: np.ndarray, yh: np.ndarray, adaptive: AdaptiveSettings):
    t, n = uh.shape
    change = simulate(model, np.diff(uh, axis=0).T).T.reshape(t - 1, n)
    z = yh - simulate(model, uh.T).T
    return estimate_disturbance(z, drift_scale(change), True, adaptive.drift_offset)


def paper_signals(settings: mc.MontecarloSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sec. IV's reference yd(1..N), disturbance d(1..N) and first input U_0(0..N-1)."""
    n, dt = settings.n_samples, settings.t_ilc_s
    t_out, t_in = dt * np.arange(1, n + 1), dt * np.arange(n)
    amp, omega = settings.reference_amp_m, settings.reference_omega_rad_s
    d = settings.disturbance_amp_m * np.sin(settings.disturbance_omega_rad_s * t_out) ** 2
    u0 = amp * np.sin(omega * t_in) if settings.u0 == "reference" else np.zeros(n)
    return amp * np.sin(omega * t_out), d, u0


def mass_spring_damper(wn: float, zeta: float, dt_s: float):
    return from_transfer_function([wn * wn], [1.0, 2.0 * zeta * wn, wn * wn], 0.0, dt_s)


def reference_norms(settings: mc.MontecarloSettings, level: float, adaptive: AdaptiveSettings):
    """Run by run with the one-axis functions the learning step uses (no batching)."""
    n, dt = settings.n_samples, settings.t_ilc_s
    plants = mc.sample_plants(settings, level)
    p, r = plants.wn_rad_s.size, settings.repeats
    yd, d, u0 = paper_signals(settings)
    rng = mc.noise_generator(settings, level)
    noise = [rng.standard_normal((p * r, n)) for _ in range(settings.iterations + 1)]
    weights = UpdateWeights(settings.we, settings.wdu, settings.wu)
    refresh = replace(adaptive.refresh_settings(), delay_search=0)
    norms = np.zeros((p, r, settings.iterations + 1))
    for i in range(p):
        plant = mass_spring_damper(float(plants.wn_rad_s[i]), float(plants.zeta[i]), dt)
        for k in range(r):
            model = mass_spring_damper(settings.wn_rad_s, settings.zeta, dt)
            u, us, ys = u0.copy(), [], []
            for j in range(settings.iterations + 1):
                y_true = simulate(plant, u) + d
                y = y_true + settings.noise_std * noise[j][i * r + k]
                norms[i, k, j] = np.linalg.norm(yd - y_true)
                us.append(u)
                ys.append(y)
                if j == settings.iterations:
                    break
                uh, yh = np.array(us), np.array(ys)
                est = _estimate(model, uh, yh, adaptive)
                if adaptive.refresh and j >= 1:
                    res = refresh_model(
                        model, np.diff(uh, axis=0), np.diff(yh, axis=0),
                        float(est.iteration.r_m2), refresh, settings.wdu / settings.we,
                    )  # fmt: skip
                    if res.accepted:
                        model = res.model
                        est = _estimate(model, uh, yh, adaptive)
                robust = None
                if adaptive.robustness_cutoff_rad_s is not None:
                    robust = robustness_weight(
                        model, adaptive.robustness_cutoff_rad_s, adaptive.robustness_order, u0
                    )
                u = next_input(model, yd, est.d_hat_m, u, weights, None, robust).u_m
    return norms


@pytest.mark.parametrize(
    "adaptive",
    [OPTIONS, replace(OPTIONS, refresh=False, robustness_cutoff_rad_s=15.0)],
    ids=["refresh", "robustness"],
)
def test_batched_adaptive_study_equals_run_by_run_reference(adaptive) -> None:
    batched, refreshed = mc.adaptive_error_norms(SMALL, 0.3, "smoother", adaptive)
    expected = reference_norms(SMALL, 0.3, adaptive)
    np.testing.assert_allclose(batched, expected, rtol=1e-6)
    assert refreshed.shape == (2, 2)
    if adaptive.refresh:
        assert refreshed.any()


def test_trial_zero_is_the_papers_and_learning_converges() -> None:
    paper = mc.error_norms(SMALL, 0.3, "smoother")
    new, _ = mc.adaptive_error_norms(SMALL, 0.3, "smoother", OPTIONS)
    np.testing.assert_array_equal(new[:, :, 0], paper[:, :, 0])  # same plants, same noise
    assert np.all(new[:, :, -1] < 0.2 * new[:, :, 0])


def test_compare_study_rows_and_comparison() -> None:
    settings = replace(SMALL, levels=(0.05, 0.4), plants=3)
    done = []
    rows, comparison = mc.compare_study(settings, OPTIONS, progress=lambda d, t: done.append(t))
    assert [r.algorithm for r in rows] == ["smoother+adaptive"] * 2
    assert [c.uncertainty for c in comparison] == [0.05, 0.4]
    assert done and done[-1] == 2 * settings.iterations
    for c in comparison:
        paper = mc.error_norms(settings, c.uncertainty, "smoother")
        assert c.paper_mean_2_5 == pytest.approx(paper[:, :, 2:6].mean())
        assert c.change_pct == pytest.approx(100 * (c.new_mean_2_5 / c.paper_mean_2_5 - 1))
        assert 0 <= c.refreshed_pct <= 100 and c.seconds >= 0
        assert c.plants == 3


def test_refusals() -> None:
    with pytest.raises(ValueError, match="noise"):
        mc.adaptive_error_norms(SMALL, 0.3, "smoother", AdaptiveSettings())
    with pytest.raises(ValueError, match="repeat"):
        mc.adaptive_error_norms(
            SMALL, 0.3, "smoother", replace(OPTIONS, robustness_cutoff_rad_s="auto")
        )
