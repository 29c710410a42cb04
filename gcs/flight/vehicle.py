"""One MAVSDK connection to a PX4 multirotor, flown by position setpoints in local NED.

:class:`Vehicle` is the one object the flight layer flies; it is made of rooms of one purpose,
each a part of the class in its own module:

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

from gcs.flight.clock import VehicleClock
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
    """

    def __init__(self, settings: FlightSettings, fence: Fence | None = None) -> None:
        self.settings = settings
        self.fence = fence
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
        self._mavsdk = self._system = None
        self._action = self._offboard = self._telemetry = self._direct = None
        # the safety watches (watches.py)
        self.breach = None
        self._monitor = EstimateMonitor(fence) if fence is not None else None
        self._watches = []
        # the setpoints (manoeuvres.py, landing.py)
        self.target_ned_m = None
        self._streaming_stopped = False
        self._offboard_started = False
