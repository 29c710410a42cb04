"""``gcs fly``: the request checked, the flight's sequence, and a run directory as the flight
layer's trial source.

:func:`fly` is the command: it checks everything (:func:`plan_fly`, the vehicle's options),
then says what would be flown (``--check``) or sets up the run and flies it, telling a
:class:`FlyView` (the terminal's is :class:`gcs.app.fly_view.FlyDisplay`) what to show.

The flight layer asks for "the next sequence" and hands back recordings; :class:`RunSource`
answers from the run directory and learns with :func:`gcs.app.learn.learn_run`, the same function
``gcs learn`` calls. In a flight it lives in a worker process of its own
(:mod:`gcs.app.source_worker`, built there by :func:`run_source`), so that writing the trials and
learning cannot take the flight process's time; its rows and learning outcomes come back to the
view's callbacks.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from contextlib import AbstractContextManager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from gcs.app.failures import OptionError
from gcs.app.learn import (
    LearnOutcome,
    check_algorithm,
    check_history,
    check_learnable,
    differing_field,
    learn_run,
)
from gcs.app.report import drift_sentence
from gcs.app.session import (
    MocapPlan,
    SessionRecorder,
    check_mock_config,
    check_url,
    flight_fence,
    flyable_setpoints,
    mock_config_for,
    plan_mocap,
    raw_mocap,
    to_record,
    trial_extra,
    vehicle_url,
)
from gcs.app.source_worker import Notify, WorkerSource
from gcs.core.floor import FloorDrift, FloorVerdict, floor_drift
from gcs.core.metrics import IterationMetrics, iteration_table
from gcs.core.trajectory import (
    MAX_SAMPLES,
    Reference,
    check_reference,
)
from gcs.core.trajectory_sources import sample_reference
from gcs.core.trials import trial_errors, trial_errors_3d
from gcs.errors import GcsError, ProfileError, RunLogError, TrajectoryError, VehicleError
from gcs.flight.campaign import CampaignPlan, run_campaign
from gcs.flight.mocap.link import MocapLink
from gcs.flight.trial import TrialRecording
from gcs.io.config import Profile, TrajectorySpec, load_profile, load_trajectory
from gcs.io.paths import check_new_dir, check_output_dir
from gcs.io.records import TrialStatus
from gcs.io.rundir import RunDir
from gcs.io.settings import FlightSettings

__all__ = [
    "FlyPlan",
    "FlyRequest",
    "fly",
    "check_request",
    "check_vehicle",
    "mock_session_seed",
    "resume_command",
    "plan_fly",
    "start_run",
    "RunSource",
    "run_source",
    "prepare_run",
    "fly_run",
    "converged_reason",
    "newest_record",
    "check_until_converged",
    "check_again",
    "drift_reason",
    "record_drift",
]


@dataclass(frozen=True)
class FlyPlan:
    """Everything ``gcs fly`` needs, validated before anything is created, moved or flown.

    Parameters
    ----------
    profile : Profile
        The profile (a new run's, or the resumed run's).
    trajectory : TrajectorySpec
        The trajectory.
    algorithm : str
        ``"smoother"`` or ``"kilc"``.
    settings : FlightSettings
        The profile's flight settings.
    reference : Reference
        The reference on the grid, checked against the vehicle and the arena.
    first_trial : int
        The trial to fly first.
    run : RunDir or None
        The run to resume; None for a new one.
    run_path : Path or None
        Exact path of the new run.
    logs : Path
        Parent of new runs.
    mocap : MocapPlan or None
        The motion capture of the flight.
    again : int or None
        ``--again``: the complete trial whose setpoints the first trial flies again.
    """

    profile: Profile
    trajectory: TrajectorySpec
    algorithm: str
    settings: FlightSettings
    reference: Reference
    first_trial: int
    run: RunDir | None
    run_path: Path | None
    logs: Path
    mocap: MocapPlan | None = None
    again: int | None = None


@dataclass(frozen=True)
class FlyRequest:
    """``gcs fly`` as asked: its options, before anything is checked (:func:`plan_fly`).

    Parameters
    ----------
    iterations : int
        ``--iter``: trials to fly (the cap with ``until_converged``).
    use_mock : bool
        ``--mock``: fly the mock drone.
    connect : str or None
        ``--connect``: URL of a real vehicle or PX4 SITL.
    mock_config : Path or None
        ``--mock-config``: the mock's settings (None: the default).
    seed : int
        ``--seed``: the mock's gusts.
    profile, trajectory : Path or None
        Files of a new run (None: with ``resume``, the run's own; else required).
    algorithm : str or None
        ``--algorithm`` (default: the profile's, or the resumed run's).
    run : Path or None
        ``--run``: exact path of a new run.
    resume : Path or None
        ``--resume``: the run to continue.
    logs : Path
        ``--logs``: parent of new runs.
    check_only : bool
        ``--check``: validate and say what would be flown; nothing is created or flown.
    offline : bool
        ``--offline``: with ``check_only``, connect to no vehicle.
    until_converged : bool
        ``--until-converged``: land once learning has converged or left the floor; the
        profile must measure the floor (:func:`check_until_converged`).
    mocap : str or None
        ``--mocap`` (:func:`gcs.app.session.plan_mocap`).
    again : int or None
        ``--again K`` (with ``resume``): the next trial flies complete trial K's setpoints
        instead of the learned ones (:func:`check_again`).
    """

    iterations: int = 3
    use_mock: bool = False
    connect: str | None = None
    mock_config: Path | None = None
    seed: int = 0
    profile: Path | None = None
    trajectory: Path | None = None
    algorithm: str | None = None
    run: Path | None = None
    resume: Path | None = None
    logs: Path = Path("logs")
    check_only: bool = False
    offline: bool = False
    until_converged: bool = False
    mocap: str | None = None
    again: int | None = None


def plan_fly(request: FlyRequest) -> FlyPlan:
    """Validate everything a flight needs; nothing is created, moved or flown here.

    A new run: the profile (every section, flight settings included), the trajectory on the
    flown grid against the vehicle's limits and the arena, a dry first learning update (models
    and setpoint limits admit one), the run's path. A resumed run: the run directory (a
    learning run, writable, its manifest, reference, trial files and the next trial's
    setpoints on their grid limits), and the profile / trajectory, if given, must be the
    run's own.

    Parameters
    ----------
    request : FlyRequest
        The command's options (the vehicle's are checked by the caller, which connects).

    Returns
    -------
    FlyPlan
    """
    profile_path, trajectory_path = request.profile, request.trajectory
    algorithm, run_path, resume, logs = (
        request.algorithm, request.run, request.resume, request.logs
    )  # fmt: skip
    until_converged, mocap, use_mock, again = (
        request.until_converged, request.mocap, request.use_mock, request.again
    )  # fmt: skip
    if again is not None and resume is None:
        raise RunLogError("--again flies an earlier trial of a run again: give it with --resume")
    if resume is not None:
        plan = _plan_resume(resume, profile_path, trajectory_path, algorithm, logs, again)
        where = f"{plan.run.manifest_path}:profile" if plan.run else str(resume)
        if until_converged:
            check_until_converged(plan.profile, where)
        return replace(plan, mocap=plan_mocap(plan.profile, where, mocap, use_mock))
    if profile_path is None or trajectory_path is None:
        raise ProfileError("a new run needs a profile and a trajectory")
    profile, where = load_profile(profile_path), str(profile_path)
    if until_converged:
        check_until_converged(profile, where)
    trajectory = load_trajectory(trajectory_path)
    algorithm = algorithm or profile.learning.algorithm
    mocap_plan = plan_mocap(profile, where, mocap, use_mock)
    ref = flown_reference(profile, trajectory, str(trajectory_path))
    settings = flown_yaw(profile.flight, ref)
    check_learnable(profile, ref, algorithm, where)
    if run_path is not None:
        check_new_dir(run_path, "--run")
    else:
        check_output_dir(logs, "--logs")
    return FlyPlan(
        profile, trajectory, algorithm, settings, ref, 0, None, run_path, logs, mocap_plan
    )


def flown_reference(profile: Profile, trajectory: TrajectorySpec, where: str) -> Reference:
    """The trajectory sampled on the profile's grid and checked against its limits and arena.

    Parameters
    ----------
    profile : Profile
        Its ``t_ilc_s``, vehicle limits and arena.
    trajectory : TrajectorySpec
        A loaded trajectory (a samples source read with its file).
    where : str
        The trajectory's file, for the message.

    Returns
    -------
    Reference

    Raises
    ------
    TrajectoryError
        Not a trajectory to sample, too many samples, beyond a limit or the arena.
    """
    if trajectory.shape is None:
        what = (
            "its samples file was not read (load_trajectory reads it, relative to the file)"
            if trajectory.source.get("type") == "samples"
            else "not a trajectory to sample (an identification excitation)"
        )
        raise TrajectoryError(f"{where}: {what}")
    duration = trajectory.shape.duration_s
    if not duration / profile.t_ilc_s <= MAX_SAMPLES:  # before the arrays are made
        raise TrajectoryError(
            f"{where}: a trial of {duration:g} s has more than {MAX_SAMPLES} samples of "
            f"{profile.t_ilc_s:g} s"
        )
    try:
        with np.errstate(over="raise", invalid="raise"):
            ref = sample_reference(trajectory.shape, profile.t_ilc_s)
        check_within_limits(ref, profile)
    except TrajectoryError as exc:
        raise TrajectoryError(f"{where}: {exc}") from None
    except FloatingPointError as exc:
        raise TrajectoryError(f"{where}: its numbers overflow when sampled ({exc})") from None
    return ref


def flown_yaw(settings: FlightSettings, ref: Reference) -> FlightSettings:
    """The flight settings with the heading the trajectory starts with.

    A trajectory with a yaw (a constant ``yaw_deg``, or a samples file's ``yaw_deg`` column)
    is flown facing its own way: the take-off, the moves and the hovers hold its first yaw,
    each trial's setpoints carry theirs (:func:`trial_yaw_deg`). Without one the yaw is held
    at the profile's ``flight.yaw_deg``.

    Parameters
    ----------
    settings : FlightSettings
        The profile's flight settings.
    ref : Reference
        The reference on the grid (its ``yaw_rad``).

    Returns
    -------
    FlightSettings
    """
    if ref.yaw_rad is None:
        return settings
    return replace(settings, yaw_deg=float(np.degrees(ref.yaw_rad[0])))


def trial_yaw_deg(ref: Reference) -> np.ndarray | None:
    """The heading of each trial setpoint ``u(0) .. u(N-1)``: the reference's yaw (flown as the
    reference, never learned), or None when the yaw is held.

    Parameters
    ----------
    ref : Reference
        The reference on the grid.

    Returns
    -------
    ndarray, shape (N,), or None
        [deg, clockwise from north; unwrapped].
    """
    return None if ref.yaw_rad is None else np.degrees(ref.yaw_rad[:-1])


def check_within_limits(ref: Reference, profile: Profile) -> None:
    """Refuse a reference beyond the profile's vehicle limits or arena, on the flown grid.

    Parameters
    ----------
    ref : Reference
        The sampled reference.
    profile : Profile
        Its ``vehicle`` limits (horizontal and vertical) and ``arena``.

    Raises
    ------
    TrajectoryError
        Naming the limit and the time (:func:`gcs.core.trajectory.check_reference`).
    """
    check_reference(
        ref,
        profile.max_speed_m_s,
        profile.max_accel_m_s2,
        profile.arena,
        max_jerk_m_s3=profile.max_jerk_m_s3,
        max_vertical_speed_m_s=profile.max_vertical_speed_m_s,
        max_vertical_accel_m_s2=profile.max_vertical_accel_m_s2,
        max_vertical_jerk_m_s3=profile.max_vertical_jerk_m_s3,
        max_yaw_rate_deg_s=profile.max_yaw_rate_deg_s,
    )


def _plan_resume(
    resume: Path,
    profile_path: Path | None,
    trajectory_path: Path | None,
    algorithm: str | None,
    logs: Path,
    again: int | None = None,
) -> FlyPlan:
    run = RunDir.open(resume)
    run.require_kind("learning", "gcs fly --resume")
    if algorithm is not None and algorithm != run.algorithm:
        raise RunLogError(f"{resume}: the run learns with '{run.algorithm}', not '{algorithm}'")
    for given, loader, key in (
        (profile_path, load_profile, "profile"),
        (trajectory_path, load_trajectory, "trajectory"),
    ):
        if given is not None:
            field = differing_field(loader(given).source, run.manifest[key])
            if field is not None:
                raise RunLogError(
                    f"--{key} {given}: differs from the {key} {resume} was flown with (field "
                    f"'{field}'); a resumed run keeps its own {key}: leave out --{key}, or "
                    "start a new run"
                )
    profile, trajectory = run.profile(), run.trajectory()
    ref = run.reference()
    settings = flown_yaw(profile.flight, ref)
    try:
        check_within_limits(ref, profile)
    except TrajectoryError as exc:
        raise RunLogError(f"{run.reference_path}: {exc}") from None
    first = run.next_trial()
    if again is not None:
        check_again(run, profile, first, again)
    elif first > 0:
        run.read_trial(first - 1)  # the trial the next setpoints were learned from
        if not run.setpoints_path(first).exists():
            raise RunLogError(
                f"{run.path}: no setpoints for trial {first}; run 'gcs learn {run.path}' first"
            )
    if profile.learning.adaptive is not None and first > 0:
        check_history(run, profile, first - 1)
    flyable_setpoints(run, first if again is None else again)
    run.check_writable()
    return FlyPlan(
        profile, trajectory, run.algorithm, settings, ref, first, run, None, logs, again=again
    )


def check_again(run: RunDir, profile: Profile, first: int, again: int) -> None:
    """Refuse ``--again K`` unless trial K is a complete learned trial before the next one.

    The next trial must be a learned one: the repeats of trial 0 measure the floor with
    identical setpoints and are flown as they are.

    Parameters
    ----------
    run : RunDir
        The resumed learning run.
    profile : Profile
        Its profile.
    first : int
        The next trial.
    again : int
        ``--again``.

    Raises
    ------
    RunLogError
    """
    repeats = profile.learning.repeats
    if first <= repeats:
        what = "the first trial" if first == 0 else "a repeat of trial 0 (it measures the floor)"
        raise RunLogError(
            f"--again {again}: the next trial of {run.path}, trial {first}, is {what}; "
            "it flies its own setpoints"
        )
    done = run.complete_trials()
    if again not in done or again >= first:
        raise RunLogError(
            f"--again {again}: not a complete trial of {run.path} (complete: "
            f"{', '.join(map(str, done))})"
        )


def check_until_converged(profile: Profile, where: str) -> None:
    """Refuse ``--until-converged`` with a profile that cannot say when learning has converged.

    "Converged" compares trials with the floor, which flights of identical setpoints measure:
    the profile needs a ``learning.adaptive`` section with ``repeats`` of at least 1.

    Parameters
    ----------
    profile : Profile
        The run's profile.
    where : str
        The profile's file, for the message.

    Raises
    ------
    ProfileError
    """
    if profile.learning.adaptive is None:
        raise ProfileError(
            f"--until-converged: {where} has no learning.adaptive section, so nothing measures "
            "the floor that says when learning has converged (use profile antx-adaptive)"
        )
    if profile.learning.repeats < 1:
        raise ProfileError(
            f"--until-converged: {where} sets learning.adaptive.repeats to 0: without a repeat "
            "of trial 0 there is no floor to converge to"
        )


def start_run(plan: FlyPlan) -> RunDir:
    """The run to fly: the resumed one (its next trial set to fly an earlier trial's setpoints
    with ``--again``), or a new run directory created from the plan.

    Parameters
    ----------
    plan : FlyPlan
        From :func:`plan_fly`.

    Returns
    -------
    RunDir
    """
    if plan.run is not None:
        if plan.again is not None:
            plan.run.fly_again(plan.first_trial, plan.again)
        return plan.run
    if plan.run_path is not None:
        return RunDir.create(
            plan.run_path.parent, plan.profile, plan.trajectory, plan.algorithm,
            run_id=plan.run_path.name, reference=plan.reference,
        )  # fmt: skip
    return RunDir.create(
        plan.logs, plan.profile, plan.trajectory, plan.algorithm, reference=plan.reference
    )


def prepare_run(
    logs: Path,
    profile: Profile,
    trajectory: TrajectorySpec,
    algorithm: str,
    run_path: Path | None = None,
) -> RunDir:
    """Check the trajectory against the vehicle and the arena, then create the run directory.

    Parameters
    ----------
    logs : Path
        Parent of new run directories.
    profile : Profile
        Vehicle profile.
    trajectory : TrajectorySpec
        The manoeuvre.
    algorithm : str
        ``"smoother"`` or ``"kilc"``.
    run_path : Path, optional
        Create the run exactly here instead of ``logs/<run-id>``.

    Returns
    -------
    RunDir
    """
    ref = flown_reference(profile, trajectory, trajectory.name)
    if run_path is not None:
        root, run_id = run_path.parent, run_path.name
    else:
        root, run_id = logs, None
    return RunDir.create(root, profile, trajectory, algorithm, run_id=run_id, reference=ref)


@dataclass
class RunSource(SessionRecorder):
    """Trial source of the flight layer backed by a run directory.

    Parameters
    ----------
    run : RunDir
        The run being flown.
    on_row : callable, optional
        Called with the Table IV rows of the run after each complete trial is recorded.
    session : int or None
        Number of this flight session's record in the run (set by :meth:`record_session`).
    on_learn : callable, optional
        Called with what each learning step did (:class:`gcs.app.learn.LearnOutcome`), after
        ``on_row``.
    until_converged : bool
        Fly no further trial once the learning record says learning has converged, or has
        left the floor it reached.
    mock_seed : int or None
        The mock drone's seed, kept in the session record (None on a real vehicle).
    """

    run: RunDir
    on_row: Callable[[list[IterationMetrics]], None] | None = None
    session: int | None = None
    on_learn: Callable[[LearnOutcome], None] | None = None
    until_converged: bool = False
    mock_seed: int | None = None

    def setpoints_for(self, j: int) -> np.ndarray:
        """Trial j's setpoints from the run directory, refused if any leaves the arena.

        Parameters
        ----------
        j : int
            Trial index.

        Returns
        -------
        ndarray, shape (N, 3)
            Absolute local NED [m].
        """
        return flyable_setpoints(self.run, j)

    def hover_point_for(self, j: int) -> np.ndarray:
        """The trajectory's start point, where the vehicle hovers before every trial.

        Parameters
        ----------
        j : int
            Trial index.

        Returns
        -------
        ndarray, shape (3,)
            Absolute local NED [m].
        """
        return self.run.reference().pos_ned_m[0]

    def record(self, j: int, recording: TrialRecording) -> str | None:
        """Write a complete trial, then learn the next trial's setpoints from it.

        Parameters
        ----------
        j : int
            Trial index.
        recording : TrialRecording
            The complete recording.

        Returns
        -------
        str or None
            With ``until_converged``, why no further trial can help (the campaign lands):
            learning converged (:func:`converged_reason`) or left the floor it had reached
            (:func:`drift_reason`); else None.
        """
        record = to_record(self.run, recording)
        extra = trial_extra(recording, self.session)
        try:
            measured = record.measured(self.run.profile().mocap.measurement)
        except RunLogError as exc:
            # flown, but the measurement learning needs has a hole (the mocap stream missed a
            # grid time): kept as flown, marked incomplete, so that a resume flies it again
            self.record_incomplete(j, recording, f"flown, but {exc}")
            raise
        e, m = trial_errors(measured)
        extra["epos_3d_m"], *rms = trial_errors_3d(measured)
        extra["rms_ned_m"] = rms
        if record.mocap_ned_m is not None:
            extra["epos_estimate_m"] = trial_errors(record)[0]
            extra["measurement"] = "estimate" if measured is record else "mocap"
        status = TrialStatus(
            j, True, epos_m=e, max_err_m=m, interpolated_share=recording.interpolated_share,
            extra=extra,
        )  # fmt: skip
        self.run.write_trial(j, record, status, raw_mocap(recording))
        outcome = learn_run(self.run)
        if self.on_row is not None:
            self.on_row(self.rows())
        if self.on_learn is not None:
            self.on_learn(outcome)
        if not self.until_converged:
            return None
        return converged_reason(outcome.record) or drift_reason(outcome.record)

    def record_incomplete(self, j: int, recording: TrialRecording, reason: str) -> None:
        """Write an interrupted trial, marked incomplete (never learned from).

        Parameters
        ----------
        j : int
            Trial index.
        recording : TrialRecording
            The partial recording.
        reason : str
            Why the trial stopped.
        """
        record = to_record(self.run, recording)
        status = TrialStatus(
            j, False, reason=reason, interpolated_share=recording.interpolated_share,
            extra=trial_extra(recording, self.session),
        )  # fmt: skip
        self.run.write_trial(j, record, status, raw_mocap(recording))

    def rows(self) -> list[IterationMetrics]:
        """Table IV rows of the complete trials so far (from the sidecars)."""
        done = [s for s in self.run.statuses() if s.complete]
        rows = iteration_table(
            [s.epos_m for s in done], [s.max_err_m for s in done], [s.trial for s in done]
        )
        return [_with_3d(r, s.extra or {}) for r, s in zip(rows, done, strict=True)]


def _with_3d(row: IterationMetrics, extra: dict) -> IterationMetrics:
    """A row with the 3-D e_pos and the RMS per axis a trial's sidecar records."""
    rms = extra.get("rms_ned_m")
    if extra.get("epos_3d_m") is None or not isinstance(rms, list) or len(rms) != 3:
        return row
    n, e, d = (float(v) for v in rms)
    return replace(
        row, epos_3d_m=float(extra["epos_3d_m"]), rms_north_m=n, rms_east_m=e, rms_down_m=d
    )


def converged_reason(record: dict | None) -> str | None:
    """Why further trials cannot help, from a decision record, or None (go on).

    Parameters
    ----------
    record : dict or None
        A ``learn-JJJ.json`` record (:meth:`gcs.io.rundir.RunDir.read_learn_record`).

    Returns
    -------
    str or None
        E.g. "learning has converged: trials 5 and 6 are at the floor (1.04x and 0.97x of
        21.3 mm), their mean within one scatter (2.7 mm) of it".
    """
    if record is None or not record["decision"]["converged"]:
        return None
    decision = record["decision"]
    floor, verdicts = decision["floor"], decision["verdicts"]
    a, b = verdicts[-2], verdicts[-1]
    return (
        f"learning has converged: trials {a['trial']} and {b['trial']} are at the floor "
        f"({a['ratio']:.2f}x and {b['ratio']:.2f}x of {1e3 * floor['epos_m']:.1f} mm), their "
        f"mean within one scatter ({1e3 * floor['scatter_m']:.1f} mm) of it"
    )


def drift_reason(record: dict | None) -> str | None:
    """Why the next trials are unlikely to help: learning left the floor it had reached
    (:func:`gcs.core.floor.floor_drift`), from a decision record; None when it did not.

    Parameters
    ----------
    record : dict or None
        A ``learn-JJJ.json`` record.

    Returns
    -------
    str or None
        E.g. "drifting up: trial 3 reached the floor, trials 5 and 6 are above it again; the
        best setpoints at the floor are trial 4's".
    """
    drift = record_drift(record)
    return None if drift is None else drift_sentence(drift)


def record_drift(record: dict | None) -> FloorDrift | None:
    """The drift up from the floor a decision record shows, or None.

    Parameters
    ----------
    record : dict or None
        A ``learn-JJJ.json`` record.

    Returns
    -------
    FloorDrift or None
    """
    if record is None or not record["decision"]["verdicts"]:
        return None
    return floor_drift(tuple(FloorVerdict(**v) for v in record["decision"]["verdicts"]))


def newest_record(run: RunDir) -> dict | None:
    """The decision record of the run's newest learning step, or None.

    Parameters
    ----------
    run : RunDir
        A learning run.

    Returns
    -------
    dict or None
    """
    j = run.newest_complete()
    if j is None or not run.learn_path(j).exists():
        return None
    return run.read_learn_record(j)


def run_source(
    run: RunDir, until_converged: bool, mock_seed: int | None, *, notify: Notify
) -> RunSource:
    """The run's trial source as the worker process builds it, its callbacks sent back.

    Parameters
    ----------
    run : RunDir
        The run being flown.
    until_converged : bool
        Fly no further trial once learning has converged.
    mock_seed : int or None
        The mock drone's seed (None on a real vehicle).
    notify : callable
        ``notify(kind, payload)``: ``"row"`` with the Table IV rows, ``"learn"`` with the
        learning step's outcome (:class:`gcs.app.source_worker.WorkerSource`).

    Returns
    -------
    RunSource
    """
    return RunSource(
        run,
        on_row=lambda rows: notify("row", rows),
        on_learn=lambda outcome: notify("learn", outcome),
        until_converged=until_converged,
        mock_seed=mock_seed,
    )


def fly_run(
    url: str,
    run: RunDir,
    iterations: int,
    settings: FlightSettings,
    on_event: Callable[[object], None] | None = None,
    on_row: Callable[[list[IterationMetrics]], None] | None = None,
    on_learn: Callable[[LearnOutcome], None] | None = None,
    until_converged: bool = False,
    mocap: MocapLink | None = None,
    mock_seed: int | None = None,
) -> None:
    """Fly ``iterations`` trials of ``run`` from its next trial, learning between trials.

    The run's trial source (:class:`RunSource`: trial files, learning, session records) runs
    in a worker process of its own (:class:`gcs.app.source_worker.WorkerSource`), shut down
    when the campaign ends, however it ends.

    Parameters
    ----------
    url : str
        MAVSDK connection URL.
    run : RunDir
        The run; flying starts at ``run.next_trial()``.
    iterations : int
        Number of trials.
    settings : FlightSettings
        Flight settings.
    on_event : callable, optional
        Receives the flight layer's campaign events.
    on_row : callable, optional
        Receives the Table IV rows after each complete trial.
    on_learn : callable, optional
        Receives what each learning step did.
    until_converged : bool
        Land as soon as learning has converged (``iterations`` stays the cap).
    mocap : MocapLink or None
        A started motion-capture link (forwarded, checked, watched, logged).
    mock_seed : int or None
        The mock drone's seed, recorded in the session (None on a real vehicle).
    """
    first = run.next_trial()
    if first > 0 and not run.setpoints_path(first).exists():
        raise RunLogError(f"{run.path}: no setpoints for trial {first}; run 'gcs learn' first")
    callbacks = {"row": on_row or _ignore, "learn": on_learn or _ignore}
    fence = flight_fence(run.profile(), settings)
    plan = CampaignPlan(
        url, first, iterations, run.t_ilc_s, settings, fence, trial_yaw_deg(run.reference())
    )
    with WorkerSource(run_source, (run, until_converged, mock_seed), callbacks) as source:
        run_campaign(plan, source, on_event, mocap=mocap)


def _ignore(payload: object) -> None:
    """A callback nobody asked for."""


class FlyView(Protocol):
    """What ``gcs fly`` shows (the terminal's: :class:`gcs.app.fly_view.FlyDisplay`)."""

    def say(self, text: str) -> None:
        """One line of the flight session's set-up (the mock drone, the mocap, waiting)."""

    def nothing_flown(self, run: RunDir, reason: str) -> None:
        """``--until-converged`` on a resumed run that converged (or left the floor) already."""

    def checked(self, plan: FlyPlan, iterations: int) -> None:
        """``--check``: what would be flown, and what it asks of the vehicle."""

    def checklist(self, navigation: str, url: str, verdicts: list[Any]) -> None:
        """``--check``: the vehicle's parameters judged against the checklist."""

    def started(self, run: RunDir) -> None:
        """The run about to be flown."""

    def live(
        self, run: RunDir
    ) -> tuple[
        AbstractContextManager[Any],
        Callable[[object], None],
        Callable[[list[IterationMetrics]], None],
    ]:
        """The live display around the flight, its campaign-event and table-row callbacks."""

    def learned(self, outcome: LearnOutcome, again: str | None) -> None:
        """What a learning step between trials decided; ``again``: how to fly the best
        setpoints again once learning left the floor."""

    def interrupted(self, run: RunDir, resume: str) -> None:
        """Ctrl-C: the vehicle landed; where the run is and how to continue it."""

    def stopped(self, run: RunDir, resume: str) -> None:
        """A failure mid-flight (said next, in one line): how to continue once it is fixed."""

    def left_floor(self, best_trial: int, again: str) -> None:
        """``--until-converged`` landed: learning left the floor."""

    def not_converged(self, iterations: int, resume: str) -> None:
        """``--until-converged``: learning has not converged within ``--iter``."""

    def finished(self, run: RunDir) -> None:
        """The run's table, its legend and verdict."""


def check_request(request: FlyRequest) -> None:
    """Refuse options that do not go together: one vehicle, one run, a known algorithm.

    Parameters
    ----------
    request : FlyRequest
        The command's options.

    Raises
    ------
    OptionError
    """
    check_algorithm(request.algorithm)
    if request.use_mock == (request.connect is not None):
        raise OptionError("give exactly one of --mock and --connect")
    if request.resume is not None and request.run is not None:
        raise OptionError("give at most one of --run and --resume")


def mock_session_seed(seed: int, session: int, used: Collection[int] = ()) -> int:
    """The mock drone's seed for flight session ``session`` of a run, never one flown before.

    ``--seed`` itself when no earlier session of the run flew it (a new run, or a resume given
    a seed of its own); else a seed drawn from ``(seed, session)`` by NumPy's ``SeedSequence``.
    A resumed run therefore never replays an earlier session's gusts and noise: a repeat of
    trial 0 flown after ``--resume`` with the same ``--seed`` would otherwise fly trial 0's
    gusts again and measure a floor of the replay (millimetres), not of the vehicle. The seed
    flown is kept in the session's record (``mock_seed``).

    Parameters
    ----------
    seed : int
        ``--seed``.
    session : int
        The session's number (1 for the first).
    used : collection of int
        The mock seeds the run's earlier sessions flew.

    Returns
    -------
    int
        ``seed``, or a seed in [0, 2**31) that is not in ``used``.
    """
    if seed not in used:
        return seed
    attempt = 0
    while True:
        state = np.random.SeedSequence([seed, session, attempt]).generate_state(1)[0]
        derived = int(state) % 2**31
        if derived not in used:
            return derived
        attempt += 1


def resume_command(
    run_path: Path, request: FlyRequest, iterations: int, again: int | None = None
) -> str:
    """The ``gcs fly --resume`` command that continues ``run_path`` with the same vehicle.

    The vehicle is named as the session named it (``--mock`` with its settings and seed, or
    ``--connect URL``), and motion capture when ``--mocap`` was given: a resumed run takes its
    profile and trajectory from its record, but never its vehicle (which is chosen anew by
    whoever resumes: a port, PX4 SITL or the real vehicle).

    Parameters
    ----------
    run_path : Path
        The run to continue.
    request : FlyRequest
        The session's options (``--mock-config`` as given: None for the default; ``--seed``
        only printed when it is not the default, 0; ``--until-converged`` kept).
    iterations : int
        ``--iter`` of the command.
    again : int or None
        ``--again``: the trial whose setpoints the next trial flies again.

    Returns
    -------
    str
        One shell command line, quoted where needed.
    """
    import shlex

    from gcs.io.paths import packaged_dir

    args = ["gcs", "fly", "--resume", str(run_path)]
    if request.use_mock:
        args.append("--mock")
        if request.mock_config is not None:
            config = request.mock_config
            packaged = config.parent.resolve() == packaged_dir("profile").resolve()
            args += ["--mock-config", config.stem if packaged else str(config)]
        if request.seed != 0:
            args += ["--seed", str(request.seed)]
    elif request.connect is not None:
        args += ["--connect", request.connect]
    if request.mocap is not None:
        args += ["--mocap", request.mocap]
    args += ["--iter", str(iterations)]
    if request.until_converged:
        args.append("--until-converged")
    if again is not None:
        args += ["--again", str(again)]
    return shlex.join(args)


def check_vehicle(
    plan: FlyPlan, request: FlyRequest, mock_config: Path | None, view: FlyView
) -> None:
    """Read the vehicle's parameters and judge them against the real-vehicle checklist.

    Connects (or starts the mock drone), reads every parameter, sends nothing, and judges
    them for the flight's navigation: motion capture when the plan has one, else GPS
    (:mod:`gcs.flight.checklist`, docs/real-vehicle.md); the view shows the verdicts.

    Parameters
    ----------
    plan : FlyPlan
        The checked flight.
    request : FlyRequest
        The vehicle's options (``connect``, ``use_mock``, ``seed``).
    mock_config : Path or None
        The mock's settings (:func:`gcs.app.session.mock_config_for`).
    view : FlyView
        Where the set-up lines and the verdicts go.

    Raises
    ------
    VehicleError
        A parameter is refused (the line names it and the fix), or the vehicle is unreachable.
    """
    import asyncio

    from gcs.flight.checklist import judge, read_params, refusal

    navigation = "mocap" if plan.mocap is not None else "gps"
    with vehicle_url(request.connect, request.use_mock, mock_config, request.seed, view.say) as (
        url,
        _,
    ):
        params = asyncio.run(read_params(url, plan.settings))
    verdicts = judge(params, navigation)
    view.checklist(navigation, url, verdicts)
    reason = refusal(verdicts)
    if reason is not None:
        raise VehicleError(reason)


def fly(request: FlyRequest, view: FlyView) -> RunDir | None:
    """``gcs fly``: check everything, then say what would be flown or set up the run and fly it.

    Nothing is created, moved or flown before every input has been checked: the options
    (:func:`check_request`), the profile, trajectory and run (:func:`plan_fly`), the mock's
    settings or the connection URL. With ``request.check_only`` it says what would be flown
    (and, unless ``offline``, judges the vehicle's parameters) and stops; with
    ``until_converged`` a resumed run that has converged (or left the floor) already is not
    flown. A failure mid-flight (the vehicle landed) leaves the run to be resumed; the view
    is told how.

    Parameters
    ----------
    request : FlyRequest
        The command's options.
    view : FlyView
        What the flight shows.

    Returns
    -------
    RunDir or None
        The run flown (None with ``check_only``).
    """
    check_request(request)
    plan = plan_fly(request)
    mock_config = mock_config_for(request.mock_config, request.use_mock, plan.mocap)
    if request.use_mock:
        check_mock_config(mock_config)
    else:
        assert request.connect is not None
        check_url(request.connect)
    if request.until_converged and plan.run is not None and request.again is None:
        record = newest_record(plan.run)
        drift = record_drift(record)
        reason = converged_reason(record) or (
            None
            if drift is None
            else f"{drift_sentence(drift)} (--again {drift.best_trial} flies them)"
        )
        if reason is not None:
            view.nothing_flown(plan.run, reason)
            return plan.run
    if request.check_only:
        view.checked(plan, request.iterations)
        if not request.offline:
            check_vehicle(plan, request, mock_config, view)
        return None
    run = start_run(plan)
    earlier = run.sessions()
    used = {s["mock_seed"] for s in earlier if isinstance(s.get("mock_seed"), int)}
    session_seed = mock_session_seed(request.seed, len(earlier) + 1, used)
    if request.use_mock and session_seed != request.seed:
        view.say(
            f"mock seed {session_seed}: --seed {request.seed} was flown by an earlier session of "
            "this run, and a resumed run never replays its gusts"
        )

    def resume(n: int, again: int | None = None) -> str:
        return resume_command(run.path, request, n, again)

    def left() -> int:
        return max(1, request.iterations - (run.next_trial() - plan.first_trial))

    def on_learn(outcome: LearnOutcome) -> None:
        drift = record_drift(outcome.record)
        view.learned(outcome, None if drift is None else resume(1, drift.best_trial))

    view.started(run)
    progress, on_event, on_row = view.live(run)
    if not request.use_mock:  # said at once: a vehicle that is not there is silent until then
        view.say(
            f"waiting up to {plan.settings.connect_timeout_s:g} s for a vehicle on "
            f"{request.connect} (flight.connect_timeout_s)"
        )
    try:
        with (
            vehicle_url(
                request.connect, request.use_mock, mock_config, session_seed, view.say, plan.mocap
            ) as (url, link),
            progress,
        ):
            fly_run(
                url,
                run,
                request.iterations,
                plan.settings,
                on_event,
                on_row,
                on_learn,
                request.until_converged,
                mocap=link,
                mock_seed=session_seed if request.use_mock else None,
            )
    except KeyboardInterrupt:
        view.interrupted(run, resume(left()))
        raise
    except GcsError:
        view.stopped(run, resume(left()))
        raise
    newest = newest_record(run)
    drift = record_drift(newest)
    if request.until_converged and drift is not None:
        view.left_floor(drift.best_trial, resume(1, drift.best_trial))
    elif request.until_converged and converged_reason(newest) is None:
        view.not_converged(request.iterations, resume(request.iterations))
    view.finished(run)
    return run
