"""The mock drone's telemetry streams and replies (a part of :class:`gcs.mock.server.MockServer`).

Each stream (:data:`STREAMS`) has a rate (``RatesConfig``, or a SET_MESSAGE_INTERVAL) and goes
out when due after a physics step, so its timing jitter is at most one step. Without a local
position the mock sends no LOCAL_POSITION_NED, GLOBAL_POSITION_INT or ODOMETRY (PX4 sends them
only with ``xy_valid``), and in vision mode SYS_STATUS reports no GPS and the vision position
sensor healthy only while the local position is valid (what MAVSDK's
``is_local_position_ok`` reads).
"""

from __future__ import annotations

import math
import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from gcs.mock.transport import Transport
from gcs.mock.vehicle import encode_param

__all__ = ["STREAMS", "Streams"]

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


class Streams(Transport):
    """Telemetry streams and replies of :class:`gcs.mock.server.MockServer`."""

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
