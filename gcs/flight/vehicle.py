"""One MAVSDK connection to a PX4 multirotor, flown by position setpoints in local NED.

:class:`Vehicle` owns the ``Mavsdk`` instance, the Action/Offboard/Telemetry plugins and a few
background tasks that mirror the vehicle's state (position and velocity, flight mode, armed,
landed state, link). Every wait is an event wait on that mirror with a timeout, never a fixed
sleep; every command is guarded by a timeout so that a dead link cannot hang the caller. MAVSDK
errors become one-line :class:`gcs.errors.VehicleError`.

Position samples carry two times: the receipt time on ``time.monotonic()`` and the vehicle's own
time stamp. MAVSDK's ``position_velocity_ned`` has no time stamp, so LOCAL_POSITION_NED is read
raw through MAVSDK's MavlinkDirect plugin (its ``time_boot_ms``); :attr:`Vehicle.clock` makes
that a continuous vehicle time and fits it to the local clock (:mod:`gcs.flight.clock`).

The fence (:mod:`gcs.flight.fence`). :meth:`Vehicle.send_setpoint` is the one place every
setpoint goes through, and it refuses one outside the arena. From the arm command to the
disarmed state every position sample goes through an :class:`gcs.flight.fence.EstimateMonitor`;
what it names, and what any other watch reports (:meth:`Vehicle.trip`, :meth:`Vehicle.add_watch`:
a motion-capture stream's health, say), is a *breach*: every wait, move, hold and trial of the
flight layer raises it at once as a :class:`gcs.errors.VehicleError` (or ``TrialAborted``), and the
campaign stops the vehicle (:meth:`Vehicle.emergency_stop`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from collections.abc import Awaitable, Callable, Iterator
from typing import Any, NamedTuple, TypeVar

import numpy as np
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
from mavsdk.asyncio.plugins.geofence import (
    FenceType,
    GeofenceAsync,
    GeofenceData,
    Point,
    Polygon,
)
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync, MavlinkMessage
from mavsdk.asyncio.plugins.offboard import OffboardAsync, PositionNedYaw
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState, TelemetryAsync

from gcs.errors import VehicleError
from gcs.flight.clock import ClockFit, VehicleClock
from gcs.flight.fence import EstimateMonitor, Fence
from gcs.flight.hover import SPEED_SPAN_S, is_settled
from gcs.io.settings import FlightSettings

__all__ = ["TelemetrySample", "Vehicle", "sample_arrays", "sleep_until", "min_jerk"]

_log = logging.getLogger(__name__)
_mavsdk_log = logging.getLogger("gcs.flight.mavsdk")
_T = TypeVar("_T")

_LOG_LEVELS = {
    LogLevel.DEBUG: logging.DEBUG,
    LogLevel.INFO: logging.INFO,
    LogLevel.WARN: logging.WARNING,
    LogLevel.ERROR: logging.ERROR,
}


def _route_mavsdk_log(level: LogLevel, message: str, file: str | None, line: int) -> bool:
    """Send a line of the C++ core's log to Python logging instead of coloured stderr."""
    _mavsdk_log.log(_LOG_LEVELS.get(level, logging.INFO), "%s", message)
    return True


class TelemetrySample(NamedTuple):
    """One LOCAL_POSITION_NED sample as received.

    Parameters
    ----------
    t_s : float
        Receipt time on ``time.monotonic()`` [s] (the asyncio loop clock).
    pos_ned_m : tuple of 3 float
        Position in local NED [m].
    vel_ned_m_s : tuple of 3 float
        Velocity in local NED [m/s].
    t_vehicle_s : float
        The vehicle's time stamp as a continuous vehicle time [s] (see
        :class:`gcs.flight.clock.VehicleClock`).
    """

    t_s: float
    pos_ned_m: tuple[float, float, float]
    vel_ned_m_s: tuple[float, float, float]
    t_vehicle_s: float


def sample_arrays(samples: list[TelemetrySample]) -> tuple[np.ndarray, np.ndarray]:
    """Vehicle times and positions of samples, sorted by vehicle time.

    Parameters
    ----------
    samples : list of TelemetrySample
        Samples in receipt order.

    Returns
    -------
    t_vehicle_s : ndarray, shape (M,)
        Continuous vehicle times [s], non-decreasing.
    pos_ned_m : ndarray, shape (M, 3)
        Positions, local NED [m].
    """
    t = np.array([s.t_vehicle_s for s in samples], dtype=float)
    pos = np.array([s.pos_ned_m for s in samples], dtype=float).reshape(-1, 3)
    order = np.argsort(t, kind="stable")  # a reordered datagram keeps its own time
    return t[order], pos[order]


async def sleep_until(deadline_s: float) -> None:
    """Sleep until an absolute deadline on ``time.monotonic()``; yield once if it has passed.

    Parameters
    ----------
    deadline_s : float
        Absolute time on ``time.monotonic()`` [s].
    """
    delay_s = deadline_s - time.monotonic()
    await asyncio.sleep(delay_s if delay_s > 0 else 0)


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


class Vehicle:
    """A PX4 multirotor behind one MAVSDK connection.

    Parameters
    ----------
    settings : FlightSettings
        Rates, timeouts and limits.
    fence : Fence or None
        The arena and the limits watched while armed; without one the vehicle can be
        listened to but sends no setpoint.
    """

    def __init__(self, settings: FlightSettings, fence: Fence | None = None) -> None:
        self.settings = settings
        self.fence = fence
        self.breach: str | None = None  # the first breach seen; ends the flight
        self._monitor = EstimateMonitor(fence) if fence is not None else None
        self._watches: list[tuple[str, Callable[[], str | None]]] = []
        self._arm_requested = False
        self.latest: TelemetrySample | None = None
        self.flight_mode: FlightMode = FlightMode.UNKNOWN
        self.armed: bool = False
        self.landed_state: LandedState = LandedState.UNKNOWN
        self.connected: bool = False
        self.local_position_ok: bool = False
        self.battery_pct: float = math.nan  # remaining charge [%]; NaN until reported
        self.target_ned_m: np.ndarray | None = None
        self.clock = VehicleClock(window_s=10.0)
        self._streaming_stopped = False
        self._offboard_started = False
        self._recorders: list[list[TelemetrySample]] = []
        self._changed = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._mavsdk: Mavsdk | None = None
        self._system: System | None = None
        self._action: ActionAsync | None = None
        self._offboard: OffboardAsync | None = None
        self._telemetry: TelemetryAsync | None = None
        self._direct: MavlinkDirectAsync | None = None
        self.url: str | None = None

    # ------------------------------------------------------------------ connection

    async def connect(self, url: str, timeout_s: float | None = None) -> None:
        """Open ``url``, wait for the autopilot and start mirroring its state.

        Parameters
        ----------
        url : str
            MAVSDK connection URL, e.g. ``udpout://127.0.0.1:14540`` or ``udpin://0.0.0.0:14540``.
        timeout_s : float, optional
            How long to wait for an autopilot [s]; ``settings.connect_timeout_s`` if omitted.

        Raises
        ------
        VehicleError
            Invalid URL, no autopilot within the timeout, or the telemetry rate was refused.
        """
        timeout_s = self.settings.connect_timeout_s if timeout_s is None else timeout_s
        log_subscribe(_route_mavsdk_log)
        self.url = url
        config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        self._mavsdk = Mavsdk(config)
        try:
            await self._mavsdk.add_any_connection(url)
            system = await self._mavsdk.first_autopilot(timeout_s)
        except MavsdkConnectionError as exc:
            await self.close()
            raise VehicleError(f"cannot open connection {url!r}: {exc}") from None
        except BaseException:
            await self.close()
            raise
        if system is None:
            await self.close()
            raise VehicleError(f"no autopilot answered on {url} within {timeout_s:g} s")
        self._system = system
        self._action = ActionAsync(system)
        self._offboard = OffboardAsync(system)
        self._telemetry = TelemetryAsync(system)
        self._direct = MavlinkDirectAsync(system)
        self.connected = await system.is_connected()
        for watch in (
            self._watch_position,
            self._watch_connection,
            self._watch_flight_mode,
            self._watch_armed,
            self._watch_landed_state,
            self._watch_health,
            self._watch_battery,
        ):
            self._tasks.append(asyncio.create_task(watch(), name=f"gcs-{watch.__name__}"))
        telemetry = self._telemetry
        await self._command(
            "set position telemetry rate",
            lambda: telemetry.set_rate_position_velocity_ned(self.settings.telemetry_rate_hz),
        )
        try:  # 5 Hz landed state makes landing detection snappier; not essential.
            await self._command("set landed-state rate", lambda: telemetry.set_rate_landed_state(5))
        except VehicleError as exc:
            _log.warning("%s", exc)

    async def close(self) -> None:
        """Stop the background tasks and release MAVSDK (the vehicle is left as it is)."""
        tasks, self._tasks = self._tasks, []
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        for plugin in (self._action, self._offboard, self._telemetry):
            if plugin is not None:
                plugin.destroy()
        self._action = self._offboard = self._telemetry = self._direct = None
        if self._mavsdk is not None:
            self._mavsdk.destroy()
            self._mavsdk = None
        self.connected = False

    def mocap_plugin(self) -> Any:
        """MAVSDK's blocking Mocap plugin of the connected system (external vision out).

        Blocking on purpose: :class:`gcs.flight.mocap.forward.VisionForwarder` calls it from
        the mocap client's thread, off the event loop that streams the setpoints. It is
        released with the vehicle (:meth:`close`): stop the forwarder first.

        Returns
        -------
        mavsdk.plugins.mocap.Mocap

        Raises
        ------
        VehicleError
            Not connected.
        """
        from mavsdk.plugins.mocap import Mocap

        if self._system is None:
            raise VehicleError("not connected: no vehicle to forward the mocap to")
        return Mocap(self._system._system)

    # ------------------------------------------------------------------ state mirror

    def _notify(self) -> None:
        event, self._changed = self._changed, asyncio.Event()
        event.set()

    async def _watch_position(self) -> None:
        assert self._direct is not None
        async for message in self._direct.subscribe_message("LOCAL_POSITION_NED"):
            receipt_s = time.monotonic()
            f = json.loads(message.fields_json)
            pos = (float(f["x"]), float(f["y"]), float(f["z"]))
            vel = (float(f["vx"]), float(f["vy"]), float(f["vz"]))
            if not all(math.isfinite(x) for x in pos + vel):
                continue  # an estimator without a position: not a sample
            t_vehicle_s = self.clock.add(f["time_boot_ms"] / 1000.0, receipt_s)
            sample = TelemetrySample(receipt_s, pos, vel, t_vehicle_s)
            if self._monitor is not None:
                problem = self._monitor.update(t_vehicle_s, pos, vel)
                if problem is not None and self.fence_active:
                    self.trip("fence", problem)
            if self.latest is None or t_vehicle_s >= self.latest.t_vehicle_s:
                self.latest = sample
            for recorder in self._recorders:
                recorder.append(sample)
            self._notify()

    async def _watch_connection(self) -> None:
        assert self._system is not None
        async for connected in self._system.is_connected_state():
            self.connected = connected
            if not connected:
                _log.warning("link to %s lost (no heartbeat for 3 s)", self.url)
            self._notify()

    async def _watch_flight_mode(self) -> None:
        assert self._telemetry is not None
        async for mode in self._telemetry.subscribe_flight_mode():
            if mode != self.flight_mode:
                self.flight_mode = mode
                self._notify()

    async def _watch_armed(self) -> None:
        assert self._telemetry is not None
        async for armed in self._telemetry.subscribe_armed():
            if armed != self.armed:
                self.armed = armed
                if armed:
                    self._arm_requested = False  # armed now: the armed state covers it
                self._notify()

    async def _watch_landed_state(self) -> None:
        assert self._telemetry is not None
        async for state in self._telemetry.subscribe_landed_state():
            if state != self.landed_state:
                self.landed_state = state
                self._notify()

    async def _watch_health(self) -> None:
        assert self._telemetry is not None
        async for health in self._telemetry.subscribe_health():
            if health.is_local_position_ok != self.local_position_ok:
                self.local_position_ok = health.is_local_position_ok
                self._notify()

    async def _watch_battery(self) -> None:
        assert self._telemetry is not None
        async for battery in self._telemetry.subscribe_battery():
            self.battery_pct = float(battery.remaining_percent)

    @contextlib.contextmanager
    def record_telemetry(self) -> Iterator[list[TelemetrySample]]:
        """Collect every position sample received while the context is open.

        Yields
        ------
        list of TelemetrySample
            Grows as samples arrive; starts with the latest sample received before entry.
        """
        samples: list[TelemetrySample] = [] if self.latest is None else [self.latest]
        self._recorders.append(samples)
        try:
            yield samples
        finally:
            self._recorders.remove(samples)

    def clock_fit(self) -> ClockFit:
        """The current fit of the vehicle's clock to the local one (sliding window).

        Returns
        -------
        ClockFit

        Raises
        ------
        VehicleError
            No position samples at two vehicle times yet.
        """
        fit = self.clock.fit()
        if fit is None:
            raise VehicleError("no time-stamped position samples from the vehicle yet")
        return fit

    # ------------------------------------------------------------------ the fence

    @property
    def fence_active(self) -> bool:
        """Whether breaches count now: from the arm command until the vehicle is disarmed."""
        return self.armed or self._arm_requested

    def trip(self, source: str, reason: str) -> None:
        """Report a breach: the flight stops at once (the first one is kept).

        The entry point of every watch: the estimate monitor calls it for each sample that
        breaks the fence, a motion-capture health check would call it with its own reason. Call
        it on the event loop (from another thread: ``loop.call_soon_threadsafe``).

        Parameters
        ----------
        source : str
            What saw it, e.g. ``"fence"`` or ``"mocap"``.
        reason : str
            One line naming what was seen.
        """
        if self.breach is None:
            self.breach = f"{source}: {reason}"
            _log.info("breach: %s", self.breach)
            self._notify()

    def add_watch(self, source: str, problem: Callable[[], str | None]) -> None:
        """Watch one more condition while the vehicle is armed (polled at every check).

        Parameters
        ----------
        source : str
            Its name in the breach line, e.g. ``"mocap"``.
        problem : callable
            Returns None while all is well, else one line (e.g. a motion-capture client's
            ``problem``); called on the event loop at every state change, so it must be fast.
        """
        self._watches.append((source, problem))

    def safety_problem(self) -> str | None:
        """The breach that ends the flight, or None (see :meth:`trip`).

        Returns
        -------
        str or None
        """
        if self.breach is None and self.fence_active:
            for source, problem in self._watches:
                reason = problem()
                if reason is not None:
                    self.trip(source, reason)
                    break
        return self.breach

    def _require_inside(self, what: str) -> None:
        """Refuse to start ``what`` from a measured position outside the arena plus margin."""
        if self.fence is None or self.latest is None:
            return
        problem = self.fence.position_problem(self.latest.pos_ned_m)
        if problem is not None:
            raise VehicleError(f"fence: {problem}; not {what}")

    def telemetry_age_s(self) -> float:
        """Age of the newest position sample [s] (infinite before the first one)."""
        return math.inf if self.latest is None else time.monotonic() - self.latest.t_s

    def control_problem(self) -> str | None:
        """Why the vehicle is not under our offboard control right now, or None if it is.

        Returns
        -------
        str or None
            A breach (:meth:`safety_problem`), "link lost", a flight mode other than OFFBOARD,
            or stale position telemetry (older than ``settings.max_telemetry_age_s``).
        """
        breach = self.safety_problem()
        if breach is not None:
            return breach
        if not self.connected:
            return "link lost (no heartbeat for 3 s)"
        if self.flight_mode != FlightMode.OFFBOARD:
            return f"flight mode is {self.flight_mode.name}, not OFFBOARD"
        age_s = self.telemetry_age_s()
        if age_s > self.settings.max_telemetry_age_s:
            return f"position telemetry stale ({age_s:.2f} s old)"
        return None

    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
        """Wait (on the vehicle's state-change events, at least every telemetry-age limit)
        until ``predicate()`` holds, on the ground (a breach or a lost link ends it).

        Parameters
        ----------
        predicate : callable
            Checked on every state change.
        timeout_s : float
            Limit [s].
        what : str
            Named in the timeout's message.

        Raises
        ------
        VehicleError
            Not within ``timeout_s``, link lost, or a breach.
        """
        await self._wait_until(predicate, timeout_s, what, in_control=False)

    def notify(self) -> None:
        """Wake the waits (:meth:`wait_until`): something they check has changed."""
        self._notify()

    @property
    def system(self) -> System:
        """The connected MAVSDK system (for plugins gcs opens beside the vehicle's own).

        Raises
        ------
        VehicleError
            Not connected.
        """
        return self._require(self._system)

    async def _wait_until(
        self,
        predicate: Callable[[], bool],
        timeout_s: float,
        what: str,
        *,
        in_control: bool,
        stopping: bool = False,
    ) -> None:
        """Wait (on state-change events) until ``predicate()`` holds.

        Raises :class:`_WaitTimeout` (a VehicleError) on timeout, VehicleError on link loss,
        on a breach (unless ``stopping``: the emergency stop itself) and, with ``in_control``,
        on any :meth:`control_problem`.
        """
        deadline_s = time.monotonic() + timeout_s
        while True:
            # problems first: a breach seen with the sample that also ends the wait ends it
            problem = self.control_problem() if in_control else None
            if problem is None and not stopping:
                problem = self.safety_problem()
            if problem is not None:
                raise VehicleError(f"{problem} while waiting for {what}")
            if predicate():
                return
            if not self.connected:
                raise VehicleError(f"link lost (no heartbeat for 3 s) while waiting for {what}")
            remaining_s = deadline_s - time.monotonic()
            if remaining_s <= 0:
                raise _WaitTimeout(f"{what} did not happen within {timeout_s:g} s")
            # Wake up at least at the telemetry-age limit so that silence is noticed.
            changed = self._changed
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(min(remaining_s, self.settings.max_telemetry_age_s)):
                    await changed.wait()

    async def _command(self, what: str, call: Callable[[], Awaitable[_T]]) -> _T:
        """Run one MAVSDK command with the command timeout; errors become VehicleError."""
        if self._system is None:
            raise VehicleError(f"{what}: not connected")
        try:
            async with asyncio.timeout(self.settings.command_timeout_s):
                return await call()
        except TimeoutError:
            raise VehicleError(
                f"{what}: no answer within {self.settings.command_timeout_s:g} s"
            ) from None
        except MavsdkError as exc:
            result = getattr(exc, "result", None)
            name = getattr(result, "name", None) or str(exc)
            raise VehicleError(f"{what} failed: {name}") from None

    async def read_int_params(self, names: tuple[str, ...]) -> dict[str, int | None]:
        """Read integer parameters of the autopilot; None for each one it does not answer.

        Parameters
        ----------
        names : tuple of str
            PX4 parameter names.

        Returns
        -------
        dict of str to int or None
        """
        if self._system is None:
            raise VehicleError("reading parameters: not connected")
        param = ParamAsync(self._system)
        values: dict[str, int | None] = {}
        try:
            for name in names:
                try:
                    values[name] = await self._command(
                        f"read {name}", lambda name=name: param.get_param_int(name)
                    )
                except VehicleError as exc:
                    _log.warning("%s", exc)
                    values[name] = None
        finally:
            param.destroy()
        return values

    async def set_params(self, values: dict[str, int | float]) -> None:
        """Set autopilot parameters (an int as INT32, a float as REAL32), one after the other.

        Parameters
        ----------
        values : dict of str to int or float
            PX4 parameter names and values.

        Raises
        ------
        VehicleError
            A parameter was refused or not answered.
        """
        if self._system is None:
            raise VehicleError("setting parameters: not connected")
        param = ParamAsync(self._system)
        try:
            for name, value in values.items():
                if isinstance(value, int):
                    call = lambda n=name, v=value: param.set_param_int(n, v)  # noqa: E731
                else:
                    call = lambda n=name, v=value: param.set_param_float(n, float(v))  # noqa: E731
                await self._command(f"set {name}", call)
        finally:
            param.destroy()

    async def read_float_param(self, name: str) -> float | None:
        """Read one float parameter of the autopilot; None if it does not answer.

        Parameters
        ----------
        name : str
            PX4 parameter name.

        Returns
        -------
        float or None
        """
        if self._system is None:
            raise VehicleError("reading parameters: not connected")
        param = ParamAsync(self._system)
        try:
            return float(await self._command(f"read {name}", lambda: param.get_param_float(name)))
        except VehicleError as exc:
            _log.warning("%s", exc)
            return None
        finally:
            param.destroy()

    async def read_all_params(self) -> dict[str, float | None]:
        """Read every parameter of the autopilot at once (one list request).

        Returns
        -------
        dict of str to float or None
            Integer and float parameters by name.
        """
        if self._system is None:
            raise VehicleError("reading parameters: not connected")
        param = ParamAsync(self._system)
        try:
            found = await self._command("read all parameters", param.get_all_params)
        finally:
            param.destroy()
        values: dict[str, float | None] = {p.name: float(p.value) for p in found.int_params}
        values |= {p.name: float(p.value) for p in found.float_params}
        return values

    async def gps_global_origin(self) -> tuple[float, float, float]:
        """The global position of the local NED frame's origin (PX4's GPS_GLOBAL_ORIGIN).

        Returns
        -------
        tuple of float
            Latitude [deg], longitude [deg], altitude AMSL [m].

        Raises
        ------
        VehicleError
            Not answered, or not a finite position.
        """
        telemetry = self._require(self._telemetry)
        origin = await self._command("read the global origin", telemetry.get_gps_global_origin)
        values = (origin.latitude_deg, origin.longitude_deg, origin.altitude_m)
        if not all(math.isfinite(float(x)) for x in values):
            raise VehicleError(f"read the global origin: not a position {values}")
        return (float(values[0]), float(values[1]), float(values[2]))

    async def set_global_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Set the global position of the local NED origin (MAVLink ``SET_GPS_GLOBAL_ORIGIN``).

        PX4 without GPS (motion capture) has no global origin until one is set; EKF2 takes
        it once, and PX4 answers with ``GPS_GLOBAL_ORIGIN`` (read it with
        :meth:`gps_global_origin`).

        Parameters
        ----------
        lat_deg, lon_deg : float
            WGS84 latitude and longitude [deg].
        alt_m : float
            Altitude AMSL [m].

        Raises
        ------
        VehicleError
            Not connected, or MAVSDK refused the message.
        """
        direct = self._require(self._direct)
        system = self._require(self._system)
        fields = {
            "target_system": await system.get_system_id(),
            "latitude": round(lat_deg * 1e7),
            "longitude": round(lon_deg * 1e7),
            "altitude": round(alt_m * 1e3),
            "time_usec": 0,
        }
        message = MavlinkMessage("SET_GPS_GLOBAL_ORIGIN", 0, 0, fields["target_system"], 0,
                                 json.dumps(fields))  # fmt: skip
        await self._command("set the global origin", lambda: direct.send_message(message))

    async def upload_inclusion_polygon(self, vertices_deg: list[tuple[float, float]]) -> None:
        """Replace the autopilot's geofence by one inclusion polygon (MAVSDK's Geofence plugin).

        Parameters
        ----------
        vertices_deg : list of (float, float)
            The polygon's vertices, (latitude, longitude) [deg].

        Raises
        ------
        VehicleError
            The upload was refused or not answered.
        """
        if self._system is None:
            raise VehicleError("geofence upload: not connected")
        fence = GeofenceAsync(self._system)
        points = [Point(lat, lon) for lat, lon in vertices_deg]
        data = GeofenceData([Polygon(points, FenceType.INCLUSION)], [])
        try:
            await self._command("geofence upload", lambda: fence.upload_geofence(data))
        finally:
            fence.destroy()

    # ------------------------------------------------------------------ flight

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
        await self._wait_until(
            lambda: (
                self.local_position_ok
                and self.telemetry_age_s() <= self.settings.max_telemetry_age_s
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
            self._require_inside("arming")
        action = self._require(self._action)
        try:
            await self._command(
                "set take-off altitude", lambda: action.set_takeoff_altitude(float(altitude_m))
            )
        except VehicleError as exc:
            _log.warning("%s; taking off to the vehicle's default altitude", exc)
        self._arm_requested = True  # the fence watches from the arm command on
        try:
            await self._command("arm", action.arm)
            await self._wait_until(
                lambda: self.armed, self.settings.command_timeout_s, "armed state", in_control=False
            )
        except BaseException:
            self._arm_requested = self.armed
            raise
        await self._command("take-off", action.takeoff)
        tolerance_m = self.settings.settle_tolerance_m
        seen_takeoff_mode = [False]

        def airborne() -> bool:
            if self.latest is None:
                return False
            seen_takeoff_mode[0] |= self.flight_mode == FlightMode.TAKEOFF
            height_m = -self.latest.pos_ned_m[2]
            done_in_hold = (
                seen_takeoff_mode[0]
                and self.flight_mode == FlightMode.HOLD
                and self.landed_state == LandedState.IN_AIR
            )
            return height_m >= altitude_m - tolerance_m or done_in_hold

        await self._wait_until(
            airborne,
            self.settings.takeoff_timeout_s,
            f"take-off to {altitude_m:g} m",
            in_control=False,
        )

    async def send_setpoint(self, pos_ned_m: Any) -> None:
        """Send one position setpoint (MAVSDK re-sends the last one at 20 Hz by itself).

        Parameters
        ----------
        pos_ned_m : array_like, shape (3,)
            Absolute local NED position [m].

        Raises
        ------
        VehicleError
            The setpoint lies outside the arena (or the vehicle has no fence), after
            :meth:`emergency_stop` (streaming is over for good), or MAVSDK refused it.
        """
        if self._streaming_stopped:
            raise VehicleError("setpoint streaming was stopped by an emergency stop")
        if self.fence is None:
            raise VehicleError("no arena fence: gcs sends setpoints only inside an arena")
        problem = self.fence.setpoint_problem(pos_ned_m)
        if problem is not None:
            raise VehicleError(f"fence: {problem}; not sent")
        offboard = self._require(self._offboard)
        n, e, d = (float(x) for x in pos_ned_m)
        setpoint = PositionNedYaw(n, e, d, self.settings.yaw_deg)
        try:
            await offboard.set_position_ned(setpoint)
        except MavsdkError as exc:
            raise VehicleError(f"setpoint refused: {getattr(exc, 'result', exc)}") from None
        self.target_ned_m = np.array([n, e, d])

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
        if self.latest is None or self.telemetry_age_s() > self.settings.max_telemetry_age_s:
            raise VehicleError("cannot start offboard: no fresh position telemetry")
        self._require_inside("starting offboard")
        hover_ned_m = self._hover_point(np.array(self.latest.pos_ned_m))
        period_s = 1.0 / self.settings.stream_rate_hz
        t0 = time.monotonic()
        for i in range(max(1, math.ceil(preroll_s / period_s))):
            await sleep_until(t0 + i * period_s)
            breach = self.safety_problem()
            if breach is not None:
                raise VehicleError(f"{breach} while starting offboard")
            await self.send_setpoint(hover_ned_m)
        offboard = self._require(self._offboard)
        await self.send_setpoint(hover_ned_m)
        await self._command("start offboard", offboard.start)
        self._offboard_started = True
        await self._wait_until(
            lambda: self.flight_mode == FlightMode.OFFBOARD,
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
            raise VehicleError(f"fence: cannot move to {_fmt(target)}: {problem}")
        self._require_inside(f"moving to {_fmt(target)}")
        if self.target_ned_m is not None:
            start = self.target_ned_m.copy()
        elif self.latest is not None:
            start = self._hover_point(np.array(self.latest.pos_ned_m))
        else:
            raise VehicleError("cannot move: no position telemetry yet")
        distance_m = float(np.linalg.norm(target - start))
        rate_hz = self.settings.stream_rate_hz
        duration_s = 1.875 * distance_m / speed_m_s
        n_ticks = max(1, math.ceil(duration_s * rate_hz))
        t0 = time.monotonic()
        for i in range(1, n_ticks + 1):
            await sleep_until(t0 + i / rate_hz)
            problem = self.control_problem()
            if problem is not None:
                raise VehicleError(f"{problem} while moving to {_fmt(target)}")
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
        with self.record_telemetry() as samples:

            def settled() -> bool:
                t, pos = sample_arrays(samples[-keep:])
                return is_settled(t, pos, target, tolerance_m, speed_tolerance_m_s, s.settle_time_s)

            try:
                await self._wait_until(
                    settled, s.settle_timeout_s, f"settling at {_fmt(target)}", in_control=True
                )
            except _WaitTimeout:
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
        fit = self.clock_fit()
        with self.record_telemetry() as samples:
            # until a sample stamped duration_s after the vehicle's "now" (not its last sample)
            end_s = float(fit.to_vehicle(time.monotonic())) + duration_s
            # twice the expected wall time: a simulator may slow down meanwhile (silence is the
            # watchdog's to catch, not the timeout's)
            await self._wait_until(
                lambda: self.clock.latest_s >= end_s,
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
        elif self.latest is not None:
            hover = self._hover_point(np.array(self.latest.pos_ned_m))
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
            changed = asyncio.ensure_future(self._changed.wait())
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
            problem = self.control_problem()
            if problem is not None:
                raise VehicleError(f"{problem} while hovering for {what}")

    async def land_and_disarm(self) -> None:
        """Land, wait for ON_GROUND, then disarm unless PX4 has disarmed by itself.

        Raises
        ------
        VehicleError
            Landing refused or not finished within ``settings.land_timeout_s``, link lost.
        """
        action = self._require(self._action)
        self._streaming_stopped = True
        await self._command("land", action.land)
        self._offboard_started = False  # PX4 lands now: a stop must not switch it to Hold
        await self._wait_until(
            lambda: self.landed_state == LandedState.ON_GROUND,
            self.settings.land_timeout_s,
            "landing",
            in_control=False,
        )
        if self.armed:
            await self._command("disarm", action.disarm)
            await self._wait_until(
                lambda: not self.armed,
                self.settings.command_timeout_s,
                "disarmed state",
                in_control=False,
            )

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
        self._streaming_stopped = True
        if self._system is None or self._action is None or self._offboard is None:
            return "not connected"
        if not (self.armed or self._arm_requested) and not self._offboard_started:
            return "vehicle not armed; nothing to do"
        action, offboard = self._action, self._offboard
        notes: list[str] = []

        async def attempt(what: str, call: Callable[[], Awaitable[Any]]) -> bool:
            try:
                await self._command(what, call)
                return True
            except VehicleError as exc:
                _log.warning("emergency stop: %s", exc)
                notes.append(str(exc))
                return False

        if self._offboard_started:
            await attempt("offboard stop (Hold)", offboard.stop)
            self._offboard_started = False
        on_ground = self.landed_state == LandedState.ON_GROUND
        if self.armed and not on_ground:
            on_ground = await self._land_with_retries(lambda: attempt("land", action.land), notes)
        if on_ground and (self.armed or self._arm_requested) and self.connected:
            await attempt("disarm", action.disarm)
            with contextlib.suppress(VehicleError):
                await self._wait_until(
                    lambda: not self.armed,
                    self.settings.command_timeout_s,
                    "disarmed state",
                    in_control=False,
                    stopping=True,
                )
        if not self.connected:
            return "link lost: vehicle left to its own failsafe (" + "; ".join(notes) + ")"
        if on_ground and not self.armed:
            return "landed and disarmed"
        return "; ".join(notes) or ("on the ground, armed" if on_ground else "airborne")

    async def _land_with_retries(
        self, send_land: Callable[[], Awaitable[bool]], notes: list[str]
    ) -> bool:
        """Command LAND until the vehicle is on the ground or ``land_timeout_s`` passes.

        A land command lost in a link outage is sent again once the vehicle is heard from and
        still not landing, so that a temporary loss of the link does not leave it hovering.
        """
        deadline_s = time.monotonic() + self.settings.land_timeout_s
        last_try_s = -math.inf
        last_heard_s = time.monotonic()
        while self.landed_state != LandedState.ON_GROUND:
            now_s = time.monotonic()
            heard = self.connected and self.telemetry_age_s() < self.settings.max_telemetry_age_s
            if heard:
                last_heard_s = now_s
            elif now_s - last_heard_s > self.settings.link_regain_s:
                notes.append(f"link not back within {self.settings.link_regain_s:g} s")
                return False
            if now_s >= deadline_s:
                break
            if heard and self.flight_mode != FlightMode.LAND and now_s - last_try_s > 1.0:
                last_try_s = now_s
                await send_land()
            changed = self._changed  # woken by any state change of the mirror
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(min(deadline_s - now_s, 0.5)):
                    await changed.wait()
        if self.landed_state == LandedState.ON_GROUND:
            return True
        notes.append(f"not on the ground after {self.settings.land_timeout_s:g} s")
        return False

    @staticmethod
    def _require(plugin: _T | None) -> _T:
        if plugin is None:
            raise VehicleError("not connected")
        return plugin


class _WaitTimeout(VehicleError):
    """A wait of :meth:`Vehicle._wait_until` ran out of time (control was not lost)."""


def _fmt(ned_m: np.ndarray) -> str:
    return "NED (" + ", ".join(f"{x:.2f}" for x in ned_m) + ") m"
