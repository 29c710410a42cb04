"""What ``gcs report`` exports for other tools: the table as CSV, and the learned setpoints as
a ``samples`` file (docs/trajectories.md) that gcs, or another stack, flies as a trajectory.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np

from gcs.app.report import RunLearning
from gcs.core.trials import iteration_of, trial_errors
from gcs.errors import RunLogError
from gcs.io.atomic import atomic_write_text
from gcs.io.rundir import RunDir

__all__ = ["TABLE_COLUMNS", "write_rows_csv", "write_table_csv", "best_learned_trial",
           "setpoints_samples", "write_setpoints"]  # fmt: skip

#: The columns of ``--csv``, in order (the keys of the JSON rows that are one value each).
TABLE_COLUMNS = (
    "trial", "iteration", "status", "epos_m", "epos_pct", "change_pct", "max_err_m",
    "epos_3d_m", "rms_north_m", "rms_east_m", "rms_down_m", "start_offset_m",
    "vehicle_time_rate", "repeat_of", "sp_rms_m", "sp_max_m", "floor_m", "floor_ratio",
    "floor_z", "at_floor", "converged", "reason",
)  # fmt: skip


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.9g}"
    return str(value)


def write_rows_csv(path: Path, rows: list[dict], comment: str | None = None) -> Path:
    """Write dictionaries as CSV (header from the first row's keys; empty cell for null).

    ``path``: the file (written atomically; its directory created if missing). ``rows``: the rows,
    each with the same keys. ``comment``: a first line ``# comment``.
    """
    buf = io.StringIO()
    if comment:
        buf.write(f"# {comment}\n")
    columns = list(rows[0]) if rows else []
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in columns])
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, buf.getvalue())
    return path


def write_table_csv(path: Path, json_rows: list[dict]) -> Path:
    """Write the report's table as CSV: one line per trial, the columns :data:`TABLE_COLUMNS`
    that the run has (SI units, as in the JSON rows; empty where the JSON has null).
    """
    present = [c for c in TABLE_COLUMNS if any(c in r for r in json_rows)]
    rows = [{c: r.get(c) for c in present} for r in json_rows]
    for row, src in zip(rows, json_rows, strict=True):
        if "trial" not in src:  # runs without a repeat: the iteration is the trial number
            row.pop("trial", None)
    return write_rows_csv(path, rows)


def best_learned_trial(run: RunDir, learning: RunLearning) -> int:
    """The complete trial with the smallest e_pos among those learned (j >= 1)."""
    learned = [t for t in learning.trials if iteration_of(t, learning.repeats) >= 1]
    if not learned:
        raise RunLogError(
            f"--export-setpoints: {run.path} has no learned trial yet (trial 0 and its repeats "
            "fly the reference); fly one more trial first"
        )
    return min(learned, key=lambda t: trial_errors(run.measured_trial(t, _measurement(run)))[0])


def _measurement(run: RunDir) -> str:
    return run.profile().mocap.measurement


def setpoints_samples(run: RunDir, trial: int) -> np.ndarray:
    """Trial ``trial``'s setpoints as samples: (t_s, north, east, down), local NED.

    The first row is the hover point the trial started from, one sample before the first
    setpoint; then setpoint u(k) at t_k + t_ilc_s (k = 0..N-1), the time it was held until;
    the last setpoints are pinned to the end's hover point, so the file ends where it began
    as the samples format asks.
    """
    sp = run.read_setpoints(trial)
    ref = run.reference()
    dt = run.t_ilc_s
    t = np.arange(len(sp) + 1) * dt
    pos = np.vstack([ref.pos_ned_m[0], sp])
    return np.column_stack([t, pos])


def write_setpoints(run: RunDir, path: Path, trial: int) -> Path:
    """Write a trial's setpoints as a ``samples`` CSV (docs/trajectories.md).

    ``path``: the ``.csv`` file (written atomically). ``trial``: the trial
    (:func:`best_learned_trial`).
    """
    table = setpoints_samples(run, trial)
    lines = [
        f"# setpoints of trial {trial} of run {run.path.resolve().name} (gcs report "
        "--export-setpoints): time [s], local NED position [m]; first row the hover point",
        "t_s,north_m,east_m,down_m",
        *(",".join(f"{v:.6f}" for v in row) for row in table),
    ]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path
