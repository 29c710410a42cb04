"""One connection to a PX4 multirotor, flown by position setpoints in local NED.

:class:`Vehicle` is the one object the flight layer flies: :class:`CampaignVehicle`, what a
campaign needs from its vehicle, made of parts. It is built from two injected pieces:

- the link (:class:`gcs.flight.backend.VehicleLink`): MAVSDK's (:mod:`gcs.flight.mavsdk_link`)
  by default, chosen by the URL when connecting, or one given at construction (a simulated
  link in the tests);
- the local clock (:class:`gcs.flight.clock.Clock`: ``now``, ``sleep``): every receipt time,
  deadline and wait of the flight layer reads it; the link's (the wall clock on the wire, the
  virtual clock of a simulated link) unless one is given;

and of five parts, each a small class that owns its own state and is given only the parts it
uses (none knows the vehicle):

- :class:`gcs.flight.link.Link`: the connection, the command timeout and the mirror of the
  vehicle's state (the ``_watch_*`` coroutines), position samples on the vehicle's clock;
- :class:`gcs.flight.watches.Watches` (reads the mirror): the safety watches (the fence's
  estimate monitor, :meth:`add_watch`, the breach) and the waits that end on one;
- :class:`gcs.flight.params.Params` (the connection): parameters, the global origin and the
  geofence upload;
- :class:`gcs.flight.manoeuvres.Manoeuvres` (the mirror, the watches): take-off, offboard,
  moves, settling and holds, every setpoint through :meth:`send_setpoint` (which refuses one
  outside the arena);
- :class:`gcs.flight.landing.Landing` (the mirror, the watches, the manoeuvres' stream):
  landing and the emergency stop.

The fence (:mod:`gcs.flight.fence`). :meth:`Vehicle.send_setpoint` is the one place every
setpoint goes through, and it refuses one outside the arena. From the arm command to the
disarmed state every position sample goes through an :class:`gcs.flight.fence.EstimateMonitor`;
what it names, and what any other watch reports (:meth:`Vehicle.trip`, :meth:`Vehicle.add_watch`:
a motion-capture stream's health, say), is a *breach*: every wait, move, hold and trial of the
flight layer raises it at once as a :class:`gcs.errors.VehicleError` (or ``TrialAborted``), and the
campaign stops the vehicle (:meth:`Vehicle.emergency_stop`).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from contextlib import AbstractContextManager
from typing import Any, Protocol, TypeVar

import numpy as np

from gcs.flight.backend import VehicleLink
from gcs.flight.clock import Clock, ClockFit, VehicleClock
from gcs.flight.fence import Fence
from gcs.flight.landing import Landing
from gcs.flight.link import Link, TelemetrySample
from gcs.flight.manoeuvres import Manoeuvres
from gcs.flight.params import Params
from gcs.flight.watches import Watches
from gcs.io.settings import FlightSettings

__all__ = ["CampaignVehicle", "Vehicle"]

_T = TypeVar("_T")


class CampaignVehicle(Protocol):
    """What a campaign needs from its vehicle.

    The calls of :mod:`gcs.flight.campaign` and of the steps it hands the vehicle to
    (:mod:`gcs.flight.trial`, :mod:`gcs.flight.prearm`, :mod:`gcs.flight.geofence`,
    :mod:`gcs.flight.mocap.campaign`, :mod:`gcs.flight.checklist`). :class:`Vehicle` is the one
    that flies; each call is documented in full by the part that does it.
    """

    @property
    def settings(self) -> FlightSettings:
        """Rates, timeouts and limits."""
        ...

    @property
    def fence(self) -> Fence | None:
        """The arena and the limits watched while armed (None: no setpoint is sent)."""
        ...

    @property
    def latest(self) -> TelemetrySample | None:
        """The newest position sample (by vehicle time), None before the first."""
        ...

    @property
    def battery_pct(self) -> float:
        """Remaining charge [%]; NaN until reported."""
        ...

    @property
    def breach(self) -> str | None:
        """The first breach seen (it ends the flight), or None."""
        ...

    @property
    def below_floor_landing_m(self) -> float:
        """Deepest estimate below the arena's floor while landing [m] (0: none)."""
        ...

    @property
    def clock(self) -> VehicleClock:
        """The vehicle's continuous time and its fit to the local clock."""
        ...

    @property
    def local_clock(self) -> Clock:
        """The local clock of receipt times, waits and deadlines."""
        ...

    @property
    def link(self) -> VehicleLink:
        """The connected link (VehicleError when not connected)."""
        ...

    async def connect(self, url: str, timeout_s: float | None = None) -> None:
        """Open ``url``, wait ``timeout_s`` for the autopilot, start mirroring its state."""
        ...

    async def close(self) -> None:
        """Stop mirroring and release the link (the vehicle is left as it is)."""
        ...

    def mocap_plugin(self) -> Any:
        """MAVSDK's blocking Mocap plugin of the connected system (external vision out)."""
        ...

    def record_telemetry(self) -> AbstractContextManager[list[TelemetrySample]]:
        """Collect every position sample received while the context is open."""
        ...

    def clock_fit(self) -> ClockFit:
        """The current fit of the vehicle's clock to the local one (VehicleError without)."""
        ...

    def notify(self) -> None:
        """Wake the waits: something they check has changed."""
        ...

    def add_watch(self, source: str, problem: Callable[[], str | None]) -> None:
        """Watch one more condition while armed: ``problem()`` names a breach of ``source``."""
        ...

    def trip(self, source: str, reason: str) -> None:
        """Report a breach seen by ``source``: the flight stops at once (the first is kept)."""
        ...

    def control_problem(self) -> str | None:
        """Why the vehicle is not under our offboard control right now, or None if it is."""
        ...

    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
        """Wait until ``predicate()`` holds, on the ground; a timeout names ``what``."""
        ...

    async def read_int_params(self, names: tuple[str, ...]) -> dict[str, int | None]:
        """Read integer parameters by name; None for each one not answered."""
        ...

    async def read_float_param(self, name: str) -> float | None:
        """Read one float parameter; None if not answered."""
        ...

    async def read_all_params(self) -> dict[str, float | None]:
        """Read every parameter of the autopilot at once."""
        ...

    async def set_params(self, values: dict[str, int | float]) -> None:
        """Set parameters (an int as INT32, a float as REAL32), one after the other."""
        ...

    async def gps_global_origin(self) -> tuple[float, float, float]:
        """The global position of the local NED origin: latitude, longitude [deg], AMSL [m]."""
        ...

    async def set_global_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Set the global position of the local NED origin (WGS84 [deg], AMSL [m])."""
        ...

    async def upload_inclusion_polygon(self, vertices_deg: list[tuple[float, float]]) -> None:
        """Replace the autopilot's geofence by one inclusion polygon of (lat, lon) [deg]."""
        ...

    async def wait_healthy_local_position(self, timeout_s: float | None = None) -> None:
        """Wait for a valid local position estimate and fresh samples."""
        ...

    async def leave_offboard_on_ground(self) -> bool:
        """Switch a disarmed vehicle in OFFBOARD mode to Hold (PX4 returns to OFFBOARD after a
        disarm, where it cannot arm); whether it was switched."""
        ...

    async def arm_and_takeoff(self, altitude_m: float) -> None:
        """Arm and take off to ``altitude_m`` above the local origin (positive up)."""
        ...

    async def send_setpoint(self, pos_ned_m: Any, yaw_deg: float | None = None) -> None:
        """Send one position setpoint (local NED [m]); one outside the arena is refused."""
        ...

    async def start_offboard_at_current_position(self, preroll_s: float = 1.0) -> None:
        """Stream the current position as setpoint, switch to OFFBOARD and wait for it."""
        ...

    async def goto(self, ned_m: Any, speed_m_s: float) -> None:
        """Move in a straight line (minimum jerk) to ``ned_m``, watching control."""
        ...

    async def settle(self, ned_m: Any, tolerance_m: float, speed_tolerance_m_s: float) -> bool:
        """Hover at ``ned_m`` until settled; False when the settle timeout ran out first."""
        ...

    async def hold(self, duration_s: float, what: str) -> list[TelemetrySample]:
        """Hover at the current target for ``duration_s`` of vehicle time; its samples."""
        ...

    async def hold_position(self) -> np.ndarray:
        """Hover at the current target (else the measured position); the hover point."""
        ...

    async def hover_while(self, work: Awaitable[_T], what: str) -> _T:
        """Hover while ``work`` runs, watching the vehicle; the result of ``work``."""
        ...

    async def land_and_disarm(self) -> None:
        """Land, wait for ON_GROUND, then disarm unless PX4 has disarmed by itself."""
        ...

    async def emergency_stop(self, reason: str) -> str:
        """Stop streaming, Hold, land, disarm once on the ground; never raises."""
        ...


class Vehicle(CampaignVehicle):
    """A PX4 multirotor behind one connection, made of its parts.

    Each member of :class:`CampaignVehicle` delegates to one part, which documents it in full:
    :class:`gcs.flight.link.Link`, :class:`gcs.flight.watches.Watches`,
    :class:`gcs.flight.params.Params`, :class:`gcs.flight.manoeuvres.Manoeuvres`,
    :class:`gcs.flight.landing.Landing`.

    Parameters
    ----------
    settings : FlightSettings
        Rates, timeouts and limits.
    fence : Fence or None
        The arena and the limits watched while armed; without one the vehicle can be
        listened to but sends no setpoint.
    link : VehicleLink or None
        The link to fly through; None: the one the URL names when connecting (MAVSDK's).
    clock : Clock or None
        The local clock; None: the link's (the wall clock until connected).
    """

    def __init__(
        self,
        settings: FlightSettings,
        fence: Fence | None = None,
        *,
        link: VehicleLink | None = None,
        clock: Clock | None = None,
    ) -> None:
        self._mirror = Link(settings, link=link, clock=clock)
        self._watches = Watches(self._mirror, settings, fence)
        self._mirror.on_sample = self._watches.check_sample
        self._params = Params(self._mirror)
        self._manoeuvres = Manoeuvres(self._mirror, self._watches, settings, fence)
        self._landing = Landing(self._mirror, self._watches, self._manoeuvres, settings)

    # the state, read from the parts that own it

    @property
    def settings(self) -> FlightSettings:
        return self._mirror.settings

    @property
    def fence(self) -> Fence | None:
        return self._watches.fence

    @property
    def latest(self) -> TelemetrySample | None:
        return self._mirror.latest

    @property
    def battery_pct(self) -> float:
        return self._mirror.battery_pct

    @property
    def breach(self) -> str | None:
        return self._watches.breach

    @property
    def below_floor_landing_m(self) -> float:
        return self._watches.below_floor_landing_m

    @property
    def clock(self) -> VehicleClock:
        return self._mirror.clock

    @property
    def local_clock(self) -> Clock:
        return self._mirror.local_clock

    @property
    def link(self) -> VehicleLink:
        return self._mirror.link

    # the connection and its mirror (Link)

    async def connect(self, url: str, timeout_s: float | None = None) -> None:
        await self._mirror.connect(url, timeout_s)

    async def close(self) -> None:
        await self._mirror.close()

    def mocap_plugin(self) -> Any:
        return self._mirror.mocap_plugin()

    def record_telemetry(self) -> AbstractContextManager[list[TelemetrySample]]:
        return self._mirror.record_telemetry()

    def clock_fit(self) -> ClockFit:
        return self._mirror.clock_fit()

    def notify(self) -> None:
        self._mirror.notify()

    # the safety watches (Watches)

    def add_watch(self, source: str, problem: Callable[[], str | None]) -> None:
        self._watches.add_watch(source, problem)

    def trip(self, source: str, reason: str) -> None:
        self._watches.trip(source, reason)

    def control_problem(self) -> str | None:
        return self._watches.control_problem()

    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
        await self._watches.wait_until(predicate, timeout_s, what)

    # parameters, origin, geofence (Params)

    async def read_int_params(self, names: tuple[str, ...]) -> dict[str, int | None]:
        return await self._params.read_int_params(names)

    async def read_float_param(self, name: str) -> float | None:
        return await self._params.read_float_param(name)

    async def read_all_params(self) -> dict[str, float | None]:
        return await self._params.read_all_params()

    async def set_params(self, values: dict[str, int | float]) -> None:
        await self._params.set_params(values)

    async def gps_global_origin(self) -> tuple[float, float, float]:
        return await self._params.gps_global_origin()

    async def set_global_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        await self._params.set_global_origin(lat_deg, lon_deg, alt_m)

    async def upload_inclusion_polygon(self, vertices_deg: list[tuple[float, float]]) -> None:
        await self._params.upload_inclusion_polygon(vertices_deg)

    # flying (Manoeuvres)

    async def wait_healthy_local_position(self, timeout_s: float | None = None) -> None:
        await self._manoeuvres.wait_healthy_local_position(timeout_s)

    async def leave_offboard_on_ground(self) -> bool:
        return await self._manoeuvres.leave_offboard_on_ground()

    async def arm_and_takeoff(self, altitude_m: float) -> None:
        await self._manoeuvres.arm_and_takeoff(altitude_m)

    async def send_setpoint(self, pos_ned_m: Any, yaw_deg: float | None = None) -> None:
        await self._manoeuvres.send_setpoint(pos_ned_m, yaw_deg)

    async def start_offboard_at_current_position(self, preroll_s: float = 1.0) -> None:
        await self._manoeuvres.start_offboard_at_current_position(preroll_s)

    async def goto(self, ned_m: Any, speed_m_s: float) -> None:
        await self._manoeuvres.goto(ned_m, speed_m_s)

    async def settle(self, ned_m: Any, tolerance_m: float, speed_tolerance_m_s: float) -> bool:
        return await self._manoeuvres.settle(ned_m, tolerance_m, speed_tolerance_m_s)

    async def hold(self, duration_s: float, what: str) -> list[TelemetrySample]:
        return await self._manoeuvres.hold(duration_s, what)

    async def hold_position(self) -> np.ndarray:
        return await self._manoeuvres.hold_position()

    async def hover_while(self, work: Awaitable[_T], what: str) -> _T:
        return await self._manoeuvres.hover_while(work, what)

    # coming down (Landing)

    async def land_and_disarm(self) -> None:
        await self._landing.land_and_disarm()

    async def emergency_stop(self, reason: str) -> str:
        return await self._landing.emergency_stop(reason)
