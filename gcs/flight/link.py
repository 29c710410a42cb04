"""The MAVSDK connection to a PX4 multirotor and the mirror of its state.

:class:`Link` owns the ``Mavsdk`` instance, the Action/Offboard/Telemetry plugins and a few
background tasks, the ``_watch_*`` coroutines, that mirror the vehicle's state (position and
velocity, flight mode, armed, landed state, link, health, battery). Each state change wakes the
waits (:meth:`Link.notify`); every command is guarded by a timeout (:meth:`Link._command`) so
that a dead link cannot hang the caller, and MAVSDK errors become one-line
:class:`gcs.errors.VehicleError`.

Position samples carry two times: the receipt time on ``time.monotonic()`` and the vehicle's own
time stamp. MAVSDK's ``position_velocity_ned`` has no time stamp, so LOCAL_POSITION_NED is read
raw through MAVSDK's MavlinkDirect plugin (its ``time_boot_ms``); :attr:`Link.clock` makes
that a continuous vehicle time and fits it to the local clock (:mod:`gcs.flight.clock`).

:class:`Link` is one part of :class:`gcs.flight.vehicle.Vehicle`, which sets its state.
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
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState, TelemetryAsync

from gcs.errors import VehicleError
from gcs.flight.clock import ClockFit, VehicleClock
from gcs.io.settings import FlightSettings

__all__ = ["Link", "TelemetrySample", "sample_arrays"]

_log = logging.getLogger(__name__)
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


def _route_mavsdk_log(level: LogLevel, message: str, file: str | None, line: int) -> bool:
    """Send a line of the C++ core's log to Python logging instead of coloured stderr."""
    logged = logging.DEBUG if message.strip() in _HARMLESS else _LOG_LEVELS.get(level, logging.INFO)
    _mavsdk_log.log(logged, "%s", message)
    return True


def connect_hint(url: str) -> str:
    """What to check when nothing answered on ``url`` (a clause for the error's line).

    Parameters
    ----------
    url : str
        The MAVSDK connection URL.

    Returns
    -------
    str
        E.g. ``"; nothing arrived on UDP port 14540: is PX4 SITL running ..."``.
    """
    scheme, _, rest = url.partition("://")
    port = rest.rsplit(":", 1)[-1] if ":" in rest else "?"
    if scheme == "udpin":
        return (
            f"; nothing arrived on UDP port {port}: is PX4 SITL running (it sends to port "
            "14540), or the vehicle's telemetry link sending to this machine on that port?"
        )
    if scheme in ("udpout", "tcpout", "tcp"):
        return f"; is a vehicle listening at {rest} (PX4 SITL: udpin://0.0.0.0:14540)?"
    if scheme == "serial":
        return f"; is the vehicle on {rest.rsplit(':', 1)[0]}, powered, at that baud rate?"
    return ""


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


class Link:
    """The connection and the state mirror of :class:`gcs.flight.vehicle.Vehicle`."""

    settings: FlightSettings
    url: str | None
    connected: bool
    latest: TelemetrySample | None
    flight_mode: FlightMode
    armed: bool
    _arm_requested: bool  # the arm command was sent, the armed state not yet seen
    landed_state: LandedState
    local_position_ok: bool
    battery_pct: float
    clock: VehicleClock
    _changed: asyncio.Event
    _recorders: list[list[TelemetrySample]]
    _tasks: list[asyncio.Task[None]]
    _mavsdk: Mavsdk | None
    _system: System | None
    _action: ActionAsync | None
    _offboard: OffboardAsync | None
    _telemetry: TelemetryAsync | None
    _direct: MavlinkDirectAsync | None
    _check_sample: Callable[[TelemetrySample], None]  # the safety watches (watches.py)

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
            raise VehicleError(
                f"no autopilot answered on {url} within {timeout_s:g} s{connect_hint(url)}"
            )
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
            self._check_sample(sample)
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

    def telemetry_age_s(self) -> float:
        """Age of the newest position sample [s] (infinite before the first one)."""
        return math.inf if self.latest is None else time.monotonic() - self.latest.t_s

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

    @staticmethod
    def _require(plugin: _T | None) -> _T:
        if plugin is None:
            raise VehicleError("not connected")
        return plugin
