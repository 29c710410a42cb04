"""Altitude as a learned axis: the profile's ``model_z`` and ``learning.axes``, the vertical
limits, identification seeds of z, the estimate file with down, and the 3-D metrics."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import yaml
from synthetic import ROOT, SHORT

from gcs import Learner, LearnerSettings, learner_settings
from gcs.core.metrics import axis_rms, epos, epos_3d
from gcs.core.model import from_transfer_function, simulate
from gcs.core.trajectory import check_setpoints, sample_eight
from gcs.errors import ProfileError, TrajectoryError
from gcs.io.config import profile_from_dict, trajectory_from_dict
from gcs.io.rundir import RunDir
from gcs.io.settings import IdentifySettings

#: A vertical loop for the tests: second order, 0.15 s delay (not the profile's horizontal one).
MODEL_Z = {"num": [27.5625], "den": [1.0, 10.08, 27.5625], "delay_s": 0.15}


def antx() -> dict:
    return yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())


def three_d(**limits: float) -> dict:
    data = antx()
    data["model_z"] = dict(MODEL_Z)
    data["learning"]["axes"] = ["north", "east", "down"]
    data["learning"]["limits"].update(limits)
    return data


# ---------------------------------------------------------------------------- the profile


def test_the_paper_profile_learns_north_and_east_with_two_models() -> None:
    prof = profile_from_dict(antx(), "antx")
    assert prof.learning.axes == (0, 1) and prof.model_z is None
    settings = learner_settings(prof)
    assert settings.axes == (0, 1) and len(settings.models) == 2
    assert settings.models == prof.models()


def test_down_learned_with_its_own_model_and_the_horizontal_limits_by_default() -> None:
    prof = profile_from_dict(three_d(), "3d")
    assert prof.learning.axes == (0, 1, 2)
    settings = learner_settings(prof)
    assert settings.axes == (0, 1, 2)
    assert settings.models[2] is prof.model_z and settings.models[2] is not prof.model_x
    expected = from_transfer_function(MODEL_Z["num"], MODEL_Z["den"], 0.15, prof.t_ilc_s)
    np.testing.assert_allclose(prof.model_z.A, expected.A)
    assert settings.limits_of(2) == (0.5, 2.5) == settings.limits_of(0)


def test_vertical_limits_of_their_own() -> None:
    prof = profile_from_dict(three_d(max_vertical_step_m=0.05, max_vertical_deviation_m=0.4), "p")
    settings = learner_settings(prof)
    assert settings.limits_of(2) == (0.05, 0.4) and settings.limits_of(1) == (0.5, 2.5)
    # the numerics' own default: down bounded as north and east unless told otherwise
    core = LearnerSettings(models=(prof.model_z,), max_step_m=0.3, axes=(2,))
    assert core.limits_of(2) == (0.3, None)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("model_z"), "field 'model_z' is required when learning.axes has down"),
        (lambda d: d["learning"].update(axes=["down"]), "field 'learning.axes' must be"),
        (lambda d: d["learning"].update(axes=["east", "north"]), "field 'learning.axes' must be"),
        (lambda d: d["learning"].update(axes="north"), "field 'learning.axes' must be"),
        (lambda d: d["learning"].update(axes=[["north"]]), "field 'learning.axes' must be"),
        (
            lambda d: d["learning"].update(adaptive={}),
            "field 'learning.axes' down cannot be learned with learning.adaptive",
        ),
        (
            lambda d: d["learning"]["limits"].update(max_vertical_step_m=0),
            "field 'learning.limits.max_vertical_step_m' must be > 0",
        ),
        (
            lambda d: d["learning"]["limits"].update(max_vertical_deviation_m="x"),
            "field 'learning.limits.max_vertical_deviation_m' must be a number",
        ),
        (lambda d: d["model_z"].pop("den"), "model_z"),
    ],
)
def test_bad_axes_fields_are_refused_by_name(edit, message: str) -> None:
    data = three_d()
    edit(data)
    with pytest.raises(ProfileError, match=message.replace("(", r"\(")):
        profile_from_dict(data, "p.yaml")


def test_model_z_alone_does_not_change_what_is_learned() -> None:
    data = antx()
    data["model_z"] = dict(MODEL_Z)
    prof = profile_from_dict(data, "p")
    assert prof.learning.axes == (0, 1) and len(learner_settings(prof).models) == 2


# ----------------------------------------------------------------------- identification


def test_z_seeds_are_its_own_and_x_y_keep_theirs() -> None:
    s = IdentifySettings(seed=7)
    xy = {s.seed_for(e, a) for e in (0, 1) for a in ("x", "y")}
    assert xy == {7, 8, 9, 10}  # x/y: seed + 2 e + a, as before
    z = {s.seed_for(0, "z"), s.seed_for(1, "z")}
    assert len(z) == 2 and not z & xy
    assert s.amplitude_for("z") == s.vertical_amplitude_m and s.amplitude_for("x") == s.amplitude_m


def test_vertical_amplitude_is_parsed_and_checked() -> None:
    data = antx()
    data["identification"]["vertical_amplitude_m"] = 0.5
    assert profile_from_dict(data, "p").identification.amplitude_for("z") == 0.5
    data["identification"]["vertical_amplitude_m"] = -0.5
    with pytest.raises(ProfileError, match="identification.vertical_amplitude_m' must be > 0"):
        profile_from_dict(data, "p")


def test_z_experiments_excite_down_only_with_the_vertical_amplitude() -> None:
    from gcs.app.identify_plan import plan_experiments

    prof = profile_from_dict(antx(), "antx")
    exp = plan_experiments(prof.identification, prof.t_ilc_s, "z", prof.arena)
    fit = exp.setpoints_ned_m[0] - exp.center_ned_m
    assert exp.axes == ("z",)
    assert np.all(fit[:, :2] == 0.0)
    np.testing.assert_allclose(np.abs(fit[:, 2]), prof.identification.vertical_amplitude_m)
    everything = plan_experiments(prof.identification, prof.t_ilc_s, "all", prof.arena)
    assert everything.axes == ("x", "y", "z")
    np.testing.assert_array_equal(everything.setpoints_ned_m[1][:, 2], exp.setpoints_ned_m[1][:, 2])


# ----------------------------------------------------------------------------- learning


def test_three_axes_learn_down_as_a_one_axis_learner_and_its_error_falls() -> None:
    """Down learned with model_z and the vertical limits: the 3-axis learner's down column is
    a one-axis learner's (built here from the same model and limits), and on a vehicle with a
    repeated vertical disturbance the down error falls trial after trial."""
    prof = profile_from_dict(three_d(max_vertical_step_m=0.08), "p")
    settings = learner_settings(prof)
    spec = copy.deepcopy(SHORT)
    ref = sample_eight(trajectory_from_dict(spec).shape, prof.t_ilc_s).pos_ned_m.copy()
    n = ref.shape[0] - 1
    t = np.arange(1, n + 1) * prof.t_ilc_s
    ref[1:, 2] += -0.3 * np.sin(np.pi * t / t[-1]) ** 2  # climb 0.3 m and back
    models = (prof.model_x, prof.model_y, prof.model_z)
    disturbance = 0.1 * np.sin(2 * np.pi * t / t[-1])  # repeats every trial

    def fly(u: np.ndarray) -> np.ndarray:
        y = np.column_stack(
            [ref[0, a] + simulate(m, u[:, a] - ref[0, a]) for a, m in enumerate(models)]
        )
        y[:, 2] += disturbance
        return y

    three = Learner(settings, ref)
    down = Learner(
        LearnerSettings(models=(prof.model_z,), arena=prof.arena, max_step_m=0.5,
                        max_deviation_m=2.5, axes=(2,), max_vertical_step_m=0.08),
        ref[:, [2]],
    )  # fmt: skip
    u = ref[:-1].copy()
    rms_down = []
    for _ in range(4):
        y = fly(u)
        rms_down.append(float(np.sqrt(np.mean((y[:, 2] - ref[1:, 2]) ** 2))))
        u_next = three.step(u, y)
        np.testing.assert_array_equal(u_next[:, [2]], down.step(u[:, [2]], y[:, [2]]))
        steps = np.abs(np.diff(np.concatenate([[ref[0, 2]], u_next[:, 2]])))
        assert np.max(steps) <= 0.08 + 1e-7  # the vertical step limit, not the horizontal 0.5
        u = u_next
    assert rms_down[-1] < 0.5 * rms_down[0], rms_down
    assert all(b < a for a, b in zip(rms_down, rms_down[1:], strict=False)), rms_down


def test_check_setpoints_applies_the_vertical_limits_only_when_down_is_learned() -> None:
    prof = profile_from_dict(antx(), "antx")
    ref = sample_eight(trajectory_from_dict(SHORT).shape, prof.t_ilc_s)
    sp = ref.pos_ned_m[:-1].copy()
    sp[10:, 2] -= 0.2  # a 0.2 m step up at k = 10
    check_setpoints(sp, ref, prof.arena, 0.5, 2.5, (1, 1))  # down not learned: not checked
    with pytest.raises(TrajectoryError, match="k = 10 steps 0.200 m on down .*max_vertical_step"):
        check_setpoints(sp, ref, prof.arena, 0.5, 2.5, (1, 1, 1), vertical=(0.1, None))
    with pytest.raises(TrajectoryError, match="on down .*max_vertical_deviation_m = 0.1"):
        check_setpoints(sp, ref, prof.arena, 0.5, 2.5, (1, 1, 1), vertical=(None, 0.1))


def test_estimates_with_down_round_trip_and_two_axis_files_read_as_before(tmp_path) -> None:
    run = RunDir.create(
        tmp_path, profile_from_dict(three_d(), "p"), trajectory_from_dict(SHORT), "kilc", "run"
    )
    n = run.n_samples
    rng = np.random.default_rng(3)
    d3, p3 = rng.normal(0, 0.1, (n, 3)), rng.uniform(0.01, 0.1, (n, 3))
    run.write_estimate(0, d3, p3)
    header = (run.path / "estimate-000.csv").read_text().splitlines()[0]
    assert header == "k,t_s,d_north_m,d_east_m,p_north_m2,p_east_m2,d_down_m,p_down_m2"
    d, p = run.read_estimate(0)
    np.testing.assert_allclose(d, d3, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(p, p3, rtol=1e-8)
    run.write_estimate(1, d3[:, :2], p3[:, :2])
    d, p = run.read_estimate(1)
    assert d.shape == (n, 2) and p.shape == (n, 2)
    np.testing.assert_allclose(d, d3[:, :2], rtol=1e-8, atol=1e-12)


# ------------------------------------------------------------------------------ metrics


def test_3d_epos_and_rms_per_axis_by_hand() -> None:
    ref = np.zeros((2, 3))
    pos = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 2.0]])
    assert epos_3d(ref, pos) == pytest.approx((5.0 + 2.0) / 2)
    assert epos(ref[:, :2], pos[:, :2]) == pytest.approx((5.0 + 0.0) / 2)
    n, e, d = axis_rms(ref, pos)
    assert (n, e, d) == pytest.approx((math.sqrt(9 / 2), math.sqrt(16 / 2), math.sqrt(4 / 2)))
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        epos_3d(ref[:, :2], pos[:, :2])


def test_3d_epos_is_at_least_the_horizontal_one() -> None:
    rng = np.random.default_rng(0)
    ref, pos = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    assert epos_3d(ref, pos) >= epos(ref[:, :2], pos[:, :2])
    pos[:, 2] = ref[:, 2]
    assert epos_3d(ref, pos) == pytest.approx(epos(ref[:, :2], pos[:, :2]))


# ------------------------------------------------------------------- a 3-D run's report


def test_a_synthetic_3d_run_learns_down_and_reports_it_within_80_columns(tmp_path) -> None:
    import io

    from rich.console import Console
    from synthetic import fly_synthetic, true_plants

    from gcs.app.learn import learn_run
    from gcs.app.report import is_three_d, run_learning, run_metrics, trial_clock_rates
    from gcs.app.report_figures import report_figures
    from gcs.app.report_text import metrics_table
    from gcs.core.trajectory import Reference

    prof = profile_from_dict(three_d(), "p")
    run = RunDir.create(tmp_path, prof, trajectory_from_dict(SHORT), "smoother", "run")
    plants = (*true_plants(), prof.model_z)
    fly_synthetic(run, 0, plants=plants)
    learn_run(run)
    ref = run.reference()
    assert isinstance(ref, Reference) and is_three_d(run)
    sp1 = run.read_setpoints(1)
    assert np.max(np.abs(sp1[:, 2] - ref.pos_ned_m[:-1, 2])) > 1e-3  # down is learned
    assert run.read_estimate(0)[0].shape == (run.n_samples, 3)
    fly_synthetic(run, 1, plants=plants)
    rows = run_metrics(run)
    for r in rows:  # by hand, from the recorded trial
        rec = run.read_trial(r.iteration)
        err = rec.pos_ned_m[1:] - rec.ref_ned_m[1:]
        assert r.epos_3d_m == pytest.approx(float(np.mean(np.sqrt(np.sum(err**2, axis=1)))))
        assert r.rms_down_m == pytest.approx(float(np.sqrt(np.mean(err[:, 2] ** 2))))
    assert rows[1].rms_down_m < rows[0].rms_down_m
    buf = io.StringIO()
    console = Console(file=buf, width=80)
    learning, rates = run_learning(run), trial_clock_rates(run)
    console.print(metrics_table(rows, "title", rates, learning, 80, three_d=True))
    text = buf.getvalue()
    assert "e3d [m]" in text and "rms D [m]" in text
    assert max(map(len, text.splitlines())) <= 80
    figures = report_figures(run, [0, 1])
    assert {"altitude", "views"} <= set(figures)


def test_a_flat_run_keeps_its_table() -> None:
    """The paper's table has no 3-D columns; the HTML's has every axis's RMS."""
    from gcs.app.report_text import table_cells
    from gcs.core.metrics import IterationMetrics

    row = IterationMetrics(0, 0.1, 100.0, None, 0.2, 0.11, 0.05, 0.06, 0.01)
    headers, cells = table_cells([row], None, None)
    assert headers == ["j", "e_pos [m]", "e/e0 [%]", "change [%]", "max err [m]"]
    headers, cells = table_cells([row], None, None, three_d=True, every_axis=True)
    assert headers[-4:] == ["e3d [m]", "rms N [m]", "rms E [m]", "rms D [m]"]
    assert cells[0][-4:] == ["0.1100", "0.0500", "0.0600", "0.0100"]


def test_z_identified_offline_from_a_vertical_run_and_written_as_model_z(tmp_path) -> None:
    """A synthetic vertical loop excited on z: PBSID finds it (validation VAF), x and y are
    not excited, and the written profile keeps x and y and adds model_z, which loads."""
    from gcs.app.identify import create_identification_run
    from gcs.app.identify_fit import identify_run
    from gcs.app.identify_plan import plan_experiments, run_axes
    from gcs.app.identify_profile import identified_profile_text
    from gcs.io.records import TrialRecord, TrialStatus

    data = antx()
    data["identification"]["duration_s"] = 30.0
    prof = profile_from_dict(data, "antx")
    settings = prof.identification
    exps = plan_experiments(settings, prof.t_ilc_s, "z", prof.arena)
    run = create_identification_run(tmp_path, prof, settings, exps, run_id="ident")
    truth = from_transfer_function(MODEL_Z["num"], MODEL_Z["den"], 0.15, prof.t_ilc_s)
    rng = np.random.default_rng(0)
    for j, sp in enumerate(exps.setpoints_ned_m):
        n, c = sp.shape[0], exps.center_ned_m
        rows = np.vstack([sp, sp[-1]])
        pos = np.tile(c, (n + 1, 1))
        pos[1:, 2] += simulate(truth, sp[:, 2] - c[2]) + rng.normal(0, 0.002, n)
        record = TrialRecord(
            t_s=np.arange(n + 1) * prof.t_ilc_s, ref_ned_m=rows, sp_ned_m=rows, pos_ned_m=pos,
            vel_ned_m_s=np.gradient(pos, prof.t_ilc_s, axis=0),
            sp_sent_s=np.append(np.arange(n) * prof.t_ilc_s, np.nan),
            interpolated=np.zeros(n + 1, dtype=bool),
        )  # fmt: skip
        run.write_trial(j, record, TrialStatus(j, True))
    run = RunDir.open(run.path)
    assert run_axes(run) == ("z",)
    (result,) = identify_run(run, settings, prof)
    assert result.axis == "z" and result.vaf_pct > 99.0
    assert math.isnan(result.vaf_profile_pct)  # antx has no model_z to compare with
    text = identified_profile_text(prof, [result], str(run.path))
    out = profile_from_dict(yaml.safe_load(text), "identified")
    assert out.model_z is not None and out.learning.axes == (0, 1)
    np.testing.assert_array_equal(out.model_x.A, prof.model_x.A)
    assert "model_z" in text.split("learning:")[0]  # beside the other models
