"""The decisions of a learning step in words (gcs.app.report_text)."""

from __future__ import annotations

import pytest

from gcs.app.report_text import decision_lines


def _revert_record(epos_m: float, compared_m: float, threshold_m: float) -> dict:
    """A learn record whose safeguard fell back to trial 4 with step 0.5 (the fields of a
    firmware flight's ``learn-005.json``), its figures given."""
    return {
        "trial": 5,
        "next_trial": 6,
        "next_iteration": 3,
        "setpoints": {"rms_m": 1.27, "max_m": 2.14},
        "decision": {
            "safeguard": {
                "action": "revert",
                "anchor_trial": 4,
                "step": 0.5,
                "epos_m": epos_m,
                "best_trial": 4,
                "best_epos_m": compared_m,
                "compared_trial": 4,
                "compared_epos_m": compared_m,
                "threshold_m": threshold_m,
            },
            "axes": [{}, {}],
        },
    }


@pytest.mark.parametrize(
    ("epos_m", "compared_m", "threshold_m"),
    [(0.5451717, 0.3769724, 0.5443308), (0.2, 0.1, 0.15), (1.0, 0.9999, 0.99995)],
)
def test_a_fall_back_names_both_trials_e_pos_and_the_allowance_between(
    epos_m: float, compared_m: float, threshold_m: float
) -> None:
    """The line gives the trial's e_pos, the compared trial's and the allowance it exceeded,
    so that a reader does not take the allowance for the compared trial's e_pos."""
    line = decision_lines(_revert_record(epos_m, compared_m, threshold_m))[0]
    assert line.startswith("safeguard: trial 5 came out worse than trial 4 "), line
    assert f"e_pos {1e3 * epos_m:.1f} mm against {1e3 * compared_m:.1f} mm, " in line, line
    assert f"above its allowance of {1e3 * threshold_m:.1f} mm" in line, line
    assert line.endswith("fell back to trial 4 with step 0.5"), line


def test_a_record_of_an_older_run_without_the_compared_e_pos_still_reads() -> None:
    """Records written before ``compared_epos_m`` existed carry ``best_epos_m`` only; older
    still, neither: the line then leaves the compared e_pos out rather than print nan."""
    record = _revert_record(0.5, 0.4, 0.45)
    guard = record["decision"]["safeguard"]
    del guard["compared_epos_m"]
    assert "against 400.0 mm" in decision_lines(record)[0]
    del guard["best_epos_m"]
    line = decision_lines(record)[0]
    assert "nan" not in line and "(e_pos 500.0 mm, above its allowance" in line, line


def test_a_step_cut_by_the_profiles_model_names_the_axis_and_the_fraction() -> None:
    """``minmax_step`` below 1 on an axis: one line with that axis and its fraction; records
    without the field (older runs) or at 1 say nothing of it."""
    record = _revert_record(0.5, 0.4, 0.45)
    record["decision"]["safeguard"] = None
    assert not any(line.startswith("step cut") for line in decision_lines(record))
    record["decision"]["axes"] = [{"minmax_step": 1.0}, {"minmax_step": 0.574}]
    cut = [line for line in decision_lines(record) if line.startswith("step cut")]
    assert len(cut) == 1 and cut[0].endswith("fraction taken east 0.57"), cut
