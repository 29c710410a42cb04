"""Tests of the public learner (gcs.core.learner, gcs.api): state, reuse, axes, refusals."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from synthetic import SHORT, profile, true_plants

from gcs import AdaptiveSettings, Learner, LearnerSettings, learner_settings
from gcs.core.learner import Trial
from gcs.core.model import simulate
from gcs.core.trajectory import Box, sample_eight
from gcs.core.update import InputUpdate, SetpointLimits, UpdateWeights, next_input
from gcs.errors import PathError
from gcs.io.config import trajectory_from_dict

PROFILE = profile()
REF = sample_eight(trajectory_from_dict(SHORT).shape, PROFILE.t_ilc_s)
REF2 = REF.pos_ned_m[:, :2]
N = REF2.shape[0] - 1


def fly(u: np.ndarray, seed: int, ref: np.ndarray = REF2) -> np.ndarray:
    """y(1..N) of the synthetic vehicle (tests/synthetic.py's loops), gusts and noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(1, u.shape[0] + 1) * PROFILE.t_ilc_s
    plants = true_plants() * (u.shape[1] // 2 + 1)
    y = np.empty_like(u)
    for a in range(u.shape[1]):
        y[:, a] = ref[0, a] + simulate(plants[a], u[:, a] - ref[0, a]) + 0.05 * np.sin(0.7 * t)
    return y + 0.01 * rng.standard_normal(u.shape)


@pytest.mark.parametrize("algorithm", ["smoother", "kilc"])
def test_a_kept_learner_equals_a_new_one_per_trial_bit_for_bit(algorithm: str) -> None:
    """Reusing the structure changes nothing: the same setpoints as building it every trial."""
    settings = learner_settings(PROFILE, algorithm)
    kept = Learner(settings, REF2)
    u = REF2[:-1].copy()
    for j in range(4):
        y = fly(u, j)
        fresh = Learner(settings, REF2, kilc_states=kept.kilc_states)
        u_fresh = fresh.step(u, y)
        u = kept.step(u, y)
        np.testing.assert_array_equal(u, u_fresh)
    assert len(kept.history) == 4 and kept.iteration == 4
    assert kept.last.record is None and kept.decisions is None and kept.floor is None
    assert (kept.kilc_states is None) == (algorithm == "smoother")


def test_any_number_of_axes_each_learnt_on_its_own() -> None:
    """Three axes learn as three one-axis learners, bit for bit (the axes are independent)."""
    model_n, model_e = PROFILE.models()
    ref3 = REF.pos_ned_m
    arena = PROFILE.arena
    three = Learner(LearnerSettings(models=(model_n, model_e, model_n), arena=arena,
                                    max_step_m=0.5, axes=(0, 1, 2)), ref3)  # fmt: skip
    singles = [
        Learner(LearnerSettings(models=(m,), arena=arena, max_step_m=0.5, axes=(a,)), ref3[:, [a]])
        for a, m in enumerate((model_n, model_e, model_n))
    ]
    u = ref3[:-1].copy()
    for j in range(3):
        y = fly(u, j, ref3)
        u_next = three.step(u, y)
        for a, single in enumerate(singles):
            np.testing.assert_array_equal(u_next[:, [a]], single.step(u[:, [a]], y[:, [a]]))
        assert np.all(u_next[:, 2] <= arena.down_m[1] + 1e-9)
        u = u_next
    assert len(three.last.updates) == 3 and three.last.d_hat_m.shape == (N, 3)


def test_the_step_is_bounded_by_the_arena_given_for_each_axis() -> None:
    model = PROFILE.models()[0]
    ref = np.zeros((N + 1, 1))
    ref[1:, 0] = -0.5 * np.sin(np.linspace(0, np.pi, N))  # down: 0.5 m up and back
    arena = Box((-3.0, 3.0), (-3.0, 3.0), (-0.4, 0.0))  # but no higher than 0.4 m
    learner = Learner(LearnerSettings(models=(model,), arena=arena, axes=(2,)), ref)
    u = learner.step(ref[:-1], ref[1:] + 0.1)
    assert np.min(u) >= -0.4 - 1e-7 and learner.last.methods == ("clarabel",)
    assert learner.last.active_constraints > 0


def test_with_history_repeats_then_learns_and_resumes_exactly() -> None:
    adaptive = AdaptiveSettings(noise="data", refresh=True, safeguard=True)
    settings = learner_settings(PROFILE, "smoother")
    learner = Learner(settings, REF2, adaptive, repeats=1)
    u0 = REF2[:-1].copy()
    assert learner.iteration == 0
    u = learner.step(u0, fly(u0, 0))
    np.testing.assert_array_equal(u, u0)  # the repeat
    assert learner.last.repeat_of == 0 and learner.last.methods == ("-", "-")
    assert learner.iteration == 0 and learner.decisions is None
    refreshed = False
    for j in range(1, 5):
        before = learner.models
        y = fly(u, j)
        # a new learner given what this one has seen learns the same, bit for bit
        resumed = Learner(settings, REF2, adaptive, repeats=1, models=learner.models,
                          history=learner.history)  # fmt: skip
        u_next = learner.step(u, y)
        np.testing.assert_array_equal(resumed.step(u, y), u_next)
        refreshed |= any(a is not b for a, b in zip(before, learner.models, strict=True))
        u = u_next
    assert refreshed  # the models of tests/synthetic.py are off by 10-20 %: a refresh happened
    rec = learner.decisions
    assert rec.trials == 5 and rec.floor is learner.floor and learner.floor.flights == 2
    assert learner.iteration == 4 and len(learner.history) == 5


def test_input_update_equals_next_input() -> None:
    """A kept update starts from the last trial's active set; a fresh one asks Clarabel: the
    same minimiser (the same active set, the same KKT system: equal to rounding)."""
    model = PROFILE.models()[0]
    yd = REF2[1:, 0] - REF2[0, 0]
    limits = SetpointLimits(-0.4, 0.4, 0.05, 0.3)
    update = InputUpdate(model, yd, UpdateWeights(), limits)
    rng = np.random.default_rng(3)
    methods = []
    for _ in range(3):
        d_hat, u_prev = 0.1 * rng.standard_normal(N), yd + 0.05 * rng.standard_normal(N)
        a = update.solve(d_hat, u_prev)
        b = next_input(model, yd, d_hat, u_prev, UpdateWeights(), limits)
        methods.append(a.method)
        assert b.method == "clarabel" and a.active_constraints == b.active_constraints > 0
        np.testing.assert_allclose(a.u_m, b.u_m, rtol=0, atol=1e-12)
        assert a.objective == pytest.approx(b.objective, rel=1e-12)
    assert methods == ["clarabel", "active-set", "active-set"]


def test_from_profile_by_name_path_or_profile() -> None:
    paper = Learner.from_profile("antx", REF)
    assert paper.adaptive is None and paper.repeats == 0 and paper.n_axes == 2
    expected = learner_settings(PROFILE)
    assert paper.settings.weights == expected.weights and paper.settings.arena == PROFILE.arena
    assert paper.settings.smoother == expected.smoother and paper.settings.algorithm == "smoother"
    for mine, theirs in zip(paper.models, PROFILE.models(), strict=True):
        np.testing.assert_array_equal(mine.A, theirs.A)
    adaptive = Learner.from_profile("antx-adaptive", REF2, "kilc")
    assert adaptive.adaptive is not None and adaptive.repeats == 2  # the profile's default
    assert adaptive.settings.algorithm == "kilc"
    with pytest.raises(PathError, match="no packaged profile"):
        Learner.from_profile("no-such-profile", REF2)


def test_refusals_name_the_cause_and_keep_nothing() -> None:
    settings = learner_settings(PROFILE)
    learner = Learner(settings, REF2)
    with pytest.raises(ValueError, match=r"u_m must have shape"):
        learner.step(REF2[:-2], REF2[1:])
    with pytest.raises(ValueError, match="y_m contains NaN"):
        learner.step(REF2[:-1], np.full((N, 2), np.nan))
    assert learner.history == () and learner.last is None
    with pytest.raises(ValueError, match="reference_m must have shape"):
        Learner(settings, REF.pos_ned_m)
    with pytest.raises(ValueError, match="one model per axis"):
        LearnerSettings(models=PROFILE.models(), axes=(0,))
    with pytest.raises(ValueError, match="algorithm"):
        LearnerSettings(models=PROFILE.models(), algorithm="ilc")
    with pytest.raises(ValueError, match="north and east"):
        Learner(dataclasses.replace(settings, axes=(1, 2)), REF2, AdaptiveSettings())
    with pytest.raises(ValueError, match="safeguard .* needs settings.arena"):
        Learner(dataclasses.replace(settings, arena=None), REF2, AdaptiveSettings(safeguard=True))
    Learner(dataclasses.replace(settings, arena=None), REF2, AdaptiveSettings(refresh=True))
    with pytest.raises(ValueError, match="repeats"):
        Learner(settings, REF2, AdaptiveSettings(), repeats=-1)
    trials = [Trial(REF2[:-1], REF2[1:]), Trial(REF2[:-1], REF2[2:])]
    with pytest.raises(ValueError, match="y_m must have shape"):
        Learner(settings, REF2, history=trials)


def test_import_gcs_stays_light() -> None:
    """``import gcs`` (the CLI, the mock's process) loads no numerics until a name is used."""
    code = (
        "import sys, gcs\n"
        "print([m for m in ('gcs.api', 'scipy', 'clarabel') if m in sys.modules])\n"
        "gcs.Learner\n"
        "print('gcs.api' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["[]", "True"]
