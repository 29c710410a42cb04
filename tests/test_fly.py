"""The run directory as the flight layer's trial source (no vehicle: recordings are built here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from synthetic import make_run, true_plants

from gcs.app.fly import RunSource, prepare_run
from gcs.app.session import to_record
from gcs.core.model import simulate
from gcs.errors import ProfileError, RunLogError, TrajectoryError
from gcs.flight.trial import TrialRecording
from gcs.io.config import profile_from_dict
from gcs.io.rundir import RunDir


def recording(run: RunDir, setpoints: np.ndarray, complete: bool = True) -> TrialRecording:
    """What the flight layer would hand over: a simulated flight of ``setpoints``."""
    ref = run.reference()
    start = ref.pos_ned_m[0]
    pos = np.tile(start, (run.n_samples + 1, 1))
    for a, plant in enumerate(true_plants()):
        pos[1:, a] += simulate(plant, setpoints[:, a] - start[a])
    if not complete:
        pos[run.n_samples // 2 :] = np.nan
    return TrialRecording(
        t_s=ref.t_s,
        pos_ned_m=pos,
        vel_ned_m_s=np.gradient(pos, run.t_ilc_s, axis=0),
        sent_s=ref.t_s[:-1] + 0.001,
        interpolated=np.zeros(run.n_samples + 1, dtype=bool),
        complete=complete,
        abort_reason=None if complete else "interrupted",
        setpoints_ned_m=setpoints,
        t_ilc_s=run.t_ilc_s,
    )


def test_record_writes_the_trial_and_learns_the_next(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=0)
    rows = []
    source = RunSource(run, on_row=rows.append)
    sp = source.setpoints_for(0)
    np.testing.assert_allclose(sp, run.reference().pos_ned_m[:-1])
    np.testing.assert_allclose(source.hover_point_for(0), run.reference().pos_ned_m[0])
    source.record(0, recording(run, sp))
    assert run.complete_trials() == [0]
    assert (run.path / "setpoints-001.csv").exists()
    assert rows[-1][0].iteration == 0 and rows[-1][0].epos_m > 0
    source.record(1, recording(run, source.setpoints_for(1)))
    assert rows[-1][1].epos_m < 0.5 * rows[-1][0].epos_m  # learned between the trials
    status = run.read_status(1)
    assert status.extra["max_send_late_s"] == 0.0
    assert status.extra["max_sent_offset_s"] == pytest.approx(0.001)  # sent 1 ms after k t_ilc
    assert status.extra["vehicle_time_rate"] is None and status.extra["session"] is None


def test_to_record_holds_the_last_setpoint_and_marks_the_unsent_row(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=0)
    sp = run.read_setpoints(0)
    record = to_record(run, recording(run, sp))
    np.testing.assert_array_equal(record.sp_ned_m[-1], sp[-1])
    assert np.isnan(record.sp_sent_s[-1]) and np.all(np.isfinite(record.sp_sent_s[:-1]))


def test_record_incomplete_is_kept_but_never_learned_from(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=0)
    source = RunSource(run)
    source.record_incomplete(0, recording(run, run.read_setpoints(0), False), "interrupted")
    status = run.read_status(0)
    assert not status.complete and status.reason == "interrupted"
    assert run.next_trial() == 0
    assert not (run.path / "setpoints-001.csv").exists()


def test_a_flown_trial_whose_mocap_misses_a_grid_time_is_kept_and_flown_again(
    tmp_path: Path,
) -> None:
    """A complete flight whose mocap has no position at k = 0 (a stream that paused across
    the trial's start): learning cannot use it, and the flight's data are kept, marked
    incomplete, so that a resume flies the trial again."""
    from dataclasses import replace

    from gcs.io.mocap_samples import MocapSeries, MocapTrial

    run = make_run(tmp_path, trials=0)
    flown = recording(run, run.read_setpoints(0))
    on_grid = flown.pos_ned_m.copy()
    on_grid[0] = np.nan
    t = flown.t_s[1:]
    series = MocapSeries(
        seq=np.arange(t.size), t_receipt_s=t, t_mocap_s=np.full(t.size, np.nan),
        tracked=np.ones(t.size, dtype=bool), pos_m=flown.pos_ned_m[1:],
        quat_wxyz=np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1)),
    )  # fmt: skip
    holed = replace(flown, mocap=MocapTrial(series, on_grid, None))
    with pytest.raises(RunLogError, match="no mocap position at k = 0"):
        RunSource(run).record(0, holed)
    status = run.read_status(0)
    assert not status.complete and "no mocap position at k = 0" in status.reason
    assert run.next_trial() == 0 and not (run.path / "setpoints-001.csv").exists()
    kept = np.genfromtxt(run.trial_path(0), delimiter=",", names=True)
    np.testing.assert_allclose(kept["pos_north_m"], flown.pos_ned_m[:, 0])  # as flown
    assert np.isnan(kept["mocap_north_m"][0]) and np.isfinite(kept["mocap_north_m"][1:]).all()
    assert (run.path / "mocap-000.csv").exists()  # and the raw stream


def test_setpoints_outside_the_arena_are_refused(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=0)
    sp = run.read_setpoints(0)
    sp[7, 0] = 10.0  # beyond the 3 m arena
    path = run.path / "setpoints-000.csv"  # edited by hand: write_setpoints never rewrites
    lines = path.read_text().splitlines(keepends=True)
    cells = lines[8].split(",")
    lines[8] = ",".join([*cells[:2], "10.0", *cells[3:]])
    path.write_text("".join(lines))

    with pytest.raises(TrajectoryError, match="k = 7 .* outside the arena"):
        RunSource(run).setpoints_for(0)


def test_prepare_run_refuses_a_trajectory_beyond_the_vehicle(tmp_path: Path) -> None:
    from synthetic import SHORT, profile

    from gcs.io.config import trajectory_from_dict

    fast = trajectory_from_dict(dict(SHORT, period_s=1.5, ramp_s=0.5))
    with pytest.raises(TrajectoryError, match="exceeds the vehicle limit"):
        prepare_run(tmp_path, profile(), fast, "smoother")
    assert list(tmp_path.iterdir()) == []  # nothing created


def test_flight_settings_from_the_profile() -> None:
    from synthetic import profile

    base = profile()
    assert base.flight.sends_per_sample(base.t_ilc_s) == 3
    fast = profile_from_dict(dict(base.source, flight={"stream_rate_hz": 100}))
    assert fast.flight.stream_rate_hz == 100.0 and fast.flight.sends_per_sample(0.05) == 5
    bad = dict(base.source, flight={"stream_rate_hz": 50})
    with pytest.raises(ProfileError, match="stream_rate_hz"):
        profile_from_dict(bad)
    typo = dict(base.source, flight={"stream_rate": 60})
    with pytest.raises(ProfileError, match="flight.stream_rate"):
        profile_from_dict(typo)
