"""``gcs montecarlo --adaptive``: the paper's study and the new options on the same plants."""

from __future__ import annotations

from cli_runner import invoke as gcs_invoke

from gcs.app.montecarlo_study import study_settings


def test_montecarlo_adaptive_refuses_a_study_too_large_for_memory() -> None:
    # 2000 x 100 runs: the paper's study fits (its runs keep one trial), the new options'
    # trials (every one of every run, about 60 GB) do not
    study_settings("0.05", 2000, 100, 30, 200, 1, False, adaptive=False)
    result = gcs_invoke(["montecarlo", "--plants", "2000", "--repeats", "100", "--adaptive"])
    assert result.exit_code == 2 and "GB" in result.output and "every trial" in result.output
