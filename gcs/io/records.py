"""The records of a run directory and their formats: trial tables, trial status, CSV, JSON.

A trial on the grid is a :class:`TrialRecord` (``trial-JJJ.csv``, columns
:data:`TRIAL_COLUMNS`, plus :data:`MOCAP_GRID_COLUMNS` with motion capture); its sidecar a
:class:`TrialStatus` (``trial-JJJ.json``). The helpers read and write the CSV and JSON of every
run file with the checks every reader relies on (header, numbers, plausible magnitudes); each
refusal is a :class:`~gcs.errors.RunLogError` naming the file.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gcs.errors import RunLogError

__all__ = [
    "TrialRecord",
    "TrialStatus",
    "json_safe",
    "json_text",
    "read_json",
    "csv_text",
    "read_csv",
    "check_plausible",
    "status_from_json",
    "is_number",
    "PLAUSIBLE",
    "TRIAL_COLUMNS",
    "MOCAP_GRID_COLUMNS",
    "MEASUREMENTS",
    "SETPOINT_COLUMNS",
    "REFERENCE_COLUMNS",
    "REFERENCE_YAW_COLUMNS",
    "ESTIMATE_COLUMNS",
    "ESTIMATE_DOWN_COLUMNS",
]

TRIAL_COLUMNS = (
    "k", "t_s",
    "ref_north_m", "ref_east_m", "ref_down_m",
    "sp_north_m", "sp_east_m", "sp_down_m",
    "pos_north_m", "pos_east_m", "pos_down_m",
    "vel_north_m_s", "vel_east_m_s", "vel_down_m_s",
    "sp_sent_s", "interpolated",
)  # fmt: skip
MOCAP_GRID_COLUMNS = ("mocap_north_m", "mocap_east_m", "mocap_down_m")
"""Optional last columns of a trial CSV: the motion capture on the grid (NaN: none there)."""
MEASUREMENTS = ("mocap", "estimate")
SETPOINT_COLUMNS = ("k", "t_s", "sp_north_m", "sp_east_m", "sp_down_m")
REFERENCE_COLUMNS = ("k", "t_s", "ref_north_m", "ref_east_m", "ref_down_m")
REFERENCE_YAW_COLUMNS = ("ref_yaw_deg",)
"""Last column of a reference file when the trajectory has a yaw (unwrapped: a turn past
180 degrees goes on counting) [deg]; absent when the yaw is held."""
ESTIMATE_COLUMNS = ("k", "t_s", "d_north_m", "d_east_m", "p_north_m2", "p_east_m2")
ESTIMATE_DOWN_COLUMNS = ("d_down_m", "p_down_m2")
"""Last columns of an estimate file when down is learned (absent otherwise)."""


@dataclass(frozen=True)
class TrialRecord:
    """One trial on the grid ``k = 0..N`` (row k holds u(k) and y(k)).

    ``t_s``: grid times ``k t_ilc_s`` [s] from the trial start. ``ref_ned_m``: reference yd(k),
    local NED [m]. ``sp_ned_m``: setpoint u(k) [m]; row N is the final setpoint held after the
    trial. ``pos_ned_m``: measured position y(k) [m]; NaN where an aborted trial has no data.
    ``vel_ned_m_s``: measured velocity [m/s]. ``sp_sent_s``: time the setpoint was first sent, from
    the trial start [s]; NaN for row N. ``interpolated``: True where the position was interpolated
    across a telemetry gap. ``mocap_ned_m``: motion-capture position on the grid [m, NED] (NaN where
    none); None without mocap.
    """

    t_s: np.ndarray
    ref_ned_m: np.ndarray
    sp_ned_m: np.ndarray
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    sp_sent_s: np.ndarray
    interpolated: np.ndarray
    mocap_ned_m: np.ndarray | None = None

    @property
    def columns(self) -> tuple[str, ...]:
        """The CSV columns of this record (the mocap ones only when it has mocap)."""
        return TRIAL_COLUMNS + (MOCAP_GRID_COLUMNS if self.mocap_ned_m is not None else ())

    def measured(self, measurement: str) -> TrialRecord:
        """The record whose ``pos_ned_m`` is what learning and e_pos use.

        ``measurement``: ``"mocap"`` (the motion capture when the record has it; else the estimate)
        or ``"estimate"`` (the vehicle's own).

        Returns: ``self``, or a copy with the mocap positions as ``pos_ned_m``.

        Raises ``RunLogError``: ``"mocap"`` with mocap columns that are NaN somewhere on the grid.
        """
        if measurement not in MEASUREMENTS:
            raise RunLogError(f"measurement must be one of {', '.join(MEASUREMENTS)}")
        if measurement == "estimate" or self.mocap_ned_m is None:
            return self
        bad = np.flatnonzero(~np.all(np.isfinite(self.mocap_ned_m), axis=1))
        if bad.size:
            raise RunLogError(
                f"no mocap position at k = {bad[0]} ({bad.size} grid points): learn from "
                "the estimate (mocap.measurement: estimate)"
            )
        return dataclasses.replace(self, pos_ned_m=self.mocap_ned_m)

    @property
    def n_samples(self) -> int:
        """N, the number of learned samples."""
        return len(self.t_s) - 1

    def table(self) -> np.ndarray:
        """The record as an array with :data:`TRIAL_COLUMNS`."""
        k = np.arange(len(self.t_s), dtype=float)
        mocap = [] if self.mocap_ned_m is None else [self.mocap_ned_m]
        return np.column_stack(
            [k, self.t_s, self.ref_ned_m, self.sp_ned_m, self.pos_ned_m, self.vel_ned_m_s,
             self.sp_sent_s, self.interpolated.astype(float), *mocap]
        )  # fmt: skip

    @classmethod
    def from_table(cls, table: np.ndarray) -> TrialRecord:
        """Inverse of :meth:`table` (16 columns, or 19 with the mocap ones)."""
        return cls(
            t_s=table[:, 1], ref_ned_m=table[:, 2:5], sp_ned_m=table[:, 5:8],
            pos_ned_m=table[:, 8:11], vel_ned_m_s=table[:, 11:14], sp_sent_s=table[:, 14],
            interpolated=table[:, 15] > 0.5,
            mocap_ned_m=table[:, 16:19] if table.shape[1] > 16 else None,
        )  # fmt: skip


@dataclass(frozen=True)
class TrialStatus:
    """The sidecar of a trial.

    ``complete``: whether the trial was flown to its end. ``epos_m``: e_pos,j of eq. (10) [m]
    (complete trials). ``max_err_m``: largest horizontal error [m] (complete trials).
    ``interpolated_share``: share of grid samples interpolated across a telemetry gap. ``extra``:
    anything else the flight layer reported (timing statistics).
    """

    trial: int
    complete: bool
    reason: str | None = None
    epos_m: float | None = None
    max_err_m: float | None = None
    interpolated_share: float = 0.0
    extra: dict | None = None


def json_safe(value: Any) -> Any:
    """``value`` with NaN and infinities as None and tuples as lists (strict JSON)."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer | np.bool_):
        return value.item()
    return value


def csv_text(columns: tuple[str, ...], table: np.ndarray) -> str:
    """A table as CSV text: a header, ``k`` and ``interpolated`` as integers, the rest to 9
    significant digits (``nan`` kept).
    """
    buf = io.StringIO()
    buf.write(",".join(columns) + "\n")
    for row in table:
        buf.write(",".join(_fmt(c, v) for c, v in zip(columns, row, strict=True)) + "\n")
    return buf.getvalue()


def _fmt(column: str, value: float) -> str:
    if column in ("k", "interpolated"):
        return str(int(value))
    if np.isnan(value):
        return "nan"
    return f"{value:.9g}"


def read_csv(path: Path, columns: tuple[str, ...], optional: tuple[str, ...] = ()) -> np.ndarray:
    """A CSV file written by :func:`csv_text`, its header checked.

    ``columns``: the header it must have. ``optional``: last columns it may have in addition.

    Raises ``RunLogError``: unreadable, another header, a value that is no number, ragged rows.
    """
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise RunLogError(f"{path}: cannot read ({exc.strerror})") from exc
    if rows and optional and tuple(rows[0]) == columns + optional:
        columns = columns + optional
    if not rows or tuple(rows[0]) != columns:
        raise RunLogError(f"{path}: header must be {','.join(columns)}")
    try:
        table = np.array([[float(v) for v in r] for r in rows[1:]], dtype=float)
    except ValueError as exc:
        raise RunLogError(f"{path}: {exc}") from exc
    if table.ndim != 2 or table.shape[1] != len(columns):
        raise RunLogError(f"{path}: every row must have {len(columns)} values")
    return table


#: Largest magnitude a recorded position, velocity or variance may have [m, m/s, m^2]: a value
#: beyond it is no measurement (a damaged file), and would overflow the learning's numerics.
PLAUSIBLE = 1e6


def check_plausible(path: Path, values: np.ndarray, columns: tuple[str, ...]) -> None:
    """Refuse values beyond :data:`PLAUSIBLE` (NaN is left to the caller), naming the column.

    ``path``: the file the values come from (for the message).
    """
    with np.errstate(invalid="ignore"):
        bad = np.argwhere(np.abs(values) > PLAUSIBLE)
    if bad.size:
        row, col = bad[0]
        raise RunLogError(
            f"{path}: column '{columns[col]}' is {values[row, col]:.3g} at row {row + 1}, "
            f"beyond ±{PLAUSIBLE:g}: not a measurement"
        )


def json_text(data: dict[str, Any]) -> str:
    """Strict JSON of a record (NaN as null), the same bytes for the same data."""
    return json.dumps(json_safe(data), indent=1, allow_nan=False) + "\n"


def read_json(path: Path, what: str) -> Any:
    """A JSON file, parsed; refusals name the file and what it should hold.

    ``what``: what it holds, for the message (``"learning record"``).
    """
    try:
        return json.loads(path.read_text())
    except OSError as exc:
        raise RunLogError(f"{path}: cannot read ({exc.strerror})") from exc
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError
        raise RunLogError(f"{path}: malformed {what} ({exc})") from exc


def is_number(value: Any) -> bool:
    """Whether a parsed JSON value is a number (``true`` and ``false`` are not)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def status_from_json(path: Path, j: int, data: Any) -> TrialStatus:
    """A trial sidecar's JSON as :class:`TrialStatus`, every field checked against its type.

    ``path``: the sidecar (for messages).
    """
    if not isinstance(data, dict):
        raise RunLogError(f"{path}: malformed trial status (not a JSON object)")

    def fail(key: str, what: str) -> RunLogError:
        return RunLogError(f"{path}: field '{key}' {what}, got {data.get(key)!r}")

    for key in ("trial", "status"):
        if key not in data:
            raise RunLogError(f"{path}: malformed trial status (field '{key}' is missing)")
    if isinstance(data["trial"], bool) or data["trial"] != j:
        raise fail("trial", f"must be {j}, as the file's name says")
    if data["status"] not in ("complete", "incomplete"):
        raise fail("status", "must be 'complete' or 'incomplete'")
    for key in ("epos_m", "max_err_m", "interpolated_share"):
        value = data.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)):
            raise fail(key, "must be a number or null")
    if data.get("reason") is not None and not isinstance(data["reason"], str):
        raise fail("reason", "must be a string or null")
    if data.get("extra") is not None and not isinstance(data["extra"], dict):
        raise fail("extra", "must be an object or null")
    return TrialStatus(
        trial=j, complete=data["status"] == "complete", reason=data.get("reason"),
        epos_m=data.get("epos_m"), max_err_m=data.get("max_err_m"),
        interpolated_share=float(data.get("interpolated_share") or 0.0),
        extra=data.get("extra"),
    )  # fmt: skip
