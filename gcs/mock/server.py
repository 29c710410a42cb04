"""MAVLink 2 UDP endpoint of the mock drone (pymavlink), in real time.

One process, one thread, one UDP socket bound on ``127.0.0.1:PORT``. The GCS connects with
``udpout://127.0.0.1:PORT``: MAVSDK sends its HEARTBEAT first, the mock learns the reply
address from it and answers with a HEARTBEAT at once. ``gcs_port`` additionally sends
everything to a GCS listening on that port (QGroundControl style).

The loop sleeps in ``select`` until the next physics step (``dt_s``, on a grid of the
monotonic clock, so there is no drift) or the next delayed datagram, whichever comes first;
a datagram wakes it at once. Telemetry that is due goes out after each physics step, so a
stream's timing jitter is at most one step.

:class:`MockServer` is made of rooms of one purpose, each a part of the class in its own module:
the transport, its link faults and the vehicle's clock (:mod:`gcs.mock.transport`), the
telemetry streams and replies (:mod:`gcs.mock.streams`), reception and commands
(:mod:`gcs.mock.commands`), external vision (:mod:`gcs.mock.vision`) and the fence transfer
(:mod:`gcs.mock.missions`). This module keeps the loop, the statistics and the truth.

The arena (:mod:`gcs.mock.mocap.arena`): with ``arena`` options a mock OptiTrack Motive serves
the vehicle's true pose, published after every physics step.
"""

from __future__ import annotations

import dataclasses
import math
import random
import select
import socket
import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from gcs.mock.commands import Commands
from gcs.mock.config import Faults, MockConfig
from gcs.mock.estimator import injected_faults
from gcs.mock.geofence import FenceTransfer
from gcs.mock.missions import Missions
from gcs.mock.mocap.arena import Arena, ArenaOptions, quat_from_euler
from gcs.mock.streams import STREAMS
from gcs.mock.transport import DatagramWriter
from gcs.mock.truth import TruthRecord
from gcs.mock.vehicle import Vehicle
from gcs.mock.vision import _VISION_KEYS, Vision

__all__ = ["MockServer"]


class MockServer(Commands, Vision, Missions):
    """The mock drone's MAVLink endpoint and real-time loop.

    ``seed``: seed of gusts, noise and packet loss. ``port``: UDP port to bind on 127.0.0.1 (0 =
    ephemeral). ``gcs_port``: also send to 127.0.0.1:gcs_port. ``arena``: serve the vehicle's true
    pose over NatNet (a mock OptiTrack Motive), started here.
    """

    def __init__(
        self,
        cfg: MockConfig,
        faults: Faults | None = None,
        seed: int = 0,
        port: int = 0,
        gcs_port: int | None = None,
        arena: ArenaOptions | None = None,
    ) -> None:
        self.cfg = cfg
        self.faults = faults or Faults()
        self.seed = seed
        self.sysid = cfg.px4.system_id
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", port))
        self.sock.setblocking(False)
        self.port: int = self.sock.getsockname()[1]
        self.peers: list[tuple[str, int]] = []
        if gcs_port is not None:
            self.peers.append(("127.0.0.1", gcs_port))
        self.mav = mavlink2.MAVLink(DatagramWriter(self), srcSystem=self.sysid, srcComponent=1)
        self.parser = mavlink2.MAVLink(None)
        self.parser.robust_parsing = True
        self.vehicle = Vehicle(cfg, seed, injected_faults(self.faults))
        self.fence_transfer = FenceTransfer()
        self.texts: list[dict[str, Any]] = []  # every STATUSTEXT sent, for the statistics
        self._fault_rng = random.Random(seed + 0xFA17)
        self._delayed: list[tuple[float, int, str, bytes, tuple[str, int] | None]] = []
        self._delayed_seq = 0
        self._telemetry_now = False
        self._stop = False
        self.t0 = time.monotonic()
        self.clock_rate = self.faults.clock_rate
        self._streams: dict[str, list[float]] = {}
        for name in STREAMS:
            self._set_rate(name, getattr(cfg.rates, f"{name}_hz"))
        self._ping_seq = 0
        self._meas_t = -1.0
        self._meas: tuple[Any, Any] = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        self._att_rng = random.Random(seed + 0xA77)
        # statistics
        self.sp_t: list[float] = []
        self.sp_t_vehicle: list[float] = []
        self.sp_values: list[tuple[float, float, float, float, int, int]] = []
        self.counts = {"rx": 0, "tx": 0, "rx_dropped": 0, "tx_dropped": 0, "steps": 0}
        self.max_lag_s = 0.0
        # the truth behind the estimate, every TRUTH_PERIOD_S of vehicle time (estimator on)
        self._truth = TruthRecord(self.vehicle.physics)
        # external vision received (ODOMETRY, VISION_POSITION_ESTIMATE), one row per message
        self._vision: dict[str, list[Any]] = {key: [] for key in _VISION_KEYS}
        self.arena: Arena | None = None
        if arena is not None:
            self.arena = Arena(arena)
            self._publish_truth()
            self.arena.start()

    @property
    def url(self) -> str:
        """MAVSDK connection URL of this mock."""
        return f"udpout://127.0.0.1:{self.port}"

    def stop(self) -> None:
        """Ask the loop to end (safe from a signal handler)."""
        self._stop = True

    def lose_link_now(self) -> None:
        """Start the link loss now, for ``link_loss_duration_s`` (``SIGUSR1``; signal-safe).

        For tests that time the loss on an event (a trial has started) rather than on the
        clock: the loop reads :attr:`faults` afresh every step, so one assignment starts it.
        Before the first OFFBOARD it starts with the first OFFBOARD, as timed faults do.
        """
        t = self._t_offboard()
        self.faults = dataclasses.replace(self.faults, link_loss_at_s=0.0 if t is None else t)

    def run(self, duration_s: float | None = None) -> None:
        """Run the real-time loop until :meth:`stop` (or for ``duration_s``).

        ``duration_s``: stop after this many seconds (None: until stopped).
        """
        dt = self.vehicle.physics.dt_s / self.clock_rate  # wall time per physics step
        t0 = self.t0
        end = math.inf if duration_s is None else time.monotonic() + duration_s
        next_tick = t0 + (math.floor((time.monotonic() - t0) / dt) + 1) * dt
        sock = self.sock
        while not self._stop and time.monotonic() < end:
            deadline = next_tick  # telemetry goes out on the physics grid: one wake-up per step
            if self._delayed:
                deadline = min(deadline, self._delayed[0][0])
            timeout = deadline - time.monotonic()
            if timeout > 0:
                readable, _, _ = select.select([sock], [], [], timeout)
            else:
                readable = [sock]
            if readable:
                self._drain()
            now = time.monotonic()
            self._release_delayed(now)
            if now >= next_tick:
                self._advance(now)
                next_tick = t0 + (math.floor((now - t0) / dt) + 1) * dt
            self._after_update()
            if self.peers:
                self._send_streams(self._t(now))
        self.sock.close()
        if self.arena is not None:
            self.arena.stop()

    def stats(self) -> dict[str, Any]:
        """Raw statistics of the run (setpoint arrivals, modes, counters).

        Returns: JSON-serialisable; see ``docs/mock.md`` for the fields.
        """
        v = self.vehicle
        cols = list(zip(*self.sp_values, strict=True)) if self.sp_values else [[]] * 6
        first = v.first_offboard_t_s
        return {
            "format": "gcs-mock-stats/1",
            "seed": self.seed,
            "port": self.port,
            "faults": dataclasses.asdict(self.faults),
            "boot_monotonic_s": self.t0,
            "clock_rate": self.clock_rate,
            "first_offboard_monotonic_s": None if first is None else self._wall(first),
            "setpoints": {
                "t_rx_monotonic_s": self.sp_t,
                "t_rx_vehicle_s": self.sp_t_vehicle,
                "north_m": list(cols[0]),
                "east_m": list(cols[1]),
                "down_m": list(cols[2]),
                "yaw_rad": list(cols[3]),
                "time_boot_ms": list(cols[4]),
                "type_mask": list(cols[5]),
            },
            "modes": [
                {
                    "t_monotonic_s": self._wall(m.t_s),
                    "t_vehicle_s": m.t_s,
                    "mode": m.mode,
                    "armed": m.armed,
                }  # fmt: skip
                for m in v.mode_log
            ],
            "packets": {k: self.counts[k] for k in ("rx", "tx", "rx_dropped", "tx_dropped")},
            "estimator": self._truth_stats(),
            "first_armed_vehicle_s": v.first_armed_t_s,
            "estimator_faults": [f.record() for f in v.faults],
            "geofence": self._geofence_stats(),
            "vision": self._vision_stats(),
            "arena": None if self.arena is None else self.arena.stats(),
            "statustexts": self.texts,
            "physics_steps": self.counts["steps"],
            "max_physics_lag_s": self.max_lag_s,
            "cpu_s": time.process_time(),
            "wall_s": time.monotonic() - self.t0,
        }

    def _truth_stats(self) -> dict[str, Any] | None:
        """The estimator's truth record (None without an estimator)."""
        est = self.vehicle.physics.estimator
        return None if est is None else self._truth.stats(resets=est.resets)

    def _publish_truth(self) -> None:
        """Hand the arena the vehicle's true pose (its mocap serves it)."""
        arena = self.arena
        if arena is None:
            return
        ph = self.vehicle.physics
        roll, pitch, yaw, *_ = ph.attitude()
        arena.publish(ph.pos, quat_from_euler(roll, pitch, yaw), ph.vel)
        if self.vehicle.first_offboard_t_s is not None:
            arena.on_first_offboard()

    def _advance(self, now: float) -> None:
        v = self.vehicle
        v.physics.wind_ne_m_s = self.faults.wind_ned_m_s(self._t_offboard())
        before = v.physics.t_s
        v.update(self._t(now))
        self._publish_truth()
        self._truth.record()
        steps = int(round((v.physics.t_s - before) / v.physics.dt_s))
        self.counts["steps"] += steps
        if steps > 1:
            self.max_lag_s = max(self.max_lag_s, (steps - 1) * v.physics.dt_s)

    def _after_update(self) -> None:
        v = self.vehicle
        self._mission_replies(self.fence_transfer.tick(v.t_s))
        if v.state_changed:
            v.state_changed = False
            self._send_heartbeat()
        while v.events:
            severity, text = v.events.pop(0)
            self.texts.append({"t_vehicle_s": v.t_s, "severity": severity, "text": text})
            self.mav.statustext_send(severity, text.encode()[:50], 0, 0)
