"""Profiles and trajectories ship with the package and are found by name from any directory.

One copy of every file: ``gcs/profiles`` and ``gcs/trajectories`` are symbolic links to the
repository's top-level folders, and a wheel carries the files they point at.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from synthetic import ROOT

FILES = sorted(
    p.relative_to(ROOT).as_posix()
    for folder in ("profiles", "trajectories")
    for pattern in ("*.yaml", "*.csv")  # a samples trajectory's file beside it
    for p in (ROOT / folder).glob(pattern)
)


def test_the_package_folders_are_links_to_the_repository_folders() -> None:
    for folder in ("profiles", "trajectories"):
        link = ROOT / "gcs" / folder
        assert link.is_symlink() and link.resolve() == (ROOT / folder).resolve()


def test_fly_finds_the_packaged_profile_and_trajectory_from_another_directory(
    tmp_path: Path,
) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "gcs", "fly", "--mock", "--profile", "antx", "--trajectory",
         "eight-short", "--check"],
        cwd=tmp_path, capture_output=True, text=True, timeout=60,
        env={**os.environ, "COLUMNS": "200"},
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "checked: profile 'antx', trajectory 'eight-short'" in proc.stdout
    assert list(tmp_path.iterdir()) == []  # --check creates nothing, not even logs/


@pytest.mark.processes
def test_an_installed_wheel_carries_the_files_and_finds_them_by_name(tmp_path: Path) -> None:
    source = tmp_path / "source"  # a copy: building in the checkout would leave build/ there
    source.mkdir()
    for name in ("pyproject.toml", "README.md", "gcs", "profiles", "trajectories"):
        copy = shutil.copytree if (ROOT / name).is_dir() else shutil.copy2
        copy(ROOT / name, source / name, **({"symlinks": True} if copy is shutil.copytree else {}))
    assert (source / "gcs" / "profiles").is_symlink()
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"),
         str(source)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert build.returncode == 0, build.stderr[-2000:]
    (wheel,) = (tmp_path / "dist").glob("gcs-*.whl")
    with zipfile.ZipFile(wheel) as z:
        for name in FILES:
            assert z.read(f"gcs/{name}") == (ROOT / name).read_bytes(), name
    target = tmp_path / "site"
    with zipfile.ZipFile(wheel) as z:
        z.extractall(target)  # what pip install puts in site-packages
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    code = (
        "import gcs, gcs.io.paths as p; "
        "print(gcs.__file__); print(p.resolve_named('antx', 'profile', '--profile')); "
        "print(p.resolve_named('eight', 'trajectory', '--trajectory'))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=elsewhere, capture_output=True, text=True,
        env={**os.environ, "PYTHONPATH": str(target)}, timeout=60,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    module, antx, eight = proc.stdout.split()
    assert Path(module).is_relative_to(target)  # the installed copy, not the repository
    for found, name in ((antx, "profiles/antx.yaml"), (eight, "trajectories/eight.yaml")):
        assert Path(found).is_relative_to(target) and not Path(found).is_symlink()
        assert Path(found).read_bytes() == (ROOT / name).read_bytes()
