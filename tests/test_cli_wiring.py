"""The command line only wires: requests to rooms, failures to one line, one registration."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import pytest
from cli_runner import invoke as gcs_invoke
from synthetic import make_adaptive_run, make_run

import gcs.cli
from gcs.app.failures import (
    EXIT_BAD_INPUT,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    OptionError,
    failure,
)
from gcs.app.fly import FlyRequest, fly
from gcs.app.montecarlo import MontecarloRequest, blas_threads, montecarlo_settings
from gcs.errors import ProfileError
from gcs.io.paths import packaged_dir


def invoke(*args: object):
    return gcs_invoke([str(a) for a in args], env={"COLUMNS": "200"})


def test_the_cli_uses_typers_public_api_and_registers_commands_one_way() -> None:
    source = inspect.getsource(gcs.cli)
    assert not re.search(r"typer\._|from click|import click", source)  # no private modules
    assert "def main(self" not in source  # Typer's own main runs, unchanged
    assert source.count("app.command(") == 1  # inside command(), the one way to register
    assert "OPENBLAS" not in source and "MontecarloSettings" not in source
    names = {c.name or c.callback.__name__ for c in gcs.cli.app.registered_commands}
    assert names == {"fly", "learn", "report", "identify", "montecarlo", "study", "mock"}


def test_a_failure_ends_as_one_line_and_its_exit_code(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("GCS_DEBUG", raising=False)
    bad = failure(ProfileError("p.yaml: field 't_ilc_s'\n  is missing"))
    assert (bad.code, bad.line) == (EXIT_BAD_INPUT, "p.yaml: field 't_ilc_s' is missing")
    gone = failure(FileNotFoundError(2, "No such file or directory", "/x/y"))
    assert (gone.code, gone.line) == (EXIT_BAD_INPUT, "/x/y: No such file or directory")
    assert failure(KeyboardInterrupt()).code == EXIT_INTERRUPTED
    assert failure(KeyboardInterrupt()).line is None  # a flight said already where its run is
    bug = failure(KeyError("a bug"))
    assert bug.code == EXIT_INTERNAL and bug.line.startswith("internal error, please report")
    assert failure(SystemExit(0)) is None
    monkeypatch.setenv("GCS_DEBUG", "1")
    assert failure(KeyError("a bug")) is None  # let through, with its traceback
    assert isinstance(OptionError("x", "--levels"), ValueError)  # derives from a builtin


def test_montecarlo_refusals_name_the_option_not_the_field() -> None:
    with pytest.raises(OptionError) as exc:
        montecarlo_settings(MontecarloRequest(repeats=0))
    assert exc.value.option == "--repeats" and "MontecarloSettings" not in exc.value.message
    with pytest.raises(OptionError) as exc:
        montecarlo_settings(MontecarloRequest(levels="0.1,x"))
    assert exc.value.option == "--levels" and "not a list of numbers" in exc.value.message


def test_local_workers_get_this_processs_blas_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")
    assert blas_threads() == 3
    monkeypatch.delenv("OPENBLAS_NUM_THREADS")
    from gcs.app.study_cluster import machine_workers

    assert blas_threads() == machine_workers()


class Recorder:
    """A FlyView that records what the room told it."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    def __getattr__(self, name: str):
        def record(*args: object) -> None:
            self.calls.append(name)

        return record


def test_fly_checks_options_first_and_a_check_only_shows(tmp_path: Path) -> None:
    view = Recorder()
    profile = packaged_dir("profile") / "antx.yaml"
    trajectory = packaged_dir("trajectory") / "eight.yaml"
    with pytest.raises(OptionError, match="exactly one of --mock and --connect"):
        fly(FlyRequest(profile=profile, trajectory=trajectory, logs=tmp_path), view)
    with pytest.raises(OptionError) as exc:
        fly(FlyRequest(use_mock=True, algorithm="pid", profile=profile, logs=tmp_path), view)
    assert exc.value.option == "--algorithm"
    assert view.calls == []
    request = FlyRequest(
        use_mock=True, profile=profile, trajectory=trajectory, logs=tmp_path / "logs",
        check_only=True, offline=True,
    )  # fmt: skip
    assert fly(request, view) is None
    assert view.calls == ["checked"]  # shown, nothing connected, created or flown
    assert not (tmp_path / "logs").exists()


def test_a_mocap_flight_on_the_mock_gets_the_vision_only_mock_by_default() -> None:
    from gcs.app.session import MocapPlan, mock_config_for
    from gcs.io.settings import MocapSettings

    mock_arena = MocapPlan(MocapSettings(), None)  # --mocap mock: the mock's own arena
    vision = mock_config_for(None, True, mock_arena)
    assert vision is not None and vision.stem == "mock-mocap"
    given = Path("mine.yaml")
    assert mock_config_for(given, True, mock_arena) == given
    assert mock_config_for(None, True, None) is None  # no mocap: the mock's defaults
    assert mock_config_for(None, False, mock_arena) is None  # no mock


def test_learn_prints_the_decisions_of_a_run_that_learns_from_its_history(tmp_path: Path) -> None:
    run = make_adaptive_run(tmp_path, trials=4, repeats=1)  # model refreshed after trial 2
    result = invoke("learn", run.path)
    assert result.exit_code == 0, result.output
    assert "learned from trial 3" in result.output and "setpoints for trial 4" in result.output
    decisions = [line for line in result.output.splitlines() if line.startswith("  ")]
    assert any(line.startswith("  model kept") for line in decisions), result.output


def test_a_bad_option_combination_is_one_line_naming_the_options(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=1)
    result = invoke("fly", "--mock", "--resume", run.path, "--run", tmp_path / "new")
    assert result.exit_code == 2
    assert result.output.strip() == (
        "error: Invalid value: give at most one of --run and --resume (see 'gcs fly --help')"
    )
    result = invoke("learn", run.path, "--algorithm", "pid")
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1
    assert "Invalid value for --algorithm: must be one of smoother, kilc" in result.output
