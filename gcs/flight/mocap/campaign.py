"""The motion-capture steps of a campaign (:mod:`gcs.flight.campaign`).

Before arming: forward the mocap to the vehicle and judge its EKF2 settings
(:func:`before_arming`), set a global origin and wait for the estimate to agree with the mocap
(:func:`ready_to_arm`). After take-off: the frame check, hover windows at home and after a
small move along each horizontal axis, the mocap moving with the estimate and the estimate
following the commands (:func:`check_moves`). Around each trial:
a mocap sample past its end (:func:`wait_past_end`) and the trial's mocap cut onto its grid
(:func:`with_mocap`).

Each step returns its part of the session's record, a frozen value: :class:`Ekf2Check`,
:class:`ArmingAgreement`, the :class:`FrameCheck` of each frame check flown; the campaign
combines them into one :class:`MocapReport` (``dataclasses.replace``), which
:func:`gcs.app.session.session_record` writes.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gcs.errors import MocapError, VehicleError
from gcs.flight.fence import format_ned
from gcs.flight.hover import hover_stats, widened
from gcs.flight.mocap.checks import (
    FrameCheck,
    frame_check,
    move_length,
    origin_shift_problem,
    pose_agreement_problem,
    window_mean,
)
from gcs.flight.mocap.link import MocapLink, trial_mocap
from gcs.flight.mocap.preflight import EKF2_FLOAT_PARAMS, EKF2_INT_PARAMS, ekf2_findings
from gcs.flight.prearm import ensure_global_origin
from gcs.flight.trial import TrialRecording
from gcs.flight.vehicle import Vehicle
from gcs.io.settings import FlightSettings

__all__ = ["MOVE_WINDOW_S", "ArmingAgreement", "Ekf2Check", "MocapReport", "before_arming",
           "check_moves", "ready_to_arm", "wait_past_end", "with_mocap"]  # fmt: skip

#: Length of the hover windows averaged by the pre-flight move check [s].
MOVE_WINDOW_S = 1.5

#: ``note(text, warning)``: one line for the operator (a campaign's status).
Note = Callable[..., None]


@dataclass(frozen=True)
class Ekf2Check:
    """EKF2's vision settings as :func:`before_arming` read and judged them.

    Parameters
    ----------
    params : dict of str to float or int or None
        The EKF2 parameters read (None: not served), integers first.
    findings : tuple of str
        The findings after the summary line, one line each.
    """

    params: dict[str, float | int | None]
    findings: tuple[str, ...]


@dataclass(frozen=True)
class ArmingAgreement:
    """The estimate where the mocap sees the vehicle, as :func:`ready_to_arm` found it.

    Parameters
    ----------
    agreement_m : float
        Distance between the mocap's position and the estimate [m].
    origin : tuple of float
        The vehicle's global origin: latitude, longitude [deg], altitude AMSL [m].
    origin_set : bool
        gcs set the origin (the vehicle had none).
    """

    agreement_m: float
    origin: tuple[float, ...]
    origin_set: bool


@dataclass(frozen=True)
class MocapReport:
    """The motion capture of a flight session, as far as the campaign has got.

    Parameters
    ----------
    ekf2 : Ekf2Check
        EKF2's vision settings, before arming.
    arming : ArmingAgreement
        The agreement of the estimate with the mocap, before arming.
    moves : tuple of FrameCheck or None
        Each frame check flown after take-off; None when none was flown
        (``mocap.check_move_m`` 0, or not yet).
    link : dict or None
        What the link used and its statistics (:meth:`MocapLink.describe`), once the session
        ends; None before.
    """

    ekf2: Ekf2Check
    arming: ArmingAgreement
    moves: tuple[FrameCheck, ...] | None = None
    link: dict[str, Any] | None = None


def with_mocap(recording: TrialRecording, mocap: MocapLink | None) -> TrialRecording:
    """The recording with the trial's motion capture (raw samples drained, on the grid).

    Parameters
    ----------
    recording : TrialRecording
        A trial's recording, complete or partial.
    mocap : MocapLink or None
        The campaign's motion-capture link; None leaves the recording as it is.

    Returns
    -------
    TrialRecording
    """
    if mocap is None:
        return recording
    on_grid = trial_mocap(mocap.drain(), mocap.mapping, recording, mocap.max_gap_s)
    return replace(recording, mocap=on_grid)


def wait_past_end(mocap: MocapLink, recording: TrialRecording) -> None:
    """Wait briefly (worker thread) for a tracked mocap sample after the trial's last grid time.

    A stream that delivers none leaves y(N) without mocap, which learning then names.

    Parameters
    ----------
    mocap : MocapLink
        The campaign's motion-capture link.
    recording : TrialRecording
        The trial just flown.
    """
    clock = recording.clock
    if clock is None or not np.isfinite(recording.t0_vehicle_s):
        return
    end_local = float(clock.to_local(recording.t0_vehicle_s + recording.t_s[-1]))
    with contextlib.suppress(MocapError):
        mocap.client.wait_until(lambda s: s.tracked and s.t_receipt_s > end_local, 0.3)


async def before_arming(vehicle: Vehicle, mocap: MocapLink, note: Note) -> Ekf2Check:
    """Start forwarding, then judge EKF2's vision settings (refusals stop here).

    Parameters
    ----------
    vehicle : Vehicle
        The connected vehicle.
    mocap : MocapLink
        The started motion-capture link.
    note : callable
        ``note(text, warning=False)``: one line for the operator.

    Returns
    -------
    Ekf2Check
        The EKF2 parameters read and the findings, for the session record.

    Raises
    ------
    MocapError
        The vehicle's settings refuse the plan.
    """
    if mocap.settings.forward:
        mocap.attach(vehicle.mocap_plugin())
        note(f"forwarding {mocap.source.url()} to the vehicle as {mocap.settings.message}")
    else:
        note(f"reading {mocap.source.url()} (not forwarded: mocap.forward is false)")
    params: dict[str, float | int | None] = dict(await vehicle.read_int_params(EKF2_INT_PARAMS))
    for name in EKF2_FLOAT_PARAMS:
        params[name] = await vehicle.read_float_param(name)
    findings = ekf2_findings(
        params, mocap.settings.forward, mocap.settings.message, mocap.settings.position_std_m
    )
    for f in findings:
        note(f.text, f.level != "info")
    refused = [f.text for f in findings if f.level == "refuse"]
    if refused:
        raise MocapError(f"vehicle settings refused: {refused[0]}")
    return Ekf2Check(params, tuple(f.text for f in findings[1:]))


async def ready_to_arm(vehicle: Vehicle, mocap: MocapLink, note: Note) -> ArmingAgreement:
    """A global origin (set when there is none), then the estimate where the mocap sees it.

    The agreement is waited for while the estimator settles (bounded), refused if it never
    comes, and at once when the estimate's height is off by the origin's altitude (PX4 moved
    its local frame when it took the origin, and does not move it back:
    :func:`gcs.flight.mocap.checks.origin_shift_problem`).

    Parameters
    ----------
    vehicle : Vehicle
        The connected vehicle, with a healthy local position.
    mocap : MocapLink
        The started motion-capture link.
    note : callable
        ``note(text, warning=False)``: one line for the operator.

    Returns
    -------
    ArmingAgreement
        The agreement [m] and the global origin, for the session record.

    Raises
    ------
    MocapError
        The estimate never agreed with the mocap, or sits the origin's altitude away from it.
    """
    origin, was_set = await ensure_global_origin(vehicle)
    where = f"{origin[0]:.6f}, {origin[1]:.6f}, {origin[2]:.1f} m"
    note(f"global origin {'set to' if was_set else 'is'} {where}")
    started = time.monotonic()
    problem: list[str | None] = [None]

    def agree() -> bool:
        # a stream that pauses before arming is waited for, as a disagreement is: the
        # timeout names the last problem (in the air the stream's watch aborts at once)
        assert vehicle.latest is not None  # a healthy local position has samples
        est = np.asarray(vehicle.latest.pos_ned_m)
        try:
            pos = mocap.require_tracked()
        except MocapError as exc:
            problem[0] = str(exc)
            return False
        shifted = origin_shift_problem(est, pos, origin[2])
        if shifted is not None:
            raise MocapError(f"pre-flight: {shifted}")
        problem[0] = pose_agreement_problem(est, pos, mocap.settings.agreement_m)
        return problem[0] is None

    try:
        await vehicle.wait_until(agree, vehicle.settings.health_timeout_s, "mocap agreement")
    except VehicleError as exc:
        if problem[0] is None:
            raise
        raise MocapError(f"pre-flight: {problem[0]}") from exc
    pos = mocap.require_tracked()
    assert vehicle.latest is not None
    distance = float(np.linalg.norm(pos - np.asarray(vehicle.latest.pos_ned_m)))
    note(f"mocap: rigid body tracked at {format_ned(pos)}, {distance:.3f} m from the estimate "
         f"(after {time.monotonic() - started:.1f} s)")  # fmt: skip
    return ArmingAgreement(distance, tuple(origin), was_set)


async def check_moves(
    vehicle: Vehicle, mocap: MocapLink, settings: FlightSettings, note: Note
) -> tuple[FrameCheck, ...]:
    """The frame check: hover windows at home, a move north, home, a move east, home.

    :func:`gcs.flight.mocap.checks.frame_check` judges them: the mocap must move with the
    vehicle's estimate (a mapping that is not the vehicle's frame is refused at once), and the
    estimate must follow the commanded moves. When it did not but the hover's wander is too
    large for that to be conclusive, the check is flown once more with moves four times the
    wander (at most 1 m); still unjudged, the flight goes on with a warning: the mapping was
    judged, and a vehicle that wanders is not refused for it. A mapping that could be judged
    along one direction only (the estimate moved across it by less than a few centimetres)
    is refused then: a mirror or a swap across that direction would not have shown.

    Parameters
    ----------
    vehicle : Vehicle
        The vehicle, hovering in offboard.
    mocap : MocapLink
        The started motion-capture link.
    settings : FlightSettings
        Transit speed and settle tolerances.
    note : callable
        ``note(text, warning=False)``: one line for the operator.

    Returns
    -------
    tuple of FrameCheck
        Each time the check was flown: its figures.

    Raises
    ------
    MocapError
        The mocap did not move with the estimate, the vehicle did not follow, or the mapping
        could not be judged in both horizontal directions.
    """
    out: list[FrameCheck] = []
    length_m: float | None = None
    tolerances: tuple[float, float] | None = None
    for attempt in (1, 2):
        check, used_m, tolerances = await _frame_check(
            vehicle, mocap, settings, length_m, tolerances
        )
        out.append(check)
        note(f"mocap check: {_figures(check)}", check.problem is not None)
        if check.problem is not None:
            raise MocapError(f"pre-flight frame check: {check.problem}")
        longer_m = move_length(used_m, check.wander_m)
        if check.following != "unjudged" or attempt == 2 or longer_m <= used_m:
            break
        note(f"mocap check: the hover wandered {check.wander_m:.2f} m, more than a quarter of "
             f"the {used_m:.2f} m moves: once more with {longer_m:.2f} m moves", True)  # fmt: skip
        length_m = longer_m
    if not mocap.settings.forward and not check.mapping_judged:
        raise MocapError(
            "pre-flight frame check: the mocap mapping could not be judged: over the check "
            f"the vehicle moved along one direction only, inside a hover wander of "
            f"{check.wander_m:.2f} m; a mirrored or swapped axis across it would not show. "
            "Fly again in a calmer hover, or with longer moves (mocap.check_move_m)"
        )
    axes = ("north", "east")
    seen = ", ".join(
        f"{name} {r.gain:.2f} at {r.angle_deg:.0f} deg"
        for name, r in zip(axes, check.mapping, strict=True)
    )
    if mocap.settings.forward:
        note(f"mocap check: the estimate is the forwarded mocap, so the mapping is not judged "
             f"in the air (the mocap on the estimate: {seen})")  # fmt: skip
    else:
        note(f"mocap check: the mocap moved with the vehicle's estimate ({seen})")
    pairs = enumerate(zip(check.cmd_ned_m, axes, strict=True))
    moves = " and ".join(f"{c[i]:+.2f} m {name}" for i, (c, name) in pairs)
    gains = ", ".join(f"{r.gain:.2f} at {r.angle_deg:.0f} deg" for r in check.estimate)
    if check.following == "ok":
        note(f"mocap check: the estimate followed {moves} ({gains}; hover wander "
             f"{check.wander_m:.3f} m)")  # fmt: skip
    else:
        note(f"mocap check: whether the vehicle follows {moves} was not judged: its hover "
             f"wandered {check.wander_m:.2f} m ({gains})", True)  # fmt: skip
    return tuple(out)


def _figures(check: FrameCheck) -> str:
    """One line of the check's figures: gain/angle per axis of each fit, the wander."""

    def pair(rs: tuple) -> str:
        return ", ".join(f"{r.gain:.2f}/{r.angle_deg:.0f} deg" for r in rs)

    size = max(abs(x) for x in check.cmd_ned_m[0])
    return (f"{size:.2f} m moves; gain/angle N, E: estimate on command {pair(check.estimate)}, "
            f"mocap on command {pair(check.mocap)}, mocap on estimate {pair(check.mapping)}; "
            f"wander {check.wander_m:.3f} m; following {check.following}")  # fmt: skip


async def _frame_check(
    vehicle: Vehicle,
    mocap: MocapLink,
    settings: FlightSettings,
    length_m: float | None,
    tolerances: tuple[float, float] | None,
) -> tuple[FrameCheck, float, tuple[float, float]]:
    """Fly home, north, home, east, home with a hover window at each; judge them. The move is
    ``length_m``, or the profile's lengthened to four times the first window's wander.

    The first window of the first check measures the hover as the hover before the first
    trial does: after ``hover_before_trial_s`` of hold, whatever the vehicle's wander. The
    windows after it settle within the tolerances of that hover
    (:func:`gcs.flight.hover.widened`, as a trial's start does after a loose hover): a vehicle
    that wanders by decimetres never settles within the profile's few centimetres, and would
    spend the whole settle timeout at every window (the first one's did: 20 s of each lab
    flight on PX4 SIH). Those tolerances are returned for the check flown once more."""
    fence = vehicle.fence
    home = await vehicle.hold_position()
    floor = (settings.settle_tolerance_m, settings.settle_speed_m_s)
    first = await _window(
        vehicle, mocap, home, settings, "the hover before the frame check", tolerances
    )
    if tolerances is None:
        try:
            stats = hover_stats(first[0], first[1], home)
        except ValueError as exc:
            raise MocapError(f"pre-flight frame check: cannot measure the hover: {exc}") from exc
        tolerances = widened(*floor, stats, settings)
    if length_m is None:
        _, wander = window_mean(first[3])
        length_m = move_length(mocap.settings.check_move_m, wander)
    windows, cmds = [first], [np.zeros(3)]
    for axis, name in ((0, "north"), (1, "east")):
        step = np.zeros(3)
        step[axis] = length_m
        if fence is not None and fence.setpoint_problem(home + step) is not None:
            step = -step  # the other way stays inside the arena
        for target, what in (
            (home + step, f"the hover after the {name} move"),
            (home, f"the hover home after the {name} move"),
        ):
            await vehicle.goto(target, settings.transit_speed_m_s)
            windows.append(await _window(vehicle, mocap, target, settings, what, tolerances))
            cmds.append(target - home)
    t_e, est, t_m, moc, span = (np.concatenate(parts) for parts in zip(*windows, strict=True))
    try:
        check = frame_check(
            t_e, est, t_m, moc, span.reshape(-1, 2), np.array(cmds),
            judge_mapping=not mocap.settings.forward,
        )  # fmt: skip
    except ValueError as exc:  # a window without samples of one source
        raise MocapError(f"pre-flight frame check: could not judge the moves: {exc}") from exc
    return check, length_m, tolerances


async def _window(
    vehicle: Vehicle,
    mocap: MocapLink,
    target: np.ndarray,
    settings: FlightSettings,
    what: str,
    tolerances: tuple[float, float] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Settle at ``target`` within ``tolerances`` (distance [m], speed [m/s]) or give up after
    the settle timeout; with None, hold ``hover_before_trial_s`` instead (the hover is not
    measured yet). Then hover a window: the estimate's times and positions, the mocap's
    (mapped to NED), and the window's span."""
    if tolerances is None:
        if settings.hover_before_trial_s > 0:
            await vehicle.hold(settings.hover_before_trial_s, f"the hold before {what}")
    else:
        await vehicle.settle(target, *tolerances)
    samples = await vehicle.hold(MOVE_WINDOW_S, what)
    mocap.require_tracked()
    t_e = np.array([s.t_s for s in samples])
    est = np.array([s.pos_ned_m for s in samples], dtype=float).reshape(-1, 3)
    series = mocap.client.recent(time.monotonic() - float(t_e[0]) + 0.1)
    t_m = np.asarray(series.t_receipt_s, dtype=float)[series.tracked]
    moc = mocap.mapping.position_to_ned(series.pos_m[series.tracked]).reshape(-1, 3)
    return t_e, est, t_m, moc, np.array([t_e[0], t_e[-1]])
