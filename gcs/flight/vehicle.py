"""One connection to a PX4 multirotor, flown by position setpoints in local NED.

:class:`Vehicle` is the one object the flight layer flies. It is built from two injected parts
and rooms of one purpose:

- the link (:class:`gcs.flight.backend.VehicleLink`): MAVSDK's (:mod:`gcs.flight.mavsdk_link`)
  by default, chosen by the URL when connecting, or one given at construction (a simulated
  link in the tests);
- the local clock (:class:`gcs.flight.clock.Clock`: ``now``, ``sleep``): every receipt time,
  deadline and wait of the flight layer reads it; the link's (the wall clock on the wire, the
  virtual clock of a simulated link) unless one is given;

and the rooms, each a part of the class in its own module:

- :mod:`gcs.flight.link`: the connection, the command timeout and the mirror of the vehicle's
  state (the ``_watch_*`` coroutines), position samples on the vehicle's clock;
- :mod:`gcs.flight.watches`: the safety watches (the fence's estimate monitor, :meth:`add_watch`,
  the breach) and the waits that end on one;
- :mod:`gcs.flight.params`: parameters, the global origin and the geofence upload;
- :mod:`gcs.flight.manoeuvres`: take-off, offboard, moves, settling and holds, every setpoint
  through :meth:`send_setpoint` (which refuses one outside the arena);
- :mod:`gcs.flight.landing`: landing and the emergency stop.

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
import math

from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState

from gcs.flight.backend import VehicleLink
from gcs.flight.clock import WALL_CLOCK, Clock, VehicleClock
from gcs.flight.fence import EstimateMonitor, Fence
from gcs.flight.landing import Landing
from gcs.flight.params import Params
from gcs.io.settings import FlightSettings

__all__ = ["Vehicle"]


class Vehicle(Landing, Params):
    """A PX4 multirotor behind one MAVSDK connection.

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
        self.settings = settings
        self.fence = fence
        self._link_given = link
        self._link = None
        self._clock_given = clock
        self.local_clock = clock if clock is not None else WALL_CLOCK
        # the link and its mirror of the vehicle's state (link.py)
        self.url = None
        self.connected = False
        self.latest = None
        self.flight_mode = FlightMode.UNKNOWN
        self.armed = False
        self._arm_requested = False
        self.landed_state = LandedState.UNKNOWN
        self.local_position_ok = False
        self.battery_pct = math.nan  # remaining charge [%]; NaN until reported
        self.clock = VehicleClock(window_s=10.0)
        self._changed = asyncio.Event()
        self._recorders = []
        self._tasks = []
        # the safety watches (watches.py)
        self.breach = None
        self._monitor = EstimateMonitor(fence) if fence is not None else None
        self._watches = []
        # the setpoints (manoeuvres.py, landing.py)
        self.target_ned_m = None
        self._streaming_stopped = False
        self._offboard_started = False
