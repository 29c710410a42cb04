"""A campaign: take off, fly trial after trial (asking the source for each sequence), land.

Sequence: connect, read what the vehicle navigates on (EKF2 parameters) and what it does on a
lost link, wait for a valid local position, arm, take off to the altitude of the first setpoint,
start offboard at the current position, move to the start point, hold it for
``settings.hover_before_trial_s`` and measure the hover there for ``settings.hover_measure_s``
(:mod:`gcs.flight.hover`): a vehicle that drifts or oscillates is refused, any other gives the
settle tolerances, and the measurement goes to ``source.record_session``. For each trial: move
to its hover point (``source.hover_point_for``: the trajectory's start, where learning assumes
the vehicle at rest before ``u(0)``), hold it for ``settings.hover_before_trial_s`` (the state
the previous trial left decays) and settle there, so that every trial starts from a settled
vehicle; fly it, hover at its end while
``source.record`` runs (in a worker thread), ask ``source.setpoints_for`` for the next sequence
(worker thread, still hovering). A settle that times out is judged like the first hover:
flown on with wider tolerances (and a warning), or refused. A trial whose stream fell behind
(a late setpoint, :class:`gcs.errors.TrialPaused`) is handed to ``source.record_incomplete``,
hovering, and flown again from its start point, at most ``settings.paused_trial_retries``
times. After the last trial: land and disarm. Every trial's vehicle-time rate is checked
(:func:`gcs.flight.clock.rate_warning`).

The fence (:mod:`gcs.flight.fence`): before take-off the campaign says what it watches, uploads
the arena to the autopilot as its own geofence (:mod:`gcs.flight.geofence`; a refusal is a
warning) and records both in the session; from arming to disarming every phase (take-off,
offboard start, moves, settle, holds, the hover measurement, trials, the hovers while learning,
landing) stops on a breach. Every setpoint is checked against the arena where it is sent
(:meth:`Vehicle.send_setpoint`), each trial's sequence also before the move to its start.

Safety: on Ctrl-C (``CancelledError``/``KeyboardInterrupt``), link loss, offboard rejection, a
breach of the fence or any other exception after connecting, the vehicle is stopped
(:meth:`Vehicle.emergency_stop`: streaming stops, Hold, land, disarm on the ground); the session
record notes why; a trial that was in flight is handed to
``source.record_incomplete`` with its partial recording; then the exception is re-raised.
Completed trials were handed to ``source.record`` already. :func:`run_campaign` runs a campaign
from synchronous code (a command line) so that a second Ctrl-C cannot cut that stop short.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from gcs.core.trajectory import setpoint_array
from gcs.errors import MocapError, TrajectoryError, TrialAborted, TrialPaused, VehicleError
from gcs.flight.clock import rate_warning
from gcs.flight.fence import Fence, format_ned
from gcs.flight.geofence import GeofenceState, install_geofence
from gcs.flight.hover import HoverStats, HoverVerdict, hover_stats, judge_hover, widened
from gcs.flight.interrupts import run_guarded
from gcs.flight.link import TelemetrySample, sample_arrays
from gcs.flight.mocap import campaign as mocap_steps
from gcs.flight.mocap.campaign import MocapReport
from gcs.flight.mocap.link import MocapLink
from gcs.flight.prearm import wait_ready_to_arm
from gcs.flight.preflight import (
    LINK_LOSS_PARAMS,
    NAV_PARAMS,
    NavigationSource,
    link_loss_warnings,
    navigation_source,
)
from gcs.flight.trial import TrialRecording, TrialRun
from gcs.flight.vehicle import Vehicle
from gcs.io.settings import FlightSettings

__all__ = [
    "TrialSource",
    "TrialStarted",
    "TrialProgress",
    "TrialFinished",
    "Status",
    "HoverRecord",
    "FlightSession",
    "CampaignEvent",
    "CampaignPlan",
    "fly_campaign",
    "run_campaign",
    "check_battery",
]

_log = logging.getLogger(__name__)


class TrialSource(Protocol):
    """Where trials come from and where their recordings go (blocking; run in a thread).

    The calls run in threads of the flight process, which must meanwhile forward the mocap,
    stream the setpoints and watch the telemetry: a source with heavy work (learning) does it
    in a process of its own, this process only waiting for the answer (``gcs fly`` and
    ``gcs identify`` do so).
    """

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

    def record(self, j: int, recording: TrialRecording) -> str | None:
        """Take the complete recording of trial ``j`` (write files, learn).

        Parameters
        ----------
        j : int
            Trial index.
        recording : TrialRecording
            The complete recording.

        Returns
        -------
        str or None
            A reason to fly no further trial (the campaign lands and says it), or None.
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

    def record_session(self, session: FlightSession) -> None:
        """Take what the campaign learned about the vehicle (called again when it changes).

        Parameters
        ----------
        session : FlightSession
            Navigation source, hover measurements and settle tolerances so far.
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


@dataclass(frozen=True)
class HoverRecord:
    """One judged hover at a start point.

    Parameters
    ----------
    before_trial : int
        The trial it preceded.
    why : str
        ``"measurement"`` (before the first trial) or ``"settle timeout"`` (a settle that ran
        out of time, judged again).
    target_ned_m : tuple of float
        The hover point, local NED [m].
    stats : HoverStats
        Its statistics.
    verdict : HoverVerdict
        The verdict and the tolerances it gives.
    clock_rate : float
        Vehicle-time / wall-time rate during the hover (NaN if unknown).
    """

    before_trial: int
    why: str
    target_ned_m: tuple[float, float, float]
    stats: HoverStats
    verdict: HoverVerdict
    clock_rate: float


@dataclass(frozen=True)
class FlightSession:
    """What one campaign found out about the vehicle, for the run directory.

    Parameters
    ----------
    url : str
        Connection URL.
    first_trial : int
        The campaign's first trial.
    navigation : NavigationSource
        What EKF2 navigates on.
    hovers : tuple of HoverRecord
        The hover measured before the first trial, then every re-judged one.
    tolerance_m : float
        Settle tolerance on the distance in force now [m].
    speed_tolerance_m_s : float
        Settle tolerance on the speed in force now [m/s].
    fence : Fence or None
        The arena and limits watched while armed.
    geofence : GeofenceState or None
        The vehicle's own geofence as gcs set it up before take-off.
    abort_reason : str or None
        Why the session stopped early (a breach, a refused hover, Ctrl-C ...); None if it ran
        to its end (or is still running).
    mocap : MocapReport or None
        The motion capture of the session (EKF2 findings, pre-flight checks, then source,
        mapping and forwarding), when there was one.
    """

    url: str
    first_trial: int
    navigation: NavigationSource
    hovers: tuple[HoverRecord, ...] = ()
    tolerance_m: float = math.nan
    speed_tolerance_m_s: float = math.nan
    fence: Fence | None = None
    geofence: GeofenceState | None = None
    abort_reason: str | None = None
    mocap: MocapReport | None = None


CampaignEvent = Status | TrialStarted | TrialProgress | TrialFinished
EventCallback = Callable[[CampaignEvent], None]


@dataclass(frozen=True)
class CampaignPlan:
    """What a campaign flies: which vehicle, which trials, on which grid, inside which arena.

    Parameters
    ----------
    url : str
        MAVSDK connection URL of the vehicle.
    first_trial : int
        Index ``j`` of the first trial (to resume a run).
    iterations : int
        Number of trials to fly, >= 1.
    t_ilc_s : float
        ILC sample time [s].
    settings : FlightSettings
        Flight settings; ``stream_rate_hz`` must be an integer multiple of ``1 / t_ilc_s``.
    fence : Fence
        The arena every setpoint must lie in and the limits watched while armed.
    yaw_deg : ndarray, shape (N,), or None
        Heading of each trial setpoint [deg, clockwise from north], the same every trial (the
        yaw is flown as the reference, not learned); None: ``settings.yaw_deg`` throughout.
        Outside the trials (take-off, moves, hovers) the heading is ``settings.yaw_deg``: give
        it the first of these so that each trial starts facing its own way.
    """

    url: str
    first_trial: int
    iterations: int
    t_ilc_s: float
    settings: FlightSettings
    fence: Fence
    yaw_deg: np.ndarray | None = field(default=None, compare=False)


async def fly_campaign(
    plan: CampaignPlan,
    source: TrialSource,
    on_event: EventCallback | None = None,
    *,
    mocap: MocapLink | None = None,
) -> None:
    """Fly ``plan.iterations`` trials ``plan.first_trial, plan.first_trial + 1, ...`` and land.

    Parameters
    ----------
    plan : CampaignPlan
        The vehicle, the trials, the grid and the arena.
    source : TrialSource
        Supplies each trial's setpoints and takes each recording (called in worker threads).
    on_event : callable, optional
        Receives :class:`Status`, :class:`TrialStarted`, :class:`TrialProgress` and
        :class:`TrialFinished` events on the event loop; must return quickly.
    mocap : MocapLink or None
        A started motion-capture link: forwarded to the vehicle from connection on (if its
        settings say so), checked before arming (EKF2 settings, body tracked, pose agreement)
        and after take-off (one move per horizontal axis), watched like the fence while armed,
        and cut into each trial's recording.

    Raises
    ------
    VehicleError
        Unreachable vehicle, refused command, lost link, a breach of the fence, a hover
        refused (drifting, oscillating, too far off).
    MocapError
        The mocap stream or a pre-flight mocap check refused the flight.
    TrialAborted
        The trial watchdog fired (the trial went to ``source.record_incomplete``).
    asyncio.CancelledError
        Cancelled (Ctrl-C); the vehicle was landed first.
    """
    if plan.iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {plan.iterations}")
    plan.settings.sends_per_sample(plan.t_ilc_s)  # fail before connecting
    flight = _Campaign(plan, source, on_event, mocap)
    flight.emit(Status(f"connecting to {plan.url}"))
    await flight.vehicle.connect(plan.url)
    try:
        hover, setpoints = await flight.preflight()
        await flight.take_off(hover)
        await flight.fly_trials(hover, setpoints)
        await flight.land()
    except BaseException as exc:
        named = await flight.stop(exc)
        if named is not None:
            raise named from exc
        raise
    finally:
        if mocap is not None:
            mocap.detach()  # no send may run into the plugin released with the vehicle
        await flight.vehicle.close()


class _Campaign:
    """One campaign's vehicle, what it flies and what it has learned so far, by phases."""

    def __init__(
        self,
        plan: CampaignPlan,
        source: TrialSource,
        on_event: EventCallback | None,
        mocap: MocapLink | None,
    ) -> None:
        self.plan, self.source, self.on_event, self.mocap = plan, source, on_event, mocap
        self.settings, self.t_ilc_s, self.fence = plan.settings, plan.t_ilc_s, plan.fence
        self.vehicle = Vehicle(plan.settings, plan.fence)
        self.j = plan.first_trial  # the trial in hand
        self.run: TrialRun | None = None  # the trial in flight
        self.session: FlightSession | None = None

    def emit(self, event: CampaignEvent) -> None:
        """Hand ``event`` to the caller's callback."""
        if self.on_event is not None:
            self.on_event(event)

    def note(self, text: str, warning: bool = False) -> None:
        """Emit one line of status."""
        self.emit(Status(text, warning=warning))

    async def record_session(self, session: FlightSession, what: str) -> None:
        """Keep ``session`` and hand it to the source, hovering meanwhile."""
        self.session = session
        await self.vehicle.hover_while(asyncio.to_thread(self.source.record_session, session), what)

    async def preflight(self) -> tuple[np.ndarray, np.ndarray]:
        """Read the vehicle, wait for it, install the fence; the first trial's plan."""
        vehicle, mocap, emit = self.vehicle, self.mocap, self.emit
        hover, setpoints = await asyncio.to_thread(_plan, self.source, self.j, self.fence)
        ekf2 = None if mocap is None else await mocap_steps.before_arming(vehicle, mocap, self.note)
        for warning in link_loss_warnings(await vehicle.read_int_params(LINK_LOSS_PARAMS)):
            emit(Status(warning, warning=True))
        navigation = navigation_source(await vehicle.read_int_params(NAV_PARAMS))
        emit(Status(navigation.text, warning=navigation.warning))
        emit(Status("waiting for a valid local position"))
        await vehicle.wait_healthy_local_position()
        report = None
        if mocap is not None:
            assert ekf2 is not None
            arming = await mocap_steps.ready_to_arm(vehicle, mocap, self.note)
            report = MocapReport(ekf2, arming)
            vehicle.add_watch("mocap", mocap.problem)
        await _wait_prearm(vehicle, emit)
        emit(Status(self.fence.describe()))
        geofence = await install_geofence(vehicle, self.fence)
        emit(Status(geofence.text(self.fence.margin_m), warning=not geofence.ok))
        self.session = FlightSession(
            self.plan.url, self.plan.first_trial, navigation, fence=self.fence,
            geofence=geofence, mocap=report,
        )  # fmt: skip
        await asyncio.to_thread(self.source.record_session, self.session)
        return hover, setpoints

    async def take_off(self, hover: np.ndarray) -> None:
        """Arm, take off to the hover point's altitude, start offboard, check the mocap."""
        vehicle, mocap, settings = self.vehicle, self.mocap, self.settings
        check_battery(vehicle.battery_pct, settings.min_battery_pct, "taking off")
        altitude_m = -float(hover[2])
        self.emit(Status(f"arming and taking off to {altitude_m:.1f} m"))
        await vehicle.arm_and_takeoff(altitude_m)
        self.emit(Status("starting offboard"))
        await vehicle.start_offboard_at_current_position()
        if mocap is not None and mocap.settings.check_move_m > 0:
            moves = await mocap_steps.check_moves(vehicle, mocap, settings, self.note)
            session = self.session
            assert session is not None and session.mocap is not None
            session = replace(session, mocap=replace(session.mocap, moves=moves))
            await self.record_session(session, "recording the mocap checks")

    async def fly_trials(self, hover: np.ndarray, setpoints: np.ndarray) -> None:
        """Trial after trial: to its start point, settled, flown, recorded (and planned).

        A trial whose stream fell behind (:class:`gcs.errors.TrialPaused`) is kept as an
        incomplete attempt and flown again from its start point, at most
        ``settings.paused_trial_retries`` times.
        """
        first, iterations = self.plan.first_trial, self.plan.iterations
        for number, j in enumerate(range(first, first + iterations), start=1):
            self.j = j
            if number > 1:
                hover, setpoints = await self.vehicle.hover_while(
                    asyncio.to_thread(_plan, self.source, j, self.fence), f"setpoints of trial {j}"
                )
            attempt = 0
            while True:
                await self.to_start(j, hover, measure=number == 1 and attempt == 0)
                try:
                    stop = await self.fly_trial(j, number, iterations, setpoints)
                    break
                except TrialPaused as exc:
                    attempt += 1
                    await self.keep_paused(j, exc, attempt)
            if stop:
                self.emit(Status(f"no further trial after trial {j}: {stop}"))
                break

    async def keep_paused(self, j: int, exc: TrialPaused, attempt: int) -> None:
        """Keep the paused attempt of trial ``j`` as incomplete, hovering, and say that it is
        flown again; or raise ``exc`` when this ``attempt`` is one more than the profile allows.
        """
        retries = self.settings.paused_trial_retries
        if attempt > retries:
            raise exc
        partial = exc.recording  # type: ignore[attr-defined]
        partial = await asyncio.to_thread(mocap_steps.with_mocap, partial, self.mocap)
        self.run = None  # kept below: no longer in flight
        self.emit(TrialFinished(j, partial))
        reason = str(exc)
        await self.vehicle.hover_while(
            asyncio.to_thread(self.source.record_incomplete, j, partial, reason),
            f"recording the paused attempt of trial {j}",
        )
        self.note(
            f"{reason.replace('trial aborted', f'trial {j} stopped', 1)}: gcs fell behind its "
            f"stream, the vehicle stayed under control; flying trial {j} again ({attempt} of "
            f"{retries})",
            warning=True,
        )

    async def to_start(self, j: int, hover: np.ndarray, measure: bool) -> None:
        """Move to trial ``j``'s start point, hold it (the initial reset) and settle there.

        With ``measure`` (before the first trial) the hover there is measured and judged. The
        settle comes last, so that the trial starts from a settled vehicle: within the
        session's tolerances of the point, at rest.
        """
        vehicle, settings, emit = self.vehicle, self.settings, self.emit
        check_battery(vehicle.battery_pct, settings.min_battery_pct, f"trial {j}")
        emit(Status(f"moving to the start point of trial {j}"))
        await vehicle.goto(hover, settings.transit_speed_m_s)
        session = self.session
        assert session is not None
        if measure:
            record = await measure_hover(vehicle, hover, j, settings, emit)
            v = record.verdict
            session = _with_hover(session, record, v.tolerance_m, v.speed_tolerance_m_s)
            await self.record_session(session, "recording the hover")
            if not record.verdict.ok:
                raise VehicleError(
                    f"the vehicle does not hold the start point {format_ned(hover)}: it "
                    f"{record.verdict.reason}"
                )
        if settings.hover_before_trial_s > 0:
            # the initial reset of ILC: let the state the previous trial left decay
            emit(Status(f"holding the start point for {settings.hover_before_trial_s:g} s"))
            await vehicle.hold(settings.hover_before_trial_s, f"the hold before trial {j}")
        # the settle last: learning assumes the vehicle at rest at the start point at u(0),
        # and a vehicle that wanders by decimetres, settled before the hold, was carried up
        # to 0.8 m away during it (PX4 SIH on vision)
        record = await settle_at_start(vehicle, hover, j, session, settings, emit)
        if record is not None:
            tolerances = widened(
                session.tolerance_m, session.speed_tolerance_m_s, record.stats, settings
            )
            session = _with_hover(session, record, *tolerances)
            await self.record_session(session, "recording the hover")

    async def fly_trial(
        self, j: int, number: int, iterations: int, setpoints: np.ndarray
    ) -> str | None:
        """Fly trial ``j`` and hand its recording over, hovering; why to stop, or None."""
        emit, mocap, t_ilc_s = self.emit, self.mocap, self.t_ilc_s
        n = setpoints.shape[0]
        emit(TrialStarted(j, number, iterations, n, n * t_ilc_s))

        def progress(k: int, n: int, err_m: float, j: int = j) -> None:
            emit(TrialProgress(j, k, n, err_m))

        self.run = TrialRun(
            self.vehicle, setpoints, t_ilc_s, self.settings, progress, self.plan.yaw_deg
        )
        if mocap is not None:
            mocap.start_journal()  # the trial's raw file starts here
        recording = await self.run.fly()
        if mocap is not None:  # y(N) needs a mocap sample on both sides
            await asyncio.to_thread(mocap_steps.wait_past_end, mocap, recording)
            # the trial's raw mocap onto the grid, in a thread: on this loop it held the frames
            # forwarded to the vehicle for tens of milliseconds on a loaded machine
            recording = await asyncio.to_thread(mocap_steps.with_mocap, recording, mocap)
        self.run = None  # handed over below: no longer "in flight"
        emit(TrialFinished(j, recording))
        if recording.clock is not None:
            warning = rate_warning(j, recording.clock.rate, n * t_ilc_s, t_ilc_s)
            if warning is not None:
                emit(Status(warning, warning=True))
        return await self.vehicle.hover_while(
            asyncio.to_thread(self.source.record, j, recording), f"recording trial {j}"
        )

    async def land(self) -> None:
        """Land and disarm; the session's last mocap statistics."""
        self.emit(Status("landing"))
        await self.vehicle.land_and_disarm()
        self.emit(Status("landed and disarmed"))
        below_m = self.vehicle.below_floor_landing_m
        if self.fence is not None and below_m > self.fence.margin_m:
            self.emit(Status(
                f"while landing the position estimate read up to {below_m:.2f} m below the "
                "arena's floor: its height drifted (the vehicle cannot be below the ground; "
                "PX4 lands on its vertical velocity), so gcs let it land; check the height "
                "source before the next flight", warning=True,
            ))  # fmt: skip
        if self.mocap is not None and self.session is not None:
            self.session = _with_link(self.session, self.mocap)
            await asyncio.to_thread(self.source.record_session, self.session)

    async def stop(self, exc: BaseException) -> VehicleError | None:
        """Stop the vehicle after ``exc``; record why and the trial that was in flight.

        Returns the breach as the error to raise when ``exc`` did not name it (else None).
        """
        reason = _describe(exc)
        named = _breach_first(self.vehicle.breach, exc, reason)
        reason = str(named) if named is not None else reason
        self.emit(Status(f"aborting: {reason}"))
        outcome = await self.vehicle.emergency_stop(reason)
        self.emit(Status(f"emergency stop: {outcome}"))
        session, mocap = self.session, self.mocap
        if session is not None:
            if mocap is not None:
                session = _with_link(session, mocap)
            try:
                await asyncio.to_thread(
                    self.source.record_session, replace(session, abort_reason=reason)
                )
            except Exception:  # keep the original exception; the failure is logged
                _log.exception("record_session failed")
        if self.run is not None:
            partial = getattr(exc, "recording", None)
            if not isinstance(partial, TrialRecording):
                partial = self.run.recording(reason)
            partial = mocap_steps.with_mocap(partial, mocap)
            self.emit(TrialFinished(self.j, partial))
            try:
                await asyncio.to_thread(self.source.record_incomplete, self.j, partial, reason)
            except Exception:  # keep the original exception; the handover failure is logged
                _log.exception("record_incomplete(%d) failed", self.j)
        return named


def run_campaign(
    plan: CampaignPlan,
    source: TrialSource,
    on_event: EventCallback | None = None,
    *,
    mocap: MocapLink | None = None,
) -> None:
    """Fly a campaign from synchronous code: :func:`fly_campaign` under :func:`run_guarded`.

    The first Ctrl-C (or SIGTERM) cancels the campaign, which stops the vehicle; any further one
    while it is stopping is reported as a :class:`Status` event and otherwise ignored, so the
    hold, landing and disarm run to their end (each bounded by the settings' timeouts).

    Parameters
    ----------
    plan : CampaignPlan
        The vehicle, the trials, the grid and the arena.
    source : TrialSource
        Supplies each trial's setpoints and takes each recording.
    on_event : callable, optional
        Receives the campaign events, and the notice of a repeated Ctrl-C.
    mocap : MocapLink or None
        A started motion-capture link (see :func:`fly_campaign`).

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

    run_guarded(fly_campaign(plan, source, on_event, mocap=mocap), on_repeat)


async def measure_hover(
    vehicle: Vehicle,
    target: np.ndarray,
    j: int,
    settings: FlightSettings,
    emit: EventCallback,
) -> HoverRecord:
    """Hold the start point (the initial reset), then measure and judge the hover there.

    A hover still approaching the point is measured again, up to two more times.
    """
    hold_s, measure_s = settings.hover_before_trial_s, settings.hover_measure_s
    emit(Status(f"measuring the hover at the start point for {measure_s:g} s, after {hold_s:g} s "
                "to settle"))  # fmt: skip
    if hold_s > 0:
        await vehicle.hold(hold_s, "the hold before the hover measurement")
    samples = await vehicle.hold(measure_s, "the hover measurement")
    record = await _judge_arrived(samples, target, j, "measurement", vehicle, settings)
    emit(
        Status(
            f"hover at the start point: {record.stats.describe()}", warning=not record.verdict.ok
        )
    )
    if record.verdict.ok:
        v = record.verdict
        emit(Status(f"settle tolerances: {v.tolerance_m:.2f} m, {v.speed_tolerance_m_s:.2f} m/s"))
    return record


async def settle_at_start(
    vehicle: Vehicle,
    target: np.ndarray,
    j: int,
    session: FlightSession,
    settings: FlightSettings,
    emit: EventCallback,
) -> HoverRecord | None:
    """Settle at the start point; judge the hover if that times out (None when it settled).

    A hover still approaching the point when the settle times out is measured again, as in
    :func:`measure_hover`: a vehicle that wanders by decimetres can be on its way back.
    """
    with vehicle.record_telemetry() as samples:
        if await vehicle.settle(target, session.tolerance_m, session.speed_tolerance_m_s):
            return None
        recent = _last(samples, settings.hover_measure_s)
    record = await _judge_arrived(
        recent, target, j, "settle timeout", vehicle, settings, hovered=samples
    )
    if not record.verdict.ok:
        raise VehicleError(
            f"the vehicle did not settle at the start point {format_ned(target)} of trial {j} "
            f"within {settings.settle_timeout_s:g} s: it {record.verdict.reason}"
        )
    tolerance_m, speed_m_s = widened(
        session.tolerance_m, session.speed_tolerance_m_s, record.stats, settings
    )
    emit(
        Status(
            f"trial {j}: not settled within {settings.settle_timeout_s:g} s "
            f"({session.tolerance_m:.2f} m, {session.speed_tolerance_m_s:.2f} m/s); the hover "
            f"now: {record.stats.describe()}; flying on with tolerances {tolerance_m:.2f} m, "
            f"{speed_m_s:.2f} m/s",
            warning=True,
        )
    )
    return record


async def _judge_arrived(
    samples: list[TelemetrySample],
    target: np.ndarray,
    j: int,
    why: str,
    vehicle: Vehicle,
    settings: FlightSettings,
    hovered: list[TelemetrySample] | None = None,
) -> HoverRecord:
    """Judge a hover; while it is still approaching the point, measure it again (twice at most),
    and once more when it drifts away.

    A vehicle that wanders by decimetres moves away from the point through a short window at
    its wander's speed and comes back through a later one; one that does not hold the point
    goes on drifting. When the new measurement drifts away too, the drift is judged over
    everything the vehicle has hovered at the point since it was told to: ``hovered`` (default:
    ``samples``) and the new measurement. A wander's trend over that time is small, a drift's
    is not. (Two 2 s windows alone refused PX4 SIH on vision, wandering 0.24 m, after a 20 s
    settle, drifting away at 0.31 m/s through both.)
    """
    hovered = list(samples if hovered is None else hovered)
    record = _judge(samples, target, j, why, vehicle, settings)
    again = {"approaching": 2, "drifting": 1}
    while again.get(record.verdict.kind, 0) > 0:
        kind = record.verdict.kind
        again[kind] -= 1
        samples = await vehicle.hold(settings.hover_measure_s, "the hover measurement")
        hovered += samples
        record = _judge(samples, target, j, why, vehicle, settings)
        if kind == record.verdict.kind == "drifting":
            record = _judge(hovered, target, j, why, vehicle, settings)
    return record


def _judge(
    samples: list[TelemetrySample],
    target: np.ndarray,
    j: int,
    why: str,
    vehicle: Vehicle,
    settings: FlightSettings,
) -> HoverRecord:
    """Statistics and verdict of a hover recorded as samples."""
    t, pos = sample_arrays(samples)
    try:
        stats = hover_stats(t, pos, target)
    except ValueError as exc:
        raise VehicleError(f"cannot measure the hover at {format_ned(target)}: {exc}") from None
    fit = vehicle.clock.fit()
    rate = fit.rate if fit is not None else math.nan
    target_t = (float(target[0]), float(target[1]), float(target[2]))
    return HoverRecord(j, why, target_t, stats, judge_hover(stats, settings), rate)


def _last(samples: list[TelemetrySample], duration_s: float) -> list[TelemetrySample]:
    """The samples of the last ``duration_s`` of vehicle time."""
    if not samples:
        return []
    newest = max(s.t_vehicle_s for s in samples)
    return [s for s in samples if s.t_vehicle_s >= newest - duration_s]


def _with_hover(
    session: FlightSession, record: HoverRecord, tolerance_m: float, speed_tolerance_m_s: float
) -> FlightSession:
    """The session with one more judged hover and the settle tolerances now in force."""
    return replace(
        session,
        hovers=session.hovers + (record,),
        tolerance_m=tolerance_m,
        speed_tolerance_m_s=speed_tolerance_m_s,
    )


def _with_link(session: FlightSession, mocap: MocapLink) -> FlightSession:
    """The session with what the mocap link used and its statistics so far."""
    if session.mocap is None:  # not reached: a session with a mocap link has its report
        return session
    return replace(session, mocap=replace(session.mocap, link=mocap.describe()))


def _plan(source: TrialSource, j: int, fence: Fence) -> tuple[np.ndarray, np.ndarray]:
    """Trial j's hover point and setpoints, checked against the arena (worker thread)."""
    setpoints = setpoint_array(source.setpoints_for(j))
    hover = np.asarray(source.hover_point_for(j), dtype=float).reshape(3)
    problem = fence.setpoint_problem(hover)
    if problem is not None:
        raise TrajectoryError(f"hover point of trial {j}: {problem}; not flown")
    problem = fence.setpoints_problem(setpoints)
    if problem is not None:
        raise TrajectoryError(f"trial {j}: {problem}; not flown")
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


def _breach_first(breach: str | None, exc: BaseException, reason: str) -> VehicleError | None:
    """The breach as the campaign's error, when another error (say, a hover judged as
    drifting, on the same samples) came out first; None when ``exc`` already names it."""
    if breach is None or breach in reason or not isinstance(exc, VehicleError):
        return None
    return VehicleError(breach)


async def _wait_prearm(vehicle: Vehicle, emit: EventCallback) -> None:
    """Wait for PX4's own pre-arm verdict (bounded); its reasons end the flight if it refuses."""
    if await vehicle.leave_offboard_on_ground():
        emit(Status("the vehicle was in Offboard mode, where PX4 cannot arm without a setpoint "
                    "stream (it returns there after an offboard flight's disarm): switched to "
                    "Hold"))  # fmt: skip
    emit(Status("waiting for the vehicle's pre-arm checks"))
    state = await wait_ready_to_arm(vehicle, vehicle.settings.health_timeout_s)
    emit(Status(f"vehicle ready to arm (after {state.waited_s:.1f} s)"))


def _describe(exc: BaseException) -> str:
    """One line naming why the campaign stopped."""
    if isinstance(exc, asyncio.CancelledError | KeyboardInterrupt):
        return "interrupted (Ctrl-C or cancelled)"
    if isinstance(exc, TrialAborted | VehicleError | MocapError):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"
