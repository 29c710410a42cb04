"""Before arming: a global origin when the vehicle has none, and PX4's own pre-arm verdict.

Global origin. PX4 (v1.16) navigating on motion capture alone has a local position but no
global one until its local frame is given a place on the earth (MAVLink
``SET_GPS_GLOBAL_ORIGIN``). Without it the arming checks report "No valid global position
estimate" and arming is denied ("Resolve system health failures first") for as long as one
waits (measured on the SIH firmware, docs/mocap.md). :func:`ensure_global_origin` reads the
origin and, when there is none, sets :data:`LAB_ORIGIN`: any fixed place does, since the lab's
geometry lives in the local frame (the arena's geofence is uploaded relative to the same
origin). A vehicle that has an origin (GPS, or set by someone else) keeps it.

The origin's altitude is 0 m. PX4 v1.16's EKF2 (``Ekf::setAltOrigin``) keeps the local height
when the origin comes only if its vertical position is already valid; otherwise (vision not yet
fused: a loaded machine, a PX4 just started) it keeps its height as the altitude and the local
height moves by the origin's altitude. With vision as the height reference, every later start
or reset of the vision height (``controlEvHeightFusion``: after a mocap dropout of some
seconds) also sets the altitude to the vision height itself, whatever the origin's altitude.
Flown on the SIH firmware with 488 m (SIH's home altitude): the local position read 488 m down
in both cases and never came back; at 0 m neither moved it.

Pre-arm verdict. PX4 decides whether it can arm from its health and arming checks; it reports
them through the events interface (each failing check as one line, e.g. "Horizontal position
unstable") and sums them up in the ``SYS_STATUS`` pre-arm bit, which MAVSDK gives as
``Health.is_armable``. On vision these checks pass 4-5 s after the first vision sample, some
seconds after the local position is first valid, so arming as soon as the position is valid is
denied. :func:`wait_ready_to_arm` waits (on events, bounded) until PX4 says it can arm, and when
it does not, raises with PX4's own reasons.
"""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass, field

from gcs.errors import VehicleError
from gcs.flight.vehicle import Vehicle

__all__ = [
    "LAB_ORIGIN",
    "NOT_BLOCKING",
    "PrearmState",
    "ensure_global_origin",
    "refusal_text",
    "wait_ready_to_arm",
]

LAB_ORIGIN = (47.397742, 8.545594, 0.0)
"""Latitude [deg], longitude [deg] and altitude AMSL [m] set as the origin of a vehicle that has
none (PX4's SIH home at 0 m: any fixed place serves a lab, whose geometry is local, and only
0 m keeps EKF2's local height whenever its vision height starts, see the module's text)."""

NOT_BLOCKING = ("No manual control input",)
"""Problems PX4 lists while it can arm (no RC is fine for an offboard flight): not reasons."""


@dataclass
class PrearmState:
    """What PX4 said about arming while gcs waited (filled by :func:`wait_ready_to_arm`).

    ``armable``: ``SYS_STATUS`` pre-arm bit (MAVSDK ``Health.is_armable``). ``problems``: the
    current mode's failing checks from PX4's latest health report (events interface; empty where the
    vehicle does not report them). ``texts``: PX4's status texts seen (newest last). ``waited_s``:
    time from the start of the wait to its end [s].
    """

    armable: bool = False
    problems: list[str] = field(default_factory=list)
    texts: list[str] = field(default_factory=list)
    waited_s: float = 0.0


def refusal_text(state: PrearmState) -> str:
    """PX4's reasons for not arming, in one line.

    ``state``: what PX4 reported.

    Returns: its failing checks, else its last status texts about arming, else a plain statement.
    """
    reasons = [p for p in state.problems if p not in NOT_BLOCKING]
    if reasons:
        return "; ".join(reasons)
    about = [t for t in state.texts if "fail" in t.lower() or "denied" in t.lower()]
    if about:
        return "; ".join(dict.fromkeys(about[-3:]))
    return "its pre-arm check does not pass (no reason reported)"


async def ensure_global_origin(
    vehicle: Vehicle, origin: tuple[float, float, float] = LAB_ORIGIN
) -> tuple[tuple[float, float, float], bool]:
    """The vehicle's global origin, set to ``origin`` first if it has none.

    ``origin``: latitude [deg], longitude [deg], altitude AMSL [m] to set when there is none.

    Returns: the origin read back, and whether gcs set it.

    Raises ``VehicleError``: the vehicle took no origin.
    """
    with contextlib.suppress(VehicleError):
        return await vehicle.gps_global_origin(), False
    await vehicle.set_global_origin(*origin)
    try:
        return await vehicle.gps_global_origin(), True
    except VehicleError as exc:
        raise VehicleError(f"the vehicle has no global origin and took none: {exc}") from None


async def wait_ready_to_arm(vehicle: Vehicle, timeout_s: float) -> PrearmState:
    """Wait until PX4 reports that it can arm (its pre-arm bit), at most ``timeout_s``.

    ``timeout_s``: limit [s].

    Returns: what PX4 reported; ``waited_s`` is the time spent.

    Raises ``VehicleError``: not ready within ``timeout_s`` (naming PX4's reasons), or the link was
    lost.
    """
    state = PrearmState()
    link = vehicle.link

    async def watch_health() -> None:
        async for armable in link.armable_states():
            if armable != state.armable:
                state.armable = armable
                vehicle.notify()

    async def watch_checks() -> None:
        async for problems in link.arming_problems():
            state.problems = list(problems)

    async def watch_texts() -> None:
        async for text in link.status_texts():
            state.texts = [*state.texts[-19:], text.strip()]

    tasks = [asyncio.create_task(w()) for w in (watch_health, watch_checks, watch_texts)]
    clock = vehicle.local_clock
    started = clock.now()
    try:
        await vehicle.wait_until(lambda: state.armable, timeout_s, "PX4's pre-arm checks")
    except VehicleError as exc:
        if "did not happen" not in str(exc):
            raise
        raise VehicleError(
            f"PX4 is not ready to arm after {timeout_s:g} s: {refusal_text(state)}"
        ) from None
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        state.waited_s = clock.now() - started
    return state
