"""gcs identify --from-log on synthetic identification runs with a known closed loop."""

from __future__ import annotations

import copy
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import invoke as gcs_invoke
from synthetic import ROOT

from gcs.app.identify import create_identification_run, run_identify
from gcs.app.identify_fit import identify_run
from gcs.app.identify_plan import IdentifyRequest, plan_experiments
from gcs.core.model import frequency_response, from_transfer_function, markov_parameters, simulate
from gcs.core.pbsid import continuous_poles
from gcs.errors import ProfileError, TrajectoryError
from gcs.io.config import load_profile, profile_from_dict
from gcs.io.records import TrialRecord, TrialStatus
from gcs.io.rundir import RunDir
from gcs.io.settings import IdentifySettings

DT = 0.05
# Truth: a second-order-plus-delay closed loop (wn 1.6 rad/s, zeta 0.55, gain 1, 0.25 s),
# x and y different so that a mix-up of the axes shows.
WN, ZETA = {"x": 1.6, "y": 1.3}, {"x": 0.55, "y": 0.7}
TRUTH = {
    a: from_transfer_function([WN[a] ** 2], [1.0, 2 * ZETA[a] * WN[a], WN[a] ** 2], 0.25, DT)
    for a in ("x", "y")
}
NOISE_M = 0.003


def invoke(*args: object):
    return gcs_invoke([str(a) for a in args])


def antx_data(**identification) -> dict:
    data = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    data["identification"].update(identification)
    return data


def make_run(
    tmp: Path,
    axis: str = "both",
    duration_s: float = 60.0,
    seed: int = 0,
    mutate=None,
    statuses=(True, True),
    constant_x: bool = False,
) -> RunDir:
    """An identification run whose two trials were 'flown' by TRUTH with output noise."""
    data = antx_data()
    # TRUTH is second order: the automatic order rule, not antx.yaml's fixed multirotor order
    del data["identification"]["order"]
    profile = profile_from_dict(data, "antx")
    settings = IdentifySettings(duration_s=duration_s)  # unchecked: short runs are wanted
    exps = plan_experiments(replace(settings, duration_s=60.0), DT, axis, profile.arena)
    n = settings.n_samples(DT)
    exps = replace(exps, setpoints_ned_m=tuple(sp[:n].copy() for sp in exps.setpoints_ned_m))
    if constant_x:  # flown as recorded: the setpoints files say so too
        for sp in exps.setpoints_ned_m:
            sp[:, 0] = sp[0, 0]
    run = create_identification_run(tmp, profile, settings, exps, run_id="ident")
    rng = np.random.default_rng(seed)
    center = exps.center_ned_m
    for j, sp in enumerate(exps.setpoints_ned_m):
        n = sp.shape[0]
        rows = np.vstack([sp, sp[-1]])
        pos = np.tile(center, (n + 1, 1))
        for a, c in (("x", 0), ("y", 1)):
            pos[1:, c] += simulate(TRUTH[a], sp[:, c] - center[c])
            pos[:, c] += rng.normal(0.0, NOISE_M, n + 1)
        record = TrialRecord(
            t_s=np.arange(n + 1) * DT, ref_ned_m=rows, sp_ned_m=rows, pos_ned_m=pos,
            vel_ned_m_s=np.gradient(pos, DT, axis=0),
            sp_sent_s=np.append(np.arange(n) * DT, np.nan),
            interpolated=np.zeros(n + 1, dtype=bool),
        )  # fmt: skip
        if mutate is not None:
            record = mutate(j, record)
        status = TrialStatus(j, statuses[j], reason=None if statuses[j] else "link lost")
        run.write_trial(j, record, status)
    return run


def pole_error(model, truth) -> float:
    p, q = continuous_poles(model), continuous_poles(truth)
    return max(float(np.min(np.abs(p - t)) / abs(t)) for t in q)


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> RunDir:
    return make_run(tmp_path_factory.mktemp("ident"))


def test_from_log_recovers_the_closed_loop_and_writes_a_usable_profile(
    run: RunDir, tmp_path: Path
) -> None:
    out = tmp_path / "out" / "identified.yaml"
    plots = tmp_path / "plots"
    result = invoke("identify", "--from-log", run.path, "--out", out, "--plot", plots)
    assert result.exit_code == 0, result.output
    assert "VAF" in result.output and "x: G(s)" in result.output and "y: G(s)" in result.output
    assert (plots / "identify_validation.png").stat().st_size > 1000
    assert (plots / "identify_bode.png").stat().st_size > 1000
    text = out.read_text()
    assert text.startswith("# Written by 'gcs identify'")
    profile = load_profile(out)
    assert "gcs identify" in profile.source["description"] and str(run.path) in text
    base = run.profile()
    assert profile.learning == base.learning and profile.arena == base.arena
    assert profile.identification == base.identification
    for a, model in zip(("x", "y"), profile.models(), strict=True):
        assert model.delay_samples == 5
        assert pole_error(model, TRUTH[a]) < 0.02, (a, continuous_poles(model))
        f_id = markov_parameters(model, 80)
        f_true = markov_parameters(TRUTH[a], 80)
        assert np.max(np.abs(f_id - f_true)) < 0.05 * np.max(np.abs(f_true))
        assert np.sum(f_id) == pytest.approx(np.sum(f_true), rel=0.03)  # ~ static gain


def test_validation_vaf_and_table_figures(run: RunDir) -> None:
    profile = run.profile()
    settings = profile.identification
    results = identify_run(run, settings, profile)
    assert [r.axis for r in results] == ["x", "y"]
    for r in results:
        assert r.vaf_pct > 95.0 and r.fit_pct > 80.0
        assert r.wn_rad_s == pytest.approx(WN[r.axis], rel=0.02)
        assert r.zeta == pytest.approx(ZETA[r.axis], rel=0.03)
        # the true loops differ from eq. (11): the profile's model validates worse
        assert r.vaf_profile_pct < r.vaf_pct
        assert np.abs(r.y_sim_m - r.y_val_m).max() < 0.05
    f = np.array([0.05, 0.3, 1.0])
    h = frequency_response(results[0].model, 2 * np.pi * f)
    h_true = frequency_response(TRUTH["x"], 2 * np.pi * f)
    assert np.allclose(np.abs(h), np.abs(h_true), rtol=0.03)


def test_the_identified_profile_flies_learning(run: RunDir, tmp_path: Path) -> None:
    """``gcs fly --profile`` uses it as is: the learning step runs on a run made with it."""
    from synthetic import SHORT, fly_synthetic

    from gcs.app.learn import learn_run
    from gcs.io.config import trajectory_from_dict

    out = tmp_path / "id.yaml"
    assert invoke("identify", "--from-log", run.path, "--out", out).exit_code == 0
    learning = RunDir.create(
        tmp_path, load_profile(out), trajectory_from_dict(SHORT), "smoother", run_id="learn"
    )
    fly_synthetic(learning, 0)
    outcome = learn_run(learning)
    assert outcome.next_trial == 1 and outcome.setpoints_path.exists()


def test_single_axis_keeps_the_other_model(run: RunDir, tmp_path: Path) -> None:
    out = tmp_path / "x.yaml"
    result = invoke("identify", "--from-log", run.path, "--axis", "x", "--out", out)
    assert result.exit_code == 0, result.output
    profile = load_profile(out)
    base = load_profile(ROOT / "profiles" / "antx.yaml")
    assert pole_error(profile.model_x, TRUTH["x"]) < 0.02
    assert np.allclose(markov_parameters(profile.model_y, 40), markov_parameters(base.model_y, 40))


def test_default_output_is_in_the_run_directory(tmp_path: Path) -> None:
    r = make_run(tmp_path, axis="y", seed=3)
    result = invoke("identify", "--from-log", r.path)
    assert result.exit_code == 0, result.output
    profile = load_profile(r.path / "identified.yaml")
    assert pole_error(profile.model_y, TRUTH["y"]) < 0.02
    manifest = json.loads((r.path / "manifest.json").read_text())
    assert manifest["algorithm"] == "identify"
    assert manifest["trajectory"]["type"] == "excitation"
    assert manifest["trajectory"]["axes"] == ["y"]
    assert manifest["trajectory"]["seeds"] == {"fit": {"y": 2}, "validation": {"y": 4}}
    # the axis that was not excited cannot be identified
    result = invoke("identify", "--from-log", r.path, "--axis", "x", "--out", tmp_path / "x.yaml")
    assert result.exit_code == 2 and "axis x was not excited" in result.output
    assert not (tmp_path / "x.yaml").exists()


class Shown:
    """A display that keeps what the room asks it to show."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def __getattr__(self, name: str):
        return lambda *args: self.calls.append((name, *args))


def test_the_room_tells_its_display_each_step_and_writes_the_run_profile_once(
    tmp_path: Path,
) -> None:
    r = make_run(tmp_path, axis="x", seed=5)
    shown = Shown()
    assert run_identify(IdentifyRequest(from_log=r.path, check_only=True), shown) is None
    assert [c[0] for c in shown.calls] == ["checked"] and shown.calls[0][1].run.path == r.path
    assert not r.identified_path.exists()
    for new in (True, False):  # again: the same bytes, the run's record is not rewritten
        shown = Shown()
        assert run_identify(IdentifyRequest(from_log=r.path), shown) == r.identified_path
        assert [c[0] for c in shown.calls] == ["results", "wrote_profile"]
        assert [x.axis for x in shown.calls[0][1]] == ["x"]
        assert shown.calls[1][1:] == (r.identified_path, new)
    assert load_profile(r.identified_path).name.endswith("-identified")


# ---------------------------------------------------------------------------- refusals


def _nan(j: int, rec: TrialRecord) -> TrialRecord:
    if j == 0:
        rec.pos_ned_m[100, 0] = np.nan
    return rec


REFUSALS = [
    pytest.param({"mutate": _nan}, "NaN or inf at k = 100", id="nan"),
    pytest.param({"constant_x": True}, "input u is constant", id="constant-input"),
    pytest.param({"statuses": (True, False)}, "trial 1 is incomplete", id="incomplete"),
    pytest.param({"duration_s": 8.0}, "too little data", id="too-little-data"),
]


@pytest.mark.parametrize(("kwargs", "message"), REFUSALS)
def test_bad_logs_are_refused_and_nothing_is_written(
    tmp_path: Path, kwargs: dict, message: str
) -> None:
    r = make_run(tmp_path, **kwargs)
    out = tmp_path / "out.yaml"
    result = invoke("identify", "--from-log", r.path, "--out", out)
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert len(result.output.strip().splitlines()) == 1, result.output
    assert not out.exists()
    assert not (r.path / "identified.yaml").exists()


def test_truncated_trial_is_refused(tmp_path: Path) -> None:
    r = make_run(tmp_path)
    path = r.path / "trial-000.csv"
    path.write_text("".join(path.read_text().splitlines(keepends=True)[:-50]))
    result = invoke("identify", "--from-log", r.path, "--out", tmp_path / "o.yaml")
    assert result.exit_code == 2 and "truncated" in result.output
    assert not (tmp_path / "o.yaml").exists()


def test_a_learning_run_is_not_an_identification_run(tmp_path: Path) -> None:
    from synthetic import make_run as make_learning_run

    r = make_learning_run(tmp_path, trials=1)
    result = invoke("identify", "--from-log", r.path, "--out", tmp_path / "o.yaml")
    assert result.exit_code == 2 and "not an identification run" in result.output


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"amplitude_m": -0.1}, "identification.amplitude_m"),
        ({"excitation": "chirp"}, "identification.excitation"),
        ({"f_min_hz": 0.1}, "identification.f_min_hz"),
        ({"bandwidth_hz": 11.0}, "identification.bandwidth_hz"),
        ({"future": 30}, "identification.future"),
        ({"order": 10}, "identification.order"),
        ({"past": 2.5}, "identification.past"),
        ({"typo": 1}, "identification.typo"),
        ({"center_ned_m": [0, 0]}, "identification.center_ned_m"),
    ],
)
def test_profile_identification_section_is_validated(change: dict, field: str) -> None:
    with pytest.raises(ProfileError, match=f"p.yaml: field '{field}'"):
        profile_from_dict(antx_data(**change), "p.yaml")


def test_multisine_needs_its_band() -> None:
    data = antx_data()
    ident = {"excitation": "multisine", "f_min_hz": 0.02, "f_max_hz": 9.0}
    data["identification"] = {**{k: data["identification"][k] for k in ("past", "future")}, **ident}
    settings = profile_from_dict(data, "p").identification
    assert (settings.f_min_hz, settings.f_max_hz, settings.bandwidth_hz) == (0.02, 9.0, None)
    del data["identification"]["f_max_hz"]
    with pytest.raises(ProfileError, match="identification.f_max_hz' is missing"):
        profile_from_dict(data, "p")


def test_excitation_is_independent_per_axis_and_experiment() -> None:
    profile = profile_from_dict(antx_data(), "antx")
    settings = profile.identification
    exps = plan_experiments(settings, DT, "both", profile.arena)
    fit, val = exps.setpoints_ned_m
    assert fit.shape == (1200, 3)
    center = np.array(settings.center_ned_m)
    assert np.allclose(fit[:, 2], center[2]) and np.allclose(val[:, 2], center[2])
    signals = [fit[:, 0], fit[:, 1], val[:, 0], val[:, 1]]
    for s, c in zip(signals, [0, 1, 0, 1], strict=True):
        assert np.allclose(np.abs(s - center[c]), settings.amplitude_m)  # PRBS of +/- level
    for i in range(4):
        for k in range(i + 1, 4):
            assert abs(np.corrcoef(signals[i], signals[k])[0, 1]) < 0.2
    x_only = plan_experiments(settings, DT, "x", profile.arena)
    assert np.allclose(x_only.setpoints_ned_m[0][:, 1], center[1])
    assert np.allclose(x_only.setpoints_ned_m[0][:, 0], fit[:, 0])


def test_too_short_experiments_are_refused_before_flying() -> None:
    profile = profile_from_dict(antx_data(duration_s=5.0), "p.yaml")
    settings = profile.identification
    with pytest.raises(ProfileError, match="p.yaml: field 'identification.duration_s' is too sh"):
        plan_experiments(settings, DT, "both", profile.arena, "p.yaml")


def test_excitation_leaving_the_arena_is_refused_before_flying(tmp_path: Path) -> None:
    data = antx_data(center_ned_m=[2.9, 0.0, -1.5])
    path = tmp_path / "edge.yaml"
    path.write_text(yaml.safe_dump(data))
    # an unreachable vehicle: the refusal must come before any connection attempt
    result = invoke(
        "identify", "--connect", "udpout://127.0.0.1:9", "--profile", path,
        "--logs", tmp_path / "logs", "--out", tmp_path / "o.yaml",
    )  # fmt: skip
    assert result.exit_code == 2, result.output
    assert "outside the arena" in result.output and "identification.amplitude_m" in result.output
    assert not (tmp_path / "logs").exists() and not (tmp_path / "o.yaml").exists()
    profile = profile_from_dict(data, "edge")
    with pytest.raises(TrajectoryError, match="experiment 0: setpoint k = "):
        plan_experiments(profile.identification, DT, "x", profile.arena)


def test_mode_options_are_exclusive(tmp_path: Path) -> None:
    result = invoke("identify")
    assert result.exit_code == 2 and "exactly one of --mock" in result.output
    result = invoke("identify", "--mock", "--from-log", tmp_path)
    assert result.exit_code == 2
    result = invoke("identify", "--from-log", tmp_path, "--axis", "w")
    assert result.exit_code == 2 and "--axis" in result.output


def test_help_reads_like_a_manual() -> None:
    text = invoke("identify", "--help").output
    for word in ("PBSID", "validation", "--from-log", "Example:", "exit code 2"):
        assert word in text


def test_identified_profile_round_trips_exactly(run: RunDir, tmp_path: Path) -> None:
    out = tmp_path / "p.yaml"
    assert invoke("identify", "--from-log", run.path, "--out", out).exit_code == 0
    profile = run.profile()
    settings = profile.identification
    results = identify_run(run, settings, profile)
    loaded = load_profile(out)
    for r, m in zip(results, loaded.models(), strict=True):
        assert np.array_equal(r.model.A, m.A) and np.array_equal(r.model.C, m.C)
    again = copy.deepcopy(loaded.source)
    assert again["model"]["D"] == [[0.0]] and again["model"]["dt_s"] == DT
