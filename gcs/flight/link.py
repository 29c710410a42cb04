"""The connection to a PX4 multirotor and the mirror of its state.

:class:`Link` owns a :class:`gcs.flight.backend.VehicleLink` (MAVSDK's, or a simulated one:
:func:`gcs.flight.backend.registered_link` picks it by the URL) and a few background tasks, the
``_watch_*`` coroutines, that mirror the vehicle's state (position and
velocity, flight mode, armed, landed state, link, health, battery). Each state change wakes the
waits (:meth:`Link.notify`, :meth:`Link.wait_change`); every command is guarded by a timeout
(:meth:`Link.command`) so that a dead link cannot hang the caller, and MAVSDK errors become
one-line :class:`gcs.errors.VehicleError`. Each position sample is handed to
:attr:`Link.on_sample` (the safety watches' check) before anything else sees it.

Position samples carry two times: the receipt time on the local clock (:attr:`Link.local_clock`,
the link's: ``time.monotonic()`` on the wire) and the vehicle's own time stamp
(LOCAL_POSITION_NED's ``time_boot_ms``); :attr:`Link.clock` makes that a continuous vehicle time
and fits it to the local clock (:mod:`gcs.flight.clock`).

:class:`Link` is one part of :class:`gcs.flight.vehicle.Vehicle`; the other parts read its mirror
and command through it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Awaitable, Callable, Coroutine, Iterator
from typing import Any, NamedTuple, TypeVar

import numpy as np
from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState

from gcs.errors import VehicleError
from gcs.flight.backend import CommandRefused, LinkUnreachable, VehicleLink, registered_link
from gcs.flight.clock import WALL_CLOCK, ClockFit, VehicleClock
from gcs.flight.clock import Clock as LocalClock
from gcs.flight.mavsdk_link import MavsdkLink
from gcs.io.settings import FlightSettings

__all__ = ["Link", "TelemetrySample", "connect_hint", "sample_arrays"]

_log = logging.getLogger(__name__)
_T = TypeVar("_T")


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
        Receipt time on the local clock [s] (``time.monotonic()``, the asyncio loop clock, on
        the wire).
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


def _ignore(sample: TelemetrySample) -> None:
    """No check of a position sample (a link without safety watches)."""


class Link:
    """The connection to the vehicle and the mirror of its state.

    Parameters
    ----------
    settings : FlightSettings
        Rates and timeouts (the telemetry rate, the command timeout).
    link : VehicleLink or None
        The link to fly through; None: the one the URL names when connecting (MAVSDK's).
    clock : Clock or None
        The local clock; None: the link's (the wall clock until connected).
    """

    def __init__(
        self,
        settings: FlightSettings,
        *,
        link: VehicleLink | None = None,
        clock: LocalClock | None = None,
    ) -> None:
        self.settings = settings
        self._link_given = link  # injected at construction (else by the URL)
        self._clock_given = clock  # injected at construction (else the link's)
        self.backend: VehicleLink | None = None  # the connected link
        self.local_clock: LocalClock = clock if clock is not None else WALL_CLOCK
        self.on_sample: Callable[[TelemetrySample], None] = _ignore  # the safety watches' check
        self.url: str | None = None
        self.connected = False
        self.latest: TelemetrySample | None = None
        self.flight_mode = FlightMode.UNKNOWN
        self.armed = False
        self.arm_requested = False  # the arm command was sent, the armed state not yet seen
        self.landed_state = LandedState.UNKNOWN
        self.local_position_ok = False
        self.battery_pct = math.nan  # remaining charge [%]; NaN until reported
        self.clock = VehicleClock(window_s=10.0)
        self._changed = asyncio.Event()
        self._recorders: list[list[TelemetrySample]] = []
        self._tasks: list[asyncio.Task[None]] = []

    async def connect(self, url: str, timeout_s: float | None = None) -> None:
        """Open ``url``, wait for the autopilot and start mirroring its state.

        Parameters
        ----------
        url : str
            Connection URL, e.g. ``udpout://127.0.0.1:14540`` or ``udpin://0.0.0.0:14540``
            (MAVSDK), or a scheme registered with :func:`gcs.flight.backend.register_scheme`.
        timeout_s : float, optional
            How long to wait for an autopilot [s]; ``settings.connect_timeout_s`` if omitted.

        Raises
        ------
        VehicleError
            Invalid URL, no autopilot within the timeout, or the telemetry rate was refused.
        """
        timeout_s = self.settings.connect_timeout_s if timeout_s is None else timeout_s
        self.url = url
        link = self._link_given or registered_link(url) or MavsdkLink()
        self.backend = link
        if self._clock_given is None:
            self.local_clock = link.clock
        try:
            found = await link.connect(url, timeout_s)
        except LinkUnreachable as exc:
            await self.close()
            raise VehicleError(f"cannot open connection {url!r}: {exc}") from None
        except BaseException:
            await self.close()
            raise
        if not found:
            await self.close()
            raise VehicleError(
                f"no autopilot answered on {url} within {timeout_s:g} s{connect_hint(url)}"
            )
        self.connected = await link.is_connected()
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
        rate_hz = self.settings.telemetry_rate_hz
        await self.command("set position telemetry rate", lambda: link.set_position_rate(rate_hz))
        try:  # 5 Hz landed state makes landing detection snappier; not essential.
            await self.command("set landed-state rate", lambda: link.set_landed_state_rate(5))
        except VehicleError as exc:
            _log.warning("%s", exc)

    async def close(self) -> None:
        """Stop the background tasks and release the link (the vehicle is left as it is)."""
        tasks, self._tasks = self._tasks, []
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        link, self.backend = self.backend, None
        if link is not None:
            await link.close()
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
        if self.backend is None:
            raise VehicleError("not connected: no vehicle to forward the mocap to")
        return self.backend.mocap_plugin()

    # ------------------------------------------------------------------ state mirror

    async def _watch_position(self) -> None:
        async for report in self.link.positions():
            receipt_s = self.local_clock.now()
            pos, vel = report.pos_ned_m, report.vel_ned_m_s
            if not all(math.isfinite(x) for x in pos + vel):
                continue  # an estimator without a position: not a sample
            t_vehicle_s = self.clock.add(report.time_boot_s, receipt_s)
            sample = TelemetrySample(receipt_s, pos, vel, t_vehicle_s)
            self.on_sample(sample)
            if self.latest is None or t_vehicle_s >= self.latest.t_vehicle_s:
                self.latest = sample
            for recorder in self._recorders:
                recorder.append(sample)
            self.notify()

    async def _watch_connection(self) -> None:
        async for connected in self.link.connection_states():
            self.connected = connected
            if not connected:
                _log.warning("link to %s lost (no heartbeat for 3 s)", self.url)
            self.notify()

    async def _watch_flight_mode(self) -> None:
        async for mode in self.link.flight_modes():
            if mode != self.flight_mode:
                self.flight_mode = mode
                self.notify()

    async def _watch_armed(self) -> None:
        async for armed in self.link.armed_states():
            if armed != self.armed:
                self.armed = armed
                if armed:
                    self.arm_requested = False  # armed now: the armed state covers it
                self.notify()

    async def _watch_landed_state(self) -> None:
        async for state in self.link.landed_states():
            if state != self.landed_state:
                self.landed_state = state
                self.notify()

    async def _watch_health(self) -> None:
        async for ok in self.link.local_position_health():
            if ok != self.local_position_ok:
                self.local_position_ok = ok
                self.notify()

    async def _watch_battery(self) -> None:
        async for level_pct in self.link.battery_levels():
            self.battery_pct = float(level_pct)

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
        return math.inf if self.latest is None else self.local_clock.now() - self.latest.t_s

    def notify(self) -> None:
        """Wake the waits (:meth:`wait_change`): something they check has changed."""
        event, self._changed = self._changed, asyncio.Event()
        event.set()

    def next_change(self) -> Coroutine[Any, Any, bool]:
        """An awaitable that ends at the next state change (:meth:`notify`).

        Returns
        -------
        coroutine
            Ends (True) at the next change after this call.
        """
        return self._changed.wait()

    async def wait_change(self, timeout_s: float) -> None:
        """Wait for the next state change (:meth:`notify`), at most ``timeout_s``.

        Parameters
        ----------
        timeout_s : float
            Limit [s] on the local clock's loop; no error when it runs out.
        """
        changed = self._changed
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                await changed.wait()

    @property
    def link(self) -> VehicleLink:
        """The connected link (MAVSDK's, or a simulated one).

        Raises
        ------
        VehicleError
            Not connected.
        """
        if self.backend is None:
            raise VehicleError("not connected")
        return self.backend

    @property
    def system(self) -> Any:
        """The connected MAVSDK system (for plugins gcs opens beside the vehicle's own).

        Raises
        ------
        VehicleError
            Not connected, or the link is not MAVSDK's.
        """
        system = getattr(self.backend, "system", None)
        if system is None:
            raise VehicleError("not connected over MAVSDK")
        return system

    async def command(self, what: str, call: Callable[[], Awaitable[_T]]) -> _T:
        """Run one link command with the command timeout; a refusal becomes VehicleError.

        Parameters
        ----------
        what : str
            The command's name in the error's line, e.g. ``"arm"``.
        call : callable
            Makes the command's awaitable on the link.

        Returns
        -------
        object
            What the command returned.

        Raises
        ------
        VehicleError
            Not connected, no answer within ``settings.command_timeout_s``, or refused.
        """
        if self.backend is None:
            raise VehicleError(f"{what}: not connected")
        try:
            async with asyncio.timeout(self.settings.command_timeout_s):
                return await call()
        except TimeoutError:
            raise VehicleError(
                f"{what}: no answer within {self.settings.command_timeout_s:g} s"
            ) from None
        except CommandRefused as exc:
            raise VehicleError(f"{what} failed: {exc.result}") from None
