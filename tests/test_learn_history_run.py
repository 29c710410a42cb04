"""Learning with history on a run directory (gcs.app.learn with profiles/antx-adaptive.yaml).

Synthetic trials (tests/synthetic.py) stand in for flights: what is tested is what the run
directory holds after each learning step, and that learning from it equals learning in memory.
The repeats and the floor are tested with the profile's default (``repeats: 2``: trials 1 and 2
repeat trial 0); the records, models, resuming and the live table with one repeat
(``repeats=1``: trial 2 the first learned one), their trial plan whatever the default.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from synthetic import (
    ROOT,
    SHORT,
    adaptive_profile,
    fly_synthetic,
    make_adaptive_run,
    make_run,
    synthetic_positions,
)

from gcs.api import Learner, learner_settings
from gcs.app.fly import (
    FlyRequest,
    RunSource,
    check_until_converged,
    converged_reason,
    drift_reason,
    plan_fly,
    record_drift,
    start_run,
)
from gcs.app.learn import learn_run, models_in_use
from gcs.app.session import flyable_setpoints
from gcs.core.learner import Trial
from gcs.errors import ProfileError, RunLogError, TrajectoryError
from gcs.flight.trial import TrialRecording
from gcs.io.config import load_profile, profile_from_dict, trajectory_from_dict
from gcs.io.rundir import RunDir


def files(path: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(path.iterdir()) if p.is_file()}


def history(run: RunDir, j: int) -> list[Trial]:
    """Setpoints u(0..N-1) and positions y(1..N), north and east, of trials 0..j as recorded."""
    records = [run.read_trial(t) for t in range(j + 1)]
    return [Trial(r.sp_ned_m[:-1, :2], r.pos_ned_m[1:, :2]) for r in records]


def test_trial_0_is_repeated_byte_for_byte_then_every_trial_is_learned_from(tmp_path):
    run = RunDir.create(
        tmp_path, adaptive_profile(), trajectory_from_dict(SHORT), "smoother", run_id="run"
    )
    assert run.profile().learning.repeats == 2  # the profile's default: trials 1 and 2
    sp0 = (run.path / "setpoints-000.csv").read_bytes()
    for j in (0, 1):
        fly_synthetic(run, j)
        outcome = learn_run(run)
        assert outcome.repeat_of == 0 and outcome.next_trial == j + 1
        assert outcome.next_iteration == 0 and outcome.record is None
        assert (run.path / f"setpoints-00{j + 1}.csv").read_bytes() == sp0
        assert sorted(p.name for p in run.path.glob(f"*-00{j}.*")) == [
            f"setpoints-00{j}.csv", f"trial-00{j}.csv", f"trial-00{j}.json"
        ]  # fmt: skip  # no estimate, no record: nothing was learned
    fly_synthetic(run, 2)
    outcome = learn_run(run)
    assert outcome.repeat_of is None and outcome.next_iteration == 1
    record = outcome.record
    assert record == json.loads((run.path / "learn-002.json").read_text())
    assert record["learned_from"] == [0, 1, 2] and record["next_trial"] == 3
    assert record["models_from"] == "profile" and record["model_file"] is None
    assert (run.path / "estimate-002.csv").exists() and (run.path / "setpoints-003.csv").exists()
    assert not (run.path / "estimate-001.csv").exists()
    # the record's decisions are those of a learner given the three trials
    profile = adaptive_profile()
    trials = history(run, 2)
    learner = Learner(
        learner_settings(profile, "smoother"), run.reference().pos_ned_m[:, :2],
        profile.learning.adaptive, repeats=2, history=trials[:2],
    )  # fmt: skip
    u3 = learner.step(trials[2].u_m, trials[2].y_m)
    plan = learner.last
    np.testing.assert_allclose(run.read_setpoints(3)[:, :2], u3, atol=1e-8)
    assert record["decision"]["epos_m"] == list(plan.record.epos_m)
    assert [v["at_floor"] for v in record["decision"]["verdicts"]] == [False] * 3


def test_the_floor_is_measured_from_the_repeats_and_kept_in_the_run(tmp_path):
    run = make_adaptive_run(tmp_path, trials=3, gust_m=0.01)  # the default: two repeats
    floor = json.loads((run.path / "floor.json").read_text())
    assert floor["trials"] == [0, 1, 2] and floor["source"] == "repeat" and floor["flights"] == 3
    # independently: one flight's non-repeatable error is sqrt(3 / 2) (Y_i - mean Y)
    y = np.stack([run.read_trial(t).pos_ned_m[1:, :2] for t in (0, 1, 2)])
    delta = np.sqrt(1.5) * (y - y.mean(axis=0))
    dist = np.hypot(delta[..., 0], delta[..., 1])  # (3, N)
    assert floor["epos_m"] == pytest.approx(np.mean(dist))
    assert floor["rms_m"] == pytest.approx(np.sqrt(np.mean(dist**2)))
    # three flights: the scatter between them is measured too, and the larger one is used
    assert floor["scatter_between_m"] is not None and floor["scatter_within_m"] is not None
    # the e_pos of the three deviations share their mean: their spread is sqrt(1 - 1/4) times
    # that of independent flights (gcs.core.floor)
    spread = np.std(dist.mean(axis=1), ddof=1)
    assert floor["scatter_between_m"] == pytest.approx(spread / np.sqrt(0.75))
    assert floor["scatter_m"] == max(floor["scatter_within_m"], floor["scatter_between_m"])
    assert run.read_learn_record(2)["decision"]["floor"]["epos_m"] == floor["epos_m"]
    assert not (run.path / "learn-001.json").exists()  # the first repeat measures nothing yet
    assert run.read_floor() == floor


def test_a_refreshed_model_is_a_profile_to_fly_and_the_next_step_starts_from_it(tmp_path):
    run = make_adaptive_run(tmp_path, trials=4, repeats=1)  # trials 0, 1 (repeat), 2, 3
    record = run.read_learn_record(2)
    assert record["model_file"] == "model-002.yaml"  # the first pair of different setpoints
    moved = [ax["refresh"]["moved"] for ax in record["decision"]["axes"]]
    assert max(moved) > 0.05
    profile = load_profile(run.path / "model-002.yaml")  # a profile a user can fly as it is
    assert profile.learning == adaptive_profile(repeats=1).learning and profile.arena is not None
    for a, model in enumerate(profile.models()):
        recorded = record["decision"]["axes"][a]["refresh"]["model"]
        np.testing.assert_array_equal(model.A, np.array(recorded["A"]))
        assert model.delay_samples == recorded["delay_samples"]
    assert run.read_learn_record(3)["models_from"] == "model-002.yaml"
    newest = run.read_learn_record(3)["model_file"] or "model-002.yaml"
    models, source = models_in_use(run, adaptive_profile(repeats=1), 4)
    assert source == newest
    np.testing.assert_array_equal(models[1].B, load_profile(run.path / newest).models()[1].B)


def test_learning_from_the_directory_equals_learning_in_memory(tmp_path):
    """Resuming reads the models back from the run: the same setpoints as one long session."""
    run = make_adaptive_run(tmp_path, trials=6, repeats=1)
    learner = Learner.from_profile(adaptive_profile(repeats=1), run.reference())
    trials = history(run, 5)
    assert learner.step(trials[0].u_m, trials[0].y_m) is not None  # the repeat
    assert learner.last.repeat_of == 0
    for j in range(1, 6):  # one learner, its models carried in memory, never written
        u_next = learner.step(trials[j].u_m, trials[j].y_m)
        written = run.read_setpoints(j + 1)[:, :2]
        np.testing.assert_allclose(written, u_next, rtol=0, atol=1e-8)
        d_hat, _ = run.read_estimate(j)
        np.testing.assert_allclose(d_hat, learner.last.d_hat_m, rtol=1e-8, atol=1e-12)
    assert len(learner.history) == 6 and learner.floor is not None
    assert any(run.read_learn_record(j)["model_file"] for j in range(1, 6))


def test_learning_is_idempotent_and_an_interrupted_step_completes_with_the_same_bytes(tmp_path):
    run = make_adaptive_run(tmp_path, trials=3)
    before = files(run.path)
    assert learn_run(run).next_trial == 3
    assert files(run.path) == before
    # interrupted after the model and the estimate: neither the record nor the setpoints
    (run.path / "learn-002.json").unlink()
    (run.path / "setpoints-003.csv").unlink()
    with pytest.raises(RunLogError, match="no setpoints for trial 3"):
        plan_fly(FlyRequest(resume=run.path))
    learn_run(run)
    assert files(run.path) == before


def test_the_paper_profile_learns_as_before_and_writes_no_record(tmp_path):
    run = make_run(tmp_path, trials=2)
    learn_run(run)
    assert not list(run.path.glob("learn-*")) + list(run.path.glob("model-*"))
    assert not (run.path / "floor.json").exists()
    record = run.read_trial(1)
    learner = Learner(learner_settings(run.profile(), "smoother"), run.reference().pos_ned_m[:, :2])
    u_next = learner.step(record.sp_ned_m[:-1, :2], record.pos_ned_m[1:, :2])
    text = (run.path / "setpoints-002.csv").read_text().splitlines()[1:]
    expected = np.column_stack([u_next, run.reference().pos_ned_m[:-1, 2]])
    assert [f"{v:.9g}" for v in expected[7]] == text[7].split(",")[2:]


def test_learning_with_history_needs_every_trial(tmp_path):
    run = make_adaptive_run(tmp_path, trials=3)
    (run.path / "trial-001.json").unlink()
    (run.path / "setpoints-003.csv").unlink()
    before = files(run.path)
    with pytest.raises(RunLogError, match="trial 1 is not complete"):
        learn_run(run)
    assert files(run.path) == before


def damage_record_trial(run: Path) -> None:
    data = json.loads((run / "learn-002.json").read_text())
    data["trial"] = 1
    (run / "learn-002.json").write_text(json.dumps(data))


def damage_model(run: Path) -> None:
    data = yaml.safe_load((run / "model-002.yaml").read_text())
    data["model"]["A"][0][0] *= 1.001
    (run / "model-002.yaml").write_text(yaml.safe_dump(data))


def damage_model_file_field(run: Path) -> None:
    data = json.loads((run / "learn-002.json").read_text())
    data["model_file"] = None
    (run / "learn-002.json").write_text(json.dumps(data))


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (damage_record_trial, "field 'trial' must be 2, as the file's name says"),
        (lambda r: (r / "learn-002.json").write_text("{"), "malformed learning record"),
        (lambda r: (r / "learn-002.json").unlink(), "learn-002.json: missing"),
        (damage_model, "model-002.yaml: its north model is not the one learn-002.json records"),
        (lambda r: (r / "model-002.yaml").unlink(), "model-002.yaml: missing"),
        (damage_model_file_field, "must name the refreshed model exactly when"),
    ],
)
def test_records_and_models_must_agree_with_their_names(tmp_path, damage, message):
    run = make_adaptive_run(tmp_path, trials=4, repeats=1)
    assert run.read_learn_record(2)["model_file"] == "model-002.yaml"
    (run.path / "setpoints-004.csv").unlink()  # learning from trial 3 starts from model-002
    damage(run.path)
    before = files(run.path)
    with pytest.raises(RunLogError, match=message):
        learn_run(run)
    with pytest.raises(RunLogError, match=message):  # nor are the setpoints it made flown
        flyable_setpoints(run, 3)
    assert files(run.path) == before


def test_a_changed_floor_record_is_never_rewritten(tmp_path):
    run = make_adaptive_run(tmp_path, trials=3)
    (run.path / "setpoints-003.csv").unlink()
    data = json.loads((run.path / "floor.json").read_text())
    data["epos_m"] *= 0.5
    (run.path / "floor.json").write_text(json.dumps(data))
    with pytest.raises(RunLogError, match="floor.json: exists with different content"):
        learn_run(run)
    assert not (run.path / "setpoints-003.csv").exists()


def test_a_repeat_whose_setpoints_differ_from_trial_0_is_not_flown(tmp_path):
    run = RunDir.create(
        tmp_path, adaptive_profile(), trajectory_from_dict(SHORT), "smoother", run_id="run"
    )
    fly_synthetic(run, 0)
    learn_run(run)
    flyable_setpoints(run, 1)
    lines = (run.path / "setpoints-001.csv").read_text().splitlines()
    cells = lines[5].split(",")
    cells[2] = str(float(cells[2]) + 1e-4)
    lines[5] = ",".join(cells)
    (run.path / "setpoints-001.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(TrajectoryError, match="repeats trial 0, but its setpoints differ"):
        flyable_setpoints(run, 1)


def recording(run: RunDir, sp: np.ndarray, seed: int, **kw) -> TrialRecording:
    """What the flight layer hands over for a synthetic flight of ``sp``."""
    ref = run.reference()
    pos = synthetic_positions(run, sp, seed, **kw)
    return TrialRecording(
        t_s=ref.t_s, pos_ned_m=pos, vel_ned_m_s=np.gradient(pos, run.t_ilc_s, axis=0),
        sent_s=ref.t_s[:-1], interpolated=np.zeros(run.n_samples + 1, dtype=bool),
        complete=True, abort_reason=None, setpoints_ned_m=sp, t_ilc_s=run.t_ilc_s,
    )  # fmt: skip


def test_until_converged_the_source_says_stop_exactly_when_the_record_says_converged(tmp_path):
    # the profile's own models as the vehicle and 1 cm of gusts: learning reaches the floor.
    # What is tested is the source's stop against the record, on one repeat's trial plan
    profile = adaptive_profile(repeats=1)
    run = RunDir.create(tmp_path, profile, trajectory_from_dict(SHORT), "smoother", run_id="run")
    outcomes = []
    source = RunSource(run, on_learn=outcomes.append, until_converged=True)
    answers = []
    for j in range(10):
        sp = source.setpoints_for(j)
        answer = source.record(j, recording(run, sp, 300 + j, plants=profile.models(), gust_m=0.01))
        answers.append(answer)
        if answer:
            break
    converged = [bool(o.record and o.record["decision"]["converged"]) for o in outcomes]
    assert converged[-1] and not any(converged[:-1])  # stopped at the first convergence
    assert all(a is None for a in answers[:-1])
    assert answers[-1] == converged_reason(outcomes[-1].record)
    assert answers[-1].startswith("learning has converged: trials")
    last = outcomes[-1].record["decision"]
    verdicts = last["verdicts"][-2:]
    assert all(v["at_floor"] for v in verdicts)
    mean = 0.5 * (verdicts[0]["epos_m"] + verdicts[1]["epos_m"])
    assert mean - last["floor"]["epos_m"] <= last["floor"]["scatter_m"]
    # without --until-converged the same source never asks to stop
    assert RunSource(run).until_converged is False


def test_until_converged_needs_a_profile_that_measures_the_floor(tmp_path):
    with pytest.raises(ProfileError, match="no learning.adaptive section"):
        check_until_converged(load_profile(ROOT / "profiles" / "antx.yaml"), "antx.yaml")
    data = yaml.safe_load((ROOT / "profiles" / "antx-adaptive.yaml").read_text())
    data["learning"]["adaptive"]["repeats"] = 0
    with pytest.raises(ProfileError, match="repeats to 0"):
        check_until_converged(profile_from_dict(data, "p.yaml"), "p.yaml")
    check_until_converged(adaptive_profile(), "antx-adaptive.yaml")


def test_k_ilc_learns_with_history_too(tmp_path):
    profile = adaptive_profile()
    run = RunDir.create(tmp_path, profile, trajectory_from_dict(SHORT), "kilc", run_id="run")
    for j in range(4):
        fly_synthetic(run, j)
        learn_run(run)
    rec = run.read_learn_record(3)
    assert rec["learned_from"] == [0, 1, 2, 3]
    weights = rec["decision"]["axes"][0]["noise"]["weights"]
    assert len(weights) == 4 and sum(weights) == pytest.approx(1.0)
    assert run.read_trial(3).pos_ned_m.shape[0] == run.n_samples + 1


def test_the_live_table_says_each_decision_as_it_happens(tmp_path):
    from gcs.app.fly_view import learning_lines
    from gcs.app.learn import LearnOutcome

    run = make_adaptive_run(tmp_path, trials=3, repeats=1)
    record = run.read_learn_record(2)
    axis = record["decision"]["axes"][0]
    axis["refresh"] = {**axis["refresh"], "accepted": True, "moved": 0.26}
    east = record["decision"]["axes"][1]
    back = "taken back: the profile's model predicted trial 2 better (z = 2.61 > 1.64)"
    east["refresh"] = {**axis["refresh"], "moved": 0.82, "reason": back, "takeback_z": 2.61}
    record["decision"]["safeguard"] = {
        "action": "revert", "anchor_trial": 1, "step": 0.5, "epos_m": 0.05, "best_trial": 1,
        "best_epos_m": 0.02, "threshold_m": 0.03, "reason": "",
    }  # fmt: skip
    verdict = record["decision"]["verdicts"][-1]
    verdict.update(ratio=1.04, z=0.3, at_floor=True, converged=True)
    outcome = LearnOutcome(2, 3, run.path / "setpoints-003.csv", ("direct",) * 2, 0, 2,
                           record=record)  # fmt: skip
    text = "\n".join(learning_lines(outcome))
    assert "trial 2: 1.04x the floor" in text and "converged" in text
    assert "fell back to trial 1 with step 0.5" in text
    assert f"model refreshed: north moved 26 %; east {back}" in text
    assert "trial 3 (j = 2): setpoints" in text
    assert "estimate" not in text  # the report has the weights; the live table what changed
    repeat = LearnOutcome(0, 1, run.path / "setpoints-001.csv", ("-", "-"), 0, 0, repeat_of=0)
    assert "trial 1 repeats trial 0" in learning_lines(repeat)[0]


def test_the_live_table_says_when_learning_drifts_up_from_the_floor(tmp_path):
    from gcs.app.fly_view import learning_lines
    from gcs.app.learn import LearnOutcome

    run = make_adaptive_run(tmp_path, trials=3)
    record = run.read_learn_record(2)
    verdicts = record["decision"]["verdicts"]
    assert [v["trial"] for v in verdicts] == [0, 1, 2]
    base = {**verdicts[-1], "repeat_of": None}  # learned trials, not repeats
    # trial 1 at the floor, then trials 2 and 3 above it: the newest two, after one at it
    record["decision"]["verdicts"] = [
        {**base, "trial": 0, "epos_m": 0.9, "z": 40.0, "at_floor": False},
        {**base, "trial": 1, "epos_m": 0.02, "z": 0.5, "at_floor": True},
        {**base, "trial": 2, "epos_m": 0.05, "z": 3.5, "at_floor": False},
        {**base, "trial": 3, "epos_m": 0.06, "z": 4.0, "at_floor": False},
    ]  # fmt: skip
    outcome = LearnOutcome(3, 4, run.path / "setpoints-004.csv", ("direct",) * 2, 0, 3,
                           record=record)  # fmt: skip
    text = "\n".join(learning_lines(outcome))
    assert "drifting up: trial 1 reached the floor, trials 2 and 3 are above it again" in text
    assert "the best setpoints at the floor are trial 1's" in text
    record["decision"]["verdicts"][-1]["at_floor"] = True  # back at the floor: no drift
    assert "drifting" not in "\n".join(learning_lines(outcome))


def test_again_is_refused_for_the_repeat_and_flies_as_the_trial_it_copies(tmp_path: Path) -> None:
    run = make_adaptive_run(tmp_path / "a", trials=2)  # next: trial 2, the second repeat
    with pytest.raises(RunLogError, match="trial 2, is a repeat of trial 0"):
        plan_fly(FlyRequest(resume=run.path, again=0))
    run = make_adaptive_run(tmp_path / "b", trials=4, repeats=1)  # next: trial 4, learned
    plan = plan_fly(FlyRequest(resume=run.path, again=2))
    assert (plan.first_trial, plan.again) == (4, 2)
    assert run.again_of(4) is None  # planning moves nothing
    start_run(plan)
    assert run.again_of(4) == 2
    assert np.array_equal(flyable_setpoints(run, 4), run.read_setpoints(2))


def test_drift_reason_names_the_trials_above_and_the_best_at_the_floor() -> None:
    def verdict(trial: int, epos_m: float, at_floor: bool) -> dict:
        z = 0.0 if at_floor else 5.0
        return dict(trial=trial, epos_m=epos_m, ratio=epos_m / 0.02, z=z, at_floor=at_floor,
                    converged=False)  # fmt: skip

    rows = [verdict(2, 0.05, False), verdict(3, 0.021, True), verdict(4, 0.019, True)]
    record = {"decision": {"verdicts": rows}}
    assert drift_reason(record) is None and record_drift(None) is None
    rows += [verdict(5, 0.04, False)]
    assert drift_reason(record) is None  # one trial above: the scatter
    rows += [verdict(6, 0.05, False)]
    assert drift_reason(record) == (
        "drifting up: trial 3 reached the floor, trials 5 and 6 are above it again; the best "
        "setpoints at the floor are trial 4's"
    )


def test_each_learning_step_says_how_far_its_trial_flew_from_the_prediction(tmp_path):
    """The live table's line from the learning step, against the report's prediction of the
    same trial (tests/test_report_verdict.py checks that one against the lifted form)."""
    from gcs.app.fly_view import learning_lines
    from gcs.app.report import run_learning

    run = make_adaptive_run(tmp_path, trials=4, repeats=1, gust_m=0.01)
    fly_synthetic(run, 4, gust_m=0.01)
    outcome = learn_run(run)
    expected = run_learning(run).trials[4].prediction
    assert expected is not None and outcome.prediction == expected
    text = "\n".join(learning_lines(outcome))
    said = f"trial 4: {1e3 * expected.miss_m:.1f} mm from what the step before it predicted"
    assert said in text
    assert f"(noise alone: about {expected.noise_ratio:.2f}x)" in text
