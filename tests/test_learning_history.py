"""Tests of learning from the whole history of trials (gcs.Learner with adaptive settings)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from synthetic import SHORT, profile, true_plants

from gcs.api import Learner, learner_settings
from gcs.core.learner import Trial
from gcs.core.learning import AdaptiveSettings, converged_with_model
from gcs.core.metrics import epos
from gcs.core.model import simulate
from gcs.core.trajectory import points_outside, sample_eight
from gcs.io.config import trajectory_from_dict

PROFILE = profile()
REF = sample_eight(trajectory_from_dict(SHORT).shape, PROFILE.t_ilc_s).pos_ned_m
REF2 = REF[:, :2]
DATA = AdaptiveSettings(noise="data", refresh=True, safeguard=True)


def fly(sp_ne: np.ndarray, seed: int, noise_m: float = 0.01, perfect: bool = False) -> np.ndarray:
    """Positions y(0..N) of the synthetic vehicle (tests/synthetic.py) for setpoints u(0..N-1).

    Repeatable disturbance plus a non-repeatable part correlated in time (smoothed white
    noise, like gusts) and white measurement noise. ``perfect``: the profile's own models.
    """
    rng = np.random.default_rng(seed)
    start = REF2[0]
    n = sp_ne.shape[0]
    t = np.arange(1, n + 1) * PROFILE.t_ilc_s
    pos = np.tile(start, (n + 1, 1))
    plants = PROFILE.models() if perfect else true_plants()
    for a, plant in enumerate(plants):
        gust = np.convolve(rng.standard_normal(n), np.ones(15) / 15, mode="same") * noise_m * 3
        pos[1:, a] += simulate(plant, sp_ne[:, a] - start[a]) + 0.05 * np.sin(0.7 * t + a) ** 2
        pos[1:, a] += gust + 0.002 * rng.standard_normal(n)
    return pos


def campaign(
    adaptive: AdaptiveSettings,
    trials: int,
    algorithm: str = "smoother",
    seed_offset: int = 0,
    **kw,
):
    """Fly trial 0 twice (the repeat), then learn from every trial; return e_pos, steps."""
    learner = Learner(learner_settings(PROFILE, algorithm), REF2, adaptive, repeats=1)
    sp = REF2[:-1].copy()
    hist_sp, hist_pos, plans = [], [], []
    for f in range(trials + 1):
        pos = fly(sp, seed_offset + f, **kw)
        hist_sp.append(sp)
        hist_pos.append(pos)
        if f < trials:
            sp = learner.step(sp, pos[1:])
            assert (learner.last.repeat_of is None) == (f > 0)
            if f > 0:
                plans.append(learner.last)
    e = [epos(REF2[1:], p[1:]) for p in hist_pos]
    return np.array(e), plans, np.array(hist_sp), np.array(hist_pos)


@settings(max_examples=8, deadline=None)
@given(
    algorithm=st.sampled_from(["smoother", "kilc"]),
    trials=st.integers(1, 4),
    seed=st.integers(0, 1000),
)
def test_paper_settings_are_learning_step_bit_for_bit(algorithm: str, trials: int, seed: int):
    """With AdaptiveSettings() learning from the whole history is Algorithm 1 (or K-ILC)."""
    settings_ = learner_settings(PROFILE, algorithm)
    paper = Learner(settings_, REF2)
    history = Learner(settings_, REF2, AdaptiveSettings())
    sp = REF2[:-1].copy()
    for j in range(trials):
        pos = fly(sp, seed + j)
        sp_paper = paper.step(sp, pos[1:])
        np.testing.assert_array_equal(history.step(sp, pos[1:]), sp_paper)
        step, plan = paper.last, history.last
        assert step.record is None and plan.record is not None
        np.testing.assert_array_equal(plan.d_hat_m, step.d_hat_m)
        np.testing.assert_array_equal(plan.p_m2, step.p_m2)
        if algorithm == "kilc":
            for a in range(2):
                np.testing.assert_array_equal(plan.kilc_states[a].d_hat, step.kilc_states[a].d_hat)
                assert plan.kilc_states[a].p == step.kilc_states[a].p
        sp = sp_paper
    assert AdaptiveSettings().is_paper and not DATA.is_paper


def test_the_new_options_learn_and_record_every_decision() -> None:
    e, plans, sp, pos = campaign(DATA, 6)
    assert e[2] < 0.3 * e[0] and e[-1] < 0.1 * e[0]  # e[1] is the repeat of trial 0
    rec = plans[-1].record
    assert rec.trials == 6 and len(rec.epos_m) == 6
    assert rec.floor is not None and rec.floor.flights == 2  # trial 0 and its repeat
    assert [v.trial for v in rec.verdicts] == list(range(6))
    assert rec.safeguard is not None and rec.safeguard.action in ("continue", "revert")
    for axis in rec.axes:
        assert axis.noise.method == "data" and len(axis.noise.weights) == 6
        assert sum(axis.noise.weights) == pytest.approx(1.0)
        assert axis.refresh is not None and axis.update.status == "solved"
    # the first refresh sees trials 0, 0', 1: the model of tests/synthetic.py is off by 10-20 %
    first = plans[1].record.axes
    assert any(a.refresh.accepted and a.refresh.moved > 0.05 for a in first)
    assert (
        plans[1].models[0] is not plans[0].models[0] or plans[1].models[1] is not plans[0].models[1]
    )
    text = json.dumps(rec.as_dict())  # JSON-ready, for the run directory and the live table
    assert '"safeguard"' in text and '"refresh"' in text
    for plan in plans:
        full = np.column_stack([plan.setpoints_m, REF[:-1, 2]])
        assert points_outside(full, PROFILE.arena, tol_m=1e-6).size == 0


def test_averaging_beats_the_newest_residual_at_steady_state() -> None:
    """A perfect model and a repeatable disturbance: what is left is non-repeatable.

    Table I puts the newest trial's residual into the next input, so a learned trial carries
    two flights' non-repeatable errors (sqrt 2 times the floor); the data-driven estimate
    averages the trials and comes near one flight's. Floor: E|v| over 200 flights.
    """
    n = REF2.shape[0] - 1
    flights = np.array([fly(REF2[:-1], 1000 + i, 0.02, True)[1:] for i in range(200)])
    v = flights - flights.mean(axis=0)
    floor = np.mean(np.hypot(v[..., 0], v[..., 1]))
    late_new, late_paper = [], []
    for seed in range(3):
        kw = {"noise_m": 0.02, "perfect": True}
        e_new, *_ = campaign(AdaptiveSettings(noise="data"), 10, seed_offset=100 * seed, **kw)
        e_paper, *_ = campaign(AdaptiveSettings(), 10, seed_offset=100 * seed, **kw)
        late_new.append(e_new[6:])
        late_paper.append(e_paper[6:])
    assert n > 0
    assert np.mean(late_paper) > 1.25 * floor
    assert np.mean(late_new) < 1.2 * floor
    assert np.mean(late_new) < 0.9 * np.mean(late_paper)


def test_the_safeguard_reverts_after_a_bad_trial() -> None:
    e, plans, sp, pos = campaign(DATA, 4)
    bad_pos = pos.copy()
    bad_pos[-1, 1:] += 0.3  # the newest trial came out 0.3 m off
    trials = [Trial(u, y[1:]) for u, y in zip(sp, bad_pos, strict=True)]
    learner = Learner(learner_settings(PROFILE, "smoother"), REF2, DATA, history=trials[:-1])
    learner.step(trials[-1].u_m, trials[-1].y_m)
    plan = learner.last
    sg = plan.record.safeguard
    assert sg.action == "revert" and sg.anchor_trial == int(np.argmin(plan.record.epos_m[:-1]))
    assert sg.step == DATA.safeguard_step


def test_kilc_with_data_noise_uses_the_iteration_filter_alone() -> None:
    e, plans, *_ = campaign(AdaptiveSettings(noise="data"), 4, algorithm="kilc")
    assert e[-1] < 0.15 * e[0]
    assert plans[-1].kilc_states is None
    assert plans[-1].record.axes[0].noise.method == "data"


def test_robustness_weight_is_recorded_and_keeps_setpoints_smoother() -> None:
    strong = replace(DATA, robustness_cutoff_rad_s=1.0)
    _, plans, sp, _ = campaign(strong, 3)
    _, plans_free, sp_free, _ = campaign(DATA, 3)
    rob = plans[-1].record.axes[0].robustness
    assert rob["cutoff_rad_s"] == 1.0 and rob["lam"] > 0 and rob["order"] == 2
    rough = [np.sum(np.diff(s - REF2[:-1], 2, axis=0) ** 2) for s in (sp[-1], sp_free[-1])]
    assert rough[0] < rough[1]


def test_history_refusals() -> None:
    learner = Learner(learner_settings(PROFILE, "smoother"), REF2, DATA)
    sp = REF2[:-1]
    y = fly(REF2[:-1], 0)[1:]
    with pytest.raises(ValueError):
        learner.step(sp.T, y)
    with pytest.raises(ValueError):
        learner.step(sp, y[:-1])
    bad = y.copy()
    bad[4, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        learner.step(sp, bad)
    assert learner.history == ()  # nothing refused was kept
    with pytest.raises(ValueError, match="north and east"):
        Learner(replace(learner.settings, axes=(0, 2)), REF2, DATA)
    with pytest.raises(ValueError):
        AdaptiveSettings(noise="kalman")
    with pytest.raises(ValueError):
        AdaptiveSettings(robustness_cutoff_rad_s=-1.0)


def test_refresh_noise_measured_is_white_for_white_repeats() -> None:
    """Only white measurement noise: the noise model of the repeats is white (order 0) and the
    refresh, hence the learning, is the white one bit for bit."""
    white = campaign(DATA, 3, noise_m=0.0)
    measured = campaign(replace(DATA, refresh_noise="measured"), 3, noise_m=0.0)
    np.testing.assert_array_equal(measured[2], white[2])
    for a, b in zip(measured[1], white[1], strict=True):
        for ax_m, ax_w in zip(a.record.axes, b.record.axes, strict=True):
            assert ax_m.refresh.accepted == ax_w.refresh.accepted
            np.testing.assert_array_equal(ax_m.refresh.snr, ax_w.refresh.snr)  # NaN: no pair
    assert any(ax.refresh.pairs > 0 for p in measured[1] for ax in p.record.axes)


def test_refresh_noise_measured_whitens_with_the_repeats_of_trial_0() -> None:
    """A gust correlated over 0.75 s: the first refresh (trials 0, 0', 1) is the refresh of
    the pair 0' -> 1 whitened by the noise model of the difference of trial 0 and its repeat,
    axis by axis; the white refresh of the same flights is another decision."""
    from gcs.core.refresh import fit_ar_noise, refresh_model

    adaptive = replace(DATA, refresh_noise="measured")
    _, plans, sp, pos = campaign(adaptive, 3)
    _, plans_white, _, _ = campaign(DATA, 3)
    settings_ = learner_settings(PROFILE, "smoother")
    w = settings_.weights
    start = REF2[0]
    for a in range(2):
        y = pos[:3, 1:, a] - start[a]
        u = sp[:3, :, a] - start[a]
        noise = fit_ar_noise(((y[0] - y[1]) / np.sqrt(2.0))[None], 20)
        assert noise.order > 0
        got = plans[1].record.axes[a].refresh  # plans[0]: after the repeat
        expected = refresh_model(
            settings_.models[a], (u[2] - u[1])[None], (y[2] - y[1])[None], 1.0,
            adaptive.refresh_settings(), w.wdu / w.we, noise,
        )  # fmt: skip
        # the same data up to rounding (positions relative to the start point): the iterative
        # fit agrees to its stopping tolerance
        assert got.accepted == expected.accepted
        assert got.moved == pytest.approx(expected.moved, rel=1e-6)
        assert got.snr == pytest.approx(expected.snr, rel=1e-9)
        assert got.snr != pytest.approx(plans_white[1].record.axes[a].refresh.snr, rel=1e-3)


def test_learning_has_converged_with_its_model_once_the_newest_trial_beats_trial_0() -> None:
    """Where ``refresh_max_move`` applies: the newest trial better than trial 0."""
    assert converged_with_model(np.array([0.9, 0.88, 0.3]))
    assert not converged_with_model(np.array([0.9, 0.3, 0.95]))  # the newest worse: diverging
    assert not converged_with_model(np.array([0.9, 0.9]))  # a repeat of trial 0
    assert not converged_with_model(np.array([0.9]))  # nothing flown with the model yet
