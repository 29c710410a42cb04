"""How a vehicle comes down: landing, and the emergency stop that is safe in any state.

:class:`Landing` is one part of :class:`gcs.flight.vehicle.Vehicle`: it commands through the
connection, reads its state mirror, waits through the watches, and ends the manoeuvres' setpoint
stream.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Awaitable, Callable
from typing import Any

from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState

from gcs.errors import VehicleError
from gcs.flight.link import Link
from gcs.flight.manoeuvres import Manoeuvres
from gcs.flight.watches import Watches
from gcs.io.settings import FlightSettings

__all__ = ["Landing"]

_log = logging.getLogger(__name__)


class Landing:
    """Landing and the emergency stop of :class:`gcs.flight.vehicle.Vehicle`.

    Parameters
    ----------
    mirror : Link
        The connection and its state mirror.
    watches : Watches
        The safety watches whose waits the landing waits in.
    manoeuvres : Manoeuvres
        The setpoint stream a landing ends.
    settings : FlightSettings
        Timeouts (command, landing, link regain) and the telemetry-age limit.
    """

    def __init__(
        self, mirror: Link, watches: Watches, manoeuvres: Manoeuvres, settings: FlightSettings
    ) -> None:
        self._mirror = mirror
        self._watches = watches
        self._manoeuvres = manoeuvres
        self.settings = settings

    async def land_and_disarm(self) -> None:
        """Land, wait for ON_GROUND, then disarm unless PX4 has disarmed by itself.

        Raises
        ------
        VehicleError
            Landing refused or not finished within ``settings.land_timeout_s``, link lost.
        """
        mirror = self._mirror
        link = mirror.link
        self._manoeuvres.stop_streaming()
        self._watches.landing = True  # an estimate below the floor is no breach now
        try:
            await mirror.command("land", link.land)
            self._manoeuvres.offboard_started = (
                False  # PX4 lands now: a stop must not switch it to Hold
            )
            await self._watches.wait_until(
                lambda: mirror.landed_state == LandedState.ON_GROUND,
                self.settings.land_timeout_s,
                "landing",
                in_control=False,
            )
            if mirror.armed:
                await mirror.command("disarm", link.disarm)
                await self._watches.wait_until(
                    lambda: not mirror.armed,
                    self.settings.command_timeout_s,
                    "disarmed state",
                    in_control=False,
                )
        finally:
            self._watches.landing = False

    async def emergency_stop(self, reason: str) -> str:
        """Stop streaming, leave offboard (Hold), land, and disarm once on the ground.

        Every step is guarded by a timeout and failures are logged, not raised, so that a
        dead link cannot hang or break it. Safe to call in any state, also twice.

        Parameters
        ----------
        reason : str
            Why (logged).

        Returns
        -------
        str
            One line describing the outcome, e.g. "landed and disarmed".
        """
        _log.warning("emergency stop: %s", reason)
        mirror, manoeuvres = self._mirror, self._manoeuvres
        manoeuvres.stop_streaming()
        if mirror.backend is None:
            return "not connected"
        if not (mirror.armed or mirror.arm_requested) and not manoeuvres.offboard_started:
            return "vehicle not armed; nothing to do"
        link = mirror.backend
        notes: list[str] = []

        async def attempt(what: str, call: Callable[[], Awaitable[Any]]) -> bool:
            try:
                await mirror.command(what, call)
                return True
            except VehicleError as exc:
                _log.warning("emergency stop: %s", exc)
                notes.append(str(exc))
                return False

        if manoeuvres.offboard_started:
            await attempt("offboard stop (Hold)", link.stop_offboard)
            manoeuvres.offboard_started = False
        on_ground = mirror.landed_state == LandedState.ON_GROUND
        if mirror.armed and not on_ground:
            on_ground = await self._land_with_retries(lambda: attempt("land", link.land), notes)
        if on_ground and (mirror.armed or mirror.arm_requested) and mirror.connected:
            await attempt("disarm", link.disarm)
            with contextlib.suppress(VehicleError):
                await self._watches.wait_until(
                    lambda: not mirror.armed,
                    self.settings.command_timeout_s,
                    "disarmed state",
                    in_control=False,
                    stopping=True,
                )
        if not mirror.connected:
            return "link lost: vehicle left to its own failsafe (" + "; ".join(notes) + ")"
        if on_ground and not mirror.armed:
            return "landed and disarmed"
        return "; ".join(notes) or ("on the ground, armed" if on_ground else "airborne")

    async def _land_with_retries(
        self, send_land: Callable[[], Awaitable[bool]], notes: list[str]
    ) -> bool:
        """Command LAND until the vehicle is on the ground or ``land_timeout_s`` passes.

        A land command lost in a link outage is sent again once the vehicle is heard from and
        still not landing, so that a temporary loss of the link does not leave it hovering.
        """
        mirror = self._mirror
        clock = mirror.local_clock
        deadline_s = clock.now() + self.settings.land_timeout_s
        last_try_s = -math.inf
        last_heard_s = clock.now()
        while mirror.landed_state != LandedState.ON_GROUND:
            now_s = clock.now()
            heard = (
                mirror.connected and mirror.telemetry_age_s() < self.settings.max_telemetry_age_s
            )
            if heard:
                last_heard_s = now_s
            elif now_s - last_heard_s > self.settings.link_regain_s:
                notes.append(f"link not back within {self.settings.link_regain_s:g} s")
                return False
            if now_s >= deadline_s:
                break
            if heard and mirror.flight_mode != FlightMode.LAND and now_s - last_try_s > 1.0:
                last_try_s = now_s
                await send_land()
            await mirror.wait_change(min(deadline_s - now_s, 0.5))  # or any state change
        if mirror.landed_state == LandedState.ON_GROUND:
            return True
        notes.append(f"not on the ground after {self.settings.land_timeout_s:g} s")
        return False
