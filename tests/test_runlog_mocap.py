"""Trial CSVs with the mocap columns, raw samples beside them, and what learning measures."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from synthetic import SHORT, fly_synthetic, profile

from gcs.app.learn import learn_run
from gcs.app.report import mocap_lines, run_metrics
from gcs.core.trials import trial_errors
from gcs.errors import RunLogError
from gcs.io.config import trajectory_from_dict
from gcs.io.mocap_samples import MocapSeries, read_mocap_csv
from gcs.io.runlog import MOCAP_GRID_COLUMNS, TRIAL_COLUMNS, RunDir, TrialStatus


def raw(n: int = 5) -> MocapSeries:
    t = 100.0 + np.arange(n) / 120
    return MocapSeries(
        np.arange(n), t, np.full(n, np.nan), np.ones(n, bool),
        np.tile([0.1, 1.5, 0.2], (n, 1)), np.tile([1.0, 0, 0, 0], (n, 1)),
    )  # fmt: skip


def with_mocap(run: RunDir, j: int, offset_m: float, measurement: str | None = None) -> None:
    """Trial j flown (synthetic), re-recorded with a mocap that sees it ``offset_m`` north."""
    record = fly_synthetic(run, j)
    (run.path / f"trial-{j:03d}.json").unlink()  # re-write it with the mocap columns
    (run.path / f"trial-{j:03d}.csv").unlink()
    mocap = record.pos_ned_m + np.array([offset_m, 0.0, 0.0])
    record = dataclasses.replace(record, mocap_ned_m=mocap)
    e, m = trial_errors(record.measured(measurement or "mocap"))
    run.write_trial(j, record, TrialStatus(j, True, epos_m=e, max_err_m=m,
                                           extra={"mocap_lag_s": 0.012}), raw())  # fmt: skip


@pytest.fixture
def run(tmp_path: Path) -> RunDir:
    return RunDir.create(tmp_path, profile(), trajectory_from_dict(SHORT), "smoother", run_id="r")


def test_mocap_columns_and_raw_samples_are_written_and_read_back(run: RunDir) -> None:
    with_mocap(run, 0, 0.03)
    header = (run.path / "trial-000.csv").read_text().splitlines()[0].split(",")
    assert tuple(header) == TRIAL_COLUMNS + MOCAP_GRID_COLUMNS
    record = run.read_trial(0)
    np.testing.assert_allclose(record.mocap_ned_m - record.pos_ned_m, [[0.03, 0, 0]] * len(
        record.t_s), atol=1e-8)  # fmt: skip
    assert len(read_mocap_csv(run.path / "mocap-000.csv")) == 5


def test_old_logs_without_mocap_still_read_and_measure_the_estimate(run: RunDir) -> None:
    fly_synthetic(run, 0)
    record = run.read_trial(0)
    assert record.mocap_ned_m is None and record.measured("mocap") is record
    assert mocap_lines(run) == []


def test_learning_and_e_pos_use_the_mocap_by_default(run: RunDir) -> None:
    with_mocap(run, 0, 0.03)
    record = run.read_trial(0)
    by_mocap = trial_errors(record.measured("mocap"))[0]
    by_estimate = trial_errors(record)[0]
    assert by_mocap != pytest.approx(by_estimate)
    assert run_metrics(run)[0].epos_m == pytest.approx(by_mocap)
    assert run_metrics(run, "estimate")[0].epos_m == pytest.approx(by_estimate)
    lines = mocap_lines(run)
    assert lines[0] == "measurement: mocap (mocap.measurement)"
    assert f"by mocap {by_mocap:.4f} m" in lines[1] and "lags the mocap by 12 ms" in lines[1]
    learn_run(run)  # learns from the mocap: the disturbance estimate shows the 3 cm offset
    d_hat, _ = run.read_estimate(0)
    assert np.median(d_hat[:, 0]) > 0.01


def test_a_mocap_gap_on_the_grid_refuses_mocap_learning_naming_the_fix(run: RunDir) -> None:
    record = fly_synthetic(run, 0)
    mocap = record.pos_ned_m.copy()
    mocap[10] = np.nan
    with pytest.raises(RunLogError, match="k = 10.*mocap.measurement: estimate"):
        dataclasses.replace(record, mocap_ned_m=mocap).measured("mocap")


def test_a_retried_trial_keeps_the_aborted_attempts_raw_samples(run: RunDir) -> None:
    record = fly_synthetic(run, 0)
    (run.path / "trial-000.json").unlink()
    (run.path / "trial-000.csv").unlink()
    run.write_trial(0, record, TrialStatus(0, False, reason="mocap: lost"), raw(3))
    run.write_trial(0, record, TrialStatus(0, True, epos_m=0.1, max_err_m=0.2), raw(4))
    assert len(read_mocap_csv(run.path / "aborted" / "mocap-000-attempt-1.csv")) == 3
    assert len(read_mocap_csv(run.path / "mocap-000.csv")) == 4
