"""The study's figures: flights to the floor as a count, the steady state, the plot's axis."""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib
import pytest
from test_study import plan_of

from gcs.core.study import recommend, steady_window, summarise_setting

matplotlib.use("Agg")


def _plant(epos: list[float]) -> dict:
    return {"epos_m": epos, "setpoint_rms_m": 0.1, "limit_active": 0.0, "failed": None}


def test_half_the_plants_at_the_floor_is_a_count_and_the_others_are_counted_apart(
    tmp_path: Path,
) -> None:
    plan = plan_of(tmp_path, iterations=4, steady_trials=3)
    floor = 0.01 * math.sqrt(math.pi / 2)
    plants = [
        _plant([0.5, 0.2, floor, floor, floor]),  # at the floor in flight 3
        _plant([0.5, 0.2, 0.1, floor, floor]),  # in flight 4
        _plant([0.5, 0.2, 0.1, 0.05, 0.04]),  # never
        _plant([0.5, 0.3, 0.1, 0.05, 0.04]),  # never
    ]
    s = summarise_setting(plan, 0, 0, plants)
    assert (s.reached_floor, s.never_reached_floor, s.flights_to_floor) == (2, 2, 3.5)
    record = json.loads(json.dumps(s.as_dict()))
    assert record["flights_to_floor"] == 3.5 and record["never_reached_floor"] == 2
    _, reason = recommend([s])
    assert "the floor in 3.5 flights (median of the 2 of 4 plants that reached it)" in reason
    nobody = summarise_setting(plan, 0, 0, plants[2:])
    assert math.isnan(nobody.flights_to_floor) and nobody.as_dict()["flights_to_floor"] is None
    assert "none of its 2 plants reached the floor" in recommend([nobody])[1]


def test_the_steady_state_is_the_last_learned_trials_never_the_first(tmp_path: Path) -> None:
    assert [steady_window(n, 3) for n in (1, 2, 3, 4, 6, 10)] == [1, 1, 1, 2, 3, 3]
    plan = plan_of(tmp_path, iterations=3, steady_trials=3)
    s = summarise_setting(plan, 0, 0, [_plant([0.5, 0.106, 0.04, 0.017])] * 2)
    assert s.steady_trials == 1 and s.steady_mean_m == pytest.approx(0.017)


def test_the_study_plot_numbers_its_trials_in_whole_numbers(tmp_path: Path) -> None:
    from gcs.app.study_view import write_study_figures

    plan = plan_of(tmp_path, iterations=2, steady_trials=1)
    s = summarise_setting(plan, 0, 0, [_plant([0.5, 0.1, 0.05])] * 2)
    out = tmp_path / "figures"
    out.mkdir()
    import matplotlib.pyplot as plt

    made = []
    real_savefig = plt.Figure.savefig

    def keep(fig, *args, **kwargs):  # noqa: ANN001, ANN202
        made.append([t for ax in fig.axes for t in ax.get_xticks()])
        return real_savefig(fig, *args, **kwargs)

    plt.Figure.savefig = keep
    try:
        write_study_figures([s], out)
    finally:
        plt.Figure.savefig = real_savefig
    epos_ticks = made[0]
    assert epos_ticks and all(float(t).is_integer() for t in epos_ticks), epos_ticks
