"""Raw motion-capture samples of a trial: the record, its CSV file, and the trial's mocap on
its grid (:class:`MocapTrial`).

One row per frame the mocap client delivered, as received, before any frame mapping::

    seq,t_receipt_s,t_mocap_s,tracked,x_sys_m,y_sys_m,z_sys_m,qw_sys,qx_sys,qy_sys,qz_sys

- ``seq``: the client's count of delivered frames (gaps never occur in one file; a frame the
  library skipped while the reader was late is simply not there);
- ``t_receipt_s``: ``time.monotonic()`` when the library handed the frame over [s], the
  clock of everything else gcs time-stamps on this machine;
- ``t_mocap_s``: the mocap system's own time stamp [s], ``nan`` when the library gives none
  (``motioncapture`` 1.1 exposes none to Python);
- ``tracked``: 1 if the rigid body was in the frame, 0 if it was not (occluded, or not
  streamed); its pose is then ``nan``;
- pose in the mocap system's own axes (``sys``): position [m] and orientation quaternion
  ``w, x, y, z`` (body to world). The mapping to NED belongs to the run's profile.

Written atomically (temporary file + rename). Reading refuses a file whose header, order,
flags or poses are inconsistent, naming the file, line and column.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gcs.errors import RunLogError
from gcs.io.atomic import atomic_write_text

__all__ = ["MOCAP_COLUMNS", "MocapSeries", "MocapTrial", "write_mocap_csv", "read_mocap_csv"]

MOCAP_COLUMNS = (
    "seq", "t_receipt_s", "t_mocap_s", "tracked",
    "x_sys_m", "y_sys_m", "z_sys_m",
    "qw_sys", "qx_sys", "qy_sys", "qz_sys",
)  # fmt: skip


@dataclass(frozen=True)
class MocapSeries:
    """Consecutive mocap samples of one rigid body, as arrays (system frame).

    ``seq``: delivery counter, shape (N,), int. ``t_receipt_s``: monotonic receipt times, shape (N,)
    [s]. ``t_mocap_s``: the system's own time stamps, shape (N,) [s], NaN where unknown.
    ``tracked``: rigid body present in the frame, shape (N,), bool. ``pos_m``: position in the
    system's axes, shape (N, 3) [m]; NaN rows where not tracked. ``quat_wxyz``: orientation (body to
    system world), shape (N, 4); NaN rows where not tracked.
    """

    seq: np.ndarray
    t_receipt_s: np.ndarray
    t_mocap_s: np.ndarray
    tracked: np.ndarray
    pos_m: np.ndarray
    quat_wxyz: np.ndarray

    def __post_init__(self) -> None:
        n = np.asarray(self.seq).shape[0] if np.ndim(self.seq) == 1 else -1
        expected = {
            "seq": (n,),
            "t_receipt_s": (n,),
            "t_mocap_s": (n,),
            "tracked": (n,),
            "pos_m": (n, 3),
            "quat_wxyz": (n, 4),
        }
        for name, shape in expected.items():
            value = np.asarray(getattr(self, name))
            if value.shape != shape:
                raise ValueError(f"MocapSeries.{name} must have shape {shape}, got {value.shape}")
        # own copies, read-only: a frozen record must not change under its holder
        for name, dtype in (("seq", np.int64), ("tracked", bool)) + tuple(
            (n, float) for n in ("t_receipt_s", "t_mocap_s", "pos_m", "quat_wxyz")
        ):
            value = np.array(getattr(self, name), dtype=dtype)
            value.flags.writeable = False
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return int(self.seq.shape[0])

    @classmethod
    def empty(cls) -> MocapSeries:
        """A series of no samples."""
        return cls(
            np.zeros(0, np.int64),
            np.zeros(0),
            np.zeros(0),
            np.zeros(0, bool),
            np.zeros((0, 3)),
            np.zeros((0, 4)),
        )

    def since(self, t_s: float) -> MocapSeries:
        """The samples received at or after ``t_s``.

        ``t_s``: monotonic time [s].
        """
        keep = self.t_receipt_s >= t_s
        return MocapSeries(
            self.seq[keep],
            self.t_receipt_s[keep],
            self.t_mocap_s[keep],
            self.tracked[keep],
            self.pos_m[keep],
            self.quat_wxyz[keep],
        )


def _row(series: MocapSeries, i: int) -> str:
    def num(v: float, fmt: str) -> str:
        return format(v, fmt) if math.isfinite(v) else "nan"

    tracked = bool(series.tracked[i])
    pose = [*series.pos_m[i], *series.quat_wxyz[i]] if tracked else [math.nan] * 7
    fields = [
        str(int(series.seq[i])),
        num(series.t_receipt_s[i], ".6f"),
        num(series.t_mocap_s[i], ".6f"),
        "1" if tracked else "0",
        *(num(v, ".9g") for v in pose),
    ]
    return ",".join(fields)


@dataclass(frozen=True)
class MocapTrial:
    """The motion capture of one trial.

    ``series``: raw samples received during the trial, from the watch's longest gap before its start
    (system axes, receipt times). ``pos_ned_m``: mocap position on the trial's grid, shape (N+1, 3)
    [m, NED]; NaN where no tracked samples bracket the grid time within the longest gap the watch
    allows (:func:`gcs.flight.mocap.link.trial_mocap`). ``lag_s``: how far the vehicle's estimate
    lags behind the mocap [s] (None: not measurable).
    """

    series: MocapSeries
    pos_ned_m: np.ndarray
    lag_s: float | None


def write_mocap_csv(path: Path, series: MocapSeries) -> None:
    """Write raw samples atomically (times to the microsecond, poses float32-exact)."""
    lines = [",".join(MOCAP_COLUMNS)] + [_row(series, i) for i in range(len(series))]
    atomic_write_text(Path(path), "\n".join(lines) + "\n")


def _table(path: Path) -> list[list[str]]:
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise RunLogError(f"{path}: cannot read ({exc.strerror})") from exc
    if not rows or tuple(rows[0]) != MOCAP_COLUMNS:
        raise RunLogError(f"{path}: header must be {','.join(MOCAP_COLUMNS)}")
    return rows[1:]


def read_mocap_csv(path: Path) -> MocapSeries:
    """Read and check a raw-sample file.

    Raises ``RunLogError``: header, counts, order, flags or poses inconsistent (one line naming the
    line and column).
    """
    path = Path(path)
    rows = _table(path)
    width = len(MOCAP_COLUMNS)
    for i, row in enumerate(rows):
        if len(row) != width:
            raise RunLogError(f"{path}: line {i + 2} has {len(row)} fields, expected {width}")
    try:
        table = np.array([[float(v) for v in row] for row in rows], dtype=float).reshape(-1, width)
    except ValueError as exc:
        raise RunLogError(f"{path}: not a number ({exc})") from exc
    _check(path, table)
    tracked = table[:, 3] == 1
    pose = np.where(tracked[:, None], table[:, 4:], np.nan)
    return MocapSeries(
        table[:, 0].astype(np.int64), table[:, 1], table[:, 2], tracked, pose[:, :3], pose[:, 3:]
    )


def _check(path: Path, table: np.ndarray) -> None:
    def bad(rows: np.ndarray, column: str, why: str) -> RunLogError:
        return RunLogError(f"{path}: line {int(rows[0]) + 2}, {column}: {why}")

    seq, t, t_mocap, flag = table[:, 0], table[:, 1], table[:, 2], table[:, 3]
    if (r := np.flatnonzero(~np.isfinite(seq) | (seq != np.round(seq)))).size:
        raise bad(r, "seq", "not an integer")
    if (r := np.flatnonzero(np.diff(seq) <= 0)).size:
        raise bad(r + 1, "seq", "not increasing")
    if (r := np.flatnonzero(~np.isfinite(t))).size:
        raise bad(r, "t_receipt_s", "missing")
    if (r := np.flatnonzero(np.diff(t) < 0)).size:
        raise bad(r + 1, "t_receipt_s", "goes back in time")
    known = np.flatnonzero(np.isfinite(t_mocap))
    if (r := known[1:][np.diff(t_mocap[known]) < 0]).size:
        raise bad(r, "t_mocap_s", "goes back in time")
    if (r := np.flatnonzero((flag != 0) & (flag != 1))).size:
        raise bad(r, "tracked", "must be 0 or 1")
    pose = table[flag == 1, 4:]
    rows = np.flatnonzero(flag == 1)
    if (r := rows[~np.all(np.isfinite(pose), axis=1)]).size:
        raise bad(r, "pose", "missing or not finite on a tracked row")
    norms = np.linalg.norm(pose[:, 3:], axis=1)
    if (r := rows[np.abs(norms - 1.0) > 1e-3]).size:
        raise bad(r, "quaternion", "not of unit length")
