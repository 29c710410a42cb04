"""What the mock drone receives: setpoints, commands, parameters, time sync.

A part of :class:`gcs.mock.server.MockServer`. Each MAVLink message is handed to the method
``_on_<message name>`` of the server, if it has one (external vision in :mod:`gcs.mock.vision`,
the fence transfer in :mod:`gcs.mock.missions`). Setpoints are time-stamped on arrival and
handed to the vehicle after the physics has caught up to that instant.
"""

from __future__ import annotations

import math
import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from gcs.mock.streams import _ID_TO_STREAM, Streams
from gcs.mock.vehicle import MODE_FROM_CUSTOM, MavResult

__all__ = ["Commands"]

_FORCE_MAGIC = 21196


class Commands(Streams):
    """Reception and commands of :class:`gcs.mock.server.MockServer`."""

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

    def _on_set_gps_global_origin(self, msg: Any) -> None:
        if msg.target_system not in (0, self.sysid):
            return
        if self.vehicle.set_origin(msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3):
            self._send_gps_global_origin()
