"""``gcs montecarlo --adaptive``: the paper's study and the new options on the same plants."""

from __future__ import annotations

import json
from pathlib import Path

from cli_runner import invoke as gcs_invoke

from gcs.app.montecarlo_study import study_settings


def test_montecarlo_adaptive_prints_the_comparison_and_writes_json(tmp_path: Path) -> None:
    out = tmp_path / "mc.json"
    args = ["montecarlo", "--levels", "0.05,0.4", "--plants", "3", "--repeats", "2",
            "--iterations", "30", "--adaptive", "--json", str(out)]  # fmt: skip
    result = gcs_invoke(args)
    assert result.exit_code == 0, result.output
    assert "(adaptive)" in result.output  # the comparison line of each level
    assert "j = 2..5" in result.output and "diverged" in result.output
    data = json.loads(out.read_text())
    algorithms = {(r["algorithm"], r["uncertainty"]) for r in data["rows"]}
    assert ("smoother+adaptive", 0.4) in algorithms and ("kilc", 0.05) in algorithms
    assert [c["uncertainty"] for c in data["comparison"]] == [0.05, 0.4]
    assert {"paper_mean_2_5", "new_mean_2_5", "new_diverged"} <= set(data["comparison"][0])


def test_montecarlo_default_output_has_no_adaptive_rows(tmp_path: Path) -> None:
    out = tmp_path / "mc.json"
    args = ["montecarlo", "--levels", "0.05", "--plants", "3", "--repeats", "2",
            "--iterations", "30", "--json", str(out)]  # fmt: skip
    result = gcs_invoke(args)
    assert result.exit_code == 0, result.output
    assert "adaptive" not in result.output
    assert isinstance(json.loads(out.read_text()), list)


def test_montecarlo_adaptive_refuses_a_study_too_large_for_memory() -> None:
    # 2000 x 100 runs: the paper's study fits (its runs keep one trial), the new options'
    # trials (every one of every run, about 60 GB) do not
    study_settings("0.05", 2000, 100, 30, 200, 1, False, adaptive=False)
    result = gcs_invoke(["montecarlo", "--plants", "2000", "--repeats", "100", "--adaptive"])
    assert result.exit_code == 2 and "GB" in result.output and "every trial" in result.output
