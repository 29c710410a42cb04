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
    again-JJJ.json         ``gcs fly --resume --again K``: trial JJJ flies trial K's setpoints
                           instead of the learned ones, which are kept in ``superseded/``
    identified.yaml        identification runs: the profile ``gcs identify`` identified from them

:class:`RunDir` names these files (its ``*_FILE`` names and ``*_path`` members); code outside
it asks the run for a file's path instead of spelling the name again.

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

import json
import math
import os
import platform
import shutil
import tempfile
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from gcs import __version__
from gcs.core.trajectory import Reference
from gcs.core.trajectory_sources import sample_reference
from gcs.errors import PathError, RunLogError
from gcs.io.atomic import DIR_MODE, atomic_write_text, write_once
from gcs.io.config import Profile, TrajectorySpec, profile_from_dict, trajectory_from_dict
from gcs.io.learnlog import LearnLog
from gcs.io.mocap_samples import write_mocap_csv
from gcs.io.paths import check_writable_dir
from gcs.io.records import (
    MOCAP_GRID_COLUMNS,
    REFERENCE_COLUMNS,
    REFERENCE_YAW_COLUMNS,
    SETPOINT_COLUMNS,
    TRIAL_COLUMNS,
    TrialRecord,
    TrialStatus,
    check_plausible,
    csv_text,
    json_safe,
    read_csv,
    read_json,
    status_from_json,
)

__all__ = ["LEARNING_ALGORITHMS", "RUN_KINDS", "RunDir"]

_PACKAGES = ("numpy", "scipy", "clarabel", "mavsdk", "pymavlink", "typer", "rich")
#: Manifest ``algorithm`` of learning runs; identification runs record ``identify``.
LEARNING_ALGORITHMS = ("smoother", "kilc")
#: Run kind by manifest algorithm.
RUN_KINDS = {"smoother": "learning", "kilc": "learning", "identify": "identification"}
#: Tolerance of a trial's setpoint columns against its setpoints file [m].
_SP_TOL_M = 1e-6
#: The three digits JJJ of a numbered file's name, as a glob pattern.
_JJJ = "[0-9][0-9][0-9]"


class RunDir(LearnLog):
    """A run directory (see the module docstring for its layout).

    The names of the run's files are spelled here and nowhere else: the ``*_FILE`` and ``*_DIR``
    names below, the numbered files (``<kind>-JJJ.<ext>``) by the ``*_path`` members. Other code
    asks the run for a file's path or name.

    ``manifest``: its parsed ``manifest.json``.
    """

    #: The manifest: profile, trajectory and algorithm as used, software versions.
    MANIFEST_FILE = "manifest.json"
    #: The reference on the grid.
    REFERENCE_FILE = "reference.csv"
    #: The floor measured from the flights of identical setpoints (learning with history).
    FLOOR_FILE = "floor.json"
    #: The profile identified from an identification run (``gcs identify``).
    IDENTIFIED_FILE = "identified.yaml"
    #: Earlier incomplete attempts of a trial, kept when it is flown again.
    ABORTED_DIR = "aborted"
    #: Setpoints learned for a trial and replaced by ``gcs fly --again``, kept.
    SUPERSEDED_DIR = "superseded"

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

        ``root``: parent directory (``logs/``). ``algorithm``: ``"smoother"`` or ``"kilc"``.
        ``run_id``: directory name; default ``<UTC time>-<trajectory>-<algorithm>``. ``reference``:
        the reference to record; default: the trajectory sampled at ``t_ilc_s`` (identification runs
        pass their excitation here).
        """
        if algorithm not in RUN_KINDS:
            raise RunLogError(f"algorithm must be one of {', '.join(RUN_KINDS)}, got {algorithm!r}")
        root = Path(root)
        ref = (
            reference
            if reference is not None
            else sample_reference(trajectory.shape, profile.t_ilc_s)
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
        staging.chmod(DIR_MODE)
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
            atomic_write_text(staged.manifest_path, json.dumps(manifest, indent=2) + "\n")
            atomic_write_text(staged.reference_path, _reference_text(ref))
            staged.write_setpoints(0, ref.pos_ned_m[:-1])
            path = _rename_into_place(staging, root, base, fixed=run_id is not None)
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        _update_latest(root, path)
        return cls(path, manifest)

    @classmethod
    def open(cls, path: Path) -> RunDir:
        """Open an existing run directory."""
        path = Path(path)
        if not path.is_dir():
            raise RunLogError(f"{path}: not a run directory")
        mpath = path / cls.MANIFEST_FILE
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

        ``kind``: ``"learning"`` or ``"identification"``. ``command``: the command, for the message
        (``gcs learn``).

        Raises ``RunLogError``: the run is of the other kind.
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

        Raises ``RunLogError``: read-only directory or filesystem, no permission.
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
        return profile_from_dict(self.manifest["profile"], f"{self.manifest_path}:profile")

    def trajectory(self) -> TrajectorySpec:
        """The trajectory as recorded in the manifest."""
        where = f"{self.manifest_path}:trajectory"
        return trajectory_from_dict(self.manifest["trajectory"], where)

    def reference(self) -> Reference:
        """The reference on the grid as recorded in ``reference.csv``.

        Velocity and acceleration are central differences of the recorded positions.
        """
        if self._reference is None:
            self._reference = self._read_reference()
        return self._reference

    def _read_reference(self) -> Reference:
        path = self.reference_path
        table = read_csv(path, REFERENCE_COLUMNS, REFERENCE_YAW_COLUMNS)
        self._check_grid(path, table, self.n_samples + 1)
        if not np.all(np.isfinite(table)):
            raise RunLogError(f"{path}: contains NaN or inf")
        check_plausible(path, table[:, 2:], (REFERENCE_COLUMNS + REFERENCE_YAW_COLUMNS)[2:])
        pos = table[:, 2:5]
        vel = np.gradient(pos, self.t_ilc_s, axis=0)
        if table.shape[1] > 5:
            yaw = np.radians(table[:, 5])
        else:  # a run of before the yaw column: its trajectory's constant yaw, if any
            yaw_deg = self.manifest["trajectory"].get("yaw_deg")
            yaw = None if yaw_deg is None else np.full(len(pos), np.radians(float(yaw_deg)))
        return Reference(table[:, 1], pos, vel, np.gradient(vel, self.t_ilc_s, axis=0), yaw)

    # ----------------------------------------------------------------- layout
    @property
    def manifest_path(self) -> Path:
        """The path of ``manifest.json``."""
        return self.path / self.MANIFEST_FILE

    @property
    def reference_path(self) -> Path:
        """The path of ``reference.csv``."""
        return self.path / self.REFERENCE_FILE

    @property
    def floor_path(self) -> Path:
        """``floor.json``: the floor, once learning with history has measured it."""
        return self.path / self.FLOOR_FILE

    @property
    def identified_path(self) -> Path:
        """``identified.yaml``: an identification run's own identified profile."""
        return self.path / self.IDENTIFIED_FILE

    def setpoints_path(self, j: int) -> Path:
        """``setpoints-JJJ.csv``: the setpoints to fly in trial j."""
        return self._file("setpoints", j, "csv")

    def trial_path(self, j: int) -> Path:
        """``trial-JJJ.csv``: trial j as flown, on the grid."""
        return self._file("trial", j, "csv")

    def status_path(self, j: int) -> Path:
        """``trial-JJJ.json``: the status sidecar of trial j (the trial counts once it says so)."""
        return self._file("trial", j, "json")

    def mocap_path(self, j: int) -> Path:
        """``mocap-JJJ.csv``: every raw motion-capture sample of trial j."""
        return self._file("mocap", j, "csv")

    def estimate_path(self, j: int) -> Path:
        """``estimate-JJJ.csv``: the disturbance estimate learned from trial j."""
        return self._file("estimate", j, "csv")

    def learn_path(self, j: int) -> Path:
        """``learn-JJJ.json``: the decision record of the learning step from trials 0..j.

        ``j``: the newest trial that step learned from.
        """
        return self._file("learn", j, "json")

    def model_path(self, j: int) -> Path:
        """``model-JJJ.yaml``: the profile with the models refreshed when learning from trial j.

        ``j``: the trial learned from.
        """
        return self._file("model", j, "yaml")

    def again_path(self, j: int) -> Path:
        """``again-JJJ.json``: the record of trial j flying an earlier trial's setpoints again."""
        return self._file("again", j, "json")

    def session_path(self, number: int) -> Path:
        """``session-SSS.json``: the record of flight session ``number``.

        ``number``: the session's number (from 1).
        """
        return self._file("session", number, "json")

    def _file(self, kind: str, j: int, ext: str) -> Path:
        return self.path / f"{kind}-{j:03d}.{ext}"

    def _numbered(self, kind: str, ext: str) -> list[int]:
        """Indices of the files ``<kind>-JJJ.<ext>`` on disk, ascending."""
        return [int(p.stem.split("-")[1]) for p in sorted(self.path.glob(f"{kind}-{_JJJ}.{ext}"))]

    def _aborted_path(self, kind: str, j: int, attempt: int, ext: str) -> Path:
        """``aborted/<kind>-JJJ-attempt-A.<ext>``: attempt A of trial j's file of ``kind``."""
        return self.path / self.ABORTED_DIR / f"{kind}-{j:03d}-attempt-{attempt}.{ext}"

    def _superseded_path(self, j: int, n: int) -> Path:
        """``superseded/setpoints-JJJ-N.csv``: the n-th setpoints of trial j replaced."""
        return self.path / self.SUPERSEDED_DIR / f"setpoints-{j:03d}-{n}.csv"

    def csv_trials(self) -> list[int]:
        """Indices of the trials with a ``trial-JJJ.csv`` on disk (whatever their status, also
        one whose sidecar was never written), ascending."""
        return self._numbered("trial", "csv")

    def again_trials(self) -> list[int]:
        """Indices of the trials with a record ``again-JJJ.json``, ascending (in force or not:
        :meth:`again_of`)."""
        return self._numbered("again", "json")

    def aborted_attempts(self) -> dict[int, int]:
        """Incomplete attempts of each trial that was flown again, kept in ``aborted/``.

        Returns: number of attempts (their sidecars) by trial index.
        """
        counts: dict[int, int] = {}
        for p in (self.path / self.ABORTED_DIR).glob(f"trial-{_JJJ}-attempt-*.json"):
            j = int(p.name.split("-")[1])
            counts[j] = counts.get(j, 0) + 1
        return counts

    # ----------------------------------------------------------------- setpoints
    def write_setpoints(self, j: int, sp_ned_m: np.ndarray) -> Path:
        """Write trial j's setpoints u(0..N-1), shape (N, 3), local NED [m].

        ``sp_ned_m``: setpoints [m].
        """
        path = self.setpoints_path(j)
        write_once(path, self._setpoints_text(j, sp_ned_m))
        return path

    def _setpoints_text(self, j: int, sp_ned_m: np.ndarray) -> str:
        sp = np.asarray(sp_ned_m, dtype=float)
        n = self.n_samples
        if sp.shape != (n, 3) or not np.all(np.isfinite(sp)):
            raise RunLogError(f"setpoints for trial {j} must be finite with shape ({n}, 3)")
        table = np.column_stack([np.arange(n), np.arange(n) * self.t_ilc_s, sp])
        return csv_text(SETPOINT_COLUMNS, table)

    def read_setpoints(self, j: int) -> np.ndarray:
        """Trial j's setpoints, shape (N, 3), local NED [m]."""
        path = self.setpoints_path(j)
        if not path.exists():
            raise RunLogError(f"{path}: no setpoints for trial {j} (run 'gcs learn' first)")
        table = read_csv(path, SETPOINT_COLUMNS)
        self._check_grid(path, table, self.n_samples)
        check_plausible(path, table[:, 2:5], SETPOINT_COLUMNS[2:5])
        return table[:, 2:5]

    def fly_again(self, j: int, k: int) -> Path:
        """Make trial j fly trial k's setpoints again instead of the ones learned for it.

        The record ``again-JJJ.json`` is written first (each call appends an entry, so nothing
        said before is lost), then the learned ``setpoints-JJJ.csv`` is moved to
        ``superseded/setpoints-JJJ-N.csv`` and trial k's setpoints are written in its place.
        An interruption between the two leaves trial j without setpoints, which learning
        from trial j-1 again writes back (the same bytes); :meth:`again_of` believes the
        record only while the setpoints in force are trial k's.

        ``j``: the next trial (not flown to completion yet).

        Raises ``RunLogError``: ``j`` complete, or ``k`` not a complete trial before it.
        """
        if j in self.complete_trials():
            raise RunLogError(f"{self.path}: trial {j} is complete; its setpoints stay")
        if not 0 <= k < j or k not in self.complete_trials():
            raise RunLogError(f"{self.path}: trial {k} is not a complete trial before trial {j}")
        sp = self.read_setpoints(k)
        current = self.setpoints_path(j)
        if current.exists() and np.array_equal(self.read_setpoints(j), sp):
            return current  # in force already (an earlier --again, or learned identical)
        n = 1
        while self._superseded_path(j, n).exists():
            n += 1
        moved = self._superseded_path(j, n)
        moved.parent.mkdir(exist_ok=True)
        entries = self._again_entries(j)
        entries.append(
            {
                "setpoints_of": k,
                "superseded": str(moved.relative_to(self.path)) if current.exists() else None,
                "written_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            }
        )
        atomic_write_text(
            self.again_path(j),
            json.dumps({"trial": j, "again": entries}, indent=2) + "\n",
        )
        if current.exists():
            os.replace(current, moved)
        return self.write_setpoints(j, sp)

    def again_of(self, j: int) -> int | None:
        """The trial whose setpoints trial j flies again (``gcs fly --again``), or None.

        Returns: None when trial j flies the setpoints learned for it.
        """
        entries = self._again_entries(j)
        if not entries or not self.setpoints_path(j).exists():
            return None
        k = entries[-1]["setpoints_of"]
        same = np.array_equal(self.read_setpoints(j), self.read_setpoints(k))
        return k if same else None

    def _again_entries(self, j: int) -> list[dict[str, Any]]:
        path = self.again_path(j)
        if not path.exists():
            return []
        what = "record of setpoints flown again"
        data = read_json(path, what)
        try:
            entries = list(data["again"])
            ok = data["trial"] == j and all(
                isinstance(e["setpoints_of"], int) and 0 <= e["setpoints_of"] < j for e in entries
            )
        except (KeyError, TypeError) as exc:
            raise RunLogError(f"{path}: malformed {what} (no {exc})") from None
        if not ok:
            raise RunLogError(f"{path}: malformed {what} (names another trial)")
        return entries

    # ----------------------------------------------------------------- trials
    def statuses(self) -> list[TrialStatus]:
        """Status of every trial on disk, by trial index."""
        return [self.read_status(j) for j in self._numbered("trial", "json")]

    def read_status(self, j: int) -> TrialStatus:
        """The sidecar of trial j."""
        path = self.status_path(j)
        try:
            data = json.loads(path.read_text())
        except OSError as exc:
            raise RunLogError(f"{path}: cannot read ({exc.strerror})") from exc
        except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError
            raise RunLogError(f"{path}: malformed trial status ({exc})") from exc
        return status_from_json(path, j, data)

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

        ``mocap``: the trial's raw motion-capture samples (``mocap-JJJ.csv``).
        """
        csv_path, json_path = self.trial_path(j), self.status_path(j)
        if record.n_samples != self.n_samples:
            raise RunLogError(f"trial {j} has {record.n_samples} samples, the run {self.n_samples}")
        if json_path.exists():
            if self.read_status(j).complete:
                raise RunLogError(f"{json_path}: trial {j} is complete; refusing to overwrite it")
            self._archive_attempt(j)
        elif csv_path.exists():  # a CSV whose sidecar was never written (interrupted write)
            self._archive_attempt(j)
        if mocap is not None:
            write_mocap_csv(self.mocap_path(j), mocap)
        atomic_write_text(csv_path, csv_text(record.columns, record.table()))
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
        (self.path / self.ABORTED_DIR).mkdir(exist_ok=True)
        attempt = 1
        while any(self._aborted_path("trial", j, attempt, ext).exists() for ext in ("csv", "json")):
            attempt += 1
        for src, ext in ((self.trial_path(j), "csv"), (self.status_path(j), "json")):
            if src.exists():
                os.replace(src, self._aborted_path("trial", j, attempt, ext))
        raw = self.mocap_path(j)
        if raw.exists():
            os.replace(raw, self._aborted_path("mocap", j, attempt, "csv"))

    def measured_trial(self, j: int, measurement: str | None = None) -> TrialRecord:
        """Trial j as learning and e_pos see it: its motion capture or its estimate.

        ``measurement``: ``"mocap"`` (the trial's mocap columns where it has them, else the
        estimate) or ``"estimate"``; None: the run's own profile's ``mocap.measurement``.

        Returns: with ``pos_ned_m`` the chosen measurement [m, NED].

        Raises ``RunLogError``: as :meth:`read_trial`, or mocap columns without a position on the
        grid.
        """
        if measurement is None:
            measurement = self.profile().mocap.measurement
        record = self.read_trial(j)
        try:
            return record.measured(measurement)
        except RunLogError as exc:
            raise RunLogError(f"{self.trial_path(j)}: {exc}") from None

    def read_trial(self, j: int) -> TrialRecord:
        """Read and validate a complete trial for learning or reporting.

        Raises ``RunLogError``: incomplete trial, wrong length, NaN values, or a grid that does not
        match t_ilc_s.
        """
        status = self.read_status(j)
        path = self.trial_path(j)
        if not status.complete:
            raise RunLogError(
                f"{path}: trial {j} is incomplete ({status.reason}); not learned from"
            )
        if not path.exists():
            raise RunLogError(f"{path}: missing, but {path.stem}.json says the trial is complete")
        table = read_csv(path, TRIAL_COLUMNS, MOCAP_GRID_COLUMNS)
        self._check_grid(path, table, self.n_samples + 1)
        values = table[:, :14]
        bad = np.argwhere(~np.isfinite(values))
        if bad.size:
            row, col = bad[0]
            raise RunLogError(f"{path}: column '{TRIAL_COLUMNS[col]}' is NaN or inf at k = {row}")
        check_plausible(path, table[:, 2:14], TRIAL_COLUMNS[2:14])
        record = TrialRecord.from_table(table)
        self._check_flown_setpoints(path, j, record)
        return record

    def _check_flown_setpoints(self, path: Path, j: int, record: TrialRecord) -> None:
        """The setpoint columns of trial j must be ``setpoints-JJJ.csv``: files agree with names."""
        sp_path = self.setpoints_path(j)
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

        ``number``: None for a new session (it takes the next free number; an existing record is
        never replaced), else the number this session was given before.

        Returns: the session's number.
        """

        def text(n: int) -> str:
            return json.dumps(json_safe({"session": n, **data}), indent=2) + "\n"

        if number is not None:
            atomic_write_text(self.session_path(number), text(number))
            return number
        number = len(self.sessions()) + 1
        tmp = self.path / f".session-new.{os.getpid()}.tmp"
        try:
            while True:
                atomic_write_text(tmp, text(number))
                try:
                    os.link(tmp, self.session_path(number))  # fails if it exists
                    return number
                except FileExistsError:
                    number += 1
        finally:
            tmp.unlink(missing_ok=True)

    def sessions(self) -> list[dict[str, Any]]:
        """Every session record of the run, by number."""
        out = []
        for number in self._numbered("session", "json"):
            path = self.session_path(number)
            try:
                data = json.loads(path.read_text())
            except (OSError, ValueError) as exc:
                raise RunLogError(f"{path}: unreadable session record ({exc})") from exc
            if not isinstance(data, dict) or data.get("session") != number:
                raise RunLogError(f"{path}: field 'session' must be {number}, as its name says")
            out.append(data)
        return out


def _reference_text(ref: Reference) -> str:
    """``reference.csv``: k, t and the position; the yaw [deg] last when the reference has one."""
    table = np.column_stack([np.arange(ref.n_samples + 1), ref.t_s, ref.pos_ned_m])
    if ref.yaw_rad is None:
        return csv_text(REFERENCE_COLUMNS, table)
    table = np.column_stack([table, np.degrees(ref.yaw_rad)])
    return csv_text(REFERENCE_COLUMNS + REFERENCE_YAW_COLUMNS, table)


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
