"""``gcs fly``: a run directory as the flight layer's trial source, and the live display.

The flight layer asks for "the next sequence" and hands back recordings; :class:`RunSource`
answers from the run directory and learns with :func:`gcs.app.learn.learn_run`, the same function
``gcs learn`` calls. Everything here runs in worker threads while the vehicle hovers.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from gcs.app.learn import (
    LearnOutcome,
    check_history,
    check_learnable,
    check_learned,
    differing_field,
    learn_run,
    models_in_use,
    run_measurement,
)
from gcs.core.metrics import IterationMetrics, iteration_table
from gcs.core.trajectory import (
    MAX_SAMPLES,
    Reference,
    check_reference,
    points_outside,
    sample_eight,
)
from gcs.core.trials import trial_errors
from gcs.errors import PathError, ProfileError, RunLogError, TrajectoryError
from gcs.flight.campaign import FlightSession, run_campaign
from gcs.flight.fence import Fence
from gcs.flight.mocap.link import MocapLink
from gcs.flight.mocap.settings import MocapSettings, mocap_settings
from gcs.flight.mocap.source import MocapSource
from gcs.flight.settings import FlightSettings
from gcs.flight.trial import TrialRecording
from gcs.io.config import Profile, TrajectorySpec, load_profile, load_trajectory
from gcs.io.paths import check_new_dir, check_output_dir
from gcs.io.runlog import RunDir, TrialRecord, TrialStatus

__all__ = [
    "MOCK_MOCAP",
    "MocapPlan",
    "plan_mocap",
    "FlyPlan",
    "plan_fly",
    "start_run",
    "check_url",
    "check_mock_config",
    "RunSource",
    "SessionRecorder",
    "flyable_setpoints",
    "flight_settings",
    "flight_fence",
    "prepare_run",
    "to_record",
    "trial_extra",
    "session_record",
    "fly_run",
    "converged_reason",
    "newest_record",
    "check_until_converged",
    "raw_mocap",
]


def flight_settings(profile: Profile, where: str | None = None) -> FlightSettings:
    """The profile's ``flight`` section as :class:`FlightSettings` (unknown keys refused).

    Parameters
    ----------
    profile : Profile
        The profile.
    where : str, optional
        The profile's file for messages (default: ``profile '<name>'``).

    Returns
    -------
    FlightSettings
    """
    where = where or f"profile '{profile.name}'"
    known = {f.name for f in fields(FlightSettings)}
    for key, value in profile.flight.items():
        if key not in known:
            raise ProfileError(f"{where}: field 'flight.{key}' is not known")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ProfileError(f"{where}: field 'flight.{key}' must be a number, got {value!r}")
    try:
        settings = FlightSettings(**{k: float(v) for k, v in profile.flight.items()})
        settings.sends_per_sample(profile.t_ilc_s)
    except ValueError as exc:  # FlightSettings' own messages start with the field's name
        text = str(exc)
        field = text.split(":", 1)[0] if text.startswith("flight.") else "flight.stream_rate_hz"
        detail = text.split(":", 1)[1].strip() if text.startswith("flight.") else text
        raise ProfileError(f"{where}: field '{field}': {detail}") from None
    return settings


def flight_fence(profile: Profile, settings: FlightSettings) -> Fence:
    """The live fence of a flight: the profile's arena and vehicle limits, the flight settings.

    Parameters
    ----------
    profile : Profile
        The profile (``arena``, ``vehicle``).
    settings : FlightSettings
        Its flight settings (``fence_*``).

    Returns
    -------
    Fence
    """
    return Fence.around(
        profile.arena.bounds(), settings, profile.max_speed_m_s, profile.max_vertical_speed_m_s
    )


#: MAVSDK connection URLs (MAVSDK 2: udpin/udpout/tcpin/tcpout/serial/serial_flowcontrol;
#: udp:// and tcp:// are its older spellings of udpin and tcpout).
_URL = re.compile(
    r"^(?:(?:udpin|udpout|udp|tcpin|tcpout|tcp)://[^/:\s]*:(?P<port>\d{1,5})"
    r"|(?:serial|serial_flowcontrol)://\S+?(?::\d+)?)$"
)


def check_url(url: str) -> str:
    """Refuse a MAVSDK connection URL that MAVSDK would not open.

    Parameters
    ----------
    url : str
        E.g. ``udpin://0.0.0.0:14540``, ``udpout://127.0.0.1:14540``,
        ``serial:///dev/ttyUSB0:57600``.

    Returns
    -------
    str
        ``url``.

    Raises
    ------
    PathError
        Unknown scheme, no port, or a port outside 1..65535.
    """
    match = _URL.match(url)
    port = match.group("port") if match else None
    if match is None or (port is not None and not 1 <= int(port) <= 65535):
        raise PathError(
            f"--connect {url}: not a MAVSDK connection URL (udpin://HOST:PORT, "
            "udpout://HOST:PORT, tcpout://HOST:PORT, serial:///dev/DEVICE:BAUD)"
        )
    return url


def check_mock_config(path: Path | None) -> None:
    """Load the mock drone's settings once, so that a bad file is refused before flying.

    Parameters
    ----------
    path : Path or None
        ``--mock-config``; None for the defaults.
    """
    if path is not None:
        from gcs.mock.config import load_mock_config

        load_mock_config(path)


MOCK_MOCAP = "mock"
"""``--mocap mock``: the mock drone's own arena (with ``--mock``)."""


@dataclass(frozen=True)
class MocapPlan:
    """The motion capture of a flight, checked before anything starts.

    Parameters
    ----------
    settings : MocapSettings
        The profile's ``mocap`` section.
    source : MocapSource or None
        Where to read; None for the mock drone's arena (its URL is known once it runs).
    """

    settings: MocapSettings
    source: MocapSource | None

    def link(self, mock_url: str | None = None) -> MocapLink:
        """The (not yet started) link of this plan.

        Parameters
        ----------
        mock_url : str or None
            The arena's URL, for a plan of the mock's arena.

        Returns
        -------
        MocapLink
        """
        from gcs.flight.mocap.source import parse_mocap_url

        source = self.source or parse_mocap_url(mock_url or "")
        return MocapLink(source, self.settings.mapping(source), self.settings)

    def describe(self) -> str:
        """One line: source, mapping, forwarding, measurement.

        Returns
        -------
        str
        """
        where = self.source.url() if self.source is not None else "the mock drone's arena"
        s = self.settings
        forward = f"forwarded as {s.message}" if s.forward else "not forwarded"
        return f"mocap {where} ({forward}; learning on {s.measurement})"


def plan_mocap(profile: Profile, where: str, mocap: str | None, use_mock: bool) -> MocapPlan | None:
    """Check the profile's ``mocap`` section and ``--mocap``; None when no mocap is used.

    Parameters
    ----------
    profile : Profile
        The profile (its ``mocap`` section is checked even when no mocap is used).
    where : str
        The profile's file, for messages.
    mocap : str or None
        ``--mocap``: a URL, ``mock`` (with ``--mock``) or None (the profile's ``mocap.url``).
    use_mock : bool
        The flight is on the mock drone.

    Returns
    -------
    MocapPlan or None
    """
    settings = mocap_settings(profile.mocap, where)
    if mocap == MOCK_MOCAP:
        if not use_mock:
            raise PathError("--mocap mock: the mock's arena needs --mock (a real arena: its URL)")
        settings.mapping(MocapSource("optitrack", "127.0.0.1", 1510, "drone"))  # axes valid
        return MocapPlan(settings, None)
    source = settings.source(mocap)
    if source is None:
        return None
    try:
        settings.mapping(source)
    except ProfileError as exc:
        raise ProfileError(f"{where}: field 'mocap': {exc}") from None
    return MocapPlan(settings, source)


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


def plan_fly(
    profile_path: Path | None,
    trajectory_path: Path | None,
    algorithm: str | None,
    run_path: Path | None = None,
    resume: Path | None = None,
    logs: Path = Path("logs"),
    until_converged: bool = False,
    mocap: str | None = None,
    use_mock: bool = False,
) -> FlyPlan:
    """Validate everything a flight needs; nothing is created, moved or flown here.

    A new run: the profile (every section, flight settings included), the trajectory on the
    flown grid against the vehicle's limits and the arena, a dry first learning update (models
    and setpoint limits admit one), the run's path. A resumed run: the run directory (a
    learning run, writable, its manifest, reference, trial files and the next trial's
    setpoints on their grid limits), and ``profile_path`` / ``trajectory_path``, if given,
    must be the run's own.

    Parameters
    ----------
    profile_path, trajectory_path : Path or None
        Files of a new run (None: with ``resume``, the run's own; else required).
    algorithm : str or None
        Learning algorithm (default: the profile's, or the resumed run's).
    run_path : Path or None
        Exact path of a new run.
    resume : Path or None
        Run to continue.
    logs : Path
        Parent of new runs.
    until_converged : bool
        ``--until-converged``: the profile must measure the floor (see
        :func:`check_until_converged`).
    mocap : str or None
        ``--mocap`` (see :func:`plan_mocap`).
    use_mock : bool
        The flight is on the mock drone.

    Returns
    -------
    FlyPlan
    """
    if resume is not None:
        plan = _plan_resume(resume, profile_path, trajectory_path, algorithm, logs)
        if until_converged:
            check_until_converged(plan.profile, f"{resume}/manifest.json:profile")
        where = f"{plan.run.path}/manifest.json:profile" if plan.run else str(resume)
        return replace(plan, mocap=plan_mocap(plan.profile, where, mocap, use_mock))
    if profile_path is None or trajectory_path is None:
        raise ProfileError("a new run needs a profile and a trajectory")
    profile, where = load_profile(profile_path), str(profile_path)
    if until_converged:
        check_until_converged(profile, where)
    trajectory = load_trajectory(trajectory_path)
    algorithm = algorithm or profile.learning.algorithm
    settings = flight_settings(profile, where)
    mocap_plan = plan_mocap(profile, where, mocap, use_mock)
    ref = _reference(profile, trajectory, str(trajectory_path))
    check_learnable(profile, ref, algorithm, where)
    if run_path is not None:
        check_new_dir(run_path, "--run")
    else:
        check_output_dir(logs, "--logs")
    return FlyPlan(
        profile, trajectory, algorithm, settings, ref, 0, None, run_path, logs, mocap_plan
    )


def _reference(profile: Profile, trajectory: TrajectorySpec, where: str) -> Reference:
    if trajectory.shape is None:
        raise TrajectoryError(f"{where}: not an eight (an identification excitation)")
    duration = trajectory.shape.duration_s
    if not duration / profile.t_ilc_s <= MAX_SAMPLES:  # before the arrays are made
        raise TrajectoryError(
            f"{where}: a trial of {duration:g} s has more than {MAX_SAMPLES} samples of "
            f"{profile.t_ilc_s:g} s"
        )
    try:
        with np.errstate(over="raise", invalid="raise"):
            ref = sample_eight(trajectory.shape, profile.t_ilc_s)
        check_reference(ref, profile.max_speed_m_s, profile.max_accel_m_s2, profile.arena)
    except TrajectoryError as exc:
        raise TrajectoryError(f"{where}: {exc}") from None
    except FloatingPointError as exc:
        raise TrajectoryError(f"{where}: its numbers overflow when sampled ({exc})") from None
    return ref


def _plan_resume(
    resume: Path,
    profile_path: Path | None,
    trajectory_path: Path | None,
    algorithm: str | None,
    logs: Path,
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
    where = f"{run.path}/manifest.json:profile"
    profile, trajectory = run.profile(), run.trajectory()
    settings = flight_settings(profile, where)
    ref = run.reference()
    try:
        check_reference(ref, profile.max_speed_m_s, profile.max_accel_m_s2, profile.arena)
    except TrajectoryError as exc:
        raise RunLogError(f"{run.path}/reference.csv: {exc}") from None
    first = run.next_trial()
    if first > 0:
        run.read_trial(first - 1)  # the trial the next setpoints were learned from
        if not (run.path / f"setpoints-{first:03d}.csv").exists():
            raise RunLogError(
                f"{run.path}: no setpoints for trial {first}; run 'gcs learn {run.path}' first"
            )
    if profile.learning.history and first > 0:
        check_history(run, profile, first - 1)
    flyable_setpoints(run, first)
    run.check_writable()
    return FlyPlan(profile, trajectory, run.algorithm, settings, ref, first, run, None, logs)


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
    if not profile.learning.history:
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
    """The run to fly: the resumed one, or a new run directory created from the plan.

    Parameters
    ----------
    plan : FlyPlan
        From :func:`plan_fly`.

    Returns
    -------
    RunDir
    """
    if plan.run is not None:
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
    ref = _reference(profile, trajectory, trajectory.name)
    if run_path is not None:
        root, run_id = run_path.parent, run_path.name
    else:
        root, run_id = logs, None
    return RunDir.create(root, profile, trajectory, algorithm, run_id=run_id, reference=ref)


def to_record(
    run: RunDir, recording: TrialRecording, ref_ned_m: np.ndarray | None = None
) -> TrialRecord:
    """A flight recording as a row-per-sample trial record of the run.

    Parameters
    ----------
    run : RunDir
        The run (for its reference).
    recording : TrialRecording
        What the flight layer sent and measured.
    ref_ned_m : ndarray, shape (N+1, 3), optional
        Reference rows of the record; default the run's reference (an identification
        experiment passes its own excitation).

    Returns
    -------
    TrialRecord
    """
    if ref_ned_m is None:
        ref_ned_m = run.reference().pos_ned_m
    sp = recording.setpoints_ned_m
    return TrialRecord(
        t_s=np.arange(run.n_samples + 1) * run.t_ilc_s,
        ref_ned_m=ref_ned_m,
        sp_ned_m=np.vstack([sp, sp[-1]]),
        pos_ned_m=recording.pos_ned_m,
        vel_ned_m_s=recording.vel_ned_m_s,
        sp_sent_s=np.append(recording.sent_s, np.nan),
        interpolated=recording.interpolated,
        mocap_ned_m=None if recording.mocap is None else recording.mocap.pos_ned_m,
    )


def trial_extra(recording: TrialRecording, session: int | None) -> dict[str, Any]:
    """Timing of a flown trial for its sidecar: send delays, vehicle clock, flight session.

    Parameters
    ----------
    recording : TrialRecording
        What the flight layer sent and measured.
    session : int or None
        Number of the session record it was flown in.

    Returns
    -------
    dict
        ``max_send_late_s``, ``max_sent_offset_s`` (largest distance of a setpoint's first send
        from its sample boundary, on the vehicle's clock: how well the stream kept to the
        vehicle's grid), ``vehicle_time_rate`` (vehicle-time / wall-time rate of the trial,
        None if unknown), ``clock_latency_p50_s`` (median receipt delay above the
        clock fit), ``t0_vehicle_s`` (the trial's k = 0 on the vehicle's clock: time since
        boot for PX4, to find the trial in its own log), ``session``; with motion capture
        also ``mocap_lag_s`` (how far the estimate lags the mocap), ``mocap_samples`` and
        ``mocap_tracked_share``.
    """
    clock = recording.clock
    offset = np.abs(recording.sent_s - recording.t_s[:-1])
    mocap = {}
    if recording.mocap is not None:
        series = recording.mocap.series
        mocap = {
            "mocap_lag_s": recording.mocap.lag_s,
            "mocap_samples": len(series),
            "mocap_tracked_share": float(np.mean(series.tracked)) if len(series) else None,
        }
    return mocap | {
        "max_send_late_s": recording.max_send_late_s,
        "max_sent_offset_s": float(np.nanmax(offset)) if np.any(np.isfinite(offset)) else None,
        "t0_vehicle_s": recording.t0_vehicle_s,
        "vehicle_time_rate": None if clock is None else clock.rate,
        "clock_latency_p50_s": None if clock is None else clock.latency_p50_s,
        "session": session,
    }


def session_record(session: FlightSession) -> dict[str, Any]:
    """A flight session as the JSON object of ``session-SSS.json``.

    Parameters
    ----------
    session : FlightSession
        What the campaign found out about the vehicle.

    Returns
    -------
    dict
        ``url``, ``first_trial``, ``navigation`` (source name, line, parameters),
        ``tolerance_m``, ``speed_tolerance_m_s``, ``hovers`` (statistics, verdict and
        clock rate of each judged hover), ``fence`` (arena, margin and limits watched),
        ``geofence`` (the vehicle's own fence as set up before take-off), ``mocap`` (source,
        mapping, forwarding, EKF2 findings, pre-flight checks; None without), ``abort_reason``
        (why the session stopped early, or None), plus ``written_utc``.
    """
    from datetime import UTC, datetime

    nav = session.navigation
    return {
        "url": session.url,
        "first_trial": session.first_trial,
        "navigation": {"source": nav.name, "text": nav.text, "params": nav.params},
        "fence": None if session.fence is None else asdict(session.fence),
        "geofence": None if session.geofence is None else asdict(session.geofence),
        "abort_reason": session.abort_reason,
        "mocap": session.mocap,
        "tolerance_m": session.tolerance_m,
        "speed_tolerance_m_s": session.speed_tolerance_m_s,
        "hovers": [asdict(h) for h in session.hovers],
        "written_utc": datetime.now(UTC).isoformat(timespec="seconds"),
    }


def flyable_setpoints(run: RunDir, j: int) -> np.ndarray:
    """Trial j's setpoints from the run directory, refused if any breaks a limit, on its grid.

    Every sequence must lie inside the profile's arena. A learned sequence of a learning run
    (j >= 1) must also keep the learning's limits (step per sample, deviation from the
    reference aligned by the models it was learned with; :func:`gcs.app.learn.check_learned`):
    the file on disk is what is flown, and it is checked as such, whoever wrote it. A repeat
    of trial 0 must have trial 0's setpoints exactly.

    Parameters
    ----------
    run : RunDir
        The run.
    j : int
        Trial index.

    Returns
    -------
    ndarray, shape (N, 3)
        Absolute local NED [m].
    """
    sp = run.read_setpoints(j)
    profile = run.profile()
    arena = profile.arena
    outside = points_outside(sp, arena)
    if outside.size:
        k = outside[0]
        raise TrajectoryError(
            f"setpoints-{j:03d}.csv: setpoint k = {k} {np.round(sp[k], 3).tolist()} is "
            f"outside the arena {arena}; not flown"
        )
    if run.kind != "learning" or j == 0:
        return sp
    repeats = profile.learning.repeats if profile.learning.history else 0
    if j <= repeats:
        if not np.array_equal(sp, run.read_setpoints(0)):
            raise TrajectoryError(
                f"{run.path}/setpoints-{j:03d}.csv: trial {j} repeats trial 0, but its "
                "setpoints differ from setpoints-000.csv; not flown"
            )
        return sp
    models = models_in_use(run, profile, j)[0] if profile.learning.history else None
    try:
        check_learned(sp, profile, run.reference(), models)
    except TrajectoryError as exc:
        raise TrajectoryError(f"{run.path}/setpoints-{j:03d}.csv: {exc}; not flown") from None
    return sp


class SessionRecorder:
    """What the run-directory trial sources share: the record of their flight session.

    Subclasses provide ``run`` (:class:`RunDir`) and ``session`` (int or None, the record's
    number once written).
    """

    run: RunDir
    session: int | None

    def record_session(self, session: FlightSession) -> None:
        """Write (or update) this flight session's record in the run directory.

        Parameters
        ----------
        session : FlightSession
            Navigation source, hover measurements, settle tolerances.
        """
        self.session = self.run.write_session(self.session, session_record(session))


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
        Fly no further trial once the learning record says learning has converged.
    """

    run: RunDir
    on_row: Callable[[list[IterationMetrics]], None] | None = None
    session: int | None = None
    on_learn: Callable[[LearnOutcome], None] | None = None
    until_converged: bool = False

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
            With ``until_converged``, why no further trial can help (the campaign lands);
            else None.
        """
        record = to_record(self.run, recording)
        extra = trial_extra(recording, self.session)
        measured = record.measured(run_measurement(self.run.profile()))
        e, m = trial_errors(measured)
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
        return converged_reason(outcome.record) if self.until_converged else None

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
        return iteration_table(
            [s.epos_m for s in done], [s.max_err_m for s in done], [s.trial for s in done]
        )


def converged_reason(record: dict | None) -> str | None:
    """Why further trials cannot help, from a decision record, or None (go on).

    Parameters
    ----------
    record : dict or None
        A ``learn-JJJ.json`` record (:meth:`gcs.io.runlog.RunDir.read_learn_record`).

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
    if j is None or not (run.path / f"learn-{j:03d}.json").exists():
        return None
    return run.read_learn_record(j)


def raw_mocap(recording: TrialRecording) -> Any:
    """A recording's raw mocap samples (None without mocap).

    Parameters
    ----------
    recording : TrialRecording
        What the flight layer recorded.

    Returns
    -------
    MocapSeries or None
    """
    return None if recording.mocap is None else recording.mocap.series


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
) -> RunSource:
    """Fly ``iterations`` trials of ``run`` from its next trial, learning between trials.

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

    Returns
    -------
    RunSource
    """
    first = run.next_trial()
    if first > 0 and not (run.path / f"setpoints-{first:03d}.csv").exists():
        raise RunLogError(f"{run.path}: no setpoints for trial {first}; run 'gcs learn' first")
    source = RunSource(run, on_row, on_learn=on_learn, until_converged=until_converged)
    fence = flight_fence(run.profile(), settings)
    run_campaign(
        url, source, iterations, first, settings, run.t_ilc_s, on_event, fence=fence, mocap=mocap
    )
    return source
