"""``gcs fly``: a run directory as the flight layer's trial source, and the live display.

The flight layer asks for "the next sequence" and hands back recordings; :class:`RunSource`
answers from the run directory and learns with :func:`gcs.app.learn.learn_run`, the same function
``gcs learn`` calls. Everything here runs in worker threads while the vehicle hovers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from gcs.app.learn import learn_run, trial_errors
from gcs.core.metrics import IterationMetrics, iteration_table
from gcs.core.trajectory import check_reference, points_outside
from gcs.errors import ProfileError, RunLogError, TrajectoryError
from gcs.flight.campaign import FlightSession, run_campaign
from gcs.flight.settings import FlightSettings
from gcs.flight.trial import TrialRecording
from gcs.io.config import Profile, TrajectorySpec
from gcs.io.runlog import RunDir, TrialRecord, TrialStatus

__all__ = [
    "RunSource",
    "SessionRecorder",
    "flyable_setpoints",
    "flight_settings",
    "prepare_run",
    "to_record",
    "trial_extra",
    "session_record",
    "fly_run",
]


def flight_settings(profile: Profile) -> FlightSettings:
    """The profile's ``flight`` section as :class:`FlightSettings` (unknown keys refused).

    Parameters
    ----------
    profile : Profile
        The profile.

    Returns
    -------
    FlightSettings
    """
    known = {f.name for f in fields(FlightSettings)}
    for key, value in profile.flight.items():
        if key not in known:
            raise ProfileError(f"profile '{profile.name}': field 'flight.{key}' is not known")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ProfileError(f"profile '{profile.name}': field 'flight.{key}' must be a number")
    settings = FlightSettings(**{k: float(v) for k, v in profile.flight.items()})
    try:
        settings.sends_per_sample(profile.t_ilc_s)
    except ValueError as exc:
        raise ProfileError(
            f"profile '{profile.name}': field 'flight.stream_rate_hz': {exc}"
        ) from exc
    return settings


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
    from gcs.core.trajectory import sample_eight

    ref = sample_eight(trajectory.shape, profile.t_ilc_s)
    check_reference(ref, profile.max_speed_m_s, profile.max_accel_m_s2, profile.arena)
    if run_path is not None:
        return RunDir.create(run_path.parent, profile, trajectory, algorithm, run_id=run_path.name)
    return RunDir.create(logs, profile, trajectory, algorithm)


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
        boot for PX4, to find the trial in its own log), ``session``.
    """
    clock = recording.clock
    offset = np.abs(recording.sent_s - recording.t_s[:-1])
    return {
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
        ``tolerance_m``, ``speed_tolerance_m_s`` and ``hovers`` (statistics, verdict and
        clock rate of each judged hover), plus ``written_utc``.
    """
    from datetime import UTC, datetime

    nav = session.navigation
    return {
        "url": session.url,
        "first_trial": session.first_trial,
        "navigation": {"source": nav.name, "text": nav.text, "params": nav.params},
        "tolerance_m": session.tolerance_m,
        "speed_tolerance_m_s": session.speed_tolerance_m_s,
        "hovers": [asdict(h) for h in session.hovers],
        "written_utc": datetime.now(UTC).isoformat(timespec="seconds"),
    }


def flyable_setpoints(run: RunDir, j: int) -> np.ndarray:
    """Trial j's setpoints from the run directory, refused if any leaves the profile's arena.

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
    arena = run.profile().arena
    outside = points_outside(sp, arena)
    if outside.size:
        k = outside[0]
        raise TrajectoryError(
            f"setpoints-{j:03d}.csv: setpoint k = {k} {np.round(sp[k], 3).tolist()} is "
            f"outside the arena {arena}; not flown"
        )
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
    """

    run: RunDir
    on_row: Callable[[list[IterationMetrics]], None] | None = None
    session: int | None = None

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

    def record(self, j: int, recording: TrialRecording) -> None:
        """Write a complete trial, then learn the next trial's setpoints from it.

        Parameters
        ----------
        j : int
            Trial index.
        recording : TrialRecording
            The complete recording.
        """
        record = to_record(self.run, recording)
        e, m = trial_errors(record)
        status = TrialStatus(
            j, True, epos_m=e, max_err_m=m, interpolated_share=recording.interpolated_share,
            extra=trial_extra(recording, self.session),
        )  # fmt: skip
        self.run.write_trial(j, record, status)
        learn_run(self.run)
        if self.on_row is not None:
            self.on_row(self.rows())

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
        self.run.write_trial(j, record, status)

    def rows(self) -> list[IterationMetrics]:
        """Table IV rows of the complete trials so far (from the sidecars)."""
        done = [s for s in self.run.statuses() if s.complete]
        return iteration_table(
            [s.epos_m for s in done], [s.max_err_m for s in done], [s.trial for s in done]
        )


def fly_run(
    url: str,
    run: RunDir,
    iterations: int,
    settings: FlightSettings,
    on_event: Callable[[object], None] | None = None,
    on_row: Callable[[list[IterationMetrics]], None] | None = None,
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

    Returns
    -------
    RunSource
    """
    first = run.next_trial()
    if first > 0 and not (run.path / f"setpoints-{first:03d}.csv").exists():
        raise RunLogError(f"{run.path}: no setpoints for trial {first}; run 'gcs learn' first")
    source = RunSource(run, on_row)
    run_campaign(url, source, iterations, first, settings, run.t_ilc_s, on_event)
    return source
