"""External vision into the mock drone, as PX4's ``mavlink_receiver`` takes it.

A part of :class:`gcs.mock.server.MockServer`. ``ODOMETRY`` with ``frame_id`` LOCAL_NED or
LOCAL_FRD (ENU and FLU converted; any other frame, e.g. MAVSDK's MOCAP_NED, leaves the position
unset) and ``estimator_type`` UNKNOWN, NAIVE, VISION or VIO goes to EKF2; ``estimator_type``
MOCAP goes to PX4's ``vehicle_mocap_odometry``, which EKF2 does not read (the mock counts it and
fuses nothing); ``VISION_POSITION_ESTIMATE`` is NED. Every sample is stamped on arrival (PX4's
``sync_stamp`` without a converged time sync) and handed to the vehicle
(:meth:`gcs.mock.vehicle.Vehicle.on_vision`).
"""

from __future__ import annotations

import math
import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from gcs.mock.transport import Transport

__all__ = ["Vision"]

#: ODOMETRY estimator types PX4 publishes as visual odometry (EKF2's input).
_EV_ESTIMATORS = (
    mavlink2.MAV_ESTIMATOR_TYPE_UNKNOWN, mavlink2.MAV_ESTIMATOR_TYPE_NAIVE,
    mavlink2.MAV_ESTIMATOR_TYPE_VISION, mavlink2.MAV_ESTIMATOR_TYPE_VIO,
)  # fmt: skip
_VISION_KEYS = (
    "t_rx_monotonic_s", "t_rx_vehicle_s", "time_usec", "message", "frame_id",
    "estimator_type", "quality", "north_m", "east_m", "down_m", "fused",
)  # fmt: skip


class Vision(Transport):
    """External vision of :class:`gcs.mock.server.MockServer`."""

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
