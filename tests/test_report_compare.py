"""gcs report RUN RUN: runs compared; the exports (CSV, SVG/PDF figures, learned setpoints)."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from cli_runner import invoke as gcs_invoke
from synthetic import make_adaptive_run, make_run

from gcs.app.report_export import setpoints_samples
from gcs.core.trials import trial_errors
from gcs.io.config import load_trajectory


def invoke(*args: object):
    return gcs_invoke([str(a) for a in args], env={"COLUMNS": "200"})


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory):
    root = tmp_path_factory.mktemp("runs")
    paper = make_run(root / "paper", trials=3)
    adaptive = make_adaptive_run(root / "adaptive", trials=4, gust_m=0.01)
    return paper, adaptive


def test_two_runs_side_by_side_with_what_differed(runs, tmp_path: Path, monkeypatch) -> None:
    import gcs.cli

    monkeypatch.setattr(gcs.cli.console, "width", 200)
    paper, adaptive = runs
    result = invoke("report", paper.path, adaptive.path, "--plot", tmp_path / "p",
                    "--csv", tmp_path / "c.csv")  # fmt: skip
    assert result.exit_code == 0, result.output
    out = result.output
    assert "2 runs compared" in out and "e_pos [mm] per trial" in out
    assert "profile differs" in out and "antx-adaptive" in out
    assert "learning differs: profile.learning.adaptive" in out  # the adaptive section
    assert "different trajectories" not in out  # the same tiny eight
    pairs = (("p", paper), ("a", adaptive))
    e = {(n, j): trial_errors(r.read_trial(j))[0] for n, r in pairs for j in r.complete_trials()}
    rows = list(csv.reader(line for line in (tmp_path / "c.csv").open() if line[0] != "#"))
    # both runs are named "run" by make_run: each is named by its path instead
    assert rows[0] == ["trial", str(paper.path), str(adaptive.path)]
    assert float(rows[1][1]) == pytest.approx(1e3 * e["p", 0], abs=0.05)
    assert float(rows[4][2]) == pytest.approx(1e3 * e["a", 3], abs=0.05)
    assert rows[4][1] == ""  # the paper's run flew three trials
    assert (tmp_path / "p" / "compare-epos.png").read_bytes()[:4] == b"\x89PNG"
    doc = json.loads(invoke("report", paper.path, adaptive.path, "--json").output)
    assert doc["format"] == "gcs-report-compare" and doc["same_trajectory"] is True
    assert [d["verdict"]["best_trial"] for d in doc["runs"]] == [2, 3]
    assert any(line.startswith("profile differs") for line in doc["differences"])


def test_runs_of_different_trajectories_are_compared_and_said_so(runs, tmp_path: Path) -> None:
    paper, _ = runs
    other = tmp_path / "other"
    shutil.copytree(paper.path, other)
    manifest = json.loads((other / "manifest.json").read_text())
    manifest["trajectory"]["name"] = "circle-ish"
    (other / "manifest.json").write_text(json.dumps(manifest))
    result = invoke("report", paper.path, other)
    assert result.exit_code == 0, result.output
    assert "note: these runs fly different trajectories (tiny, circle-ish)" in result.output
    assert "trajectory differs" in result.output
    doc = json.loads(invoke("report", paper.path, other, "--json").output)
    assert doc["same_trajectory"] is False


def test_the_table_as_csv_and_the_figures_as_svg_and_pdf(runs, tmp_path: Path) -> None:
    _, adaptive = runs
    result = invoke("report", adaptive.path, "--csv", tmp_path / "t.csv", "--plot",
                    tmp_path / "svg", "--format", "svg")  # fmt: skip
    assert result.exit_code == 0, result.output
    with (tmp_path / "t.csv").open() as f:
        table = list(csv.DictReader(f))
    doc = json.loads(invoke("report", adaptive.path, "--json").output)
    assert [int(r["trial"]) for r in table] == [r["trial"] for r in doc["rows"]]
    for got, want in zip(table, doc["rows"], strict=True):
        assert float(got["epos_m"]) == pytest.approx(want["epos_m"], rel=1e-8)
        assert got["repeat_of"] == ("" if want["repeat_of"] is None else str(want["repeat_of"]))
        assert got["at_floor"] == str(want["at_floor"]).lower()
    assert "delta_pct" not in table[0]
    svg = sorted(p.name for p in (tmp_path / "svg").iterdir())
    assert "epos.svg" in svg and "xy.svg" in svg
    assert (tmp_path / "svg" / "epos.svg").read_text().lstrip().startswith("<?xml")
    result = invoke("report", adaptive.path, "--plot", tmp_path / "pdf", "--format", "pdf")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "pdf" / "xy.pdf").read_bytes()[:5] == b"%PDF-"


def test_the_best_learned_setpoints_as_a_samples_file_gcs_reads(runs, tmp_path: Path) -> None:
    _, adaptive = runs
    out = tmp_path / "best.csv"
    result = invoke("report", adaptive.path, "--export-setpoints", out)
    assert result.exit_code == 0, result.output
    learned = [t for t in adaptive.complete_trials() if t >= 2]  # 1 repeats trial 0
    best = min(learned, key=lambda t: trial_errors(adaptive.read_trial(t))[0])
    assert f"the setpoints of trial {best}" in result.output
    # gcs reads it as any samples trajectory: the same points, starting at the hover point
    spec = load_trajectory(out)
    assert spec.source["type"] == "samples"
    samples = np.loadtxt(out, delimiter=",", skiprows=2)
    sp = adaptive.read_setpoints(best)
    np.testing.assert_allclose(samples[1:, 1:], sp, atol=1e-6)
    np.testing.assert_allclose(samples[0, 1:], adaptive.reference().pos_ned_m[0], atol=1e-6)
    np.testing.assert_allclose(np.diff(samples[:, 0]), adaptive.t_ilc_s, atol=1e-6)
    np.testing.assert_allclose(setpoints_samples(adaptive, best), samples, atol=1e-6)
    assert np.hypot(*(samples[-1, 1:3] - samples[0, 1:3])) < 1e-3  # ends where it began
