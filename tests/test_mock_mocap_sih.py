"""The lab rig's receiver: PX4 SIH's HIL_STATE_QUATERNION over UDP to a NED pose."""

from __future__ import annotations

import math
import socket
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from gcs.mock.mocap.sih import SIH_DISPLAY_PORT, SihTruth, sih_display_port

LAT0, LON0, ALT0 = 47.397742, 8.545594, 488.0
R = 6_378_137.0


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def state(mav: mavlink2.MAVLink, north: float, east: float, up: float, vn: float = 0.0) -> bytes:
    lat = LAT0 + math.degrees(north / R)
    lon = LON0 + math.degrees(east / (R * math.cos(math.radians(LAT0))))
    half = math.radians(30.0) / 2  # yaw 30 deg
    msg = mav.hil_state_quaternion_encode(
        0, [math.cos(half), 0.0, 0.0, math.sin(half)], 0.0, 0.0, 0.0,
        round(lat * 1e7), round(lon * 1e7), round((ALT0 + up) * 1e3),
        round(vn * 100), 0, 0, 0, 0, 0, 0, 0,
    )  # fmt: skip
    return msg.pack(mav)


def test_instance_ports() -> None:
    assert sih_display_port(0) == SIH_DISPLAY_PORT == 19410 and sih_display_port(3) == 19413
    with pytest.raises(ValueError):
        sih_display_port(-1)


def test_states_become_ned_poses_from_the_first_one_carried_forward_with_their_velocity() -> None:
    port = free_port()
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    with (
        SihTruth(port, max_age_s=0.5) as truth,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out,
    ):
        assert truth(0.0) is None  # nothing yet: out of view
        out.sendto(state(mav, 0.0, 0.0, 0.0), ("127.0.0.1", port))
        assert truth.wait_first(5.0)
        sent = time.monotonic()
        out.sendto(state(mav, 2.0, -1.0, 1.5, vn=1.0), ("127.0.0.1", port))
        assert truth.wait_received(2, 5.0)
        pose = truth(0.0)
        assert pose is not None
        pos, quat = pose
        age = time.monotonic() - truth.latest.t_receipt_s
        # 1e-7 deg resolution: about 1 cm
        ahead = min(age, SihTruth.MAX_EXTRAPOLATION_S)  # then held: PX4's clock may stop
        np.testing.assert_allclose(pos, [2.0 + ahead, -1.0, -1.5], atol=0.02)
        assert time.monotonic() - sent < 5.0
        np.testing.assert_allclose(
            quat, [math.cos(math.radians(15)), 0, 0, math.sin(math.radians(15))], atol=1e-6
        )
        truth.max_age_s = 0.0
        assert truth(0.0) is None  # too old: out of view
