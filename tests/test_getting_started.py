"""docs/getting-started.md's walk-through, run command by command against the mock drone.

The commands are read from the console blocks of its section "Your first hour, step by
step" and run as they stand (``gcs`` being ``python -m gcs``; ``> FILE`` writes the output
there), in a fresh directory, in order; the only change is the one the page states: every
``gcs fly`` gets a copy of antx.yaml with the test suite's flight settings
(``synthetic.CI_FLIGHT``: a 2 s hover measurement, a loaded machine's watchdog limits).
The page cannot drift from the tool: a renamed option, a command that fails, or a file it no
longer writes fails this test.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from synthetic import CI_FLIGHT, ROOT

from gcs.io.config import load_trajectory
from gcs.io.rundir import RunDir

pytestmark = pytest.mark.e2e

PAGE = ROOT / "docs" / "getting-started.md"
SECTION = "## Your first hour, step by step"


def walkthrough_commands(text: str) -> list[str]:
    """The command lines of the section's console blocks, in order (comments dropped)."""
    section = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    commands = []
    for block in re.findall(r"```console\n(.*?)```", section, flags=re.S):
        for line in block.splitlines():
            line = line.split("  #", 1)[0].strip()
            if line and not line.startswith("#"):
                commands.append(line)
    return commands


def test_the_walkthrough_is_commands_of_gcs() -> None:
    commands = walkthrough_commands(PAGE.read_text())
    assert len(commands) >= 7 and all(c.startswith("gcs ") for c in commands), commands
    assert commands[0].startswith("gcs fly") and "--check" in commands[0]


def test_the_getting_started_walkthrough_runs_as_written(tmp_path: Path) -> None:
    profile = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    profile["flight"] = dict(profile.get("flight") or {}, **CI_FLIGHT)  # hover_measure_s 2
    (tmp_path / "antx-walkthrough.yaml").write_text(yaml.safe_dump(profile))
    env = {**os.environ, "COLUMNS": "120", "PYTHONUNBUFFERED": "1"}
    outputs = []
    for line in walkthrough_commands(PAGE.read_text()):
        argv = shlex.split(line)
        target = None
        if ">" in argv:
            at = argv.index(">")
            argv, target = argv[:at], argv[at + 1]
        if argv[1] == "fly" and "--profile" not in argv:
            argv += ["--profile", "antx-walkthrough.yaml"]  # the change the page states
        done = subprocess.run(
            [sys.executable, "-m", "gcs", *argv[1:]], cwd=tmp_path, env=env,
            capture_output=True, text=True, timeout=600,
        )  # fmt: skip
        assert done.returncode == 0, f"{line}\n{done.stdout}\n{done.stderr}"
        if target is not None:
            (tmp_path / target).write_text(done.stdout)
        outputs.append((line, done.stdout + done.stderr))
    text = "\n".join(out for _, out in outputs)
    assert "sized up: each trial flies" in outputs[0][1]
    run = RunDir.open(tmp_path / "logs" / "latest")
    assert run.complete_trials() == [0, 1]
    assert "from the setpoint in force (lag included)" in text  # the live error per segment
    assert "verdict: e_pos" in text
    doc = json.loads((tmp_path / "run.json").read_text())
    assert doc["version"] == 4 and doc["verdict"]["flights"] == 2
    assert len((tmp_path / "table.csv").read_text().splitlines()) == 3  # header + 2 trials
    assert (tmp_path / "plots" / "epos.svg").is_file()
    best = load_trajectory(tmp_path / "best-setpoints.csv")
    assert best.source["type"] == "samples"
    assert (tmp_path / "report.html").read_text().startswith("<!DOCTYPE html>")
