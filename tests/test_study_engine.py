"""One engine for every study: the batched learning equals a Learner per plant."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml

from gcs.app.study_chunks import build_plan
from gcs.core.learner import FOLD_MIN_PLANTS, Learner, LearnerBatch
from gcs.core.metrics import epos
from gcs.core.study import PLANT_NOISE, StudyPlan, draw_plant, fly_plants, plant_stream
from gcs.io.study import load_study

STUDY = {
    "name": "engine",
    "profile": "antx",
    "trajectory": "eight-short",
    "seed": 5,
    "plants": 4,
    "iterations": 3,
    "chunk_plants": 4,
    "steady_trials": 1,
    "uncertainty": {"levels": [0.4], "noise_std_m": 0.01, "disturbance_rms_m": 0.05},
    # one repeat: the batch against the learner is tested, not the floor (one flight fewer)
    "settings": [{"profile": "antx"}, {"profile": "antx-adaptive", "repeats": 1}],
}


def _plan(tmp_path_factory: pytest.TempPathFactory, plants: int) -> StudyPlan:
    path = Path(tmp_path_factory.mktemp("engine")) / "study.yaml"
    path.write_text(yaml.safe_dump({**STUDY, "plants": plants, "chunk_plants": plants}))
    return build_plan(load_study(path))


@pytest.fixture(scope="module")
def plan(tmp_path_factory: pytest.TempPathFactory) -> StudyPlan:
    return _plan(tmp_path_factory, 4)


@pytest.fixture(scope="module")
def plans(tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201
    """Plans by their number of plants, each built once."""
    built: dict[int, StudyPlan] = {}

    def get(plants: int) -> StudyPlan:
        if plants not in built:
            built[plants] = _plan(tmp_path_factory, plants)
        return built[plants]

    return get


def _setting(plan: StudyPlan, case: str):  # noqa: ANN202
    paper, adaptive = plan.settings
    if case == "antx":
        return paper
    if case == "antx-adaptive":
        return adaptive
    if case == "kilc":
        return dataclasses.replace(
            paper, settings=dataclasses.replace(paper.settings, algorithm="kilc")
        )
    if case == "adaptive-robustness":  # every plant's update solved alone, with its weight
        options = dataclasses.replace(adaptive.adaptive, robustness_cutoff_rad_s=3.0)
        return dataclasses.replace(adaptive, adaptive=options)
    # active limits: a deviation bound that the optimum of some plants and updates breaks
    setting = adaptive if case == "adaptive-limits" else paper
    limited = dataclasses.replace(setting.settings, max_deviation_m=0.12, max_step_m=0.05)
    return dataclasses.replace(setting, settings=limited)


def _by_hand(plan: StudyPlan, setting, plant: int) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """Today's Learner on one plant, one step per trial: e_pos per flight, last setpoints."""
    true = draw_plant(plan, 0, plant)
    noise = plant_stream(plan.seed, 0, plant, PLANT_NOISE)
    ref, n = plan.ref_ne_m, plan.n_samples
    learner = Learner(setting.settings, ref, setting.adaptive, setting.repeats)
    flights = 1 + learner.repeats + plan.iterations
    u, e = ref[:-1].copy(), []
    for f in range(flights):
        y = true.respond(u - ref[0]) + ref[0]
        y += np.asarray(true.noise_std_m) * noise.standard_normal((n, 2))
        e.append(epos(ref[1:], y))
        if f < flights - 1:
            u = learner.step(u, y)
    return np.array(e), u


# 4 plants: one banded solve of the KKT system per trial; FOLD_MIN_PLANTS: the paper's step
# folded into dense matrices (the adaptive options batch without folding at any size)
@pytest.mark.parametrize(
    ("case", "plants"),
    [("antx", 4), ("antx-adaptive", 4), ("kilc", 4), ("active-limits", 4),
     ("adaptive-limits", 4), ("adaptive-robustness", 4),
     ("antx", FOLD_MIN_PLANTS), ("kilc", FOLD_MIN_PLANTS), ("active-limits", FOLD_MIN_PLANTS)],
)  # fmt: skip
def test_the_batch_equals_a_learner_per_plant(plans, case: str, plants: int) -> None:  # noqa: ANN001
    plan = plans(plants)
    setting = _setting(plan, case)
    plants = range(plan.plants)
    batch = fly_plants(plan, setting, 0, plants)
    each = fly_plants(plan, setting, 0, plants, batched=False)
    for b, r in zip(batch, each, strict=True):
        assert b.failed is None and r.failed is None
        np.testing.assert_allclose(b.epos_m, r.epos_m, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.setpoints_m, r.setpoints_m, rtol=0, atol=1e-9)
        assert b.limit_active == r.limit_active
    for p in (0, plan.plants - 1):  # the engine's loop is the plain loop of a Learner
        e, u = _by_hand(plan, setting, p)
        np.testing.assert_allclose(batch[p].epos_m, e, rtol=0, atol=1e-9)
        np.testing.assert_allclose(batch[p].setpoints_m, u, rtol=0, atol=1e-9)
    assert batch[0].epos_m[-1] < batch[0].epos_m[0]  # it learned
    shares = [b.limit_active for b in batch]
    if case == "antx":  # some updates took the QP, others the batched direct solve
        assert max(shares) > 0 and min(shares) < 1
    if case in ("active-limits", "adaptive-limits"):  # a limit held in every update
        assert min(shares) == 1


def _fly_batch(plan: StudyPlan, setting, batched: bool) -> tuple[LearnerBatch, np.ndarray, list]:  # noqa: ANN001
    """The plants of ``plan`` learning through one LearnerBatch: the batch, the setpoints of
    every flight (F, P, N, 2) and the safeguard's action per update and plant (reference
    only)."""
    count, ref, n = plan.plants, plan.ref_ne_m, plan.n_samples
    true = [draw_plant(plan, 0, p) for p in range(count)]
    noise = [plant_stream(plan.seed, 0, p, PLANT_NOISE) for p in range(count)]
    batch = LearnerBatch(setting.settings, ref, count, setting.adaptive, setting.repeats,
                         batched=batched)  # fmt: skip
    u, flown, actions = ref[None, :-1].repeat(count, axis=0), [], []
    for f in range(batch.repeats + plan.iterations):
        flown.append(u)
        y = np.array([t.respond(u[p] - ref[0]) + ref[0] for p, t in enumerate(true)])
        y += np.array([np.asarray(t.noise_std_m) * noise[p].standard_normal((n, 2))
                       for p, t in enumerate(true)])  # fmt: skip
        u = batch.step(u, y)
        if not batched and f >= batch.repeats:
            actions.append([learner.last.record.safeguard.action for learner in batch._each])
    return batch, np.array([*flown, u]), actions


def test_the_adaptive_batch_refreshes_some_plants_and_reverts_one_alone(plan: StudyPlan) -> None:
    adaptive = plan.settings[1]
    # a stricter signal-to-noise gate: two plants refresh their east model, two keep it (with
    # consecutive pairs: a pair against trial 0's flights carries more of the change, and all
    # four pass it)
    strict = dataclasses.replace(adaptive.adaptive, refresh_min_snr=300.0, refresh_anchor=False)
    for setting in (adaptive, dataclasses.replace(adaptive, adaptive=strict)):
        batch, flown, _ = _fly_batch(plan, setting, batched=True)
        each, flown_each, actions = _fly_batch(plan, setting, batched=False)
        assert batch._each is None and each._each is not None  # the batched path, not a loop
        np.testing.assert_allclose(flown, flown_each, rtol=0, atol=1e-9)
        assert batch.failed == each.failed == [None] * plan.plants
        nominal = setting.settings.models
        replaced = [[m is not n for m, n in zip(ms, nominal, strict=True)] for ms in batch.models]
        assert replaced == [[m is not n for m, n in zip(ms, nominal, strict=True)]
                            for ms in each.models]  # fmt: skip
        if setting is adaptive:  # the safeguard took one plant back to its best trial
            assert sum(a.count("revert") for a in actions) >= 1
        else:
            assert [r[1] for r in replaced] == [True, True, False, False]


@pytest.mark.parametrize(
    "change", [{"refresh_max_move": 0.05}, {"refresh_min_gain_z": 3.0}], ids=lambda c: next(iter(c))
)
def test_the_refresh_refusals_hold_alike_batched_and_per_plant(
    plan: StudyPlan, change: dict
) -> None:
    """``refresh_max_move``: the plants whose learning converged keep models the limit
    refuses; ``refresh_min_gain_z``: the plants keep the models whose held-out gain falls
    short of it (each gain judged); in the batch as in a learner per plant."""
    adaptive = plan.settings[1]
    nominal = adaptive.settings.models

    def replaced(batch: LearnerBatch) -> int:
        return sum(m is not n for ms in batch.models for m, n in zip(ms, nominal, strict=True))

    free, _, _ = _fly_batch(plan, adaptive, batched=True)
    strict = dataclasses.replace(
        adaptive, adaptive=dataclasses.replace(adaptive.adaptive, **change)
    )
    batch, flown, _ = _fly_batch(plan, strict, batched=True)
    each, flown_each, _ = _fly_batch(plan, strict, batched=False)
    np.testing.assert_allclose(flown, flown_each, rtol=0, atol=1e-9)
    assert batch.failed == each.failed == [None] * plan.plants
    assert replaced(batch) == replaced(each)
    if "refresh_max_move" in change:
        assert replaced(batch) < replaced(free)
    else:
        axes = [ax for learner in each._each for ax in learner.last.record.axes]
        assert np.isfinite([ax.refresh.gain_z for ax in axes if ax.refresh]).any()
        assert replaced(batch) <= replaced(free)


def test_a_plant_whose_trial_is_refused_stops_alone(plan: StudyPlan) -> None:
    paper = plan.settings[0]
    ref = plan.ref_ne_m
    u = np.repeat(ref[None, :-1], 3, axis=0)
    y = u + 0.01
    y[1, 7, 0] = np.inf  # a plant that blew up
    with pytest.raises(ValueError, match="NaN or inf") as why:
        Learner(paper.settings, ref).step(u[1], y[1])
    for batched in (True, False):
        batch = LearnerBatch(paper.settings, ref, 3, batched=batched)
        out = batch.step(u, y)
        assert batch.failed == [None, str(why.value), None]
        assert np.isnan(out[1]).all() and np.isfinite(out[[0, 2]]).all()
        alone = Learner(paper.settings, ref).step(u[2], y[2])
        np.testing.assert_allclose(out[2], alone, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="plants"):
        LearnerBatch(paper.settings, ref, 0)
    with pytest.raises(ValueError, match="shape"):
        LearnerBatch(paper.settings, ref, 2).step(u, y)


def _decided(learner, option: str) -> list[float]:  # noqa: ANN001
    """What ``option`` decided for each axis of a learner's newest step."""
    axes = learner.last.record.axes
    if option == "refresh_takeback":
        return [ax.refresh.takeback_z for ax in axes]
    if option == "refresh_holdout":
        return [ax.refresh.holdout_z for ax in axes]
    if option in ("refresh_pool_repeats", "refresh_anchor"):
        return [ax.refresh.snr if ax.refresh else float("nan") for ax in axes]
    return [ax.minmax_step for ax in axes]


@pytest.mark.parametrize(
    "option",
    [
        "refresh_takeback",
        "refresh_minmax_step",
        "refresh_holdout",
        "refresh_pool_repeats",
        "refresh_anchor",
    ],
)
def test_the_refresh_options_hold_alike_batched_and_per_plant(plan: StudyPlan, option: str) -> None:
    """``refresh_takeback``: the same plants go back to the nominal model, at the same step;
    ``refresh_minmax_step``: the same fractions of the same updates; ``refresh_holdout``: the
    same candidates adopted or not; ``refresh_pool_repeats``, ``refresh_anchor``: the same
    pooled pairs; in the
    batch as in a learner per plant. Each option acts on some plant: refreshed models judged,
    steps cut, pairs weighed."""
    adaptive = plan.settings[1]
    on = dataclasses.replace(
        adaptive, adaptive=dataclasses.replace(adaptive.adaptive, **{option: True})
    )
    batch, flown, _ = _fly_batch(plan, on, batched=True)
    each, flown_each, _ = _fly_batch(plan, on, batched=False)
    np.testing.assert_allclose(flown, flown_each, rtol=0, atol=1e-9)
    assert batch.failed == each.failed == [None] * plan.plants
    decided = [x for learner in each._each for x in _decided(learner, option)]
    if option in ("refresh_takeback", "refresh_holdout", "refresh_pool_repeats", "refresh_anchor"):
        assert np.isfinite(decided).any()  # refreshed models were judged, pairs weighed
    else:
        assert all(0.0 <= f <= 1.0 for f in decided) and min(decided) < 0.9
