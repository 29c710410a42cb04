"""A campaign: take off, fly trial after trial (asking the source for each sequence), land.

Sequence: connect, wait for a valid local position, arm, take off to the altitude of the first
setpoint, start offboard at the current position, move to the start point and settle. For each
trial: fly it, hover at its end while ``source.record`` runs (in a worker thread), ask
``source.setpoints_for`` for the next sequence (worker thread, still hovering), move to its hover
point (``source.hover_point_for``: the trajectory's start, where learning assumes the vehicle at
rest before ``u(0)``), settle, and hold it for ``settings.hover_before_trial_s`` so that every
trial starts from the same state. After the last trial: land and disarm.

Safety: on Ctrl-C (``CancelledError``/``KeyboardInterrupt``), link loss, offboard rejection or any
other exception after connecting, the vehicle is stopped (:meth:`Vehicle.emergency_stop`:
streaming stops, Hold, land, disarm on the ground); a trial that was in flight is handed to
``source.record_incomplete`` with its partial recording; then the exception is re-raised.
Completed trials were handed to ``source.record`` already. :func:`run_campaign` runs a campaign
from synchronous code (a command line) so that a second Ctrl-C cannot cut that stop short.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from gcs.errors import TrajectoryError, TrialAborted, VehicleError
from gcs.flight.interrupts import run_guarded
from gcs.flight.preflight import LINK_LOSS_PARAMS, link_loss_warnings
from gcs.flight.settings import FlightSettings
from gcs.flight.trial import TrialRecording, TrialRun, check_setpoints
from gcs.flight.vehicle import Vehicle

__all__ = [
    "TrialSource",
    "TrialStarted",
    "TrialProgress",
    "TrialFinished",
    "Status",
    "CampaignEvent",
    "fly_campaign",
    "run_campaign",
    "check_battery",
]

_log = logging.getLogger(__name__)


class TrialSource(Protocol):
    """Where trials come from and where their recordings go (blocking; run in a thread)."""

    def setpoints_for(self, j: int) -> np.ndarray:
        """Setpoints of trial ``j`` (may run a learner).

        Parameters
        ----------
        j : int
            Trial index.

        Returns
        -------
        ndarray, shape (N, 3)
            Absolute local NED setpoints [m]; setpoint k holds from t0 + k t_ilc_s.
        """
        ...

    def hover_point_for(self, j: int) -> np.ndarray:
        """Where the vehicle hovers, settled, before trial ``j`` starts.

        The hover setpoint is the setpoint in force just before ``u(0)``; learning assumes the
        vehicle at rest there, so it is the trajectory's start point, not ``u(0)`` (a learned
        first setpoint generally differs from it).

        Parameters
        ----------
        j : int
            Trial index.

        Returns
        -------
        ndarray, shape (3,)
            Absolute local NED [m].
        """
        ...

    def record(self, j: int, recording: TrialRecording) -> None:
        """Take the complete recording of trial ``j`` (write files, learn).

        Parameters
        ----------
        j : int
            Trial index.
        recording : TrialRecording
            The complete recording.
        """
        ...

    def record_incomplete(self, j: int, recording: TrialRecording, reason: str) -> None:
        """Take the partial recording of trial ``j``, which stopped early.

        Parameters
        ----------
        j : int
            Trial index.
        recording : TrialRecording
            The partial recording (``complete=False``; NaN after the last sample).
        reason : str
            Why the trial stopped, one line.
        """
        ...


@dataclass(frozen=True)
class Status:
    """A line of campaign status (phase changes, warnings).

    Parameters
    ----------
    text : str
        Human-readable, one line.
    warning : bool
        Something the operator should act on or know before going on (shown as a warning).
    """

    text: str
    warning: bool = False


@dataclass(frozen=True)
class TrialStarted:
    """A trial begins streaming.

    Parameters
    ----------
    trial : int
        Trial index ``j``.
    number : int
        1-based position of the trial in this campaign.
    iterations : int
        Number of trials in this campaign.
    n_setpoints : int
        Number of setpoints N.
    duration_s : float
        Nominal duration ``N t_ilc_s`` [s].
    """

    trial: int
    number: int
    iterations: int
    n_setpoints: int
    duration_s: float


@dataclass(frozen=True)
class TrialProgress:
    """Live progress of the trial in flight (at most ~10 per second).

    Parameters
    ----------
    trial : int
        Trial index ``j``.
    k : int
        Current setpoint index (N once the final hover has begun).
    n : int
        Number of setpoints N.
    err_m : float
        Horizontal distance between the newest measured position and the setpoint in force
        when it was received [m] (live indicator, includes the closed-loop lag).
    """

    trial: int
    k: int
    n: int
    err_m: float


@dataclass(frozen=True)
class TrialFinished:
    """A trial ended (complete, or aborted).

    Parameters
    ----------
    trial : int
        Trial index ``j``.
    recording : TrialRecording
        What was sent and measured (``recording.complete`` tells which case).
    """

    trial: int
    recording: TrialRecording


CampaignEvent = Status | TrialStarted | TrialProgress | TrialFinished
EventCallback = Callable[[CampaignEvent], None]


async def fly_campaign(
    url: str,
    source: TrialSource,
    iterations: int,
    first_trial: int,
    settings: FlightSettings,
    t_ilc_s: float,
    on_event: EventCallback | None = None,
) -> None:
    """Fly ``iterations`` trials ``first_trial, first_trial + 1, ...`` and land.

    Parameters
    ----------
    url : str
        MAVSDK connection URL of the vehicle.
    source : TrialSource
        Supplies each trial's setpoints and takes each recording (called in worker threads).
    iterations : int
        Number of trials to fly, >= 1.
    first_trial : int
        Index ``j`` of the first trial (to resume a run).
    settings : FlightSettings
        Flight settings; ``stream_rate_hz`` must be an integer multiple of ``1 / t_ilc_s``.
    t_ilc_s : float
        ILC sample time [s].
    on_event : callable, optional
        Receives :class:`Status`, :class:`TrialStarted`, :class:`TrialProgress` and
        :class:`TrialFinished` events on the event loop; must return quickly.

    Raises
    ------
    VehicleError
        Unreachable vehicle, refused command, lost link, failed settling.
    TrialAborted
        The trial watchdog fired (the trial went to ``source.record_incomplete``).
    asyncio.CancelledError
        Cancelled (Ctrl-C); the vehicle was landed first.
    """
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    settings.sends_per_sample(t_ilc_s)  # fail before connecting

    def emit(event: CampaignEvent) -> None:
        if on_event is not None:
            on_event(event)

    vehicle = Vehicle(settings)
    emit(Status(f"connecting to {url}"))
    await vehicle.connect(url)
    run: TrialRun | None = None
    j = first_trial
    try:
        hover, setpoints = await asyncio.to_thread(_plan, source, j)
        for warning in link_loss_warnings(await vehicle.read_int_params(LINK_LOSS_PARAMS)):
            emit(Status(warning, warning=True))
        emit(Status("waiting for a valid local position"))
        await vehicle.wait_healthy_local_position()
        check_battery(vehicle.battery_pct, settings.min_battery_pct, "taking off")
        altitude_m = -float(hover[2])
        emit(Status(f"arming and taking off to {altitude_m:.1f} m"))
        await vehicle.arm_and_takeoff(altitude_m)
        emit(Status("starting offboard"))
        await vehicle.start_offboard_at_current_position()
        for number, j in enumerate(range(first_trial, first_trial + iterations), start=1):
            if number > 1:
                hover, setpoints = await vehicle.hover_while(
                    asyncio.to_thread(_plan, source, j), f"setpoints of trial {j}"
                )
            check_battery(vehicle.battery_pct, settings.min_battery_pct, f"trial {j}")
            emit(Status(f"moving to the start point of trial {j}"))
            await vehicle.goto(hover, settings.transit_speed_m_s)
            if settings.hover_before_trial_s > 0:
                # the initial reset of ILC: let the state the previous trial left decay
                emit(Status(f"holding the start point for {settings.hover_before_trial_s:g} s"))
                await vehicle.hover_while(
                    asyncio.sleep(settings.hover_before_trial_s), f"the hold before trial {j}"
                )
            n = setpoints.shape[0]
            emit(TrialStarted(j, number, iterations, n, n * t_ilc_s))

            def progress(k: int, n: int, err_m: float, j: int = j) -> None:
                emit(TrialProgress(j, k, n, err_m))

            run = TrialRun(vehicle, setpoints, t_ilc_s, settings, progress)
            recording = await run.fly()
            run = None  # handed over below: no longer "in flight"
            emit(TrialFinished(j, recording))
            await vehicle.hover_while(
                asyncio.to_thread(source.record, j, recording), f"recording trial {j}"
            )
        emit(Status("landing"))
        await vehicle.land_and_disarm()
        emit(Status("landed and disarmed"))
    except BaseException as exc:
        reason = _describe(exc)
        emit(Status(f"aborting: {reason}"))
        outcome = await vehicle.emergency_stop(reason)
        emit(Status(f"emergency stop: {outcome}"))
        if run is not None:
            partial = getattr(exc, "recording", None)
            if not isinstance(partial, TrialRecording):
                partial = run.recording(reason)
            emit(TrialFinished(j, partial))
            try:
                await asyncio.to_thread(source.record_incomplete, j, partial, reason)
            except Exception:  # keep the original exception; the handover failure is logged
                _log.exception("record_incomplete(%d) failed", j)
        raise
    finally:
        await vehicle.close()


def run_campaign(
    url: str,
    source: TrialSource,
    iterations: int,
    first_trial: int,
    settings: FlightSettings,
    t_ilc_s: float,
    on_event: EventCallback | None = None,
) -> None:
    """Fly a campaign from synchronous code: :func:`fly_campaign` under :func:`run_guarded`.

    The first Ctrl-C (or SIGTERM) cancels the campaign, which stops the vehicle; any further one
    while it is stopping is reported as a :class:`Status` event and otherwise ignored, so the
    hold, landing and disarm run to their end (each bounded by the settings' timeouts).

    Parameters
    ----------
    url : str
        MAVSDK connection URL of the vehicle.
    source : TrialSource
        Supplies each trial's setpoints and takes each recording.
    iterations : int
        Number of trials to fly, >= 1.
    first_trial : int
        Index ``j`` of the first trial.
    settings : FlightSettings
        Flight settings.
    t_ilc_s : float
        ILC sample time [s].
    on_event : callable, optional
        Receives the campaign events, and the notice of a repeated Ctrl-C.

    Raises
    ------
    KeyboardInterrupt
        Interrupted by Ctrl-C or SIGTERM; the vehicle was stopped first.
    VehicleError, TrialAborted
        As :func:`fly_campaign`.
    """

    def on_repeat(count: int) -> None:
        if on_event is not None:
            text = f"interrupt {count} ignored: stopping the vehicle (land, disarm)"
            on_event(Status(text, warning=True))

    run_guarded(
        fly_campaign(url, source, iterations, first_trial, settings, t_ilc_s, on_event), on_repeat
    )


def _plan(source: TrialSource, j: int) -> tuple[np.ndarray, np.ndarray]:
    """Trial j's hover point and checked setpoints (blocking: runs in a worker thread)."""
    setpoints = check_setpoints(source.setpoints_for(j))
    hover = np.asarray(source.hover_point_for(j), dtype=float).reshape(3)
    if not np.all(np.isfinite(hover)):
        raise TrajectoryError(f"hover point of trial {j} is not finite: {hover.tolist()}")
    return hover, setpoints


def check_battery(level_pct: float, min_pct: float, before: str) -> None:
    """Refuse to go on with less charge than ``min_pct`` (the campaign's stop then lands).

    Parameters
    ----------
    level_pct : float
        Remaining charge the battery reports [%]; NaN or negative (MAVLink's -1: not
        reported) passes.
    min_pct : float
        ``FlightSettings.min_battery_pct`` [%].
    before : str
        What would come next, for the message ("taking off", "trial 3").

    Raises
    ------
    VehicleError
        One line naming the level, the setting and what to do.
    """
    if math.isfinite(level_pct) and 0.0 <= level_pct < min_pct:
        raise VehicleError(
            f"battery at {level_pct:.0f} % before {before}, below flight.min_battery_pct "
            f"({min_pct:g} %): swap it and continue with --resume"
        )


def _describe(exc: BaseException) -> str:
    """One line naming why the campaign stopped."""
    if isinstance(exc, asyncio.CancelledError | KeyboardInterrupt):
        return "interrupted (Ctrl-C or cancelled)"
    if isinstance(exc, TrialAborted | VehicleError):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"
