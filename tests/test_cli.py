"""The learn and report commands on a synthetic run directory, and their refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_runner import invoke as gcs_invoke
from synthetic import fly_synthetic, make_run

from gcs.io.rundir import RunDir


def invoke(*args: str):
    return gcs_invoke([str(a) for a in args], env={"COLUMNS": "200"})


def files(path: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(path.iterdir()) if p.is_file()}


def test_help_reads_like_a_manual() -> None:
    result = invoke("--help")
    assert result.exit_code == 0
    for command in ("learn", "report"):
        assert command in result.output
    learn_help = invoke("learn", "--help").output
    assert "newest complete trial" in learn_help and "Example" in learn_help


def test_learn_then_report_round_trip(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=1)
    result = invoke("learn", run.path)
    assert result.exit_code == 0, result.output
    assert (run.path / "setpoints-001.csv").exists()
    assert (run.path / "estimate-000.csv").exists()
    fly_synthetic(run, 1)
    result = invoke("report", run.path, "--json")
    assert result.exit_code == 0, result.output
    rows = json.loads(result.output)["rows"]
    assert [r["iteration"] for r in rows] == [0, 1]
    assert set(rows[0]) == {
        "iteration", "status", "reason", "epos_m", "epos_pct", "change_pct",
        "max_err_m", "epos_3d_m", "rms_north_m", "rms_east_m", "rms_down_m", "start_offset_m",
        "vehicle_time_rate", "trial", "repeat_of", "sp_rms_m", "sp_max_m",
        "predicted_epos_m", "prediction_miss_m", "limits_active",
    }  # fmt: skip
    # the paper's method flies no repeat: trial and iteration are one; no floor keys
    assert [(r["trial"], r["repeat_of"]) for r in rows] == [(0, None), (1, None)]
    # trial 1 was predicted by the step from trial 0 (no decision record: no limit count)
    assert rows[0]["predicted_epos_m"] is None and rows[1]["prediction_miss_m"] > 0
    assert rows[1]["limits_active"] is None
    assert rows[0]["sp_rms_m"] == 0.0  # trial 0 flies the reference
    # where each trial began: its first measured position against the start point
    for r in rows:
        first = run.read_trial(r["trial"])
        offset = first.pos_ned_m[0, :2] - run.reference().pos_ned_m[0, :2]
        assert r["start_offset_m"] == pytest.approx(np.hypot(*offset), rel=1e-8, abs=1e-12)
    dev = run.read_setpoints(1)[:, :2] - run.reference().pos_ned_m[:-1, :2]
    assert rows[1]["sp_rms_m"] == pytest.approx(np.sqrt(np.mean(np.sum(dev**2, axis=1))))
    assert rows[1]["sp_max_m"] == pytest.approx(np.max(np.hypot(dev[:, 0], dev[:, 1])))
    assert rows[0]["status"] == "complete" and rows[0]["reason"] is None
    assert rows[0]["vehicle_time_rate"] is None  # simulated trials: no vehicle clock
    assert rows[0]["epos_pct"] == pytest.approx(100.0)
    assert rows[0]["change_pct"] is None
    assert rows[1]["epos_m"] < 0.5 * rows[0]["epos_m"]  # learning helped
    # the signed change: negative is better (Table IV's |change| cannot tell)
    expected_change = 100 * (rows[1]["epos_m"] - rows[0]["epos_m"]) / rows[0]["epos_m"]
    assert rows[1]["change_pct"] == pytest.approx(expected_change) and expected_change < 0


def test_report_table_and_plots(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=3)
    result = invoke("report", run.path, "--plot", tmp_path / "plots")
    assert result.exit_code == 0, result.output
    assert "e_pos [m]" in result.output
    for name in ("xy", "position", "setpoints", "error", "epos", "disturbance"):
        data = (tmp_path / "plots" / f"{name}.png").read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000


def test_learn_is_idempotent(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=1)
    assert invoke("learn", run.path).exit_code == 0
    first = files(run.path)
    assert invoke("learn", run.path).exit_code == 0
    assert files(run.path) == first


def _corrupt(run: RunDir, column: str, row: int, value: str) -> None:
    path = run.path / "trial-000.csv"
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[row + 1].split(",")
    cells[header.index(column)] = value
    lines[row + 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda run: _corrupt(run, "pos_east_m", 7, "nan"), "'pos_east_m' is NaN"),
        (
            lambda run: (run.path / "trial-000.csv").write_text(
                "\n".join((run.path / "trial-000.csv").read_text().splitlines()[:-5]) + "\n"
            ),
            "truncated",
        ),
        (lambda run: _corrupt(run, "t_s", 3, "0.2"), "does not match t_ilc_s"),
        (lambda run: (run.path / "manifest.json").write_text("{not json"), "malformed JSON"),
    ],
)
def test_learn_refuses_bad_logs_and_writes_nothing(tmp_path: Path, damage, message) -> None:
    run = make_run(tmp_path, trials=1)
    damage(run)
    before = files(run.path)
    result = invoke("learn", run.path)
    assert result.exit_code == 2
    assert message in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert files(run.path) == before


def test_learn_refuses_mismatching_profile_and_algorithm(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=1)
    other = tmp_path / "other.yaml"
    text = (Path(__file__).parents[1] / "profiles" / "antx.yaml").read_text()
    text = text.replace("stream_rate_hz: 60", "stream_rate_hz: 50")  # 2 sends per 0.04 s
    other.write_text(text.replace("t_ilc_s: 0.05", "t_ilc_s: 0.04"))
    result = invoke("learn", run.path, "--profile", other)
    assert result.exit_code == 2 and "does not match" in result.output
    result = invoke("learn", run.path, "--algorithm", "kilc")
    assert result.exit_code == 2 and "learns with 'smoother'" in result.output
    assert not (run.path / "setpoints-001.csv").exists()


def test_learn_refuses_incomplete_only_run(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=0)
    result = invoke("learn", run.path)
    assert result.exit_code == 2 and "no complete trial" in result.output


def test_missing_run_directory(tmp_path: Path) -> None:
    result = invoke("report", tmp_path / "nope")
    assert result.exit_code == 2 and "not a run directory" in result.output


def test_learned_setpoints_respect_the_arena(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=1)
    assert invoke("learn", run.path).exit_code == 0
    sp = run.read_setpoints(1)
    bounds = run.profile().arena.bounds()
    assert np.all(sp >= bounds[:, 0] - 1e-9) and np.all(sp <= bounds[:, 1] + 1e-9)


def test_montecarlo_prints_tables_and_writes_json(tmp_path: Path) -> None:
    out = tmp_path / "mc.json"
    result = invoke(
        "montecarlo", "--levels", "0.05,0.2", "--plants", "4", "--repeats", "2",
        "--iterations", "30", "--json", out,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "0.84±0.10" in result.output  # the paper's Table II value beside ours
    rows = json.loads(out.read_text())
    assert {(r["algorithm"], r["uncertainty"]) for r in rows} == {
        (a, u) for a in ("smoother", "kilc") for u in (0.05, 0.2)
    }
    keys = {"algorithm", "uncertainty", "first_mean", "first_std", "steady_mean", "steady_std"}
    for r in rows:
        assert keys | {"excluded", "excluded_rule"} <= set(r)
        assert r["steady_mean"] < r["first_mean"]  # learning reduced the error


def test_montecarlo_refuses_bad_levels() -> None:
    result = invoke("montecarlo", "--levels", "0.05,abc")
    assert result.exit_code == 2 and "not a list of numbers" in result.output


def test_identify_interrupted_exits_130_and_writes_no_profile(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt  # what run_campaign raises after landing the vehicle

    monkeypatch.setattr("gcs.app.identify.fly_identification", interrupted)
    run = tmp_path / "ident"
    result = invoke("identify", "--connect", "udpout://127.0.0.1:9", "--run", run)
    assert result.exit_code == 130, result.output
    assert "interrupted; no profile written" in result.output
    assert (run / "manifest.json").exists()  # the run is kept for the experiments flown
    assert not (run / "identified.yaml").exists()


# ------------------------------------------------------------------------ run integrity


def test_learn_refuses_an_identification_run_and_keeps_its_setpoints(tmp_path: Path) -> None:
    """A case once seen: `gcs learn` on an interrupted identification run (logs/latest after
    `gcs identify`) overwrote the validation experiment's setpoints."""
    from badinputs import Templates

    ident = Templates(tmp_path / "t").get("ident")
    (ident / "trial-001.json").unlink()  # interrupted before the validation experiment
    (ident / "trial-001.csv").unlink()
    before = files(ident)
    result = invoke("learn", ident)
    assert result.exit_code == 2
    assert "not a learning run" in result.output
    assert files(ident) == before


def test_learning_twice_writes_the_same_bytes_and_refuses_different_ones(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=1)
    assert invoke("learn", run.path).exit_code == 0
    first = files(run.path)
    second = invoke("learn", run.path)
    assert second.exit_code == 0 and files(run.path) == first
    path = run.path / "setpoints-001.csv"
    lines = path.read_text().splitlines(keepends=True)
    cells = lines[6].split(",")
    lines[6] = ",".join([*cells[:2], "0.25", *cells[3:]])  # k = 5, north: edited by hand
    edited = "".join(lines)
    path.write_text(edited)
    result = invoke("learn", run.path)
    assert result.exit_code == 2 and "never rewritten" in result.output
    assert path.read_text() == edited


def test_learned_setpoints_are_checked_on_their_grid_before_they_are_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import gcs.app.learn as learn

    run = make_run(tmp_path, trials=1)
    real = learn.Learner.step

    def jumpy(self, *args, **kwargs):  # a solver that broke its step constraint
        u_next = real(self, *args, **kwargs)
        self.last.setpoints_m[30, 1] += 0.8
        return u_next

    monkeypatch.setattr(learn.Learner, "step", jumpy)
    before = files(run.path)
    result = invoke("learn", run.path)
    assert result.exit_code == 2
    assert "setpoint k = 30 steps" in result.output and "max_step_m = 0.5" in result.output
    assert files(run.path) == before


def test_resume_accepts_the_runs_own_files_and_refuses_others(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=1)
    assert invoke("learn", run.path).exit_code == 0
    profile = tmp_path / "same.yaml"
    profile.write_text((Path(__file__).parents[1] / "profiles" / "antx.yaml").read_text())
    result = invoke(
        "fly", "--connect", "udpout://127.0.0.1:9", "--resume", run.path, "--profile", profile,
        "--check", "--offline",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "checked: profile 'antx', trajectory 'tiny'" in result.output
    assert "trials 1..3" in result.output
    result = invoke("fly", "--mock", "--resume", run.path, "--trajectory", "eight-short")
    assert result.exit_code == 2
    assert "eight-short.yaml: differs from the trajectory" in result.output
    assert "(field 'amplitude_east_m')" in result.output


def test_every_help_states_the_exit_codes() -> None:
    for command in ("fly", "learn", "report", "identify", "montecarlo", "mock"):
        text = " ".join(invoke(command, "--help").output.split())
        assert "Exit codes: 0 " in text, command
        assert "2 bad input" in text and "1 an internal error" in text, command
        if command != "mock":
            assert "130 interrupted" in text, command


def test_montecarlo_iterations_help_and_validation_agree() -> None:
    text = " ".join(invoke("montecarlo", "--help").output.split())
    assert "x>=30" in text and "at least 30" in text
    result = invoke("montecarlo", "--iterations", "29")
    assert result.exit_code == 2 and "'--iterations'" in result.output
    assert "MontecarloSettings" not in result.output
    result = invoke("montecarlo", "--levels", "nan")
    assert result.exit_code == 2 and "--levels" in result.output
    assert "MontecarloSettings" not in result.output


def test_an_internal_error_is_one_line_with_exit_code_1(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run = make_run(tmp_path, trials=1)

    def broken(*args, **kwargs):
        raise KeyError("a bug")

    monkeypatch.setattr("gcs.app.learn.Learner.step", broken)
    result = invoke("learn", run.path)
    assert result.exit_code == 1
    assert result.output.strip() == ("error: internal error, please report it: KeyError: 'a bug'")
    monkeypatch.setenv("GCS_DEBUG", "1")
    result = invoke("learn", run.path)
    assert isinstance(result.exception, KeyError)  # with its traceback


def test_help_is_a_manual_short_prose_grouped_options_flags_as_flags() -> None:
    import re

    for command in ("fly", "identify", "learn", "report"):
        text = invoke(command, "--help").output
        head = text.split("╭─", 1)[0]  # the prose before the first panel of options
        assert len([line for line in head.splitlines() if line.strip()]) <= 10, command
        assert "Example: gcs " + command in " ".join(head.split()), command
        assert "<bool>" not in text, command  # a flag takes no value
    fly = invoke("fly", "--help").output
    panels = re.findall(r"╭─ (\w+) ─", fly)
    assert panels == ["Options", "Vehicle", "Learning", "Output", "Safety"], panels
    flat = " ".join(fly.split())
    assert "Fly a simulated drone" in flat and "Dry run" not in flat.split("--check")[0]
    from gcs.io.paths import packaged_names

    for name in (*packaged_names("profile"), *packaged_names("trajectory")):
        assert name in flat, name  # --profile, --trajectory and --mock-config list them
    mock_config = flat.split("--mock-config", 1)[1].split("--seed", 1)[0]
    assert "mock-gps" in mock_config and "antx" not in mock_config
    # a flag given a value stays a usage error, in one line
    result = invoke("fly", "--mock", "true", "--check")
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1


def test_shared_options_are_declared_once() -> None:
    import inspect
    import re

    import gcs.cli

    source = inspect.getsource(gcs.cli)
    own = {"--check": 1}  # gcs study's own: it checks a study file, in its own words
    for option in ("--mock", "--connect", "--mock-config", "--check", "--run", "--logs",
                   "--algorithm"):  # fmt: skip
        declared = re.findall(r'Option\(\s*"' + re.escape(option) + '"', source)
        assert len(declared) == 1 + own.get(option, 0), option


def test_python_m_gcs_runs_the_command_only_as_the_main_module(monkeypatch, capsys) -> None:
    # multiprocessing's "spawn" imports the parent's main module as __mp_main__ in a child:
    # with `python -m gcs ...` that is gcs/__main__.py, which must then not run the command
    import runpy
    import sys

    monkeypatch.setattr(sys, "argv", ["gcs", "--help"])
    runpy.run_module("gcs.__main__", run_name="__mp_main__")  # no SystemExit: nothing ran
    assert capsys.readouterr().out == ""
    with pytest.raises(SystemExit) as exc:  # as the main module it is the command line
        runpy.run_module("gcs.__main__", run_name="__main__")
    assert exc.value.code == 0 and "Usage" in capsys.readouterr().out
