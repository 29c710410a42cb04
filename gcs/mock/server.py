"""MAVLink 2 UDP endpoint of the mock drone (pymavlink), in real time.

One process, one thread, one UDP socket bound on ``127.0.0.1:PORT``. The GCS connects with
``udpout://127.0.0.1:PORT``: MAVSDK sends its HEARTBEAT first, the mock learns the reply
address from it and answers with a HEARTBEAT at once. ``gcs_port`` additionally sends
everything to a GCS listening on that port (QGroundControl style).

The loop sleeps in ``select`` until the next physics step (``dt_s``, on a grid of the
monotonic clock, so there is no drift) or the next delayed datagram, whichever comes first;
a datagram wakes it at once. Telemetry that is due goes out after each physics step, so a
stream's timing jitter is at most one step. Setpoints are time-stamped on
arrival and handed to the vehicle after the physics has caught up to that instant.

Vehicle time. The vehicle's clock is ``Faults.clock_rate`` times the monotonic clock since
boot (1 by default): the physics, the PX4 timeouts, the stream periods and every time stamp
sent (``time_boot_ms``, ``time_usec``, TIMESYNC) run on it, as in a simulator that is slower
(or faster) than real time. Only the injected link latency is wall time.

External vision, as PX4's ``mavlink_receiver`` takes it: ``ODOMETRY`` with ``frame_id``
LOCAL_NED or LOCAL_FRD (ENU and FLU converted; any other frame, e.g. MAVSDK's MOCAP_NED, leaves
the position unset) and ``estimator_type`` UNKNOWN, NAIVE, VISION or VIO goes to EKF2;
``estimator_type`` MOCAP goes to PX4's ``vehicle_mocap_odometry``, which EKF2 does not read
(the mock counts it and fuses nothing); ``VISION_POSITION_ESTIMATE`` is NED. Every sample is
stamped on arrival (PX4's ``sync_stamp`` without a converged time sync) and handed to the
vehicle (:meth:`gcs.mock.vehicle.Vehicle.on_vision`). Without a local position the mock sends
no LOCAL_POSITION_NED, GLOBAL_POSITION_INT or ODOMETRY (PX4 sends them only with
``xy_valid``), and in vision mode SYS_STATUS reports no GPS and the vision position sensor
healthy only while the local position is valid (what MAVSDK's ``is_local_position_ok`` reads).

The arena (:mod:`gcs.mock.mocap.arena`): with ``arena`` options a mock OptiTrack Motive serves
the vehicle's true pose, published after every physics step.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
import random
import select
import socket
import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from gcs.mock.config import Faults, MockConfig
from gcs.mock.estimator import injected_faults
from gcs.mock.geofence import FenceItem, FenceTransfer, Reply
from gcs.mock.mocap.arena import Arena, ArenaOptions, quat_from_euler
from gcs.mock.vehicle import MODE_FROM_CUSTOM, MavResult, Vehicle, encode_param

__all__ = ["MockServer", "STREAMS", "TRUTH_PERIOD_S"]

# stream name -> MAVLink message id (rates in RatesConfig are named <stream>_hz)
STREAMS = {
    "heartbeat": 0,
    "sys_status": 1,
    "system_time": 2,
    "ping": 4,
    "gps_raw_int": 24,
    "attitude": 30,
    "attitude_quaternion": 31,
    "local_position_ned": 32,
    "global_position_int": 33,
    "vfr_hud": 74,
    "position_target_local_ned": 85,
    "battery_status": 147,
    "home_position": 242,
    "extended_sys_state": 245,
    "odometry": 331,
}
_ID_TO_STREAM = {v: k for k, v in STREAMS.items()}
# Streams that a telemetry dropout silences (heartbeats and replies keep going).
_TELEMETRY = set(STREAMS) - {"heartbeat", "ping"}

# SYS_STATUS sensor bits of the PX4 v1.16 SIH capture; PREARM_CHECK follows the arming checks.
_SENSORS_PRESENT = 50348079
_SENSORS_ENABLED = 50413615
_SENSORS_HEALTH = 52480063
_PREARM_CHECK = 0x10000000
_GPS_BIT = mavlink2.MAV_SYS_STATUS_SENSOR_GPS
_VISION_BIT = mavlink2.MAV_SYS_STATUS_SENSOR_VISION_POSITION
#: ODOMETRY estimator types PX4 publishes as visual odometry (EKF2's input).
_EV_ESTIMATORS = (
    mavlink2.MAV_ESTIMATOR_TYPE_UNKNOWN, mavlink2.MAV_ESTIMATOR_TYPE_NAIVE,
    mavlink2.MAV_ESTIMATOR_TYPE_VISION, mavlink2.MAV_ESTIMATOR_TYPE_VIO,
)  # fmt: skip
_VISION_KEYS = (
    "t_rx_monotonic_s", "t_rx_vehicle_s", "time_usec", "message", "frame_id",
    "estimator_type", "quality", "north_m", "east_m", "down_m", "fused",
)  # fmt: skip
TRUTH_PERIOD_S = 0.02
"""Period of the truth-and-error record in the statistics (vehicle time) [s]."""
_TRUTH_KEYS = (
    "t_vehicle_s", "north_m", "east_m", "down_m", "err_north_m", "err_east_m", "err_down_m",
    "err_vn_m_s", "err_ve_m_s", "err_vd_m_s", "vn_m_s", "ve_m_s", "vd_m_s",
)  # fmt: skip
_MISSION_PLANNER = 190  # MAV_COMP_ID_MISSIONPLANNER, also addressed by mission messages
_FORCE_MAGIC = 21196


class _Writer:
    """File-like sink that pymavlink's ``*_send`` methods write packed datagrams into."""

    def __init__(self, server: MockServer) -> None:
        self.server = server

    def write(self, buf: bytes) -> None:
        self.server._transmit(bytes(buf))


class MockServer:
    """The mock drone's MAVLink endpoint and real-time loop.

    Parameters
    ----------
    cfg : MockConfig
        Vehicle configuration.
    faults : Faults
        Injected faults.
    seed : int
        Seed of gusts, noise and packet loss.
    port : int
        UDP port to bind on 127.0.0.1 (0 = ephemeral).
    gcs_port : int or None
        Also send to 127.0.0.1:gcs_port.
    arena : ArenaOptions or None
        Serve the vehicle's true pose over NatNet (a mock OptiTrack Motive), started here.
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
        self.mav = mavlink2.MAVLink(_Writer(self), srcSystem=self.sysid, srcComponent=1)
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
        self._truth: dict[str, list[float]] | None = None
        if self.vehicle.physics.estimator is not None:
            self._truth = {key: [] for key in _TRUTH_KEYS}
        self._truth_next_t = 0.0
        # external vision received (ODOMETRY, VISION_POSITION_ESTIMATE), one row per message
        self._vision: dict[str, list[Any]] = {key: [] for key in _VISION_KEYS}
        self.arena: Arena | None = None
        if arena is not None:
            self.arena = Arena(arena)
            self._publish_truth()
            self.arena.start()

    # -- public ---------------------------------------------------------------------------
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

        Parameters
        ----------
        duration_s : float or None
            Stop after this many seconds (None: until stopped).
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

        Returns
        -------
        dict
            JSON-serialisable; see ``docs/mock.md`` for the fields.
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

    def _geofence_stats(self) -> dict[str, Any]:
        """The fence stored and in force, its parameters, uploads and breaches."""
        v, transfer = self.vehicle, self.fence_transfer
        return {
            "items": [dataclasses.asdict(i) for i in transfer.items],
            "areas_in_force": len(v.geofence.areas),
            "uploads": transfer.uploads,
            "clears": transfer.clears,
            "params": {n: v.params[n] for n in ("GF_ACTION", "GF_MAX_HOR_DIST", "GF_MAX_VER_DIST")},
            "breaches": v.gf_breaches,
        }

    def _vision_stats(self) -> dict[str, Any]:
        """External vision received and what became of it; the local position's validity."""
        v = self.vehicle
        vision = v.vision
        return {
            "enabled": vision is not None,
            "fused": None if vision is None else vision.fused,
            "rejected": None if vision is None else vision.rejected,
            "resets": None if vision is None else vision.resets,
            "local_position": v.lpos_log,
            **self._vision,
        }

    def _truth_stats(self) -> dict[str, Any] | None:
        """The estimator's truth record (None without an estimator)."""
        est = self.vehicle.physics.estimator
        if self._truth is None or est is None:
            return None
        return {"period_s": TRUTH_PERIOD_S, "resets": est.resets, **self._truth}

    def _record_truth(self) -> None:
        ph = self.vehicle.physics
        est = ph.estimator
        if self._truth is None or est is None or ph.t_s < self._truth_next_t - 1e-9:
            return
        self._truth_next_t = ph.t_s + TRUTH_PERIOD_S
        row = (ph.t_s, *ph.pos, *est.pos_err_m, *est.vel_err_m_s, *ph.vel)
        for key, value in zip(_TRUTH_KEYS, row, strict=True):
            self._truth[key].append(value)

    # -- time -----------------------------------------------------------------------------
    def _t(self, now: float | None = None) -> float:
        """Vehicle time [s] at a monotonic time (default: now)."""
        return ((time.monotonic() if now is None else now) - self.t0) * self.clock_rate

    def _wall(self, t_s: float) -> float:
        """Monotonic time [s] of a vehicle time."""
        return self.t0 + t_s / self.clock_rate

    def _t_offboard(self) -> float | None:
        first = self.vehicle.first_offboard_t_s
        return None if first is None else self._t() - first

    def _publish_truth(self) -> None:
        """Hand the arena the vehicle's true pose (its mocap serves it)."""
        arena = self.arena
        if arena is None:
            return
        ph = self.vehicle.physics
        roll, pitch, yaw, *_ = ph.attitude()
        arena.publish(ph.pos, quat_from_euler(roll, pitch, yaw))
        if self.vehicle.first_offboard_t_s is not None:
            arena.on_first_offboard()

    def _advance(self, now: float) -> None:
        v = self.vehicle
        v.physics.wind_ne_m_s = self.faults.wind_ned_m_s(self._t_offboard())
        before = v.physics.t_s
        v.update(self._t(now))
        self._publish_truth()
        self._record_truth()
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

    # -- transport ------------------------------------------------------------------------
    def _transmit(self, buf: bytes) -> None:
        f = self.faults
        t_off = self._t_offboard()
        if f.link_lost(t_off) or (self._telemetry_now and f.dropout_active(t_off)):
            self.counts["tx_dropped"] += 1
            return
        if f.loss_fraction > 0 and self._fault_rng.random() < f.loss_fraction:
            self.counts["tx_dropped"] += 1
            return
        if f.latency_ms > 0:
            self._push_delayed("out", buf, None)
            return
        self._sendto(buf)

    def _sendto(self, buf: bytes) -> None:
        for peer in self.peers:
            try:
                self.sock.sendto(buf, peer)
                self.counts["tx"] += 1
            except OSError:
                pass  # nobody listening (ICMP port unreachable); UDP carries on

    def _push_delayed(self, kind: str, buf: bytes, addr: tuple[str, int] | None) -> None:
        self._delayed_seq += 1
        due = time.monotonic() + self.faults.latency_ms / 1000.0
        heapq.heappush(self._delayed, (due, self._delayed_seq, kind, buf, addr))

    def _release_delayed(self, now: float) -> None:
        while self._delayed and self._delayed[0][0] <= now:
            _, _, kind, buf, addr = heapq.heappop(self._delayed)
            if kind == "out":
                self._sendto(buf)
            else:
                assert addr is not None
                self._handle_datagram(buf, addr)

    def _drain(self) -> None:
        f = self.faults
        while True:
            try:
                data, addr = self.sock.recvfrom(4096)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue  # ICMP error from an earlier send
            self.counts["rx"] += 1
            if f.link_lost(self._t_offboard()) or (
                f.loss_fraction > 0 and self._fault_rng.random() < f.loss_fraction
            ):
                self.counts["rx_dropped"] += 1
                continue
            if f.latency_ms > 0:
                self._push_delayed("in", data, addr)
            else:
                self._handle_datagram(data, addr)

    # -- reception ------------------------------------------------------------------------
    def _handle_datagram(self, data: bytes, addr: tuple[str, int]) -> None:
        if addr not in self.peers:
            if len(self.peers) >= 4:
                self.peers.pop(0)
            self.peers.append(addr)
            self._send_heartbeat()
        try:
            msgs = self.parser.parse_buffer(data) or []
        except mavlink2.MAVError:
            return
        for msg in msgs:
            handler = getattr(self, f"_on_{msg.get_type().lower()}", None)
            if handler is not None:
                handler(msg)

    def _for_me(self, msg: Any) -> bool:
        return msg.target_system in (0, self.sysid) and msg.target_component in (0, 1)

    def _on_set_position_target_local_ned(self, msg: Any) -> None:
        if msg.target_system not in (0, self.sysid):
            return
        now = time.monotonic()
        t = self._t(now)
        v = self.vehicle
        self.sp_t.append(now)
        self.sp_t_vehicle.append(t)
        self.sp_values.append((msg.x, msg.y, msg.z, msg.yaw, msg.time_boot_ms, msg.type_mask))
        v.update(t)
        if msg.coordinate_frame == mavlink2.MAV_FRAME_LOCAL_NED and msg.type_mask & 0b111 == 0:
            yaw = math.nan if msg.type_mask & 1024 else msg.yaw  # NaN: keep the current yaw
            v.on_setpoint(t, (msg.x, msg.y, msg.z), yaw)
        elif v.setpoint is not None:
            # proof of life only: the mock flies position setpoints, not velocity/acceleration
            v.on_setpoint(t, v.setpoint.pos_ned_m, v.setpoint.yaw_rad)

    # -- external vision ----------------------------------------------------------------
    def _vision_sample(
        self, msg: Any, time_usec: int, frame: int, estimator: int, quality: int,
        pos: tuple[float, float, float] | None, to_ekf2: bool,
    ) -> None:  # fmt: skip
        """Record one external-vision message; hand its position to the vehicle's EKF2."""
        now = time.monotonic()
        t = self._t(now)
        v = self.vehicle
        v.update(t)
        north = frame not in (mavlink2.MAV_FRAME_LOCAL_FRD, mavlink2.MAV_FRAME_LOCAL_FLU)
        fused = to_ekf2 and pos is not None and v.on_vision(t, pos, north)
        n, e, d = pos if pos is not None else (math.nan,) * 3
        row = (now, t, time_usec, msg.get_type(), frame, estimator, quality, n, e, d, fused)
        for key, value in zip(_VISION_KEYS, row, strict=True):
            self._vision[key].append(value)
        self._after_update()

    def _on_odometry(self, msg: Any) -> None:
        if msg.get_srcSystem() == self.sysid:
            return  # another instance of ourselves
        x, y, z = msg.x, msg.y, msg.z
        frame = msg.frame_id
        pos: tuple[float, float, float] | None = None
        if not all(math.isfinite(c) for c in (x, y, z)):
            pos = None
        elif frame in (mavlink2.MAV_FRAME_LOCAL_NED, mavlink2.MAV_FRAME_LOCAL_FRD):
            pos = (x, y, z)  # FRD taken as NED: the mock's heading is the vision's
        elif frame == mavlink2.MAV_FRAME_LOCAL_ENU:
            pos = (y, x, -z)
        elif frame == mavlink2.MAV_FRAME_LOCAL_FLU:
            pos = (x, -y, -z)
        # other frames (MAVSDK's MOCAP_NED, 14, among them) leave the position unset
        estimator = msg.estimator_type
        if estimator not in _EV_ESTIMATORS and estimator != mavlink2.MAV_ESTIMATOR_TYPE_MOCAP:
            self.vehicle.events.append((2, f"ODOMETRY: estimator_type {estimator} unsupported"))
        # MOCAP goes to PX4's vehicle_mocap_odometry, which EKF2 does not read
        to_ekf2 = estimator in _EV_ESTIMATORS
        self._vision_sample(msg, msg.time_usec, frame, estimator, msg.quality, pos, to_ekf2)

    def _on_vision_position_estimate(self, msg: Any) -> None:
        pos = (msg.x, msg.y, msg.z)
        finite = all(math.isfinite(c) for c in pos)
        self._vision_sample(
            msg, msg.usec, mavlink2.MAV_FRAME_LOCAL_NED, -1, -1, pos if finite else None, True
        )

    # -- the fence transfer (MAV_MISSION_TYPE_FENCE, gcs.mock.geofence) --------------------
    def _for_missions(self, msg: Any) -> bool:
        return msg.target_system == self.sysid and msg.target_component in (
            0, 1, _MISSION_PLANNER,
        )  # fmt: skip

    def _mission_call(self, msg: Any, method: str, *args: Any) -> None:
        if not self._for_missions(msg):
            return
        v = self.vehicle
        v.update(self._t())
        sender = (msg.get_srcSystem(), msg.get_srcComponent())
        handler = getattr(self.fence_transfer, method)
        self._mission_replies(handler(v.t_s, sender, *args, msg.mission_type))
        self._after_update()

    def _on_mission_count(self, msg: Any) -> None:
        self._mission_call(msg, "on_count", msg.count)

    def _on_mission_item_int(self, msg: Any) -> None:
        item = FenceItem(msg.seq, msg.frame, msg.command, msg.param1, msg.x, msg.y, msg.z)
        self._mission_call(msg, "on_item", item)

    def _on_mission_request_list(self, msg: Any) -> None:
        self._mission_call(msg, "on_request_list")

    def _on_mission_request_int(self, msg: Any) -> None:
        self._mission_call(msg, "on_request", msg.seq)

    _on_mission_request = _on_mission_request_int  # answered with items in the INT form

    def _on_mission_ack(self, msg: Any) -> None:
        self._mission_call(msg, "on_ack", msg.type)

    def _on_mission_clear_all(self, msg: Any) -> None:
        self._mission_call(msg, "on_clear")

    def _mission_replies(self, replies: list[Reply]) -> None:
        for r in replies:
            target = r.target
            if r.kind == "request":
                self.mav.mission_request_int_send(*target, r.value, r.mission_type)
            elif r.kind == "ack":
                self.mav.mission_ack_send(*target, r.value, r.mission_type)
            elif r.kind == "count":
                self.mav.mission_count_send(*target, r.value, r.mission_type)
            elif r.kind == "item" and r.item is not None:
                i = r.item
                self.mav.mission_item_int_send(
                    *target, i.seq, i.frame, i.command, 0, 0, i.param1, 0.0, 0.0, 0.0,
                    i.x, i.y, i.z, r.mission_type,
                )  # fmt: skip
            elif r.kind == "text":
                self.vehicle.events.append((r.value, r.text))
            elif r.kind == "stored":
                self.vehicle.fence_stored(r.items)

    def _on_heartbeat(self, msg: Any) -> None:
        if msg.type == mavlink2.MAV_TYPE_GCS:  # not our own echo, not a companion computer
            t = self._t()
            self.vehicle.update(t)
            self.vehicle.on_gcs_heartbeat(t)

    def _on_command_long(self, msg: Any) -> None:
        if not self._for_me(msg):
            return
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6)
        self._command(msg.command, params + (msg.param7,), msg)

    def _on_command_int(self, msg: Any) -> None:
        if not self._for_me(msg):
            return
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z)
        self._command(msg.command, params, msg)

    def _command(self, command: int, p: tuple[float, ...], msg: Any) -> None:
        v = self.vehicle
        v.update(self._t())
        result = MavResult.UNSUPPORTED
        send_after: Any = None
        if command == mavlink2.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] == 1.0 or p[0] == 0.0:
                force = math.isfinite(p[1]) and round(p[1]) == _FORCE_MAGIC
                result = v.arm(p[0] == 1.0, force)
            else:
                result = MavResult.DENIED
        elif command == mavlink2.MAV_CMD_DO_SET_MODE:
            main = int(p[1]) if math.isfinite(p[1]) else -1
            sub = int(p[2]) if math.isfinite(p[2]) else 0
            mode = MODE_FROM_CUSTOM.get((main, sub if main == 4 else 0))
            if mode is None or not (int(p[0]) & 1 if math.isfinite(p[0]) else 0):
                result = MavResult.DENIED
            else:
                result = v.set_mode(mode)
        elif command == mavlink2.MAV_CMD_NAV_TAKEOFF:
            result = v.takeoff()
        elif command == mavlink2.MAV_CMD_NAV_LAND:
            result = v.land()
        elif command == mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._cmd_message_interval(p[0], p[1])
        elif command == mavlink2.MAV_CMD_GET_MESSAGE_INTERVAL:
            name = _ID_TO_STREAM.get(int(p[0])) if math.isfinite(p[0]) else None
            if name is not None:
                result = MavResult.ACCEPTED
                period = self._streams[name][0]
                interval = -1 if math.isinf(period) else int(period * 1e6)
                send_after = lambda: self.mav.message_interval_send(int(p[0]), interval)  # noqa: E731
        elif command == mavlink2.MAV_CMD_REQUEST_MESSAGE:
            msg_id = int(p[0]) if math.isfinite(p[0]) else -1
            sender = self._sender_for(msg_id)
            if msg_id == mavlink2.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN and self.vehicle.origin is None:
                sender = None  # PX4 denies a message it cannot send (no origin yet)
            result = MavResult.ACCEPTED if sender is not None else MavResult.DENIED
            send_after = sender
        elif command == mavlink2.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            result = MavResult.ACCEPTED
            send_after = self._send_autopilot_version
        if send_after is not None:
            send_after()
        self.mav.command_ack_send(command, int(result), 0, 0, msg.get_srcSystem(),
                                  msg.get_srcComponent())  # fmt: skip
        self._after_update()

    def _cmd_message_interval(self, msg_id: float, interval_us: float) -> MavResult:
        if not (math.isfinite(msg_id) and math.isfinite(interval_us)):
            return MavResult.DENIED
        name = _ID_TO_STREAM.get(int(msg_id))
        if name is None:
            return MavResult.DENIED
        if interval_us == 0:
            self._set_rate(name, getattr(self.cfg.rates, f"{name}_hz"))
        elif interval_us < 0:
            self._set_rate(name, 0.0)
        else:
            self._set_rate(name, 1e6 / interval_us)
        return MavResult.ACCEPTED

    def _sender_for(self, msg_id: int) -> Any:
        if msg_id == mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return self._send_autopilot_version
        if msg_id == mavlink2.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN:
            return self._send_gps_global_origin
        name = _ID_TO_STREAM.get(msg_id)
        return None if name is None else getattr(self, f"_send_{name}")

    def _on_param_request_read(self, msg: Any) -> None:
        if not self._for_me(msg):
            return
        params = self.vehicle.params
        if msg.param_index >= 0:
            if msg.param_index < len(params):
                self._send_param(params.names[msg.param_index])
        else:
            name = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) else ""
            if params.get(name) is not None:
                self._send_param(name)

    def _on_param_request_list(self, msg: Any) -> None:
        if self._for_me(msg):
            for name in self.vehicle.params.names:
                self._send_param(name)

    def _on_param_set(self, msg: Any) -> None:
        if not self._for_me(msg):
            return
        name = msg.param_id.rstrip("\x00")
        if self.vehicle.params.set(name, msg.param_value) is not None:
            self._send_param(name)

    def _on_ping(self, msg: Any) -> None:
        if msg.target_system == 0:  # a request; replies to our own pings carry our id
            self.mav.ping_send(msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent())

    def _on_timesync(self, msg: Any) -> None:
        if msg.tc1 == 0:  # a request: answer with our clock (PX4: time since boot) in ns
            self.mav.timesync_send(int(self._t() * 1e9), msg.ts1)

    # -- transmission ---------------------------------------------------------------------
    def _set_rate(self, name: str, rate_hz: float) -> None:
        period = 1.0 / rate_hz if rate_hz > 0 else math.inf  # vehicle time, as PX4's streams
        self._streams[name] = [period, self._t() + min(period, 0.05)]

    def _send_streams(self, now: float) -> None:
        for name, stream in self._streams.items():
            if stream[1] <= now:
                period = stream[0]
                stream[1] += period
                if stream[1] < now:
                    stream[1] = now + period
                self._telemetry_now = name in _TELEMETRY
                getattr(self, f"_send_{name}")()
                self._telemetry_now = False

    def _measured(self) -> tuple[Any, Any]:
        ph = self.vehicle.physics
        if ph.t_s != self._meas_t:
            self._meas_t = ph.t_s
            self._meas = ph.measure()
        return self._meas

    def _boot_ms(self) -> int:
        return int(self.vehicle.t_s * 1000) & 0xFFFFFFFF

    def _attitude(self) -> tuple[float, ...]:
        roll, pitch, yaw, p, q, r = self.vehicle.physics.attitude()
        s = self.cfg.noise.att_sigma_rad
        g = self._att_rng.gauss
        return (roll + g(0, s), pitch + g(0, s), yaw + g(0, s), p, q, r)

    @staticmethod
    def _quaternion(roll: float, pitch: float, yaw: float) -> list[float]:
        cr, sr = math.cos(roll / 2), math.sin(roll / 2)
        cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
        cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
        return [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]

    def _global(self, pos: tuple[float, float, float]) -> tuple[int, int, float]:
        lat, lon, alt = self.vehicle.global_position(pos)
        return int(round(lat * 1e7)), int(round(lon * 1e7)), alt

    def _send_gps_global_origin(self) -> None:
        """The local frame's origin (PX4 sends it on request and when EKF2 sets it; nothing
        while it has none, as on vision only before SET_GPS_GLOBAL_ORIGIN)."""
        origin = self.vehicle.origin
        if origin is None:
            return
        self.mav.gps_global_origin_send(
            int(round(origin[0] * 1e7)), int(round(origin[1] * 1e7)),
            int(round(origin[2] * 1000)), int(self.vehicle.t_s * 1e6),
        )  # fmt: skip

    def _on_set_gps_global_origin(self, msg: Any) -> None:
        if msg.target_system not in (0, self.sysid):
            return
        if self.vehicle.set_origin(msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3):
            self._send_gps_global_origin()

    def _send_heartbeat(self) -> None:
        v = self.vehicle
        base = v.mode.base_mode | (128 if v.armed else 0)
        status = mavlink2.MAV_STATE_ACTIVE if v.armed else mavlink2.MAV_STATE_STANDBY
        self.mav.heartbeat_send(
            mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_PX4, base, v.mode.custom_mode,
            status, 3,
        )  # fmt: skip

    def _battery_pct(self) -> int:
        used = self.cfg.px4.battery_drain_pct_s * self.vehicle.armed_seconds()
        return max(0, int(round(100 - used)))

    def _send_sys_status(self) -> None:
        v = self.vehicle
        present, enabled = _SENSORS_PRESENT, _SENSORS_ENABLED
        health = _SENSORS_HEALTH | (_PREARM_CHECK if v.armable else 0)
        if v.vision is not None:  # no GPS; the vision position healthy while it is valid
            present = (present & ~_GPS_BIT) | _VISION_BIT
            enabled = (enabled & ~_GPS_BIT) | _VISION_BIT
            health = (health & ~_GPS_BIT) | (_VISION_BIT if v.local_position_valid else 0)
        self.mav.sys_status_send(
            present, enabled, health, 117, 16200, -100, self._battery_pct(),
            0, 0, 0, 0, 0, 0, 0, 0, 1,
        )  # fmt: skip

    def _send_system_time(self) -> None:
        self.mav.system_time_send(int(time.time() * 1e6), self._boot_ms())

    def _send_ping(self) -> None:
        self.mav.ping_send(int(self.vehicle.t_s * 1e6), self._ping_seq, 0, 0)
        self._ping_seq += 1

    def _send_gps_raw_int(self) -> None:
        if self.vehicle.vision is not None:
            return  # no GPS receiver indoors
        pos, vel = self._measured()
        lat, lon, alt = self._global(pos)
        speed = math.hypot(vel[0], vel[1])
        cog = int(math.degrees(math.atan2(vel[1], vel[0])) % 360 * 100)
        self.mav.gps_raw_int_send(
            int(self.vehicle.t_s * 1e6), 3, lat, lon, int(alt * 1000), 70, 110,
            int(speed * 100), cog, 10, int(alt * 1000), 900, 1780, 400, 0, 0,
        )  # fmt: skip

    def _send_attitude(self) -> None:
        self.mav.attitude_send(self._boot_ms(), *self._attitude())

    def _send_attitude_quaternion(self) -> None:
        roll, pitch, yaw, p, q, r = self._attitude()
        self.mav.attitude_quaternion_send(
            self._boot_ms(), *self._quaternion(roll, pitch, yaw), p, q, r, [0.0] * 4
        )

    def _send_local_position_ned(self) -> None:
        if not self.vehicle.local_position_valid:
            return  # PX4 sends it only with xy_valid and v_xy_valid
        pos, vel = self._measured()
        self.mav.local_position_ned_send(self._boot_ms(), *pos, *vel)

    def _send_global_position_int(self) -> None:
        if not self.vehicle.local_position_valid:
            return
        pos, vel = self._measured()
        lat, lon, alt = self._global(pos)
        rel = -(pos[2] - self.vehicle.home_ned_m[2])
        hdg = int(math.degrees(self.vehicle.physics.yaw_rad) % 360 * 100)
        self.mav.global_position_int_send(
            self._boot_ms(), lat, lon, int(alt * 1000), int(rel * 1000),
            int(vel[0] * 100), int(vel[1] * 100), int(vel[2] * 100), hdg,
        )  # fmt: skip

    def _send_vfr_hud(self) -> None:
        pos, vel = self._measured()
        ph = self.vehicle.physics
        heading = int(math.degrees(ph.yaw_rad) % 360)
        throttle = 0
        if self.vehicle.armed:
            thrust_g = (ph.cfg.physics.gravity_m_s2 - ph.acc[2]) / ph.cfg.physics.gravity_m_s2
            throttle = int(min(max(50 * thrust_g, 0), 100))
        alt = self.cfg.px4.home_alt_m - pos[2]
        self.mav.vfr_hud_send(0.0, math.hypot(vel[0], vel[1]), heading, throttle, alt, -vel[2])

    def _send_position_target_local_ned(self) -> None:
        tgt = self.vehicle.physics.target
        self.mav.position_target_local_ned_send(
            self._boot_ms(), mavlink2.MAV_FRAME_LOCAL_NED, 2552, *tgt.pos_ned_m,
            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, tgt.yaw_rad, 0.0,
        )  # fmt: skip

    def _send_battery_status(self) -> None:
        self.mav.battery_status_send(
            0, 1, 1, 32767, [16200] + [65535] * 9, -100, 0, -1, self._battery_pct(), 0, 1,
            [0] * 4, 0, 0,
        )  # fmt: skip

    def _send_home_position(self) -> None:
        home = self.vehicle.home_ned_m
        lat, lon, alt = self._global(home)
        self.mav.home_position_send(
            lat, lon, int(alt * 1000), *home, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
            int(self.vehicle.t_s * 1e6),
        )  # fmt: skip

    def _send_extended_sys_state(self) -> None:
        self.mav.extended_sys_state_send(0, int(self.vehicle.landed_state))

    def _send_odometry(self) -> None:
        if not self.vehicle.local_position_valid:
            return
        pos, vel = self._measured()
        roll, pitch, yaw, p, q, r = self._attitude()
        n = self.cfg.noise
        nan = float("nan")
        pose_cov = [nan] * 21
        pose_cov[0] = pose_cov[6] = pose_cov[11] = n.pos_sigma_m**2
        pose_cov[15] = pose_cov[18] = pose_cov[20] = n.att_sigma_rad**2
        vel_cov = [nan] * 21
        vel_cov[0] = vel_cov[6] = vel_cov[11] = n.vel_sigma_m_s**2
        self.mav.odometry_send(
            int(self.vehicle.t_s * 1e6), mavlink2.MAV_FRAME_LOCAL_NED,
            mavlink2.MAV_FRAME_LOCAL_NED, *pos, self._quaternion(roll, pitch, yaw), *vel,
            p, q, r, pose_cov, vel_cov, 0, 8, 0,
        )  # fmt: skip

    def _send_autopilot_version(self) -> None:
        custom = [0, 0, 0, 87, 145, 83, 163, 110]
        self.mav.autopilot_version_send(
            59647, 17826047, 17826047, 101854463, 1, custom, custom, [0] * 8, 0, 0,
            5283920058631409231, [0] * 18,
        )  # fmt: skip

    def _send_param(self, name: str) -> None:
        params = self.vehicle.params
        found = params.get(name)
        if found is None:
            return
        index, ptype, value = found
        self.mav.param_value_send(
            name.encode(), encode_param(value, ptype), ptype, len(params), index
        )
