"""The link to a vehicle over MAVSDK: :class:`gcs.flight.backend.VehicleLink` on the wire.

:class:`MavsdkLink` owns the ``Mavsdk`` instance and its Action, Offboard, Telemetry and
MavlinkDirect plugins (Param, Geofence and Events are opened per use). MAVSDK's errors become
:class:`gcs.flight.backend.CommandRefused`; the C++ core's log goes to Python logging.

Position samples: MAVSDK's ``position_velocity_ned`` has no time stamp, so LOCAL_POSITION_NED
is read raw through MavlinkDirect (its ``time_boot_ms``).

**No MAVSDK object is destroyed under a call of its own.** MAVSDK's asyncio commands run its
blocking call in an executor thread; a timeout or a cancellation ends the await, not the call,
which returns when MAVSDK's own timeout ends it (a command without an answer: about 1.5 s).
Destroying the plugin or the ``Mavsdk`` instance meanwhile leaves that thread blocked for
good, and with it ``asyncio.run``'s exit (it joins the executor's threads) and the
interpreter's: gcs would hang after landing. So every call runs as a task the link keeps until
the thread returns (:meth:`MavsdkLink._call`), a plugin opened for one call is destroyed when
that call has returned, and :meth:`MavsdkLink.close` waits for the calls still running before
destroying anything (at most :data:`CALLS_SETTLE_S`; a call still running then keeps its
objects alive instead).
"""

from __future__ import annotations

import asyncio
import json
import logging
import threading
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any, TypeVar

from mavsdk import LogLevel, log_subscribe
from mavsdk.asyncio import (
    ComponentType,
    Configuration,
    Mavsdk,
    MavsdkConnectionError,
    MavsdkError,
    System,
)
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync, MavlinkMessage
from mavsdk.asyncio.plugins.offboard import OffboardAsync, PositionNedYaw
from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState, TelemetryAsync

from gcs.flight.backend import CommandRefused, LinkUnreachable, PositionReport, VehicleLink
from gcs.flight.clock import WALL_CLOCK, Clock
from gcs.io.scheduling import (
    Previous,
    freeze_heap,
    raise_python_threads,
    raise_thread,
    restore_python_threads,
    restore_thread,
    thaw_heap,
)

__all__ = ["MavsdkLink"]

_mavsdk_log = logging.getLogger("gcs.flight.mavsdk")
_T = TypeVar("_T")

_LOG_LEVELS = {
    LogLevel.DEBUG: logging.DEBUG,
    LogLevel.INFO: logging.INFO,
    LogLevel.WARN: logging.WARNING,
    LogLevel.ERROR: logging.ERROR,
}


#: MAVSDK's warnings that say nothing about the flight, logged at DEBUG instead: MAVSDK asks
#: every autopilot for its COMPONENT_METADATA, and when the request fails (the mock and many
#: vehicles do not serve it) its callback gets an empty message, compid 0, and MAVSDK warns.
_HARMLESS = frozenset({"Unexpected component ID 0"})

#: how long :meth:`MavsdkLink.close` waits for MAVSDK calls still running in executor threads
#: (a timed-out or cancelled call: MAVSDK ends a command without an answer in about 1.5 s, a
#: parameter list in about 12 s) [s]
CALLS_SETTLE_S = 15.0

#: the MAVSDK objects of calls that outlived :data:`CALLS_SETTLE_S`: kept, never destroyed
_KEPT_ALIVE: list[object] = []


def route_mavsdk_log(level: LogLevel, message: str, file: str | None, line: int) -> bool:
    """Send a line of the C++ core's log to Python logging instead of coloured stderr."""
    logged = logging.DEBUG if message.strip() in _HARMLESS else _LOG_LEVELS.get(level, logging.INFO)
    _mavsdk_log.log(logged, "%s", message)
    return True


async def _refused_as_command(call: Callable[[], Awaitable[_T]]) -> _T:
    """Run one MAVSDK call; its error becomes CommandRefused naming the result."""
    try:
        return await call()
    except MavsdkError as exc:
        result = getattr(exc, "result", None)
        raise CommandRefused(getattr(result, "name", None) or str(exc)) from None


def _consume(task: asyncio.Task[Any]) -> None:
    """Read a finished call's outcome, so that one nobody awaits any more is not reported."""
    if not task.cancelled():
        task.exception()


class MavsdkLink(VehicleLink):
    """A :class:`gcs.flight.backend.VehicleLink` over MAVSDK (real PX4, SITL, the mock)."""

    clock: Clock = WALL_CLOCK

    def __init__(self) -> None:
        self._mavsdk: Mavsdk | None = None
        self._system: System | None = None
        self._action: ActionAsync | None = None
        self._offboard: OffboardAsync | None = None
        self._telemetry: TelemetryAsync | None = None
        self._direct: MavlinkDirectAsync | None = None
        self._raised: tuple[int, Previous | None] | None = None
        self._raised_others: dict[int, Previous] = {}
        self._running: set[asyncio.Task[Any]] = set()

    async def _call(
        self, call: Callable[[], Awaitable[_T]], then: Callable[[], None] | None = None
    ) -> _T:
        """Run one MAVSDK call as a task the link keeps until its thread has returned.

        Parameters
        ----------
        call : callable
            Makes the call's awaitable (a MAVSDK asyncio plugin method).
        then : callable, optional
            Run when the call has returned, even if its caller stopped waiting (the
            destroy of a plugin opened for this call); never while it may still run.

        Returns
        -------
        object
            What the call returned.

        Raises
        ------
        CommandRefused
            MAVSDK's error, naming its result.
        """

        async def run() -> _T:
            try:
                result = await _refused_as_command(call)
            except asyncio.CancelledError:
                # the loop is closing while the call may still run in its thread: destroying
                # its objects now would block that thread, so they are kept instead
                if then is not None:
                    _KEPT_ALIVE.append(then)
                raise
            except BaseException:
                if then is not None:  # the call returned, with an error
                    then()
                raise
            if then is not None:
                then()
            return result

        task = asyncio.ensure_future(run())
        self._running.add(task)
        task.add_done_callback(self._running.discard)
        task.add_done_callback(_consume)
        return await asyncio.shield(task)

    async def connect(self, url: str, timeout_s: float) -> bool:
        self._enter_flight()
        try:
            connected = await self._connect(url, timeout_s)
        except BaseException:
            self._leave_flight()
            raise
        if not connected:
            self._leave_flight()
        return connected

    async def _connect(self, url: str, timeout_s: float) -> bool:
        log_subscribe(route_mavsdk_log)
        config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        self._mavsdk = Mavsdk(config)
        try:
            await self._mavsdk.add_any_connection(url)
            system = await self._mavsdk.first_autopilot(timeout_s)
        except MavsdkConnectionError as exc:
            raise LinkUnreachable(str(exc)) from None
        if system is None:
            return False
        self._system = system
        self._action = ActionAsync(system)
        self._offboard = OffboardAsync(system)
        self._telemetry = TelemetryAsync(system)
        self._direct = MavlinkDirectAsync(system)
        return True

    async def close(self) -> None:
        # the plugins and Mavsdk are destroyed; MavlinkDirect and the System are only dropped
        owned = [self._action, self._offboard, self._telemetry, self._mavsdk]
        kept = [self._direct, self._system]
        if self._running:
            _, still = await asyncio.wait(set(self._running), timeout=CALLS_SETTLE_S)
            if still:  # destroying them now would block this process's exit for good
                _mavsdk_log.warning(
                    "%d MAVSDK call(s) still running after %g s: the link is left open",
                    len(still), CALLS_SETTLE_S,
                )  # fmt: skip
                _KEPT_ALIVE.extend([*owned, *kept, *still])
                owned = []
        for obj in owned:
            if obj is not None:
                obj.destroy()
        self._action = self._offboard = self._telemetry = self._direct = None
        self._mavsdk = None
        self._system = None
        self._leave_flight()

    def _enter_flight(self) -> None:
        """The flight loop, and what MAVSDK starts for it, keep their streams at rate on a busy
        machine: a real-time policy where allowed, the heap frozen (gcs.io.scheduling). The
        process's other Python threads (the learning worker's pool) are raised too: any of them
        may hold the GIL the streams wait for."""
        if self._raised is None:
            self._raised = (threading.get_ident(), raise_thread())
            self._raised_others = raise_python_threads()
            freeze_heap()

    def _leave_flight(self) -> None:
        """Give back what :meth:`_enter_flight` took (in the thread that took it)."""
        if self._raised is not None and self._raised[0] == threading.get_ident():
            restore_thread(self._raised[1])
            restore_python_threads(self._raised_others)
            self._raised, self._raised_others = None, {}
            thaw_heap()

    @property
    def system(self) -> System:
        """The connected MAVSDK system."""
        return _need(self._system)

    async def is_connected(self) -> bool:
        return bool(await self._call(self.system.is_connected))

    # -- streams
    async def positions(self) -> AsyncIterator[PositionReport]:
        async for message in _need(self._direct).subscribe_message("LOCAL_POSITION_NED"):
            f = json.loads(message.fields_json)
            yield PositionReport(
                f["time_boot_ms"] / 1000.0,
                (float(f["x"]), float(f["y"]), float(f["z"])),
                (float(f["vx"]), float(f["vy"]), float(f["vz"])),
            )

    async def connection_states(self) -> AsyncIterator[bool]:
        async for connected in self.system.is_connected_state():
            yield bool(connected)

    async def flight_modes(self) -> AsyncIterator[FlightMode]:
        async for mode in _need(self._telemetry).subscribe_flight_mode():
            yield mode

    async def armed_states(self) -> AsyncIterator[bool]:
        async for armed in _need(self._telemetry).subscribe_armed():
            yield bool(armed)

    async def landed_states(self) -> AsyncIterator[LandedState]:
        async for state in _need(self._telemetry).subscribe_landed_state():
            yield state

    async def local_position_health(self) -> AsyncIterator[bool]:
        async for health in _need(self._telemetry).subscribe_health():
            yield bool(health.is_local_position_ok)

    async def armable_states(self) -> AsyncIterator[bool]:
        telemetry = TelemetryAsync(self.system)
        try:
            async for health in telemetry.subscribe_health():
                yield bool(health.is_armable)
        finally:
            telemetry.destroy()

    async def arming_problems(self) -> AsyncIterator[list[str]]:
        from mavsdk.asyncio.plugins.events import EventsAsync

        events = EventsAsync(self.system)
        try:
            async for report in events.subscribe_health_and_arming_checks():
                yield [p.message for p in report.current_mode_intention.problems]
        finally:
            events.destroy()

    async def status_texts(self) -> AsyncIterator[str]:
        telemetry = TelemetryAsync(self.system)
        try:
            async for status in telemetry.subscribe_status_text():
                yield status.text
        finally:
            telemetry.destroy()

    async def battery_levels(self) -> AsyncIterator[float]:
        async for battery in _need(self._telemetry).subscribe_battery():
            yield float(battery.remaining_percent)

    # -- commands
    async def set_position_rate(self, rate_hz: float) -> None:
        telemetry = _need(self._telemetry)
        await self._call(lambda: telemetry.set_rate_position_velocity_ned(rate_hz))

    async def set_landed_state_rate(self, rate_hz: float) -> None:
        telemetry = _need(self._telemetry)
        await self._call(lambda: telemetry.set_rate_landed_state(rate_hz))

    async def set_takeoff_altitude(self, altitude_m: float) -> None:
        action = _need(self._action)
        await self._call(lambda: action.set_takeoff_altitude(float(altitude_m)))

    async def arm(self) -> None:
        await self._call(_need(self._action).arm)

    async def disarm(self) -> None:
        await self._call(_need(self._action).disarm)

    async def takeoff(self) -> None:
        await self._call(_need(self._action).takeoff)

    async def land(self) -> None:
        await self._call(_need(self._action).land)

    async def start_offboard(self) -> None:
        await self._call(_need(self._offboard).start)

    async def stop_offboard(self) -> None:
        await self._call(_need(self._offboard).stop)

    async def set_position_ned(
        self, north_m: float, east_m: float, down_m: float, yaw_deg: float
    ) -> None:
        offboard = _need(self._offboard)
        setpoint = PositionNedYaw(north_m, east_m, down_m, yaw_deg)
        await self._call(lambda: offboard.set_position_ned(setpoint))

    # -- parameters, origin, geofence
    async def _with_param(self, use: Callable[[Any], Awaitable[_T]]) -> _T:
        from mavsdk.asyncio.plugins.param import ParamAsync

        param = ParamAsync(self.system)
        return await self._call(lambda: use(param), then=param.destroy)

    async def get_param_int(self, name: str) -> int:
        return int(await self._with_param(lambda p: p.get_param_int(name)))

    async def get_param_float(self, name: str) -> float:
        return float(await self._with_param(lambda p: p.get_param_float(name)))

    async def set_param_int(self, name: str, value: int) -> None:
        await self._with_param(lambda p: p.set_param_int(name, int(value)))

    async def set_param_float(self, name: str, value: float) -> None:
        await self._with_param(lambda p: p.set_param_float(name, float(value)))

    async def get_all_params(self) -> dict[str, float]:
        found = await self._with_param(lambda p: p.get_all_params())
        values = {p.name: float(p.value) for p in found.int_params}
        return values | {p.name: float(p.value) for p in found.float_params}

    async def get_gps_global_origin(self) -> tuple[float, float, float]:
        origin = await self._call(_need(self._telemetry).get_gps_global_origin)
        return (origin.latitude_deg, origin.longitude_deg, origin.altitude_m)

    async def set_gps_global_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        direct = _need(self._direct)
        target = await self._call(self.system.get_system_id)
        fields = {
            "target_system": target,
            "latitude": round(lat_deg * 1e7),
            "longitude": round(lon_deg * 1e7),
            "altitude": round(alt_m * 1e3),
            "time_usec": 0,
        }
        message = MavlinkMessage("SET_GPS_GLOBAL_ORIGIN", 0, 0, target, 0, json.dumps(fields))
        await self._call(lambda: direct.send_message(message))

    async def upload_inclusion_polygon(self, vertices_deg: list[tuple[float, float]]) -> None:
        from mavsdk.asyncio.plugins.geofence import (
            FenceType,
            GeofenceAsync,
            GeofenceData,
            Point,
            Polygon,
        )

        fence = GeofenceAsync(self.system)
        points = [Point(lat, lon) for lat, lon in vertices_deg]
        data = GeofenceData([Polygon(points, FenceType.INCLUSION)], [])
        await self._call(lambda: fence.upload_geofence(data), then=fence.destroy)

    def mocap_plugin(self) -> Any:
        from mavsdk.plugins.mocap import Mocap

        return Mocap(self.system._system)


def _need(plugin: _T | None) -> _T:
    if plugin is None:
        raise CommandRefused("not connected")
    return plugin
