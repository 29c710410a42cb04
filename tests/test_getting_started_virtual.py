"""docs/getting-started.md's walk-through, command by command, on the virtual clock.

The commands are read from the console blocks of its section "Your first hour, step by
step" (tests/test_getting_started.py) and run as they stand through gcs's command line, in
this process, in a fresh directory, in order (``> FILE`` writes the command's standard output
there); ``--mock`` starts a simulated drone of the same settings and seed (tests/virtual.py).
The only change is the one the page states: every ``gcs fly`` gets a copy of antx.yaml with
the test suite's flight settings (``synthetic.CI_FLIGHT``: a 2 s hover measurement, a loaded
machine's watchdog limits). The page cannot drift from the tool: a renamed option, a command
that fails, or a file it no longer writes fails this test. ``gcs fly --mock`` on the wire is
tests/test_fly_e2e.py's and tests/test_mock_mavsdk.py's (docs/testing.md).
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest
import yaml
from synthetic import CI_FLIGHT, ROOT
from test_getting_started import PAGE, walkthrough_commands
from virtual import invoke_gcs, sim_mock

from gcs.io.config import load_trajectory
from gcs.io.rundir import RunDir

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e


def test_the_getting_started_walkthrough_runs_as_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sim_mock(monkeypatch)
    profile = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    profile["flight"] = dict(profile.get("flight") or {}, **CI_FLIGHT)  # hover_measure_s 2
    (tmp_path / "antx-walkthrough.yaml").write_text(yaml.safe_dump(profile))
    outputs = []
    for line in walkthrough_commands(PAGE.read_text()):
        argv = shlex.split(line)
        target = None
        if ">" in argv:
            at = argv.index(">")
            argv, target = argv[:at], argv[at + 1]
        if argv[1] == "fly" and "--profile" not in argv:
            argv += ["--profile", "antx-walkthrough.yaml"]  # the change the page states
        done = invoke_gcs(*argv[1:], cwd=tmp_path)
        assert done.exit_code == 0, f"{line}\n{done.output}"
        if target is not None:
            (tmp_path / target).write_text(done.stdout)
        outputs.append((line, done.output))
    text = "\n".join(out for _, out in outputs)
    assert "sized up: each trial flies" in outputs[0][1]
    run = RunDir.open(tmp_path / "logs" / "latest")
    assert run.complete_trials() == [0, 1]
    assert "from the setpoint in force (lag included)" in text  # the live error per segment
    assert "verdict: e_pos" in text
    doc = json.loads((tmp_path / "run.json").read_text())
    assert doc["version"] == 6 and doc["verdict"]["flights"] == 2
    assert len((tmp_path / "table.csv").read_text().splitlines()) == 3  # header + 2 trials
    assert (tmp_path / "plots" / "epos.svg").is_file()
    best = load_trajectory(tmp_path / "best-setpoints.csv")
    assert best.source["type"] == "samples"
    assert (tmp_path / "report.html").read_text().startswith("<!DOCTYPE html>")
