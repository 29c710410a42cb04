"""The raw-sample file: exact round trip, atomic write, malformed files refused."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gcs.errors import RunLogError
from gcs.io.mocap_samples import MOCAP_COLUMNS, MocapSeries, read_mocap_csv, write_mocap_csv


def sample_series() -> MocapSeries:
    rng = np.random.default_rng(1)
    n = 50
    tracked = np.ones(n, bool)
    tracked[10:13] = False
    pos = rng.normal(0, 2, (n, 3)).astype(np.float32).astype(float)
    quat = rng.normal(0, 1, (n, 4))
    quat = (quat / np.linalg.norm(quat, axis=1, keepdims=True)).astype(np.float32).astype(float)
    pos[~tracked] = np.nan
    quat[~tracked] = np.nan
    t = 123456.0 + np.cumsum(rng.uniform(0.003, 0.005, n))
    return MocapSeries(np.arange(n) + 7, t, np.full(n, np.nan), tracked, pos, quat)


def test_round_trip_is_float32_exact_and_microsecond_times(tmp_path: Path) -> None:
    series = sample_series()
    path = tmp_path / "mocap-000.csv"
    write_mocap_csv(path, series)
    back = read_mocap_csv(path)
    np.testing.assert_array_equal(back.seq, series.seq)
    np.testing.assert_array_equal(back.tracked, series.tracked)
    np.testing.assert_allclose(back.t_receipt_s, series.t_receipt_s, atol=5e-7, rtol=0)
    assert np.all(np.isnan(back.t_mocap_s))
    tr = series.tracked
    f32 = np.float32  # the library's values are float32: 9 digits give them back exactly
    np.testing.assert_array_equal(back.pos_m[tr].astype(f32), series.pos_m[tr].astype(f32))
    np.testing.assert_array_equal(back.quat_wxyz[tr].astype(f32), series.quat_wxyz[tr].astype(f32))
    assert np.all(np.isnan(back.pos_m[~tr]))
    assert path.read_text().splitlines()[0] == ",".join(MOCAP_COLUMNS)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mocap-000.csv"]  # no temp left


def test_empty_series_round_trip(tmp_path: Path) -> None:
    write_mocap_csv(tmp_path / "m.csv", MocapSeries.empty())
    assert len(read_mocap_csv(tmp_path / "m.csv")) == 0


def test_since_selects_by_receipt_time() -> None:
    series = sample_series()
    cut = float(series.t_receipt_s[20])
    assert list(series.since(cut).seq) == list(series.seq[20:])


def test_records_are_read_only_copies() -> None:
    tracked = np.ones(3, bool)
    series = MocapSeries(np.arange(3), np.arange(3.0), np.zeros(3), tracked, np.zeros((3, 3)),
                         np.tile([1.0, 0, 0, 0], (3, 1)))  # fmt: skip
    tracked[0] = False
    assert series.tracked[0]
    with pytest.raises(ValueError):
        series.tracked[0] = False


def test_wrong_orientation_refused() -> None:
    with pytest.raises(ValueError, match="pos_m must have shape"):
        MocapSeries(np.arange(4), np.zeros(4), np.zeros(4), np.ones(4, bool), np.zeros((3, 4)),
                    np.zeros((4, 4)))  # fmt: skip


def _corrupt(tmp_path: Path, row: int, column: str, value: str) -> Path:
    path = tmp_path / "m.csv"
    write_mocap_csv(path, sample_series())
    lines = path.read_text().splitlines()
    fields = lines[row].split(",")
    fields[MOCAP_COLUMNS.index(column)] = value
    lines[row] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize(
    ("row", "column", "value", "match"),
    [
        (5, "seq", "3", "line 6, seq: not increasing"),
        (5, "t_receipt_s", "1.0", "line 6, t_receipt_s: goes back in time"),
        (5, "t_receipt_s", "nan", "line 6, t_receipt_s: missing"),
        (5, "tracked", "2", "line 6, tracked: must be 0 or 1"),
        (5, "x_sys_m", "nan", "line 6, pose: missing"),
        (5, "qw_sys", "3.0", "line 6, quaternion"),
        (5, "y_sys_m", "abc", "not a number"),
    ],
)
def test_malformed_file_refused_naming_line_and_column(
    tmp_path: Path, row: int, column: str, value: str, match: str
) -> None:
    with pytest.raises(RunLogError, match=match):
        read_mocap_csv(_corrupt(tmp_path, row, column, value))


def test_bad_header_and_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "m.csv"
    path.write_text("seq,t\n")
    with pytest.raises(RunLogError, match="header must be"):
        read_mocap_csv(path)
    with pytest.raises(RunLogError, match="cannot read"):
        read_mocap_csv(tmp_path / "missing.csv")
    truncated = tmp_path / "t.csv"
    write_mocap_csv(truncated, sample_series())
    text = truncated.read_text()
    truncated.write_text(text[: text.rindex(",")] + "\n")
    with pytest.raises(RunLogError, match="fields, expected 11"):
        read_mocap_csv(truncated)


def test_untracked_rows_may_hold_anything_in_the_pose(tmp_path: Path) -> None:
    path = _corrupt(tmp_path, 12, "x_sys_m", "nan")  # row 12 is sample 10: untracked
    back = read_mocap_csv(path)
    assert not back.tracked[10] and math.isnan(back.pos_m[10, 0])
