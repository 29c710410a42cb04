"""Studies of the user's set-up: plants, chunks, summaries and the study file."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from synthetic import ROOT

from gcs.app.study_chunks import build_plan, check_study_memory
from gcs.core.model import from_transfer_function, markov_parameters, simulate
from gcs.core.study import (
    StudyPlan,
    Uncertainty,
    check_nominal,
    draw_plant,
    noise_floor,
    recommend,
    run_chunk,
    summarise_setting,
)
from gcs.errors import StudyError
from gcs.io.study import load_study

TINY = {
    "name": "tiny",
    "profile": "antx",
    "trajectory": "eight-short",
    "seed": 3,
    "plants": 4,
    "iterations": 2,
    "chunk_plants": 2,
    "steady_trials": 1,
    "uncertainty": {"levels": [0.0, 0.3], "noise_std_m": 0.01, "disturbance_rms_m": 0.05},
    "grid": {"wdu": [0.01, 0.1]},
}


def write_study(tmp_path: Path, **changes: object) -> Path:
    data = {**TINY, **changes}
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def plan_of(tmp_path: Path, **changes: object):  # noqa: ANN201
    return build_plan(load_study(write_study(tmp_path, **changes)))


def test_a_plant_at_zero_spread_is_the_model(tmp_path: Path) -> None:
    plan = plan_of(tmp_path, uncertainty={"levels": [0.0]})
    true = draw_plant(plan, 0, 0)
    u = np.random.default_rng(1).standard_normal((plan.n_samples, 2))
    want = np.column_stack([simulate(m, u[:, a]) for a, m in enumerate(plan.models)])
    np.testing.assert_allclose(true.respond(u), want, atol=1e-12)


def test_markov_plants_at_zero_spread_are_the_model(tmp_path: Path) -> None:
    plan = plan_of(tmp_path, uncertainty={"levels": [0.0], "parameters": "markov"})
    true = draw_plant(plan, 0, 0)
    u = np.random.default_rng(2).standard_normal((plan.n_samples, 2))
    want = simulate(plan.models[0], u[:, 0])
    np.testing.assert_allclose(true.respond(u)[:, 0], want, atol=1e-12)


def test_a_second_order_plant_moves_as_the_paper_draws_it() -> None:
    # wn, zeta and the static gain of wn^2 / (s^2 + 2 zeta wn s + wn^2) scaled by the draws the
    # plant reports: the drawn plant is that transfer function, independently discretised,
    # but for the sampling zero, which the draw keeps where the model has it (it moves by
    # 0.02 % of the response here)
    dt, wn, zeta, n = 0.01, 1.8, 0.8, 200
    model = from_transfer_function([wn * wn], [1.0, 2 * zeta * wn, wn * wn], 0.0, dt)
    plan = StudyPlan(np.zeros((n + 1, 2)), (model, model), Uncertainty(levels=(0.1,)), (),
                     plants=50, iterations=1, seed=8, chunk_plants=1)  # fmt: skip
    true = draw_plant(plan, 0, 0)
    impulse = np.zeros((n, 2))
    impulse[0] = 1.0
    response = true.respond(impulse)
    for axis, name in enumerate(("north", "east")):
        d = true.draws[name]
        assert min(abs(d["wn"]), abs(d["zeta"]), abs(d["gain"])) > 0.03  # all three moved
        assert d["extra_delay_s"] == 0.0 and true.delay_samples[axis] == 0
        wn2, zeta2, gain2 = wn * (1 + d["wn"]), zeta * (1 + d["zeta"]), 1 + d["gain"]
        ref = from_transfer_function(
            [gain2 * wn2 * wn2], [1.0, 2 * zeta2 * wn2, wn2 * wn2], 0.0, dt
        )
        np.testing.assert_allclose(response[:, axis], markov_parameters(ref, n), rtol=1e-3,
                                   atol=1e-12)  # fmt: skip
    # the draws are the level times a standard normal
    draws = [draw_plant(plan, 0, i).draws for i in range(plan.plants)]
    for key in ("wn", "zeta", "gain"):
        spread = np.std([d[axis][key] for d in draws for axis in ("north", "east")])
        assert 0.07 < spread < 0.13, key


def test_results_do_not_depend_on_the_chunk_size(tmp_path: Path) -> None:
    two = plan_of(tmp_path)
    one = dataclasses.replace(two, chunk_plants=1)
    pair = run_chunk(two, 1, 1, 1)["plants"]  # plants 2 and 3
    singles = [run_chunk(one, 1, 1, c)["plants"][0] for c in (2, 3)]
    assert pair == singles
    assert pair[0]["epos_m"][-1] < pair[0]["epos_m"][0]  # the learning learned


def test_every_setting_sees_the_same_plants_and_noise(tmp_path: Path) -> None:
    plan = plan_of(tmp_path)
    a, b = run_chunk(plan, 0, 1, 0)["plants"], run_chunk(plan, 1, 1, 0)["plants"]
    assert [p["draws"] for p in a] == [p["draws"] for p in b]
    assert [p["epos_m"][0] for p in a] == [p["epos_m"][0] for p in b]  # trial 0 alike


def test_an_unstable_nominal_plant_is_refused(tmp_path: Path) -> None:
    study = write_study(tmp_path, uncertainty={"levels": [0.2], "bias": {"zeta": -1.5}})
    with pytest.raises(StudyError, match="uncertainty.*unstable"):
        build_plan(load_study(study))
    model = from_transfer_function([4.0], [1.0, 0.4, 4.0], 0.0, 0.05)
    check_nominal(model, Uncertainty(bias=(0.0, -0.5, 0.0)))  # damping halved: still stable


def test_summary_counts_divergence_and_the_floor(tmp_path: Path) -> None:
    plan = plan_of(tmp_path)
    floor = noise_floor(plan.uncertainty.noise_std_m)
    assert floor == pytest.approx(0.01 * np.sqrt(np.pi / 2))
    plants = [
        {"epos_m": [0.5, 0.1, floor], "setpoint_rms_m": 0.1, "limit_active": 0.5, "failed": None},
        {"epos_m": [0.5, 0.7, 0.9], "setpoint_rms_m": 0.3, "limit_active": 0.0, "failed": None},
        {"epos_m": [0.5, 0.2, None], "setpoint_rms_m": 0.2, "limit_active": 1.0, "failed": "x"},
    ]
    s = summarise_setting(plan, 0, 0, plants)
    assert s.diverged == 2 and s.plants == 3
    assert s.steady_mean_m == pytest.approx(floor)
    assert s.reached_floor == 1 and s.never_reached_floor == 2
    assert s.flights_to_floor == 3  # of the one plant that got there; never is no count
    assert s.limit_active == pytest.approx(0.5)
    best, reason = recommend([s, dataclasses.replace(s, setting="other", diverged=0)])
    assert best == "other" and "0 diverged" in reason


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"grid": {"wdux": [1]}}, "grid.wdux"),
        ({"grid": {"wdu": []}}, "grid.wdu"),
        ({"settings": []}, "settings"),
        ({"settings": [{"wdu": 0.1, "colour": 1}]}, "settings[0].colour"),
        ({"settings": [{"we": 0.0}]}, "we"),
        ({"plants": 0}, "plants"),
        ({"uncertainty": {"levels": [2.0]}}, "uncertainty.levels"),
        ({"uncertainty": {"noise_std_m": "floor"}}, "uncertainty.noise_std_m"),
        ({"uncertainty": {"parameters": "poles"}}, "uncertainty.parameters"),
        ({"trajectory": "nine"}, "trajectory"),
        ({"steady_trials": 5}, "steady_trials"),
    ],
)
def test_the_study_file_is_checked_field_by_field(
    tmp_path: Path, changes: dict, field: str
) -> None:
    with pytest.raises(StudyError) as info:
        build_plan(load_study(write_study(tmp_path, **changes)))
    message = str(info.value)
    assert message.startswith(str(tmp_path / "study.yaml")) and field in message
    assert "\n" not in message


def test_the_floor_comes_from_a_run(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "floor.json").write_text('{"axis_rms_m": [0.02, 0.03], "trials": [0, 1]}')
    plan = plan_of(tmp_path, uncertainty={"levels": [0.1], "noise_std_m": "floor", "run": "run"})
    assert plan.uncertainty.noise_std_m == (0.02, 0.03)
    assert plan.uncertainty.floor_source.endswith("floor.json")


def test_a_plant_beyond_memory_is_refused(tmp_path: Path) -> None:
    plan = plan_of(tmp_path)
    with pytest.raises(StudyError, match="GB"):
        check_study_memory(plan, memory_bytes=1e5)


def test_the_documented_example_parses() -> None:
    study = load_study(ROOT / "docs" / "studies" / "antx-wdu.yaml")
    assert len(study.settings) == 6 and study.uncertainty["levels"] == (0.2, 0.4)


@pytest.mark.parametrize("value", [True, False])
def test_a_setting_turns_the_takeback_on_or_off(tmp_path: Path, value: bool) -> None:
    settings = [{"profile": "antx-adaptive", "refresh_takeback": value}]
    study = load_study(write_study(tmp_path, settings=settings, grid=None))
    assert study.settings[0].profile.learning.adaptive.refresh_takeback is value
