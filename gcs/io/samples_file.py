"""Files of time-stamped positions from any planner (trajectory ``type: samples``).

Three formats, chosen by the file's suffix; units SI, positions in local NED:

- ``.csv``: a header line naming the columns, then one sample per line. Columns ``t_s``,
  ``north_m``, ``east_m``, ``down_m`` (required, any order) and ``yaw_deg`` (optional); no
  other column. Lines starting with ``#`` and blank lines are skipped.
- ``.npy``: a 2-D array of floats with 4 columns ``t_s, north_m, east_m, down_m`` or 5 with
  ``yaw_deg`` last.
- ``.npz``: 1-D arrays of equal length named as the CSV columns.

Every refusal is one line naming the file and the line (CSV), row (NumPy) or column.
"""

from __future__ import annotations

import csv
import io
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gcs.errors import TrajectoryError

__all__ = ["SAMPLE_COLUMNS", "YAW_COLUMN", "PlannerSamples", "read_samples", "write_samples_csv"]

#: Required columns of a samples file, in the order of a ``.npy`` array.
SAMPLE_COLUMNS = ("t_s", "north_m", "east_m", "down_m")
#: Optional yaw column [deg].
YAW_COLUMN = "yaw_deg"
#: Largest samples file read [bytes]: a planner's path at 1 kHz for 10 minutes is ~30 MB.
MAX_BYTES = 64 * 2**20


@dataclass(frozen=True, eq=False)
class PlannerSamples:
    """What a samples file holds.

    ``t_s``: sample times [s], strictly increasing. ``pos_ned_m``: positions, local NED [m].
    ``yaw_deg``: yaw [deg]; None when the file has no yaw column.
    """

    t_s: np.ndarray
    pos_ned_m: np.ndarray
    yaw_deg: np.ndarray | None


def read_samples(path: str | Path) -> PlannerSamples:
    """Read and check a samples file: finite values, times strictly increasing.

    ``path``: a ``.csv``, ``.npy`` or ``.npz`` file.

    Raises ``TrajectoryError``: naming the file and the line, row or column.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".npy", ".npz"):
        raise TrajectoryError(f"{path}: a samples file must be .csv, .npy or .npz")
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise TrajectoryError(f"{path}: cannot read ({exc.strerror})") from None
    if size > MAX_BYTES:
        raise TrajectoryError(
            f"{path}: {size} bytes, more than the {MAX_BYTES} a samples file may have"
        )
    if suffix == ".csv":
        table, names, rows = _read_csv(path)
    else:
        table, names, rows = _read_numpy(path, suffix)
    return _checked(path, table, names, rows)


def _read_csv(path: Path) -> tuple[np.ndarray, list[str], list[str]]:
    try:
        text = path.read_text()
    except OSError as exc:
        raise TrajectoryError(f"{path}: cannot read ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise TrajectoryError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    lines = [
        (i + 1, line)
        for i, line in enumerate(text.splitlines())
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        raise TrajectoryError(f"{path}: empty (a header line and samples expected)")
    header_no, header = lines[0]
    names = [c.strip() for c in next(csv.reader(io.StringIO(header)))]
    _check_names(path, names, f"line {header_no}")
    values, where = [], []
    for no, line in lines[1:]:
        cells = next(csv.reader(io.StringIO(line)))
        if len(cells) != len(names):
            raise TrajectoryError(
                f"{path}: line {no}: {len(cells)} values, the header names {len(names)} columns"
            )
        row = []
        for name, cell in zip(names, cells, strict=True):
            try:
                row.append(float(cell))
            except ValueError:
                raise TrajectoryError(
                    f"{path}: line {no}: column '{name}' is not a number: {cell.strip()!r}"
                ) from None
        values.append(row)
        where.append(f"line {no}")
    table = np.array(values, dtype=float).reshape(len(values), len(names))
    return table, names, where


def _read_numpy(path: Path, suffix: str) -> tuple[np.ndarray, list[str], list[str]]:
    try:
        data = np.load(path, allow_pickle=False)
    except OSError as exc:
        raise TrajectoryError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except (ValueError, EOFError, zipfile.BadZipFile):
        raise TrajectoryError(
            f"{path}: not a readable NumPy file (an array saved by numpy.save or numpy.savez, "
            "no pickled objects)"
        ) from None
    if suffix == ".npy":
        arr = np.asarray(data)
        if arr.ndim != 2 or arr.shape[1] not in (4, 5) or not np.issubdtype(arr.dtype, np.number):
            raise TrajectoryError(
                f"{path}: expected a 2-D array of numbers with 4 columns (t_s, north_m, "
                f"east_m, down_m) or 5 (and yaw_deg), got shape {arr.shape} of {arr.dtype}"
            )
        names = [*SAMPLE_COLUMNS, YAW_COLUMN][: arr.shape[1]]
        table = arr.astype(float)
    else:
        with data:
            names = list(data.files)
            _check_names(path, names, "arrays")
            cols = [np.asarray(data[name]) for name in names]
        for name, col in zip(names, cols, strict=True):
            if col.ndim != 1 or not np.issubdtype(col.dtype, np.number):
                raise TrajectoryError(
                    f"{path}: array '{name}' must be 1-D numbers, got {col.shape}"
                )
            if col.shape != cols[0].shape:
                raise TrajectoryError(
                    f"{path}: array '{name}' has {col.size} samples, '{names[0]}' {cols[0].size}"
                )
        table = np.column_stack(cols).astype(float)
    return table, names, [f"row {i}" for i in range(table.shape[0])]


def _check_names(path: Path, names: list[str], where: str) -> None:
    for name in SAMPLE_COLUMNS:
        if name not in names:
            raise TrajectoryError(
                f"{path}: {where}: column '{name}' is missing (columns: "
                f"{', '.join(SAMPLE_COLUMNS)}, optional {YAW_COLUMN})"
            )
    for name in names:
        if name not in (*SAMPLE_COLUMNS, YAW_COLUMN):
            raise TrajectoryError(f"{path}: {where}: column '{name}' is not a known column")
    if len(set(names)) != len(names):
        raise TrajectoryError(f"{path}: {where}: a column is named twice")


def _checked(path: Path, table: np.ndarray, names: list[str], rows: list[str]) -> PlannerSamples:
    if table.shape[0] < 2:
        raise TrajectoryError(f"{path}: {table.shape[0]} samples, at least 2 needed")
    bad = np.argwhere(~np.isfinite(table))
    if bad.size:
        i, c = bad[0]
        raise TrajectoryError(f"{path}: {rows[i]}: column '{names[c]}' is {table[i, c]}")
    col = {name: table[:, i] for i, name in enumerate(names)}
    t = col["t_s"]
    step = np.diff(t)
    back = np.flatnonzero(step <= 0)
    if back.size:
        i = int(back[0]) + 1
        what = "repeats" if step[i - 1] == 0 else "goes back from"
        raise TrajectoryError(
            f"{path}: {rows[i]}: t_s {t[i]:g} s {what} {t[i - 1]:g} s of {rows[i - 1]} "
            "(times must strictly increase)"
        )
    pos = np.column_stack([col["north_m"], col["east_m"], col["down_m"]])
    yaw = col.get(YAW_COLUMN)
    return PlannerSamples(t_s=t.copy(), pos_ned_m=pos, yaw_deg=None if yaw is None else yaw.copy())


def write_samples_csv(path: str | Path, samples: PlannerSamples) -> None:
    """Write samples as a CSV file :func:`read_samples` reads back exactly.

    ``samples``: the samples (``repr`` of each float: the values round-trip exactly).
    """
    names = list(SAMPLE_COLUMNS) + ([YAW_COLUMN] if samples.yaw_deg is not None else [])
    cols = [samples.t_s, *np.asarray(samples.pos_ned_m).T]
    if samples.yaw_deg is not None:
        cols.append(samples.yaw_deg)
    lines = [",".join(names)]
    for row in zip(*cols, strict=True):
        lines.append(",".join(repr(float(v)) if math.isfinite(v) else str(v) for v in row))
    Path(path).write_text("\n".join(lines) + "\n")
