"""gcs report: the verdict in plain words, the JSON without a second change column, the
safeguard's best trial, and the adaptive table at 80 columns."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from cli_runner import invoke as gcs_invoke
from synthetic import fly_synthetic, make_adaptive_run, make_run

from gcs.app.report import run_learning, run_metrics, run_verdict
from gcs.app.report_html import write_html
from gcs.core.model import lifted_matrix
from gcs.core.trials import trial_errors

SCHEMA = Path(__file__).resolve().parents[1] / "docs" / "report.schema.json"


def invoke(*args: object, columns: int = 200):
    return gcs_invoke([str(a) for a in args], env={"COLUMNS": str(columns)})


@pytest.fixture(scope="module")
def adaptive(tmp_path_factory: pytest.TempPathFactory):
    # the profile's default: trials 1 and 2 repeat trial 0, trials 3, 4 and 5 are learned
    return make_adaptive_run(tmp_path_factory.mktemp("adaptive"), trials=6, gust_m=0.01)


@pytest.fixture(scope="module")
def paper(tmp_path_factory: pytest.TempPathFactory):
    return make_run(tmp_path_factory.mktemp("paper"), trials=3)


def test_the_verdict_of_an_adaptive_run_against_its_trials(adaptive, monkeypatch) -> None:
    import gcs.cli

    monkeypatch.setattr(gcs.cli.console, "width", 200)
    epos = {j: trial_errors(adaptive.read_trial(j))[0] for j in adaptive.complete_trials()}
    best = min(epos, key=epos.get)
    doc = json.loads(invoke("report", adaptive.path, "--json").output)
    v = doc["verdict"]
    assert v["flights"] == len(epos) == 6
    assert v["best_trial"] == best and v["best_epos_m"] == pytest.approx(epos[best])
    assert v["best_updates"] == max(0, best - 2)  # two repeats of trial 0 before learning
    assert v["change_pct"] == pytest.approx(100 * (epos[best] - epos[0]) / epos[0])
    floor = adaptive.read_floor()["epos_m"]
    assert v["floor_m"] == pytest.approx(floor)
    assert v["floor_ratio"] == pytest.approx(epos[best] / floor)
    # the flights left, independently: the geometric decay of e_pos - floor over the newest
    # four learned trials (0, 3, 4, 5: trial 0 counts, its repeats do not; j = 0..3), flights
    # until z <= 2, plus one to confirm
    learning = run_learning(adaptive)
    row = {r["trial"]: r for r in doc["rows"]}
    if v["converged_trial"] is None and not row[5]["at_floor"]:
        x = np.array([0, 1, 2, 3], dtype=float)
        excess = np.array([epos[t] - floor for t in (0, 3, 4, 5)])
        rate = math.exp(np.polyfit(x, np.log(excess), 1)[0])
        f = learning.floor
        target = 2.0 * math.hypot(f.scatter_m, f.floor_scatter_m)
        n = max(0, math.ceil(math.log(target / excess[-1]) / math.log(rate)))
        assert v["flights_left"] == n + 1
        assert "geometric fit" in v["flights_left_how"]
    out = invoke("report", adaptive.path).output
    for line in v["text"]:
        assert line.replace("\n", " ")[:60] in out.replace("\n", " ")
    assert f"-> {1e3 * epos[best]:.1f} mm at trial {best}" in out
    assert "scatters of one trial above it" in out  # z said in words
    html = write_html(adaptive, adaptive.path.parent / "r.html", [0, 5]).read_text()
    assert 'class="verdict"' in html and f"{1e3 * epos[best]:.1f} mm at trial {best}" in html


def test_a_run_without_a_floor_says_the_flights_left_cannot_be_estimated(paper) -> None:
    doc = json.loads(invoke("report", paper.path, "--json").output)
    v = doc["verdict"]
    assert v["floor_m"] is None and v["flights_left"] is None
    assert "without a floor" in v["flights_left_how"]
    assert any("floor not measured" in line for line in v["text"])
    # one change column: the signed one (Table IV's unsigned twin is gone, version 3)
    assert doc["version"] >= 3
    assert all("delta_pct" not in r for r in doc["rows"])
    e = [r["epos_m"] for r in doc["rows"]]
    assert doc["rows"][1]["change_pct"] == pytest.approx(100 * (e[1] - e[0]) / e[0])


def test_the_verdict_keys_are_in_the_schema_and_the_docs() -> None:
    schema = json.loads(SCHEMA.read_text())
    text = (SCHEMA.parent / "report.md").read_text()
    keys = schema["properties"]["verdict"]["properties"]
    for key in keys:
        assert f"`{key}`" in text, key
    assert "delta_pct" not in schema["properties"]["rows"]["items"]["properties"]


def test_the_safeguard_records_the_best_trial_so_far(adaptive) -> None:
    # learn-003 learned from trial 3, which was 4x better than every trial before it: the
    # best so far is trial 3 (it used to say 0, the best of the trials before the newest)
    epos = {j: trial_errors(adaptive.read_trial(j))[0] for j in adaptive.complete_trials()}
    for j in range(3, 6):
        guard = adaptive.read_learn_record(j)["decision"]["safeguard"]
        so_far = {t: epos[t] for t in range(j + 1)}
        earlier = {t: epos[t] for t in range(j)}
        assert guard["best_trial"] == min(so_far, key=so_far.get)
        assert guard["compared_trial"] == min(earlier, key=earlier.get)
    assert epos[3] < 0.5 * min(epos[0], epos[1], epos[2])
    assert adaptive.read_learn_record(3)["decision"]["safeguard"]["best_trial"] == 3


def test_the_adaptive_table_fits_80_columns_and_explains_its_words(adaptive, monkeypatch) -> None:
    import gcs.cli

    # the console's width is fixed when it is made: set as a terminal of 80 columns would
    monkeypatch.setattr(gcs.cli.console, "width", 80)
    out = invoke("report", adaptive.path, columns=80).output
    table = out.split("learning step:")[0]
    assert max(len(line.rstrip()) for line in out.splitlines()) <= 80
    # every trial on one line: "0 (repeat)" unbroken, no cell folded onto a second line
    lines = [ln for ln in table.splitlines() if ln.strip()[:1].isdigit()]
    assert len(lines) == 6 and "0 (repeat)" in lines[1] and "0 (repeat)" in lines[2]
    # the learning step column did not fit: said where its contents are
    assert "after trial 3: model refreshed" in out and "too wide for this terminal" in out
    monkeypatch.setattr(gcs.cli.console, "width", 200)
    wide = invoke("report", adaptive.path, columns=200).output
    assert "repeat of 0 next" in wide and "'model N 37 %' refreshed the north (N)" in wide


def test_the_first_learned_step_is_bounded_by_the_step_limit(adaptive) -> None:
    # docs/update.md: the first setpoint's step is inherent to eq. (8) and bounded by
    # learning.max_step_m from the hover point, u(-1) = the start
    limit = adaptive.profile().learning.max_step_m
    start = adaptive.reference().pos_ned_m[0, :2]
    for j in range(3, 6):  # the learned trials
        sp = adaptive.read_setpoints(j)[:, :2]
        steps = np.abs(np.diff(np.vstack([start, sp]), axis=0))
        assert steps.max() <= limit + 1e-6


def test_rows_and_verdict_agree_on_the_numbers(paper) -> None:
    rows = run_metrics(paper)
    v = run_verdict(rows, run_learning(paper))
    assert v.first_epos_m == rows[0].epos_m and v.last_trial == rows[-1].iteration


def test_a_run_that_drifts_up_from_the_floor_says_so_with_its_best_trial(adaptive) -> None:
    from dataclasses import replace

    from gcs.core.floor import FloorVerdict

    learning = run_learning(adaptive)
    rows = run_metrics(adaptive)
    # the same run with trials 2 and 3 at the floor (3 the lower) and 4 and 5 above it
    at = {2: (True, 0.020), 3: (True, 0.018), 4: (False, 0.05), 5: (False, 0.06)}
    trials = dict(learning.trials)
    for t, (at_floor, e) in at.items():
        trials[t] = replace(
            trials[t],
            verdict=FloorVerdict(t, e, e / 0.02, 0.0 if at_floor else 3.0, at_floor, False),
        )
    v = run_verdict(rows, replace(learning, trials=trials))
    assert (v.drift_trials, v.drift_reached_trial, v.drift_best_trial) == ([4, 5], 2, 3)
    text = "\n".join(v.lines())
    assert "drifting up: trial 2 reached the floor, trials 4 and 5 are above it again" in text
    assert "the best setpoints at the floor are trial 3's; gcs fly --resume <run> --again 3" in text
    assert v.as_dict()["drift_trials"] == [4, 5]


def _prediction_by_hand(run, t: int, models) -> tuple[float, float]:
    """What the step before trial t predicted, from the run's files: ``F u + d_hat`` with the
    lifted matrix (not the report's difference equation), e_pos and the miss [m]."""
    ref = run.reference().pos_ned_m
    start, n = ref[0, :2], run.n_samples
    rec = run.read_trial(t)
    d_hat = run.read_estimate(t - 1)[0]
    u = rec.sp_ned_m[:-1, :2] - start
    y_hat = np.column_stack([lifted_matrix(models[a], n) @ u[:, a] + d_hat[:, a] for a in (0, 1)])
    y = rec.pos_ned_m[1:, :2] - start
    yd = ref[1:, :2] - start
    return float(np.hypot(*(yd - y_hat).T).mean()), float(np.hypot(*(y - y_hat).T).mean())


def test_each_learned_trial_against_the_prediction_of_the_step_before_it(adaptive) -> None:
    doc = json.loads(invoke("report", adaptive.path, "--json").output)
    rows = {r["trial"]: r for r in doc["rows"]}
    floor = adaptive.read_floor()["epos_m"]
    models = adaptive.profile().models()
    for t in (0, 1, 2):  # trial 0 and its repeats: no step planned them
        assert rows[t]["predicted_epos_m"] is None and rows[t]["prediction_miss_m"] is None
    for t in (3, 4, 5):
        record = json.loads(adaptive.learn_path(t - 1).read_text())
        if record["model_file"] is not None:  # the step refreshed the model it planned with
            models = adaptive.read_model(t - 1)
        predicted, miss = _prediction_by_hand(adaptive, t, models)
        assert rows[t]["predicted_epos_m"] == pytest.approx(predicted, rel=1e-8)
        assert rows[t]["prediction_miss_m"] == pytest.approx(miss, rel=1e-8)
        assert rows[t]["prediction_miss_ratio"] == pytest.approx(miss / floor, rel=1e-8)
        axes = record["decision"]["axes"]
        active = sum(a["update"]["active_constraints"] for a in axes)
        assert rows[t]["limits_active"] == active
        noise = np.mean([math.sqrt(1 + sum(w * w for w in a["noise"]["weights"])) for a in axes])
        assert rows[t]["prediction_noise_ratio"] == pytest.approx(noise, rel=1e-8)
    v = doc["verdict"]
    assert v["prediction_trial"] == 5
    assert v["prediction"]["miss_m"] == pytest.approx(rows[5]["prediction_miss_m"])
    said = f"the step before trial 5 predicted it at {1e3 * rows[5]['predicted_epos_m']:.1f} mm"
    assert any(line.startswith(f"verdict: {said}") for line in v["text"])
    assert any(f"{rows[5]['prediction_miss_ratio']:.2f}x the floor" in line for line in v["text"])
    assert any(f"alone give about {rows[5]['prediction_noise_ratio']:.2f}x" in x for x in v["text"])


def test_the_paper_profile_predicts_each_trial_from_the_newest_alone(paper) -> None:
    doc = json.loads(invoke("report", paper.path, "--json").output)
    rows = {r["iteration"]: r for r in doc["rows"]}
    models = paper.profile().models()
    assert rows[0]["predicted_epos_m"] is None
    for t in (1, 2):
        predicted, miss = _prediction_by_hand(paper, t, models)
        assert rows[t]["predicted_epos_m"] == pytest.approx(predicted, rel=1e-8)
        assert rows[t]["prediction_miss_m"] == pytest.approx(miss, rel=1e-8)
        assert rows[t]["limits_active"] is None  # the paper's profile records no decisions
        assert "prediction_miss_ratio" not in rows[t]  # no floor
    line = next(x for x in doc["verdict"]["text"] if "predicted it at" in x)
    assert "the floor" not in line


def test_a_trial_flying_another_ones_setpoints_again_has_no_prediction(tmp_path: Path) -> None:
    run = make_adaptive_run(tmp_path, trials=4, gust_m=0.01)
    run.fly_again(4, 3)
    fly_synthetic(run, 4, seed=7, gust_m=0.01)
    learning = run_learning(run)
    assert learning.trials[3].prediction is not None
    assert learning.trials[4].prediction is None
