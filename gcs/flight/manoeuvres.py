"""How a vehicle flies: take-off, offboard, moves, settling, holds, each watched.

Every setpoint goes through :meth:`Manoeuvres.send_setpoint`, which refuses one outside the
arena (:mod:`gcs.flight.fence`); every move and hold checks the vehicle's control at each step
(:meth:`gcs.flight.watches.Watches.control_problem`). Landing and the emergency stop are in
:mod:`gcs.flight.landing`.

:class:`Manoeuvres` is one part of :class:`gcs.flight.vehicle.Vehicle`: it commands through the
connection, reads its state mirror, waits through the watches, and owns the setpoint stream (the
last target, whether offboard was started, whether streaming was stopped for good).
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Awaitable
from typing import Any, TypeVar

import numpy as np
from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState

from gcs.errors import VehicleError
from gcs.flight.backend import CommandRefused
from gcs.flight.clock import WALL_CLOCK, Clock
from gcs.flight.fence import Fence, format_ned
from gcs.flight.hover import SPEED_SPAN_S, is_settled
from gcs.flight.link import Link, TelemetrySample, sample_arrays
from gcs.flight.watches import WaitTimeout, Watches
from gcs.io.settings import FlightSettings

__all__ = ["Manoeuvres", "heading_deg", "min_jerk", "sleep_until"]

_log = logging.getLogger(__name__)
_T = TypeVar("_T")


async def sleep_until(deadline_s: float, clock: Clock = WALL_CLOCK) -> None:
    """Sleep until an absolute deadline on ``clock``; yield once if it has passed.

    Parameters
    ----------
    deadline_s : float
        Absolute time on ``clock`` [s].
    clock : Clock
        The local clock (the wall clock, ``time.monotonic()``, by default).
    """
    await clock.sleep(deadline_s - clock.now())


def min_jerk(s: float) -> float:
    """Minimum-jerk progress ``10 s^3 - 15 s^4 + 6 s^5`` of a rest-to-rest move.

    Parameters
    ----------
    s : float
        Normalised time in [0, 1] (clipped).

    Returns
    -------
    float
        Normalised distance in [0, 1]; peak slope 1.875 at ``s = 0.5``.
    """
    s = min(max(s, 0.0), 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s * s)


def heading_deg(yaw_deg: float) -> float:
    """A yaw as the heading sent to the vehicle: wrapped to [-180, 180) [deg].

    An unwrapped yaw (a trajectory that turns past 180 degrees goes on counting) is sent as
    the same heading; a yaw already in range is sent exactly as given.

    Parameters
    ----------
    yaw_deg : float
        Yaw [deg, clockwise from north], any value.

    Returns
    -------
    float
    """
    yaw = float(yaw_deg)
    return yaw if -180.0 <= yaw < 180.0 else (yaw + 180.0) % 360.0 - 180.0


class Manoeuvres:
    """The flying verbs of :class:`gcs.flight.vehicle.Vehicle`.

    Parameters
    ----------
    mirror : Link
        The connection and its state mirror.
    watches : Watches
        The safety watches whose waits the manoeuvres wait in.
    settings : FlightSettings
        Rates, timeouts and tolerances.
    fence : Fence or None
        The arena every setpoint must lie in; None: no setpoint is sent.
    """

    def __init__(
        self, mirror: Link, watches: Watches, settings: FlightSettings, fence: Fence | None
    ) -> None:
        self._mirror = mirror
        self._watches = watches
        self.settings = settings
        self.fence = fence
        self.target_ned_m: np.ndarray | None = None  # the last setpoint sent
        self.streaming_stopped = False  # by an emergency stop, for good
        self.offboard_started = False  # PX4 follows our setpoints (a stop switches it to Hold)

    def stop_streaming(self) -> None:
        """Stop streaming for good: :meth:`send_setpoint` refuses every setpoint from now on."""
        self.streaming_stopped = True

    async def wait_healthy_local_position(self, timeout_s: float | None = None) -> None:
        """Wait until PX4 reports a valid local position and samples are arriving.

        Parameters
        ----------
        timeout_s : float, optional
            Limit [s]; ``settings.health_timeout_s`` if omitted.

        Raises
        ------
        VehicleError
            No valid local position within the timeout, or the link was lost.
        """
        timeout_s = self.settings.health_timeout_s if timeout_s is None else timeout_s
        await self._watches.wait_until(
            lambda: (
                self._mirror.local_position_ok
                and self._mirror.telemetry_age_s() <= self.settings.max_telemetry_age_s
            ),
            timeout_s,
            "a valid local position estimate",
            in_control=False,
        )

    async def arm_and_takeoff(self, altitude_m: float) -> None:
        """Arm and take off (PX4 Takeoff mode) to ``altitude_m`` above the local origin.

        The altitude is requested through ``MIS_TAKEOFF_ALT``; if the vehicle refuses that
        parameter the take-off goes to the vehicle's default and the move to the start point
        corrects the altitude. Take-off counts as done when the altitude is within the settle
        tolerance, or when PX4 reports it is airborne in Hold (its state after Takeoff).

        Parameters
        ----------
        altitude_m : float
            Height above the local NED origin, positive up [m].

        Raises
        ------
        VehicleError
            Arming or take-off refused or not finished within ``settings.takeoff_timeout_s``.
        """
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise VehicleError(f"take-off altitude must be positive, got {altitude_m} m")
        if self.fence is not None:
            (down_lo, down_hi) = self.fence.arena_ned_m[2]
            if not down_lo <= -altitude_m <= down_hi:
                raise VehicleError(
                    f"fence: take-off altitude {altitude_m:g} m is outside the arena "
                    f"{self.fence.arena_text()}; not taking off"
                )
            self._watches.require_inside("arming")
        link = self._mirror.link
        try:
            await self._mirror.command(
                "set take-off altitude", lambda: link.set_takeoff_altitude(float(altitude_m))
            )
        except VehicleError as exc:
            _log.warning("%s; taking off to the vehicle's default altitude", exc)
        self._mirror.arm_requested = True  # the fence watches from the arm command on
        try:
            await self._mirror.command("arm", link.arm)
            await self._watches.wait_until(
                lambda: self._mirror.armed,
                self.settings.command_timeout_s,
                "armed state",
                in_control=False,
            )
        except BaseException:
            self._mirror.arm_requested = self._mirror.armed
            raise
        await self._mirror.command("take-off", link.takeoff)
        tolerance_m = self.settings.settle_tolerance_m
        seen_takeoff_mode = [False]

        def airborne() -> bool:
            if self._mirror.latest is None:
                return False
            seen_takeoff_mode[0] |= self._mirror.flight_mode == FlightMode.TAKEOFF
            height_m = -self._mirror.latest.pos_ned_m[2]
            done_in_hold = (
                seen_takeoff_mode[0]
                and self._mirror.flight_mode == FlightMode.HOLD
                and self._mirror.landed_state == LandedState.IN_AIR
            )
            return height_m >= altitude_m - tolerance_m or done_in_hold

        await self._watches.wait_until(
            airborne,
            self.settings.takeoff_timeout_s,
            f"take-off to {altitude_m:g} m",
            in_control=False,
        )

    async def send_setpoint(self, pos_ned_m: Any, yaw_deg: float | None = None) -> None:
        """Send one position setpoint (MAVSDK re-sends the last one at 20 Hz by itself).

        Parameters
        ----------
        pos_ned_m : array_like, shape (3,)
            Absolute local NED position [m].
        yaw_deg : float or None
            Heading [deg, clockwise from north], sent wrapped to [-180, 180); None: the
            profile's ``flight.yaw_deg`` (the heading held outside a trial's yaw reference).

        Raises
        ------
        VehicleError
            The setpoint lies outside the arena (or the vehicle has no fence), after
            :meth:`emergency_stop` (streaming is over for good), or MAVSDK refused it.
        """
        if self.streaming_stopped:
            raise VehicleError("setpoint streaming was stopped by an emergency stop")
        if self.fence is None:
            raise VehicleError("no arena fence: gcs sends setpoints only inside an arena")
        problem = self.fence.setpoint_problem(pos_ned_m)
        if problem is not None:
            raise VehicleError(f"fence: {problem}; not sent")
        link = self._mirror.link
        n, e, d = (float(x) for x in pos_ned_m)
        yaw = heading_deg(self.settings.yaw_deg if yaw_deg is None else yaw_deg)
        try:
            await link.set_position_ned(n, e, d, yaw)
        except CommandRefused as exc:
            raise VehicleError(f"setpoint refused: {exc.result}") from None
        self.target_ned_m = np.array([n, e, d])

    async def leave_offboard_on_ground(self) -> bool:
        """Switch a disarmed vehicle that is in OFFBOARD mode to Hold, so that it can arm.

        On a disarm PX4 (v1.14 on) returns to the last mode it was put in that allows arming
        (``UserModeIntention::onDisarm``), not to the mode it landed in: after a flight of
        offboard, land, disarm that is OFFBOARD, whose arming check then fails ("No offboard
        signal") until setpoints stream. A second command on the same vehicle (``gcs fly`` after
        ``gcs identify``, a ``--resume``) would wait for the pre-arm checks in vain.

        Returns
        -------
        bool
            Whether the mode was switched (False: armed, or in another mode).

        Raises
        ------
        VehicleError
            Hold refused or not reported within ``settings.command_timeout_s``.
        """
        mirror = self._mirror
        if mirror.armed or mirror.flight_mode != FlightMode.OFFBOARD:
            return False
        await mirror.command("Hold", mirror.link.stop_offboard)
        await self._watches.wait_until(
            lambda: mirror.flight_mode == FlightMode.HOLD,
            self.settings.command_timeout_s,
            "Hold mode",
            in_control=False,
        )
        return True

    async def start_offboard_at_current_position(self, preroll_s: float = 1.0) -> None:
        """Stream the current position as setpoint, switch to OFFBOARD and wait for it.

        PX4 wants setpoints flowing before the switch (about 1 s); the last one is sent
        immediately before ``offboard.start()`` (MAVSDK stops its re-send 3 s after the first
        setpoint if the vehicle is not in OFFBOARD by then). The hover setpoint is the point of
        the arena nearest to the measured position (the same point inside it); a position
        beyond the fence's margin is refused.

        Parameters
        ----------
        preroll_s : float
            How long to stream the hover setpoint before switching [s]; must stay below 3 s.

        Raises
        ------
        VehicleError
            No fresh position, offboard refused, or OFFBOARD not reported in time.
        """
        if (
            self._mirror.latest is None
            or self._mirror.telemetry_age_s() > self.settings.max_telemetry_age_s
        ):
            raise VehicleError("cannot start offboard: no fresh position telemetry")
        self._watches.require_inside("starting offboard")
        hover_ned_m = self._hover_point(np.array(self._mirror.latest.pos_ned_m))
        period_s = 1.0 / self.settings.stream_rate_hz
        clock = self._mirror.local_clock
        t0 = clock.now()
        for i in range(max(1, math.ceil(preroll_s / period_s))):
            await sleep_until(t0 + i * period_s, clock)
            breach = self._watches.safety_problem()
            if breach is not None:
                raise VehicleError(f"{breach} while starting offboard")
            await self.send_setpoint(hover_ned_m)
        link = self._mirror.link
        await self.send_setpoint(hover_ned_m)
        await self._mirror.command("start offboard", link.start_offboard)
        self.offboard_started = True
        await self._watches.wait_until(
            lambda: self._mirror.flight_mode == FlightMode.OFFBOARD,
            self.settings.command_timeout_s,
            "OFFBOARD mode",
            in_control=False,
        )

    async def goto(self, ned_m: Any, speed_m_s: float) -> None:
        """Move in a straight line to ``ned_m`` (no waiting there: see :meth:`settle`).

        The move starts at the current target (else the measured position), follows a
        minimum-jerk profile whose peak speed is ``speed_m_s`` and is streamed at
        ``settings.stream_rate_hz`` against absolute deadlines (wall clock: a transit is not
        learned from).

        Parameters
        ----------
        ned_m : array_like, shape (3,)
            Target in local NED [m].
        speed_m_s : float
            Peak speed of the move [m/s].

        Raises
        ------
        VehicleError
            Lost control during the move (see :meth:`control_problem`).
        """
        target = np.asarray(ned_m, dtype=float).reshape(3)
        if self.fence is not None and (problem := self.fence.setpoint_problem(target)):
            raise VehicleError(f"fence: cannot move to {format_ned(target)}: {problem}")
        self._watches.require_inside(f"moving to {format_ned(target)}")
        if self.target_ned_m is not None:
            start = self.target_ned_m.copy()
        elif self._mirror.latest is not None:
            start = self._hover_point(np.array(self._mirror.latest.pos_ned_m))
        else:
            raise VehicleError("cannot move: no position telemetry yet")
        distance_m = float(np.linalg.norm(target - start))
        rate_hz = self.settings.stream_rate_hz
        duration_s = 1.875 * distance_m / speed_m_s
        n_ticks = max(1, math.ceil(duration_s * rate_hz))
        clock = self._mirror.local_clock
        t0 = clock.now()
        for i in range(1, n_ticks + 1):
            await sleep_until(t0 + i / rate_hz, clock)
            problem = self._watches.control_problem()
            if problem is not None:
                raise VehicleError(f"{problem} while moving to {format_ned(target)}")
            await self.send_setpoint(start + min_jerk(i / n_ticks) * (target - start))

    async def settle(self, ned_m: Any, tolerance_m: float, speed_tolerance_m_s: float) -> bool:
        """Hover at ``ned_m`` until settled: distance and speed within tolerance for a while.

        Settled means :func:`gcs.flight.hover.is_settled` over ``settings.settle_time_s`` of
        vehicle time: every sample within ``tolerance_m`` of the point and every speed (over
        1 s) within ``speed_tolerance_m_s``.

        Parameters
        ----------
        ned_m : array_like, shape (3,)
            Hover point in local NED [m].
        tolerance_m : float
            Largest distance from the point [m].
        speed_tolerance_m_s : float
            Largest speed [m/s].

        Returns
        -------
        bool
            True once settled; False when ``settings.settle_timeout_s`` ran out first (the
            caller judges that hover: a loose hover is no error by itself).

        Raises
        ------
        VehicleError
            Lost control meanwhile.
        """
        target = np.asarray(ned_m, dtype=float).reshape(3)
        s = self.settings
        # samples enough for the window and its speed span at up to twice the requested rate
        keep = math.ceil((s.settle_time_s + SPEED_SPAN_S) * 2 * s.telemetry_rate_hz) + 2
        with self._mirror.record_telemetry() as samples:

            def settled() -> bool:
                t, pos = sample_arrays(samples[-keep:])
                return is_settled(t, pos, target, tolerance_m, speed_tolerance_m_s, s.settle_time_s)

            try:
                await self._watches.wait_until(
                    settled,
                    s.settle_timeout_s,
                    f"settling at {format_ned(target)}",
                    in_control=True,
                )
            except WaitTimeout:
                return False
        return True

    async def hold(self, duration_s: float, what: str) -> list[TelemetrySample]:
        """Hover at the current target for ``duration_s`` of vehicle time, watching it.

        Parameters
        ----------
        duration_s : float
            How long, on the vehicle's clock [s] (a simulator slower than real time takes
            longer in wall time).
        what : str
            Name of the hold for error messages.

        Returns
        -------
        list of TelemetrySample
            The samples received during the hold.

        Raises
        ------
        VehicleError
            Control was lost (see :meth:`control_problem`) before the hold ended.
        """
        await self.hold_position()
        fit = self._mirror.clock_fit()
        with self._mirror.record_telemetry() as samples:
            # until a sample stamped duration_s after the vehicle's "now" (not its last sample)
            end_s = float(fit.to_vehicle(self._mirror.local_clock.now())) + duration_s
            # twice the expected wall time: a simulator may slow down meanwhile (silence is the
            # watchdog's to catch, not the timeout's)
            await self._watches.wait_until(
                lambda: self._mirror.clock.latest_s >= end_s,
                2 * duration_s / fit.rate + 2 * self.settings.max_telemetry_age_s,
                what,
                in_control=True,
            )
            return list(samples)

    async def hold_position(self) -> np.ndarray:
        """Hover at the current target: re-send it so MAVSDK keeps re-sending it at 20 Hz.

        Returns
        -------
        ndarray, shape (3,)
            The hover point in local NED [m] (the last target, else the measured position).
        """
        if self.target_ned_m is not None:
            hover = self.target_ned_m.copy()
        elif self._mirror.latest is not None:
            hover = self._hover_point(np.array(self._mirror.latest.pos_ned_m))
        else:
            raise VehicleError("cannot hold: no position telemetry yet")
        await self.send_setpoint(hover)
        return hover

    def _hover_point(self, pos_ned_m: np.ndarray) -> np.ndarray:
        """A hover setpoint at a measured position: its nearest point of the arena."""
        return pos_ned_m if self.fence is None else self.fence.clamp(pos_ned_m)

    async def hover_while(self, work: Awaitable[_T], what: str) -> _T:
        """Hover while ``work`` (e.g. ``asyncio.to_thread(...)``) runs, watching the vehicle.

        Parameters
        ----------
        work : awaitable
            The work to await; it is not cancelled if the vehicle fails (a thread cannot be).
        what : str
            Name of the work for error messages.

        Returns
        -------
        object
            The result of ``work``.

        Raises
        ------
        VehicleError
            Control was lost (see :meth:`control_problem`) before ``work`` finished.
        """
        await self.hold_position()
        task = asyncio.ensure_future(work)
        while True:
            # woken by every state change (each position sample), at the latest at half the
            # telemetry-age limit so that silence is noticed
            changed = asyncio.ensure_future(self._mirror.next_change())
            try:
                await asyncio.wait(
                    {task, changed},
                    timeout=self.settings.max_telemetry_age_s / 2,
                    return_when=asyncio.FIRST_COMPLETED,
                )
            finally:
                changed.cancel()
            if task.done():
                return task.result()
            problem = self._watches.control_problem()
            if problem is not None:
                raise VehicleError(f"{problem} while hovering for {what}")
