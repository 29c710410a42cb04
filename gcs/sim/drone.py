"""The mock drone in-process, flown through a simulated link on the event loop's clock.

:class:`SimulatedDrone` holds the mock's PX4-like commander and physics
(:class:`gcs.mock.vehicle.Vehicle`, with its estimator and faults) without the UDP endpoint;
:class:`SimLink` is a :class:`gcs.flight.backend.VehicleLink` to it that does what MAVSDK and
the mock's MAVLink endpoint (:mod:`gcs.mock.server`) do between them, by direct calls:

- the vehicle's time is the event loop's (``loop.time()``, a virtual clock under
  :func:`gcs.sim.loop.virtual_time`) times ``faults.clock_rate``, continued from where the
  previous connection left it; the physics is stepped up to it before anything is read or
  commanded;
- LOCAL_POSITION_NED at the requested rate, stamped with ``time_boot_ms`` (the
  measurement, with the estimator's error, only while the local position is valid); the flight
  mode, armed and landed states, local-position health, pre-arm verdict, battery and status
  texts as each changes;
- commands and their results (``COMMAND_DENIED`` for a rejection), parameters (PX4's
  bytewise INT32 encoding), the global origin and the fence (the inclusion polygon as the
  mock's fence items);
- MAVSDK's behaviour that the flight relies on: the last setpoint re-sent at 20 Hz once one
  was sent (until offboard is stopped), a ground-station heartbeat every second (the
  vehicle's data-link-loss failsafe watches it), the link declared lost after 3 s without a
  heartbeat, and a command sent while the link is down failing with ``TIMEOUT`` after 1.5 s;
- the mock's link faults on the vehicle's clock (``Faults``: link loss, telemetry dropout,
  gusts, clock rate; packet loss and latency are not modelled) and :meth:`SimulatedDrone.lose_link`
  to start a link loss on an event.

A drone is reached by the URL ``sim://NAME`` (:attr:`SimulatedDrone.url`) while it is open
(``with SimulatedDrone(...) as drone:``); :meth:`SimulatedDrone.stats` gives the mock's
statistics (modes, setpoint arrivals) in the same fields as the mock's file.
"""

from __future__ import annotations

import asyncio
import dataclasses
import itertools
import math
from collections.abc import AsyncIterator
from typing import Any

from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState

from gcs.errors import VehicleError
from gcs.flight.backend import (
    CommandRefused,
    PositionReport,
    VehicleLink,
    register_scheme,
    unregister_scheme,
)
from gcs.flight.clock import LoopClock
from gcs.mock.config import Faults, MockConfig
from gcs.mock.estimator import injected_faults
from gcs.mock.geofence import POLYGON_INCLUSION, FenceItem
from gcs.mock.truth import TruthRecord
from gcs.mock.vehicle import (
    MAV_PARAM_TYPE_INT32,
    MavResult,
    Mode,
    encode_param,
)
from gcs.mock.vehicle import LandedState as MockLanded
from gcs.mock.vehicle import Vehicle as MockVehicle

__all__ = ["SimLink", "SimulatedDrone"]

SCHEME = "sim"
HEARTBEAT_TIMEOUT_S = 3.0
"""MAVSDK declares the link lost after this long without a heartbeat [s]."""
COMMAND_TIMEOUT_S = 1.5
"""MAVSDK gives up a command after this long without an answer [s] (retries included)."""
RESEND_PERIOD_S = 0.05
"""MAVSDK re-sends the last offboard setpoint at 20 Hz."""
GCS_HEARTBEAT_PERIOD_S = 1.0
"""MAVSDK's ground-station heartbeat period [s]."""

_MODES = {
    Mode.POSCTL: FlightMode.POSCTL,
    Mode.HOLD: FlightMode.HOLD,
    Mode.TAKEOFF: FlightMode.TAKEOFF,
    Mode.LAND: FlightMode.LAND,
    Mode.OFFBOARD: FlightMode.OFFBOARD,
}
_LANDED = {
    MockLanded.UNDEFINED: LandedState.UNKNOWN,
    MockLanded.ON_GROUND: LandedState.ON_GROUND,
    MockLanded.IN_AIR: LandedState.IN_AIR,
    MockLanded.TAKEOFF: LandedState.TAKING_OFF,
    MockLanded.LANDING: LandedState.LANDING,
}
_RESULTS = {
    MavResult.TEMPORARILY_REJECTED: "COMMAND_DENIED",
    MavResult.DENIED: "COMMAND_DENIED",
    MavResult.UNSUPPORTED: "UNSUPPORTED",
    MavResult.FAILED: "FAILED",
}
_DRONES: dict[str, SimulatedDrone] = {}
_NAMES = itertools.count(1)


def _open(url: str) -> VehicleLink:
    name = url.split("://", 1)[1]
    drone = _DRONES.get(name)
    if drone is None:
        from gcs.flight.backend import LinkUnreachable

        raise LinkUnreachable(f"no simulated drone {name!r} is open")
    return SimLink(drone)


class _Topic:
    """One stream to every subscriber (a queue each), the newest value kept for new ones."""

    def __init__(self) -> None:
        self.queues: list[asyncio.Queue[Any]] = []
        self.last: Any = None

    def publish(self, value: Any, only_changes: bool = True) -> None:
        if only_changes and value == self.last:
            return
        self.last = value
        for queue in self.queues:
            queue.put_nowait(value)

    async def subscribe(self, replay: bool = True) -> AsyncIterator[Any]:
        queue: asyncio.Queue[Any] = asyncio.Queue()
        if replay and self.last is not None:
            queue.put_nowait(self.last)
        self.queues.append(queue)
        try:
            while True:
                yield await queue.get()
        finally:
            self.queues.remove(queue)


class SimulatedDrone:
    """The mock drone without its UDP endpoint, reached by ``sim://NAME`` while open.

    ``cfg``: the mock's settings; None: the defaults. ``faults``: injected faults (times after the
    first OFFBOARD, on the vehicle's clock).
    """

    def __init__(
        self, cfg: MockConfig | None = None, faults: Faults | None = None, seed: int = 0
    ) -> None:
        self.cfg = cfg if cfg is not None else MockConfig()
        self.faults = faults if faults is not None else Faults()
        self.seed = seed
        self.vehicle = MockVehicle(self.cfg, seed, injected_faults(self.faults))
        self.name = f"drone{next(_NAMES)}"
        self.texts: list[dict[str, Any]] = []
        self.setpoints: list[tuple[float, float, float, float, float]] = []
        self.fence_items: tuple[FenceItem, ...] = ()
        self.fence_uploads = 0
        self.connections = 0
        # the truth behind the estimate, every TRUTH_PERIOD_S of vehicle time (as the mock's)
        self._truth = TruthRecord(self.vehicle.physics)

    @property
    def url(self) -> str:
        """The URL that reaches it: ``sim://NAME``."""
        return f"{SCHEME}://{self.name}"

    def __enter__(self) -> SimulatedDrone:
        _DRONES[self.name] = self
        register_scheme(SCHEME, _open)
        return self

    def __exit__(self, *exc: object) -> None:
        _DRONES.pop(self.name, None)
        if not _DRONES:
            unregister_scheme(SCHEME)

    # -- time and faults
    def t_offboard(self) -> float | None:
        """Vehicle time since the first OFFBOARD [s] (None before it)."""
        first = self.vehicle.first_offboard_t_s
        return None if first is None else self.vehicle.t_s - first

    def link_up(self) -> bool:
        """Whether the link carries anything now (no link-loss fault in force)."""
        return not self.faults.link_lost(self.t_offboard())

    def telemetry_up(self) -> bool:
        """Whether streamed telemetry gets through now (link up, no dropout)."""
        return self.link_up() and not self.faults.dropout_active(self.t_offboard())

    def lose_link(self) -> None:
        """Start the link loss now, for ``faults.link_loss_duration_s`` (the mock's SIGUSR1).

        Before the first OFFBOARD it starts with the first OFFBOARD, as timed faults do.
        """
        t = self.t_offboard()
        self.faults = dataclasses.replace(self.faults, link_loss_at_s=0.0 if t is None else t)

    def advance(self, t_s: float) -> None:
        """Step the physics and the commander to vehicle time ``t_s``.

        ``t_s``: vehicle time [s]; earlier than now: nothing happens.
        """
        v = self.vehicle
        v.physics.wind_ne_m_s = self.faults.wind_ned_m_s(self.t_offboard())
        if self._truth.rows is None:
            v.update(t_s)
        else:  # step by step up to each record time, so the record is on the mock's grid
            ph = v.physics
            while ph.t_s + ph.dt_s <= t_s + 1e-9:
                v.update(ph.t_s + ph.dt_s)
                self._truth.record()
        while v.events:
            severity, text = v.events.pop(0)
            self.texts.append({"t_vehicle_s": v.t_s, "severity": severity, "text": text})

    def battery_pct(self) -> float:
        """Remaining charge as the mock reports it [%]."""
        used = self.cfg.px4.battery_drain_pct_s * self.vehicle.armed_seconds()
        return float(max(0, int(round(100 - used))))

    def stats(self) -> dict[str, Any]:
        """The mock's statistics, in the fields of its file that the tests read.

        Returns: ``clock_rate``, ``faults``, ``modes`` (``t_vehicle_s``, ``mode``, ``armed``),
        ``setpoints`` (``t_rx_vehicle_s``, ``north_m``, ``east_m``, ``down_m``, ``yaw_rad``),
        ``statustexts``, ``geofence`` (items, areas in force, parameters, breaches),
        ``first_armed_vehicle_s``, ``first_offboard_vehicle_s``, ``estimator`` (the truth and the
        estimate's error every 0.02 s) and ``estimator_faults``.
        """
        v = self.vehicle
        cols = list(zip(*self.setpoints, strict=True)) if self.setpoints else [()] * 5
        return {
            "clock_rate": self.faults.clock_rate,
            "faults": dataclasses.asdict(self.faults),
            "modes": [{"t_vehicle_s": m.t_s, "mode": m.mode, "armed": m.armed} for m in v.mode_log],
            "setpoints": {
                key: list(col)
                for key, col in zip(
                    ("t_rx_vehicle_s", "north_m", "east_m", "down_m", "yaw_rad"), cols, strict=True
                )
            },
            "statustexts": list(self.texts),
            "geofence": {
                "items": [dataclasses.asdict(i) for i in self.fence_items],
                "areas_in_force": len(v.geofence.areas),
                "uploads": self.fence_uploads,
                "params": {
                    n: v.params[n] for n in ("GF_ACTION", "GF_MAX_HOR_DIST", "GF_MAX_VER_DIST")
                },
                "breaches": list(v.gf_breaches),
            },
            "first_armed_vehicle_s": v.first_armed_t_s,
            "first_offboard_vehicle_s": v.first_offboard_t_s,
            "estimator": self._truth.stats(),
            "estimator_faults": [f.record() for f in v.faults],
        }


class SimLink(VehicleLink):
    """A :class:`gcs.flight.backend.VehicleLink` to a :class:`SimulatedDrone` (one connection)."""

    clock = LoopClock()

    def __init__(self, drone: SimulatedDrone) -> None:
        self.drone = drone
        self._topics = {
            name: _Topic()
            for name in (
                "positions", "connection", "mode", "armed", "landed", "lpos", "armable",
                "problems", "texts", "battery",
            )
        }  # fmt: skip
        self._task: asyncio.Task[None] | None = None
        self._anchor: tuple[float, float] = (0.0, drone.vehicle.t_s)  # (local, vehicle)
        self._position_period_s = 1.0 / drone.cfg.rates.local_position_ned_hz
        self._next_position_s = 0.0
        self._setpoint: tuple[tuple[float, float, float], float] | None = None
        self._last_send_s = -math.inf
        self._next_heartbeat_s = 0.0
        self._last_heard_s = 0.0
        self._connected = True
        self._texts_seen = len(drone.texts)

    # -- time
    def _t(self) -> float:
        """Vehicle time now (the loop's time at the drone's clock rate)."""
        local_s, vehicle_s = self._anchor
        return vehicle_s + (self.clock.now() - local_s) * self.drone.faults.clock_rate

    def _step(self) -> float:
        t = self._t()
        self.drone.advance(t)
        return t

    async def _run(self) -> None:
        """The simulator: step, stream, re-send, watch the heartbeat; one tick at a time."""
        drone = self.drone
        while True:
            t = self._step()
            now = self.clock.now()
            up = drone.link_up()
            if up:
                self._last_heard_s = now
                if t >= self._next_heartbeat_s:
                    self._next_heartbeat_s = t + GCS_HEARTBEAT_PERIOD_S * drone.faults.clock_rate
                    drone.vehicle.on_gcs_heartbeat(t)
                if self._setpoint is not None and now - self._last_send_s >= RESEND_PERIOD_S:
                    self._deliver_setpoint(t, now)
            connected = now - self._last_heard_s < HEARTBEAT_TIMEOUT_S
            if connected != self._connected:
                self._connected = connected
                self._topics["connection"].publish(connected)
            if up:  # HEARTBEAT (mode, armed) is not silenced by a telemetry dropout
                self._publish_heartbeat()
            if drone.telemetry_up():
                self._publish_state(t)
            period_s = min(self._position_period_s, RESEND_PERIOD_S * drone.faults.clock_rate)
            await asyncio.sleep(period_s / drone.faults.clock_rate)

    def _publish_state(self, t: float) -> None:
        v, topics = self.drone.vehicle, self._topics
        if t >= self._next_position_s and v.local_position_valid:
            self._next_position_s = t + self._position_period_s
            pos, vel = v.physics.measure()
            boot_s = (int(t * 1000) & 0xFFFFFFFF) / 1000.0
            report = PositionReport(boot_s, tuple(map(float, pos)), tuple(map(float, vel)))
            topics["positions"].publish(report, only_changes=False)
        topics["landed"].publish(_LANDED[v.landed_state])
        topics["lpos"].publish(v.local_position_valid)
        topics["armable"].publish(v.armable)
        problem = v.navigation_problem()
        topics["problems"].publish([] if problem is None else [problem])
        topics["battery"].publish(self.drone.battery_pct())
        texts = self.drone.texts
        for text in texts[self._texts_seen :]:
            topics["texts"].publish(text["text"], only_changes=False)
        self._texts_seen = len(texts)

    def _publish_heartbeat(self) -> None:
        v = self.drone.vehicle
        self._topics["mode"].publish(_MODES[v.mode])
        self._topics["armed"].publish(v.armed)

    def _deliver_setpoint(self, t: float, now: float) -> None:
        assert self._setpoint is not None
        pos, yaw_deg = self._setpoint
        self._last_send_s = now
        yaw_rad = math.radians(yaw_deg)
        self.drone.setpoints.append((t, *pos, yaw_rad))
        self.drone.vehicle.on_setpoint(t, pos, yaw_rad)

    # -- the protocol
    async def connect(self, url: str, timeout_s: float) -> bool:
        self.drone.connections += 1
        self._anchor = (self.clock.now(), self.drone.vehicle.t_s)
        self._last_heard_s = self.clock.now()
        self._publish_heartbeat()
        self._publish_state(self._step())
        self._topics["connection"].publish(True)
        self._task = asyncio.create_task(self._run(), name="gcs-sim-drone")
        return True

    async def close(self) -> None:
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)

    async def is_connected(self) -> bool:
        return self._connected

    def positions(self) -> AsyncIterator[PositionReport]:
        return self._topics["positions"].subscribe(replay=False)

    def connection_states(self) -> AsyncIterator[bool]:
        return self._topics["connection"].subscribe()

    def flight_modes(self) -> AsyncIterator[FlightMode]:
        return self._topics["mode"].subscribe()

    def armed_states(self) -> AsyncIterator[bool]:
        return self._topics["armed"].subscribe()

    def landed_states(self) -> AsyncIterator[LandedState]:
        return self._topics["landed"].subscribe()

    def local_position_health(self) -> AsyncIterator[bool]:
        return self._topics["lpos"].subscribe()

    def armable_states(self) -> AsyncIterator[bool]:
        return self._topics["armable"].subscribe()

    def arming_problems(self) -> AsyncIterator[list[str]]:
        return self._topics["problems"].subscribe()

    def status_texts(self) -> AsyncIterator[str]:
        return self._topics["texts"].subscribe(replay=False)

    def battery_levels(self) -> AsyncIterator[float]:
        return self._topics["battery"].subscribe()

    async def _exchange(self) -> float:
        """Wait out a command sent while the link is down (MAVSDK's timeout); vehicle time."""
        if not self.drone.link_up():
            await asyncio.sleep(COMMAND_TIMEOUT_S)
            raise CommandRefused("TIMEOUT")
        return self._step()

    async def _result(self, result: MavResult) -> None:
        if result is not MavResult.ACCEPTED:
            raise CommandRefused(_RESULTS.get(result, result.name))

    async def set_position_rate(self, rate_hz: float) -> None:
        await self._exchange()
        self._position_period_s = 1.0 / rate_hz

    async def set_landed_state_rate(self, rate_hz: float) -> None:
        await self._exchange()

    async def set_takeoff_altitude(self, altitude_m: float) -> None:
        await self.set_param_float("MIS_TAKEOFF_ALT", altitude_m)

    async def arm(self) -> None:
        await self._exchange()
        await self._result(self.drone.vehicle.arm(True))

    async def disarm(self) -> None:
        await self._exchange()
        await self._result(self.drone.vehicle.arm(False))

    async def takeoff(self) -> None:
        await self._exchange()
        await self._result(self.drone.vehicle.takeoff())

    async def land(self) -> None:
        await self._exchange()
        await self._result(self.drone.vehicle.land())

    async def start_offboard(self) -> None:
        if self._setpoint is None:
            raise CommandRefused("NO_SETPOINT_SET")
        await self._exchange()
        await self._result(self.drone.vehicle.set_mode(Mode.OFFBOARD))

    async def stop_offboard(self) -> None:
        await self._exchange()
        self._setpoint = None  # MAVSDK stops re-sending
        await self._result(self.drone.vehicle.set_mode(Mode.HOLD))

    async def set_position_ned(
        self, north_m: float, east_m: float, down_m: float, yaw_deg: float
    ) -> None:
        self._setpoint = ((north_m, east_m, down_m), yaw_deg)
        if self.drone.link_up():
            t = self._step()
            self._deliver_setpoint(t, self.clock.now())

    async def _param(self, name: str) -> tuple[int, int, float]:
        await self._exchange()
        found = self.drone.vehicle.params.get(name)
        if found is None:
            raise CommandRefused("TIMEOUT")  # PX4 does not answer for a name it lacks
        return found

    async def get_param_int(self, name: str) -> int:
        _, kind, value = await self._param(name)
        if kind != MAV_PARAM_TYPE_INT32:
            raise CommandRefused("WRONG_TYPE")
        return int(value)

    async def get_param_float(self, name: str) -> float:
        _, kind, value = await self._param(name)
        if kind == MAV_PARAM_TYPE_INT32:
            raise CommandRefused("WRONG_TYPE")
        return float(value)

    async def set_param_int(self, name: str, value: int) -> None:
        _, kind, _ = await self._param(name)
        if kind != MAV_PARAM_TYPE_INT32:
            raise CommandRefused("WRONG_TYPE")
        self.drone.vehicle.params.set(name, encode_param(value, kind))

    async def set_param_float(self, name: str, value: float) -> None:
        _, kind, _ = await self._param(name)
        if kind == MAV_PARAM_TYPE_INT32:
            raise CommandRefused("WRONG_TYPE")
        self.drone.vehicle.params.set(name, encode_param(value, kind))

    async def get_all_params(self) -> dict[str, float]:
        await self._exchange()
        params = self.drone.vehicle.params
        return {name: float(params[name]) for name in params.names}

    async def get_gps_global_origin(self) -> tuple[float, float, float]:
        await self._exchange()
        origin = self.drone.vehicle.origin
        if origin is None:
            raise CommandRefused("COMMAND_DENIED")  # PX4 has none to send yet
        return origin

    async def set_gps_global_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        await self._exchange()
        self.drone.vehicle.set_origin(lat_deg, lon_deg, alt_m)

    async def upload_inclusion_polygon(self, vertices_deg: list[tuple[float, float]]) -> None:
        await self._exchange()
        n = len(vertices_deg)
        items = tuple(
            FenceItem(i, 5, POLYGON_INCLUSION, float(n), round(lat * 1e7), round(lon * 1e7))
            for i, (lat, lon) in enumerate(vertices_deg)
        )
        self.drone.advance(self._t())
        self.drone.fence_items = items
        self.drone.fence_uploads += 1
        self.drone.vehicle.fence_stored(items)

    def mocap_plugin(self) -> Any:
        raise VehicleError("the simulated link forwards no motion capture (fly the mock over UDP)")
