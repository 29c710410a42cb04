"""The run directory: one learning campaign on disk.

Layout of ``logs/<run-id>/`` (documented for users in docs/formats.md)::

    manifest.json          profile, trajectory and algorithm as used, software versions
    reference.csv          the reference on the grid, k = 0..N
    setpoints-JJJ.csv      the setpoints to fly in trial JJJ (000 = the reference)
    trial-JJJ.csv          trial JJJ as flown: reference, setpoints, measured position and
                           velocity on the grid, send times, interpolation flags, and with
                           motion capture its position on the grid (mocap_* columns)
    mocap-JJJ.csv          with motion capture: every raw sample of trial JJJ as received
                           (``gcs.io.mocap_samples``)
    trial-JJJ.json         its status ("complete" or "incomplete" and why) and metrics
    estimate-JJJ.csv       disturbance estimate learned from trial JJJ (and K-ILC variance)
    learn-JJJ.json         profiles with ``learning.adaptive``: the record of every decision of
                           the step that learned from trials 0..JJJ (noise model, weights,
                           refresh, safeguard, robustness, floor verdicts, next setpoints' RMS)
    model-JJJ.yaml         ... and the profile with the models that step refreshed (only when
                           one was): fly it with ``gcs fly --profile``
    floor.json             ... and the floor measured from the flights of identical setpoints
                           (trial 0 and its repeats)
    session-SSS.json       one per flight session (each ``gcs fly``/``--resume``): the vehicle's
                           navigation source, the hover measured before its first trial and
                           the settle tolerances derived from it
    aborted/               earlier incomplete attempts of a trial, kept when it is re-flown

Every file is written atomically (temporary file in the same directory, then ``os.replace``),
and a trial counts as complete only once its ``.json`` says so; it is written after the CSV. A
new run is assembled in a hidden staging directory and renamed into place whole, so that an
interrupted creation leaves no half-made run. Recorded data are never rewritten: setpoints and
estimates are written once (writing the same bytes again is a no-op, different bytes are
refused), a complete trial is never replaced, and an incomplete one is moved to ``aborted/``
before it is flown again. A new session record takes the next free number by a hard link that
fails if the name exists, so that no session ever overwrites another's; a session updates only
its own record.

A learning step with history writes ``model-JJJ.yaml`` (if any), ``floor.json``,
``estimate-JJJ.csv``, ``learn-JJJ.json`` and last the next setpoints, each once: an interruption
leaves the next trial unflyable until learning again completes the step with the same bytes.
A repeat's setpoints are trial 0's, byte for byte.

Files must agree with their names: a trial's ``.json`` names its own index, its CSV carries the
setpoints of ``setpoints-JJJ.csv``, a ``learn-JJJ.json`` names trial JJJ and its model file, a
``model-JJJ.yaml`` holds the models its record names, and the manifest's fields have their
types. A run is a
learning run (algorithm ``smoother`` or ``kilc``) or an identification run (``identify``);
commands that write into a run check its kind first.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import os
import platform
import shutil
import tempfile
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from gcs import __version__
from gcs.core.model import DiscreteModel
from gcs.core.trajectory import Reference, sample_eight
from gcs.errors import PathError, RunLogError
from gcs.io.config import Profile, TrajectorySpec, profile_from_dict, trajectory_from_dict
from gcs.io.paths import check_writable_dir

__all__ = [
    "LEARNING_ALGORITHMS",
    "RUN_KINDS",
    "TrialRecord",
    "TrialStatus",
    "RunDir",
    "atomic_write_text",
    "write_once",
    "json_safe",
    "TRIAL_COLUMNS",
    "MOCAP_GRID_COLUMNS",
    "MEASUREMENTS",
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
ESTIMATE_COLUMNS = ("k", "t_s", "d_north_m", "d_east_m", "p_north_m2", "p_east_m2")
_PACKAGES = ("numpy", "scipy", "clarabel", "mavsdk", "pymavlink", "typer", "rich")


def _umask() -> int:
    mask = os.umask(0o022)  # the only way to read the umask is to set it
    os.umask(mask)
    return mask


#: Modes of the files and directories written here: what ``open()`` and ``mkdir()`` give
#: under the process's umask (``mkstemp`` and ``mkdtemp`` would make them owner-only).
_FILE_MODE, _DIR_MODE = 0o666 & ~_umask(), 0o777 & ~_umask()
#: Manifest ``algorithm`` of learning runs; identification runs record ``identify``.
LEARNING_ALGORITHMS = ("smoother", "kilc")
#: Run kind by manifest algorithm.
RUN_KINDS = {"smoother": "learning", "kilc": "learning", "identify": "identification"}
#: Tolerance of a trial's setpoint columns against its setpoints file [m].
_SP_TOL_M = 1e-6


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (temporary file + rename).

    Parameters
    ----------
    path : Path
        Destination.
    text : str
        Content.
    """
    path = Path(path)
    tmp = _temporary_copy(path, text)
    try:
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _temporary_copy(path: Path, text: str) -> Path:
    """``text`` in a new hidden file beside ``path``, on disk (fsync), with open()'s mode."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, _FILE_MODE)  # as open() would make it, not mkstemp's owner-only 0600
        with os.fdopen(fd, "w", newline="", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return Path(tmp)


def write_once(path: Path, text: str) -> bool:
    """Write ``text`` to a new file ``path`` atomically; never replace different content.

    The file appears whole (temporary file, then a hard link that fails if the name exists)
    or not at all. If ``path`` holds exactly ``text`` already nothing is written (learning
    twice from the same trial is a no-op); different content is refused.

    Parameters
    ----------
    path : Path
        Destination.
    text : str
        Content.

    Returns
    -------
    bool
        True if the file was written, False if it held ``text`` already.

    Raises
    ------
    RunLogError
        ``path`` exists with other content.
    """
    path = Path(path)
    if path.is_dir():
        raise RunLogError(f"{path}: is a directory")
    tmp = _temporary_copy(path, text)
    try:
        try:
            os.link(tmp, path)  # atomic "create if absent"
            return True
        except FileExistsError:
            pass
        except OSError:  # a filesystem without hard links: check, then rename
            if not path.exists():
                os.replace(tmp, path)
                return True
    finally:
        tmp.unlink(missing_ok=True)
    try:
        same = path.read_bytes() == text.encode("utf-8")
    except OSError as exc:
        raise RunLogError(f"{path}: cannot read ({exc.strerror})") from exc
    if not same:
        raise RunLogError(
            f"{path}: exists with different content; recorded data are never rewritten"
        )
    return False


def json_safe(value: Any) -> Any:
    """``value`` with NaN and infinities as None and tuples as lists (strict JSON).

    Parameters
    ----------
    value : Any
        Nested dicts, lists, tuples and scalars.

    Returns
    -------
    Any
    """
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer | np.bool_):
        return value.item()
    return value


def _csv_text(columns: tuple[str, ...], table: np.ndarray) -> str:
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


def _read_csv(path: Path, columns: tuple[str, ...], optional: tuple[str, ...] = ()) -> np.ndarray:
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


@dataclass(frozen=True)
class TrialRecord:
    """One trial on the grid ``k = 0..N`` (row k holds u(k) and y(k)).

    Parameters
    ----------
    t_s : ndarray, shape (N+1,)
        Grid times ``k t_ilc_s`` [s] from the trial start.
    ref_ned_m : ndarray, shape (N+1, 3)
        Reference yd(k), local NED [m].
    sp_ned_m : ndarray, shape (N+1, 3)
        Setpoint u(k) [m]; row N is the final setpoint held after the trial.
    pos_ned_m : ndarray, shape (N+1, 3)
        Measured position y(k) [m]; NaN where an aborted trial has no data.
    vel_ned_m_s : ndarray, shape (N+1, 3)
        Measured velocity [m/s].
    sp_sent_s : ndarray, shape (N+1,)
        Time the setpoint was first sent, from the trial start [s]; NaN for row N.
    interpolated : ndarray of bool, shape (N+1,)
        True where the position was interpolated across a telemetry gap.
    mocap_ned_m : ndarray, shape (N+1, 3), or None
        Motion-capture position on the grid [m, NED] (NaN where none); None without mocap.
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

        Parameters
        ----------
        measurement : str
            ``"mocap"`` (the motion capture when the record has it; else the estimate) or
            ``"estimate"`` (the vehicle's own).

        Returns
        -------
        TrialRecord
            ``self``, or a copy with the mocap positions as ``pos_ned_m``.

        Raises
        ------
        RunLogError
            ``"mocap"`` with mocap columns that are NaN somewhere on the grid.
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

    Parameters
    ----------
    trial : int
        Trial index j.
    complete : bool
        Whether the trial was flown to its end.
    reason : str or None
        Why an incomplete trial stopped.
    epos_m : float or None
        e_pos,j of eq. (10) [m] (complete trials).
    max_err_m : float or None
        Largest horizontal error [m] (complete trials).
    interpolated_share : float
        Share of grid samples interpolated across a telemetry gap.
    extra : dict
        Anything else the flight layer reported (timing statistics).
    """

    trial: int
    complete: bool
    reason: str | None = None
    epos_m: float | None = None
    max_err_m: float | None = None
    interpolated_share: float = 0.0
    extra: dict | None = None


class RunDir:
    """A run directory (see the module docstring for its layout).

    Parameters
    ----------
    path : Path
        The directory.
    manifest : dict
        Its parsed ``manifest.json``.
    """

    def __init__(self, path: Path, manifest: dict[str, Any]) -> None:
        self.path = Path(path)
        self.manifest = manifest
        self._reference: Reference | None = None  # reference.csv never changes once written

    # ----------------------------------------------------------------- creation
    @classmethod
    def create(
        cls,
        root: Path,
        profile: Profile,
        trajectory: TrajectorySpec,
        algorithm: str,
        run_id: str | None = None,
        reference: Reference | None = None,
    ) -> RunDir:
        """Create a new run directory under ``root`` with trial 0's setpoints = the reference.

        Parameters
        ----------
        root : Path
            Parent directory (``logs/``).
        profile : Profile
            The profile as used.
        trajectory : TrajectorySpec
            The trajectory as used.
        algorithm : str
            ``"smoother"`` or ``"kilc"``.
        run_id : str, optional
            Directory name; default ``<UTC time>-<trajectory>-<algorithm>``.
        reference : Reference, optional
            The reference to record; default: the trajectory's eight sampled at ``t_ilc_s``
            (identification runs pass their excitation here).

        Returns
        -------
        RunDir
        """
        if algorithm not in RUN_KINDS:
            raise RunLogError(f"algorithm must be one of {', '.join(RUN_KINDS)}, got {algorithm!r}")
        root = Path(root)
        ref = (
            reference if reference is not None else sample_eight(trajectory.shape, profile.t_ilc_s)
        )
        if abs(ref.t_ilc_s - profile.t_ilc_s) > 1e-9:
            raise RunLogError(
                f"reference sampled at {ref.t_ilc_s:g} s, profile {profile.t_ilc_s:g} s"
            )
        stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S")
        base = run_id or f"{stamp}-{trajectory.name}-{algorithm}"
        if run_id and ((root / run_id).exists() or (root / run_id).is_symlink()):
            raise RunLogError(f"{root / run_id}: run directory exists already")
        root.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(dir=root, prefix=f".{base}.", suffix=".tmp"))
        staging.chmod(_DIR_MODE)
        manifest = {
            "format": 1,
            "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            "gcs_version": __version__,
            "python": platform.python_version(),
            "packages": {p: _version(p) for p in _PACKAGES},
            "algorithm": algorithm,
            "t_ilc_s": profile.t_ilc_s,
            "n_samples": ref.n_samples,
            "profile": profile.source,
            "trajectory": trajectory.source,
        }
        try:
            staged = cls(staging, manifest)
            atomic_write_text(staging / "manifest.json", json.dumps(manifest, indent=2) + "\n")
            table = np.column_stack([np.arange(ref.n_samples + 1), ref.t_s, ref.pos_ned_m])
            atomic_write_text(staging / "reference.csv", _csv_text(REFERENCE_COLUMNS, table))
            staged.write_setpoints(0, ref.pos_ned_m[:-1])
            path = _rename_into_place(staging, root, base, fixed=run_id is not None)
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        _update_latest(root, path)
        return cls(path, manifest)

    @classmethod
    def open(cls, path: Path) -> RunDir:
        """Open an existing run directory.

        Parameters
        ----------
        path : Path
            The run directory.

        Returns
        -------
        RunDir
        """
        path = Path(path)
        if not path.is_dir():
            raise RunLogError(f"{path}: not a run directory")
        mpath = path / "manifest.json"
        try:
            manifest = json.loads(mpath.read_text())
        except OSError as exc:
            raise RunLogError(f"{mpath}: cannot read ({exc.strerror})") from exc
        except json.JSONDecodeError as exc:
            raise RunLogError(f"{mpath}: malformed JSON ({exc.msg}, line {exc.lineno})") from exc
        except UnicodeDecodeError as exc:
            raise RunLogError(f"{mpath}: not UTF-8 text ({exc.reason})") from exc
        _check_manifest(mpath, manifest)
        return cls(path, manifest)

    # ----------------------------------------------------------------- accessors
    @property
    def algorithm(self) -> str:
        """The run's learning algorithm."""
        return str(self.manifest["algorithm"])

    @property
    def kind(self) -> str:
        """``"learning"`` (algorithm smoother or kilc) or ``"identification"`` (identify)."""
        return RUN_KINDS[self.algorithm]

    def require_kind(self, kind: str, command: str) -> None:
        """Refuse a command that writes into a run of the other kind.

        Parameters
        ----------
        kind : str
            ``"learning"`` or ``"identification"``.
        command : str
            The command, for the message (``gcs learn``).

        Raises
        ------
        RunLogError
            The run is of the other kind.
        """
        if self.kind != kind:
            article = "an" if self.kind[0] in "aeiou" else "a"
            raise RunLogError(
                f"{self.path}: {article} {self.kind} run (manifest algorithm "
                f"'{self.algorithm}'), not {'an' if kind[0] in 'aeiou' else 'a'} {kind} run, "
                f"which '{command}' needs"
            )

    def check_writable(self) -> None:
        """Refuse a run directory that cannot be written into (a probe file, removed at once).

        Raises
        ------
        RunLogError
            Read-only directory or filesystem, no permission.
        """
        try:
            check_writable_dir(self.path, str(self.path))
        except PathError as exc:
            reason = str(exc).rsplit("(", 1)[-1].rstrip(")")
            raise RunLogError(f"{self.path}: run directory is not writable ({reason})") from None

    @property
    def n_samples(self) -> int:
        """N, samples per trial."""
        return int(self.manifest["n_samples"])

    @property
    def t_ilc_s(self) -> float:
        """ILC sample time [s]."""
        return float(self.manifest["t_ilc_s"])

    def profile(self) -> Profile:
        """The profile as recorded in the manifest."""
        return profile_from_dict(self.manifest["profile"], f"{self.path}/manifest.json:profile")

    def trajectory(self) -> TrajectorySpec:
        """The trajectory as recorded in the manifest."""
        where = f"{self.path}/manifest.json:trajectory"
        return trajectory_from_dict(self.manifest["trajectory"], where)

    def reference(self) -> Reference:
        """The reference on the grid as recorded in ``reference.csv``.

        Velocity and acceleration are central differences of the recorded positions.
        """
        if self._reference is None:
            self._reference = self._read_reference()
        return self._reference

    def _read_reference(self) -> Reference:
        path = self.path / "reference.csv"
        table = _read_csv(path, REFERENCE_COLUMNS)
        self._check_grid(path, table, self.n_samples + 1)
        if not np.all(np.isfinite(table)):
            raise RunLogError(f"{path}: contains NaN or inf")
        _check_plausible(path, table[:, 2:5], REFERENCE_COLUMNS[2:5])
        pos = table[:, 2:5]
        vel = np.gradient(pos, self.t_ilc_s, axis=0)
        return Reference(table[:, 1], pos, vel, np.gradient(vel, self.t_ilc_s, axis=0))

    def _file(self, kind: str, j: int, ext: str) -> Path:
        return self.path / f"{kind}-{j:03d}.{ext}"

    # ----------------------------------------------------------------- setpoints
    def write_setpoints(self, j: int, sp_ned_m: np.ndarray) -> Path:
        """Write trial j's setpoints u(0..N-1), shape (N, 3), local NED [m].

        Parameters
        ----------
        j : int
            Trial index.
        sp_ned_m : ndarray, shape (N, 3)
            Setpoints [m].

        Returns
        -------
        Path
        """
        path = self._file("setpoints", j, "csv")
        write_once(path, self._setpoints_text(j, sp_ned_m))
        return path

    def _setpoints_text(self, j: int, sp_ned_m: np.ndarray) -> str:
        sp = np.asarray(sp_ned_m, dtype=float)
        n = self.n_samples
        if sp.shape != (n, 3) or not np.all(np.isfinite(sp)):
            raise RunLogError(f"setpoints for trial {j} must be finite with shape ({n}, 3)")
        table = np.column_stack([np.arange(n), np.arange(n) * self.t_ilc_s, sp])
        return _csv_text(SETPOINT_COLUMNS, table)

    def read_setpoints(self, j: int) -> np.ndarray:
        """Trial j's setpoints, shape (N, 3), local NED [m].

        Parameters
        ----------
        j : int
            Trial index.

        Returns
        -------
        ndarray
        """
        path = self._file("setpoints", j, "csv")
        if not path.exists():
            raise RunLogError(f"{path}: no setpoints for trial {j} (run 'gcs learn' first)")
        table = _read_csv(path, SETPOINT_COLUMNS)
        self._check_grid(path, table, self.n_samples)
        _check_plausible(path, table[:, 2:5], SETPOINT_COLUMNS[2:5])
        return table[:, 2:5]

    # ----------------------------------------------------------------- trials
    def statuses(self) -> list[TrialStatus]:
        """Status of every trial on disk, by trial index."""
        out = []
        for p in sorted(self.path.glob("trial-[0-9][0-9][0-9].json")):
            out.append(self.read_status(int(p.stem.split("-")[1])))
        return out

    def read_status(self, j: int) -> TrialStatus:
        """The sidecar of trial j.

        Parameters
        ----------
        j : int
            Trial index.

        Returns
        -------
        TrialStatus
        """
        path = self._file("trial", j, "json")
        try:
            data = json.loads(path.read_text())
        except OSError as exc:
            raise RunLogError(f"{path}: cannot read ({exc.strerror})") from exc
        except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError
            raise RunLogError(f"{path}: malformed trial status ({exc})") from exc
        return _status_from_json(path, j, data)

    def complete_trials(self) -> list[int]:
        """Indices of the complete trials, ascending."""
        return [s.trial for s in self.statuses() if s.complete]

    def newest_complete(self) -> int | None:
        """Index of the newest complete trial, or None."""
        done = self.complete_trials()
        return done[-1] if done else None

    def next_trial(self) -> int:
        """Index of the next trial to fly: one after the newest complete trial."""
        newest = self.newest_complete()
        return 0 if newest is None else newest + 1

    def write_trial(
        self, j: int, record: TrialRecord, status: TrialStatus, mocap: Any = None
    ) -> None:
        """Record trial j: raw mocap samples and CSV first, then its status sidecar.

        An earlier incomplete attempt of trial j is moved to ``aborted/``; a complete trial is
        never overwritten.

        Parameters
        ----------
        j : int
            Trial index.
        record : TrialRecord
            The trial on the grid.
        status : TrialStatus
            Completion and metrics.
        mocap : MocapSeries or None
            The trial's raw motion-capture samples (``mocap-JJJ.csv``).
        """
        csv_path, json_path = self._file("trial", j, "csv"), self._file("trial", j, "json")
        if record.n_samples != self.n_samples:
            raise RunLogError(f"trial {j} has {record.n_samples} samples, the run {self.n_samples}")
        if json_path.exists():
            if self.read_status(j).complete:
                raise RunLogError(f"{json_path}: trial {j} is complete; refusing to overwrite it")
            self._archive_attempt(j)
        elif csv_path.exists():  # a CSV whose sidecar was never written (interrupted write)
            self._archive_attempt(j)
        if mocap is not None:
            from gcs.io.mocap_samples import write_mocap_csv

            write_mocap_csv(self._file("mocap", j, "csv"), mocap)
        atomic_write_text(csv_path, _csv_text(record.columns, record.table()))
        data = {
            "trial": j,
            "status": "complete" if status.complete else "incomplete",
            "reason": status.reason,
            "epos_m": status.epos_m,
            "max_err_m": status.max_err_m,
            "interpolated_share": status.interpolated_share,
            "extra": status.extra or {},
            "written_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        }
        atomic_write_text(json_path, json.dumps(data, indent=2) + "\n")

    def _archive_attempt(self, j: int) -> None:
        aborted = self.path / "aborted"
        aborted.mkdir(exist_ok=True)
        attempt = 1
        while any(
            (aborted / f"trial-{j:03d}-attempt-{attempt}.{ext}").exists() for ext in ("csv", "json")
        ):
            attempt += 1
        for ext in ("csv", "json"):
            src = self._file("trial", j, ext)
            if src.exists():
                os.replace(src, aborted / f"trial-{j:03d}-attempt-{attempt}.{ext}")
        raw = self._file("mocap", j, "csv")
        if raw.exists():
            os.replace(raw, aborted / f"mocap-{j:03d}-attempt-{attempt}.csv")

    def read_trial(self, j: int) -> TrialRecord:
        """Read and validate a complete trial for learning or reporting.

        Parameters
        ----------
        j : int
            Trial index.

        Returns
        -------
        TrialRecord

        Raises
        ------
        RunLogError
            Incomplete trial, wrong length, NaN values, or a grid that does not match t_ilc_s.
        """
        status = self.read_status(j)
        path = self._file("trial", j, "csv")
        if not status.complete:
            raise RunLogError(
                f"{path}: trial {j} is incomplete ({status.reason}); not learned from"
            )
        if not path.exists():
            raise RunLogError(f"{path}: missing, but {path.stem}.json says the trial is complete")
        table = _read_csv(path, TRIAL_COLUMNS, MOCAP_GRID_COLUMNS)
        self._check_grid(path, table, self.n_samples + 1)
        values = table[:, :14]
        bad = np.argwhere(~np.isfinite(values))
        if bad.size:
            row, col = bad[0]
            raise RunLogError(f"{path}: column '{TRIAL_COLUMNS[col]}' is NaN or inf at k = {row}")
        _check_plausible(path, table[:, 2:14], TRIAL_COLUMNS[2:14])
        record = TrialRecord.from_table(table)
        self._check_flown_setpoints(path, j, record)
        return record

    def _check_flown_setpoints(self, path: Path, j: int, record: TrialRecord) -> None:
        """The setpoint columns of trial j must be ``setpoints-JJJ.csv``: files agree with names."""
        sp_path = self._file("setpoints", j, "csv")
        if not sp_path.exists():
            raise RunLogError(f"{sp_path}: missing; trial {j} cannot be checked against it")
        diff = np.abs(record.sp_ned_m[:-1] - self.read_setpoints(j))
        if diff.max() > _SP_TOL_M:
            k = int(np.argmax(diff.max(axis=1)))
            raise RunLogError(
                f"{path}: its setpoints differ from {sp_path.name} (first at k = {k}); "
                "the files do not belong together (renamed or swapped?)"
            )

    def _check_grid(self, path: Path, table: np.ndarray, rows: int) -> None:
        if table.shape[0] != rows:
            raise RunLogError(f"{path}: {table.shape[0]} rows, expected {rows} (truncated?)")
        k = np.arange(rows)
        if not np.array_equal(table[:, 0], k):
            raise RunLogError(f"{path}: column 'k' must count 0..{rows - 1}")
        err = np.abs(table[:, 1] - k * self.t_ilc_s)
        if np.any(~np.isfinite(err)) or err.max() > 1e-6:
            worst = int(np.nanargmax(np.where(np.isfinite(err), err, np.inf)))
            raise RunLogError(
                f"{path}: column 't_s' does not match t_ilc_s = {self.t_ilc_s:g} s "
                f"(k = {worst}: {table[worst, 1]!r})"
            )

    # ----------------------------------------------------------------- sessions
    def write_session(self, number: int | None, data: dict[str, Any]) -> int:
        """Record a flight session: a new ``session-SSS.json``, or an update of one's own.

        Parameters
        ----------
        number : int or None
            None for a new session (it takes the next free number; an existing record is
            never replaced), else the number this session was given before.
        data : dict
            The record (NaN becomes null).

        Returns
        -------
        int
            The session's number.
        """

        def text(n: int) -> str:
            return json.dumps(json_safe({"session": n, **data}), indent=2) + "\n"

        if number is not None:
            atomic_write_text(self._file("session", number, "json"), text(number))
            return number
        number = len(self.sessions()) + 1
        tmp = self.path / f".session-new.{os.getpid()}.tmp"
        try:
            while True:
                atomic_write_text(tmp, text(number))
                try:
                    os.link(tmp, self._file("session", number, "json"))  # fails if it exists
                    return number
                except FileExistsError:
                    number += 1
        finally:
            tmp.unlink(missing_ok=True)

    def sessions(self) -> list[dict[str, Any]]:
        """Every session record of the run, by number.

        Returns
        -------
        list of dict
        """
        out = []
        for path in sorted(self.path.glob("session-[0-9][0-9][0-9].json")):
            try:
                data = json.loads(path.read_text())
            except (OSError, ValueError) as exc:
                raise RunLogError(f"{path}: unreadable session record ({exc})") from exc
            number = int(path.stem.split("-")[1])
            if not isinstance(data, dict) or data.get("session") != number:
                raise RunLogError(f"{path}: field 'session' must be {number}, as its name says")
            out.append(data)
        return out

    # ----------------------------------------------------------------- estimates
    def write_estimate(self, j: int, d_hat_ne_m: np.ndarray, p_ne_m2: np.ndarray) -> None:
        """Write the disturbance estimate learned from trial j.

        Parameters
        ----------
        j : int
            Trial index the estimate was learned from.
        d_hat_ne_m : ndarray, shape (N, 2)
            Estimate of d(1..N), north and east, learning coordinates [m].
        p_ne_m2 : ndarray, shape (N, 2)
            Its error variance [m^2] (K-ILC: the filter's scalar, repeated).
        """
        write_once(self._file("estimate", j, "csv"), self._estimate_text(d_hat_ne_m, p_ne_m2))

    def _estimate_text(self, d_hat_ne_m: np.ndarray, p_ne_m2: np.ndarray) -> str:
        k = np.arange(1, self.n_samples + 1)
        table = np.column_stack([k, k * self.t_ilc_s, d_hat_ne_m, p_ne_m2])
        return _csv_text(ESTIMATE_COLUMNS, table)

    def write_learned(
        self, j: int, d_hat_ne_m: np.ndarray, p_ne_m2: np.ndarray, sp_ned_m: np.ndarray
    ) -> Path:
        """Record what was learned from trial j: its estimate, then trial j+1's setpoints.

        Both files are checked first: if either exists with other content nothing is
        written (refused), so that a refusal never leaves one of the two behind. The setpoints
        come last: they are what says the next trial can be flown.

        Parameters
        ----------
        j : int
            Trial learned from.
        d_hat_ne_m, p_ne_m2 : ndarray, shape (N, 2)
            As :meth:`write_estimate`.
        sp_ned_m : ndarray, shape (N, 3)
            Setpoints of trial j+1, as :meth:`write_setpoints`.

        Returns
        -------
        Path
            The setpoints file.
        """
        for path, text in (
            (self._file("estimate", j, "csv"), self._estimate_text(d_hat_ne_m, p_ne_m2)),
            (self._file("setpoints", j + 1, "csv"), self._setpoints_text(j + 1, sp_ned_m)),
        ):
            if path.exists() and path.read_bytes() != text.encode("utf-8"):
                raise RunLogError(
                    f"{path}: exists with different content; recorded data are never rewritten"
                )
        self.write_estimate(j, d_hat_ne_m, p_ne_m2)
        return self.write_setpoints(j + 1, sp_ned_m)

    # ----------------------------------------------------------------- learning with history
    def write_repeat(self, j: int) -> Path:
        """Trial j repeats trial 0: its setpoints are ``setpoints-000.csv``'s, byte for byte.

        Parameters
        ----------
        j : int
            The repeating trial (``>= 1``).

        Returns
        -------
        Path
            The setpoints file.
        """
        if j < 1:
            raise RunLogError(f"trial {j} cannot repeat trial 0")
        return self.write_setpoints(j, self.read_setpoints(0))

    def write_plan(
        self,
        j: int,
        d_hat_ne_m: np.ndarray,
        p_ne_m2: np.ndarray,
        record: dict[str, Any],
        sp_ned_m: np.ndarray,
        model_text: str | None = None,
        floor: dict[str, Any] | None = None,
    ) -> Path:
        """Record a learning step from trials 0..j, in an order an interruption cannot break.

        ``model-JJJ.yaml`` (when a model was refreshed), ``floor.json`` (when the floor is
        known), ``estimate-JJJ.csv``, ``learn-JJJ.json``, and last ``setpoints-(J+1).csv``:
        the setpoints are what says the next trial can be flown, and learning again from trial
        j writes the same bytes, so an interrupted step is completed by learning again. Every
        file is checked first: if one exists with other content nothing is written.

        Parameters
        ----------
        j : int
            The newest trial learned from.
        d_hat_ne_m, p_ne_m2 : ndarray, shape (N, 2)
            As :meth:`write_estimate`.
        record : dict
            The decision record (JSON-ready; NaN becomes null); its ``trial`` must be ``j``.
        sp_ned_m : ndarray, shape (N, 3)
            Setpoints of trial j+1, as :meth:`write_setpoints`.
        model_text : str, optional
            A profile (YAML) with the refreshed models.
        floor : dict, optional
            The floor (JSON-ready), with the trials it was measured from.

        Returns
        -------
        Path
            The setpoints file.
        """
        if record.get("trial") != j:
            raise RunLogError(f"learning record of trial {j} names trial {record.get('trial')!r}")
        files = [
            (self._file("model", j, "yaml"), model_text),
            (self.path / "floor.json", None if floor is None else _json_text(floor)),
            (self._file("estimate", j, "csv"), self._estimate_text(d_hat_ne_m, p_ne_m2)),
            (self._file("learn", j, "json"), _json_text(record)),
            (self._file("setpoints", j + 1, "csv"), self._setpoints_text(j + 1, sp_ned_m)),
        ]
        files = [(path, text) for path, text in files if text is not None]
        for path, text in files:
            if path.exists() and path.read_bytes() != text.encode("utf-8"):
                raise RunLogError(
                    f"{path}: exists with different content; recorded data are never rewritten"
                )
        for path, text in files:
            write_once(path, text)
        return files[-1][0]

    def read_learn_record(self, j: int) -> dict[str, Any]:
        """The decision record ``learn-JJJ.json`` of the learning step from trial j.

        Parameters
        ----------
        j : int
            The newest trial that step learned from.

        Returns
        -------
        dict
            ``trial``, ``next_trial``, ``next_iteration``, ``learned_from``, ``models_from``,
            ``model_file``, ``setpoints`` and ``decision`` (the record of
            :func:`gcs.core.learning.plan_next_trial`), each checked against its type.
        """
        path = self._file("learn", j, "json")
        if not path.exists():
            raise RunLogError(f"{path}: missing; trial {j + 1} was learned without its record")
        return _check_learn_record(path, j, _read_json(path, "learning record"))

    def learn_records(self) -> dict[int, dict[str, Any]]:
        """Every decision record of the run, by the trial it learned from.

        Returns
        -------
        dict of int to dict
        """
        out = {}
        for path in sorted(self.path.glob("learn-[0-9][0-9][0-9].json")):
            j = int(path.stem.split("-")[1])
            out[j] = self.read_learn_record(j)
        return out

    def model_path(self, j: int) -> Path:
        """``model-JJJ.yaml``: the profile with the models refreshed when learning from trial j.

        Parameters
        ----------
        j : int
            The trial learned from.

        Returns
        -------
        Path
        """
        return self._file("model", j, "yaml")

    def read_model(self, j: int) -> tuple[DiscreteModel, DiscreteModel]:
        """The (north, east) models refreshed when learning from trial j (``model-JJJ.yaml``).

        The file must be a loadable profile, and its models the ones ``learn-JJJ.json``
        records (the file agrees with the record of the step that wrote it).

        Parameters
        ----------
        j : int
            The trial learned from.

        Returns
        -------
        tuple of DiscreteModel
        """
        path = self.model_path(j)
        record = self.read_learn_record(j)
        if record["model_file"] is None:
            raise RunLogError(f"{path}: learn-{j:03d}.json records no refreshed model")
        if not path.exists():
            raise RunLogError(f"{path}: missing, but learn-{j:03d}.json records a refreshed model")
        from gcs.io.yamlfile import read_yaml

        models = profile_from_dict(read_yaml(path, RunLogError), str(path)).models()
        for a, (name, model) in enumerate(zip(("north", "east"), models, strict=True)):
            refresh = record["decision"]["axes"][a]["refresh"]
            recorded = refresh.get("model") if isinstance(refresh, dict) else None
            if not _same_model(model, recorded):
                raise RunLogError(
                    f"{path}: its {name} model is not the one learn-{j:03d}.json records; the "
                    "files do not belong together"
                )
        return models

    def read_floor(self) -> dict[str, Any] | None:
        """The floor recorded in ``floor.json`` (None before it is measured).

        Returns
        -------
        dict or None
            ``trials`` (the flights of identical setpoints), ``epos_m``, ``scatter_m`` and the
            rest of :meth:`gcs.core.floor.Floor.as_dict`.
        """
        path = self.path / "floor.json"
        if not path.exists():
            return None
        data = _read_json(path, "floor record")
        trials = data.get("trials") if isinstance(data, dict) else None
        if not (
            isinstance(trials, list)
            and len(trials) >= 2
            and all(isinstance(t, int) and not isinstance(t, bool) for t in trials)
        ):
            raise RunLogError(f"{path}: field 'trials' must list two or more trial numbers")
        for key in ("epos_m", "scatter_m"):
            if not _is_number(data.get(key)):
                raise RunLogError(f"{path}: field '{key}' must be a number, got {data.get(key)!r}")
        return data

    def read_estimate(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """The estimate learned from trial j: ``(d_hat (N, 2) [m], p (N, 2) [m^2])``.

        Parameters
        ----------
        j : int
            Trial index.

        Returns
        -------
        tuple of ndarray
        """
        path = self._file("estimate", j, "csv")
        if not path.exists():
            raise RunLogError(f"{path}: no estimate for trial {j} (run 'gcs learn' on it)")
        table = _read_csv(path, ESTIMATE_COLUMNS)
        if table.shape[0] != self.n_samples or not np.all(np.isfinite(table)):
            raise RunLogError(f"{path}: expected {self.n_samples} finite rows")
        _check_plausible(path, table[:, 2:6], ESTIMATE_COLUMNS[2:6])
        return table[:, 2:4], table[:, 4:6]


#: Largest magnitude a recorded position, velocity or variance may have [m, m/s, m^2]: a value
#: beyond it is no measurement (a damaged file), and would overflow the learning's numerics.
_PLAUSIBLE = 1e6


def _check_plausible(path: Path, values: np.ndarray, columns: tuple[str, ...]) -> None:
    """Refuse values beyond :data:`_PLAUSIBLE` (NaN is left to the caller), naming the column."""
    with np.errstate(invalid="ignore"):
        bad = np.argwhere(np.abs(values) > _PLAUSIBLE)
    if bad.size:
        row, col = bad[0]
        raise RunLogError(
            f"{path}: column '{columns[col]}' is {values[row, col]:.3g} at row {row + 1}, "
            f"beyond ±{_PLAUSIBLE:g}: not a measurement"
        )


def _json_text(data: dict[str, Any]) -> str:
    """Strict JSON of a record (NaN as null), the same bytes for the same data."""
    return json.dumps(json_safe(data), indent=1, allow_nan=False) + "\n"


def _read_json(path: Path, what: str) -> Any:
    try:
        return json.loads(path.read_text())
    except OSError as exc:
        raise RunLogError(f"{path}: cannot read ({exc.strerror})") from exc
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError
        raise RunLogError(f"{path}: malformed {what} ({exc})") from exc


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _check_learn_record(path: Path, j: int, data: Any) -> dict[str, Any]:
    """A ``learn-JJJ.json`` checked against its name and the types its readers rely on."""
    if not isinstance(data, dict):
        raise RunLogError(f"{path}: malformed learning record (not a JSON object)")

    def fail(key: str, what: str) -> RunLogError:
        return RunLogError(f"{path}: field '{key}' {what}")

    if data.get("trial") != j or isinstance(data.get("trial"), bool):
        raise fail("trial", f"must be {j}, as the file's name says, got {data.get('trial')!r}")
    if data.get("next_trial") != j + 1:
        raise fail("next_trial", f"must be {j + 1}, got {data.get('next_trial')!r}")
    learned = data.get("learned_from")
    if learned != list(range(j + 1)):
        raise fail("learned_from", f"must list the trials 0..{j}, got {learned!r}")
    if not (isinstance(data.get("next_iteration"), int) and data["next_iteration"] >= 1):
        raise fail("next_iteration", f"must be an integer >= 1, got {data.get('next_iteration')!r}")
    model_file = data.get("model_file")
    if model_file not in (None, f"model-{j:03d}.yaml"):
        raise fail("model_file", f"must be null or 'model-{j:03d}.yaml', got {model_file!r}")
    decision = data.get("decision")
    if not isinstance(decision, dict):
        raise fail("decision", "must be an object")
    axes = decision.get("axes")
    if not (isinstance(axes, list) and len(axes) == 2 and all(isinstance(a, dict) for a in axes)):
        raise fail("decision.axes", "must be a list of two objects (north, east)")
    for a, axis in enumerate(axes):
        refresh = axis.get("refresh")
        if refresh is not None and not (
            isinstance(refresh, dict) and isinstance(refresh.get("accepted"), bool)
        ):
            raise fail(f"decision.axes[{a}].refresh", "must be null or an object with 'accepted'")
    refreshed = any(isinstance(a.get("refresh"), dict) and a["refresh"]["accepted"] for a in axes)
    if refreshed != (model_file is not None):
        raise fail("model_file", "must name the refreshed model exactly when one was refreshed")
    verdicts = decision.get("verdicts")
    if not (isinstance(verdicts, list) and all(isinstance(v, dict) for v in verdicts)):
        raise fail("decision.verdicts", "must be a list of objects")
    if not isinstance(decision.get("converged"), bool):
        raise fail("decision.converged", "must be true or false")
    for key in ("safeguard", "floor"):
        if decision.get(key) is not None and not isinstance(decision[key], dict):
            raise fail(f"decision.{key}", "must be an object or null")
    setpoints = data.get("setpoints")
    if not (isinstance(setpoints, dict) and all(_is_number(setpoints.get(k)) for k in
                                                ("rms_m", "max_m"))):  # fmt: skip
        raise fail("setpoints", "must be an object with numbers 'rms_m' and 'max_m'")
    return data


def _same_model(model: DiscreteModel, recorded: Any) -> bool:
    """Whether ``model`` is the state space a learning record holds (None: the axis kept its
    model, which then only has to be a valid one)."""
    if recorded is None:
        return True
    if not isinstance(recorded, dict):
        return False
    try:
        same = all(
            np.array_equal(np.asarray(recorded[k], dtype=float), getattr(model, k))
            for k in ("A", "B", "C")
        )
    except (KeyError, TypeError, ValueError):
        return False
    return same and recorded.get("delay_samples") == model.delay_samples


def _check_manifest(mpath: Path, manifest: Any) -> None:
    """Refuse a manifest whose fields are missing or of the wrong type, naming the field."""
    if not isinstance(manifest, dict):
        raise RunLogError(f"{mpath}: must be a JSON object")

    def fail(key: str, what: str) -> RunLogError:
        return RunLogError(f"{mpath}: field '{key}' {what}, got {manifest.get(key)!r}")

    for key in ("algorithm", "t_ilc_s", "n_samples", "profile", "trajectory"):
        if key not in manifest:
            raise RunLogError(f"{mpath}: field '{key}' is missing")
    if not isinstance(manifest["algorithm"], str) or manifest["algorithm"] not in RUN_KINDS:
        raise fail("algorithm", f"must be one of {', '.join(RUN_KINDS)}")
    t = manifest["t_ilc_s"]
    if isinstance(t, bool) or not isinstance(t, int | float) or not (math.isfinite(t) and t > 0):
        raise fail("t_ilc_s", "must be a positive number")
    n = manifest["n_samples"]
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        raise fail("n_samples", "must be an integer >= 2")
    for key in ("profile", "trajectory"):
        if not isinstance(manifest[key], dict):
            raise fail(key, "must be an object")
    kind = manifest["trajectory"].get("type")
    if (kind == "excitation") != (manifest["algorithm"] == "identify"):
        raise RunLogError(
            f"{mpath}: field 'algorithm' is {manifest['algorithm']!r} but field "
            f"'trajectory.type' is {kind!r}: identification runs, and only they, record an "
            "excitation"
        )


def _status_from_json(path: Path, j: int, data: Any) -> TrialStatus:
    """A trial sidecar's JSON as :class:`TrialStatus`, every field checked against its type."""
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


def _rename_into_place(staging: Path, root: Path, base: str, fixed: bool) -> Path:
    """Rename a staged run to ``root/base`` (or ``base-2``, ... unless ``fixed``)."""
    suffix = 1
    while True:
        path = root / (base if suffix == 1 else f"{base}-{suffix}")
        if not path.exists() and not path.is_symlink():
            try:
                os.rename(staging, path)  # atomic; refuses a non-empty directory in the way
                return path
            except OSError:
                if not path.exists():
                    raise
        if fixed:
            raise RunLogError(f"{path}: run directory exists already")
        suffix += 1


def _version(package: str) -> str | None:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def _update_latest(root: Path, path: Path) -> None:
    """Point ``root/latest`` at the newest run (best effort: not every filesystem has links)."""
    link = root / "latest"
    tmp = root / f".latest.{os.getpid()}"
    try:
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(path.name)
        os.replace(tmp, link)
    except OSError:
        tmp.unlink(missing_ok=True)
