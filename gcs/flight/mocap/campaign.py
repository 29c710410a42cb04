"""The motion-capture steps of a campaign (:mod:`gcs.flight.campaign`).

Before arming: forward the mocap to the vehicle and judge its EKF2 settings
(:func:`before_arming`), set a global origin and wait for the estimate to agree with the mocap
(:func:`ready_to_arm`). After take-off: one small move per horizontal axis, out and back, seen
the commanded way in both the estimate and the mocap (:func:`check_moves`). Around each trial:
a mocap sample past its end (:func:`wait_past_end`) and the trial's mocap cut onto its grid
(:func:`with_mocap`).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from gcs.errors import MocapError, VehicleError
from gcs.flight.fence import format_ned
from gcs.flight.mocap.checks import (
    move_direction_problem,
    move_length,
    moved_as_commanded,
    pose_agreement_problem,
    window_mean,
)
from gcs.flight.mocap.link import MocapLink, trial_mocap
from gcs.flight.mocap.preflight import EKF2_FLOAT_PARAMS, EKF2_INT_PARAMS, ekf2_findings
from gcs.flight.prearm import ensure_global_origin
from gcs.flight.trial import TrialRecording
from gcs.flight.vehicle import Vehicle
from gcs.io.settings import FlightSettings

__all__ = ["MOVE_WINDOW_S", "before_arming", "check_moves", "ready_to_arm", "wait_past_end",
           "with_mocap"]  # fmt: skip

#: Length of the hover windows averaged by the pre-flight move check [s].
MOVE_WINDOW_S = 1.5

#: ``note(text, warning)``: one line for the operator (a campaign's status).
Note = Callable[..., None]


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
    return replace(recording, mocap=trial_mocap(mocap.drain(), mocap.mapping, recording))


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


async def before_arming(vehicle: Vehicle, mocap: MocapLink, note: Note) -> dict:
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
    dict
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
    findings = ekf2_findings(params, mocap.settings.forward, mocap.settings.message)
    for f in findings:
        note(f.text, f.level != "info")
    refused = [f.text for f in findings if f.level == "refuse"]
    if refused:
        raise MocapError(f"vehicle settings refused: {refused[0]}")
    return {"ekf2": params, "findings": [f.text for f in findings[1:]]}


async def ready_to_arm(vehicle: Vehicle, mocap: MocapLink, note: Note) -> dict:
    """A global origin (set when there is none), then the estimate where the mocap sees it.

    The agreement is waited for while the estimator settles (bounded), refused if it never
    comes.

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
    dict
        The agreement [m] and the global origin, for the session record.

    Raises
    ------
    MocapError
        The estimate never agreed with the mocap.
    """
    origin, was_set = await ensure_global_origin(vehicle)
    where = f"{origin[0]:.6f}, {origin[1]:.6f}, {origin[2]:.1f} m"
    note(f"global origin {'set to' if was_set else 'is'} {where}")
    started = time.monotonic()
    problem: list[str | None] = [None]

    def agree() -> bool:
        assert vehicle.latest is not None  # a healthy local position has samples
        est = np.asarray(vehicle.latest.pos_ned_m)
        problem[0] = pose_agreement_problem(
            est, mocap.require_tracked(), mocap.settings.agreement_m
        )
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
    return {"agreement_m": distance, "origin": list(origin), "origin_set": was_set}


async def check_moves(
    vehicle: Vehicle, mocap: MocapLink, settings: FlightSettings, note: Note
) -> list[dict]:
    """A small move per horizontal axis, out and back, each the commanded way in both sources.

    Each move must go the commanded way in the estimate and in the mocap (a mirrored or
    swapped axis shows here, not in the eight). Positions are means over a window before and
    after; the move stands out of the wander measured before it.

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
    list of dict
        Each move: commanded, estimated and mocap displacement [m], wander [m], problem.

    Raises
    ------
    MocapError
        A move went the wrong way.
    """
    out = []
    for axis, name in ((0, "north"), (1, "east")):
        for attempt in (1, 2):
            move = await _check_move(vehicle, mocap, settings, axis, name)
            out.append(move)
            step, problem = np.asarray(move["cmd_ned_m"]), move["problem"]
            # both the estimate and the mocap saw the same wrong move: the vehicle wandered
            # (it did not follow), which says nothing about the mapping: measured once more
            wandered = problem is not None and not any(
                moved_as_commanded(step, np.asarray(move[k]))
                for k in ("est_delta_ned_m", "mocap_delta_ned_m")
            )
            if problem is None or not wandered or attempt == 2:
                break
            note(f"mocap check: {problem}; once more", True)
        if problem is not None:
            raise MocapError(f"pre-flight {name} move: {problem}")
        wander = move["wander_m"]
        note(f"mocap check: a {step[axis]:+.2f} m {name} move went the right way in "
             f"the estimate and the mocap (hover wander {wander:.3f} m)")  # fmt: skip
    return out


async def _check_move(
    vehicle: Vehicle, mocap: MocapLink, settings: FlightSettings, axis: int, name: str
) -> dict:
    """One move along ``axis`` and back, judged on averaged windows before and after it."""
    fence = vehicle.fence
    home = await vehicle.hold_position()
    est0, moc0, wander = await _still_at(vehicle, mocap, home, settings, f"before the {name} check")
    step = np.zeros(3)
    step[axis] = move_length(mocap.settings.check_move_m, wander)
    if fence is not None and fence.setpoint_problem(home + step) is not None:
        step = -step  # the other way stays inside the arena
    await vehicle.goto(home + step, settings.transit_speed_m_s)
    est1, moc1, _ = await _still_at(vehicle, mocap, home + step, settings, f"the {name} check")
    await vehicle.goto(home, settings.transit_speed_m_s)
    return {"cmd_ned_m": step.tolist(), "est_delta_ned_m": (est1 - est0).tolist(),
            "mocap_delta_ned_m": (moc1 - moc0).tolist(), "wander_m": wander,
            "problem": move_direction_problem(step, est1 - est0, moc1 - moc0)}  # fmt: skip


async def _still_at(
    vehicle: Vehicle, mocap: MocapLink, target: np.ndarray, settings: FlightSettings, what: str
) -> tuple[np.ndarray, np.ndarray, float]:
    """Settle at ``target`` (or give up after the settle timeout), then hover a window: the
    mean of the estimate, the mean of the mocap and the mocap's horizontal wander."""
    await vehicle.settle(target, settings.settle_tolerance_m, settings.settle_speed_m_s)
    samples = await vehicle.hold(MOVE_WINDOW_S, what)
    mocap.require_tracked()
    est, _ = window_mean(np.array([s.pos_ned_m for s in samples]))
    series = mocap.client.recent(MOVE_WINDOW_S)
    moc, wander = window_mean(mocap.mapping.position_to_ned(series.pos_m[series.tracked]))
    return est, moc, wander
