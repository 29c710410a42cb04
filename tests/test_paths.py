"""gcs.io.paths: profiles and trajectories by name, and output paths checked before any work."""

from __future__ import annotations

import os
import re
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from synthetic import ROOT

from gcs.errors import PathError
from gcs.io.paths import (
    RUN_FILE,
    check_new_dir,
    check_output_dir,
    check_output_file,
    check_writable_dir,
    packaged_dir,
    packaged_names,
    resolve_named,
)
from gcs.io.rundir import RunDir


@contextmanager
def read_only(path: Path) -> Iterator[Path]:
    """``path`` unwritable while in the block: the immutable attribute as root, else chmod."""
    if os.geteuid() == 0:
        subprocess.run(["chattr", "+i", str(path)], check=True)
        try:
            yield path
        finally:
            subprocess.run(["chattr", "-i", str(path)], check=True)
    else:
        mode = path.stat().st_mode
        path.chmod(0o555)
        try:
            yield path
        finally:
            path.chmod(mode)


def test_packaged_files_are_the_repository_files() -> None:
    for kind, folder in (("profile", "profiles"), ("trajectory", "trajectories")):
        in_repo = sorted(p.stem for p in (ROOT / folder).glob("*.yaml"))
        assert packaged_names(kind) == in_repo and in_repo
    for kind, folder in (("profile", "profiles"), ("trajectory", "trajectories")):
        for name in packaged_names(kind):
            packaged = packaged_dir(kind) / f"{name}.yaml"
            assert packaged.read_bytes() == (ROOT / folder / f"{name}.yaml").read_bytes()


def test_names_and_paths_resolve(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # nowhere near the repository
    antx = resolve_named("antx", "profile", "--profile")
    assert antx == packaged_dir("profile") / "antx.yaml" and antx.is_file()
    assert resolve_named("eight.yaml", "trajectory", "--trajectory").name == "eight.yaml"
    own = tmp_path / "antx"  # a file of the same name in the working directory wins
    own.write_text("name: mine\n")
    assert resolve_named("antx", "profile", "--profile") == Path("antx")
    assert resolve_named(own, "profile", "--profile") == own


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("antz", "no packaged profile of that name (antx, "),
        ("profiles/antx.yaml", "no such file"),  # a path is never looked up by name
        ("../antx", "no such file"),
    ],
)
def test_unknown_names_are_refused_naming_the_option(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, value: str, message: str
) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(PathError, match=re.escape(message)) as info:
        resolve_named(value, "profile", "--profile")
    assert str(info.value).startswith(f"--profile {value}:")


def test_a_directory_or_nothing_is_not_a_profile(tmp_path: Path) -> None:
    with pytest.raises(PathError, match="is a directory"):
        resolve_named(tmp_path, "profile", "--profile")
    with pytest.raises(PathError, match="--profile: empty"):
        resolve_named(" ", "profile", "--profile")


def test_output_file_checks(tmp_path: Path) -> None:
    assert check_output_file(tmp_path / "new" / "deeper" / "x.json", "--json")  # created later
    assert check_output_file(tmp_path / "x.json", "--json")
    with pytest.raises(PathError, match="--json .*: is a directory"):
        check_output_file(tmp_path, "--json")
    (tmp_path / "file").write_text("x")
    with pytest.raises(PathError, match="file is a file, not a directory"):
        check_output_file(tmp_path / "file" / "x.json", "--json")
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "manifest.json").write_text("{}")
    for name in ("manifest.json", "trial-003.csv", "setpoints-001.csv", "session-002.json"):
        with pytest.raises(PathError, match="is a file of the run directory"):
            check_output_file(tmp_path / "run" / name, "--html")
    assert check_output_file(tmp_path / "run" / "report.html", "--html")
    assert list(tmp_path.rglob(".gcs-probe-*")) == []  # the probes are gone


def test_output_checks_refuse_the_run_files_by_the_names_the_run_gives_them(
    tmp_path: Path,
) -> None:
    run = RunDir(tmp_path / "run", {})  # only its names are asked for
    for path in (
        run.manifest_path,
        run.reference_path,
        run.identified_path,
        run.setpoints_path(1),
        run.trial_path(3),
        run.status_path(3),
        run.estimate_path(2),
        run.session_path(2),
        run.floor_path,
        run.mocap_path(1),
        run.learn_path(1),
        run.model_path(1),
        run.again_path(4),
    ):
        assert RUN_FILE.match(path.name), path.name
    for name in ("report.html", "learn-001.csv", "model-1.yaml", "trial-0001.csv", "floor.yaml"):
        assert not RUN_FILE.match(name), name  # outputs a user may name so


def test_output_dir_and_new_dir_checks(tmp_path: Path) -> None:
    assert check_output_dir(tmp_path / "plots" / "a", "--plot")
    (tmp_path / "f").write_text("x")
    with pytest.raises(PathError, match="--plot .*: is a file, not a directory"):
        check_output_dir(tmp_path / "f", "--plot")
    with pytest.raises(PathError, match="is a file, not a directory"):
        check_output_dir(tmp_path / "f" / "plots", "--plot")
    assert check_new_dir(tmp_path / "run", "--run")
    with pytest.raises(PathError, match="a directory of that name exists already"):
        check_new_dir(tmp_path, "--run")
    with pytest.raises(PathError, match="a file of that name exists already"):
        check_new_dir(tmp_path / "f", "--run")
    assert not (tmp_path / "plots").exists() and not (tmp_path / "run").exists()


def test_unwritable_directories_are_refused(tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    with read_only(ro):
        with pytest.raises(PathError, match="is not writable"):
            check_writable_dir(ro, "--plot ro")
        with pytest.raises(PathError, match="is not writable"):
            check_output_file(ro / "x.json", "--json")
        with pytest.raises(PathError, match="is not writable"):
            check_output_dir(ro / "plots", "--plot")
        with pytest.raises(PathError, match="is not writable"):
            check_new_dir(ro / "run", "--run")
    assert list(ro.iterdir()) == []
