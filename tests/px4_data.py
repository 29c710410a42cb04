"""Recorded PX4 material of ``shared/`` (read-only, beside the checkout): runs and a capture.

``shared/data/px4-sitl/`` holds gcs run directories flown on PX4 v1.16 SITL (SIH quadrotor) with
GPS + EKF2 and with external vision; ``shared/data/px4-sih-offboard.tlog`` is a MAVLink capture
of the same firmware flown by MAVSDK (take-off, eights, hovers, steps, land; 193 s).
"""

from __future__ import annotations

import functools
import glob
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def shared() -> Path:
    """The shared directory: ``<repo>/../shared``, else ``/work/shared``."""
    beside = ROOT.parent / "shared"
    return beside if beside.is_dir() else Path("/work/shared")


@dataclass(frozen=True)
class Capture:
    """The vehicle's stream in the tlog.

    ``lpn``: LOCAL_POSITION_NED rows (receipt [s], time_boot_ms [s], x, y, z [m]);
    ``setpoints``: SET_POSITION_TARGET_LOCAL_NED rows (receipt [s], x, y, z [m]);
    ``params``: PARAM_VALUE integers by name (bytewise INT32 decoded).
    """

    lpn: np.ndarray
    setpoints: np.ndarray
    params: dict[str, int]


@functools.lru_cache(maxsize=1)
def capture() -> Capture:
    """Parse the tlog once per process (about 1.5 s)."""
    import struct

    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(shared() / "data" / "px4-sih-offboard.tlog"))
    lpn, sp, params = [], [], {}
    types = ["LOCAL_POSITION_NED", "SET_POSITION_TARGET_LOCAL_NED", "PARAM_VALUE"]
    while (msg := log.recv_match(type=types)) is not None:  # log.timestamp: tlog time of msg
        kind = msg.get_type()
        if kind == "LOCAL_POSITION_NED" and msg.get_srcSystem() == 1:
            lpn.append((log.timestamp, msg.time_boot_ms / 1000.0, msg.x, msg.y, msg.z))
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            sp.append((log.timestamp, msg.x, msg.y, msg.z))
        elif kind == "PARAM_VALUE" and msg.param_type == 6:
            value = struct.unpack("<i", struct.pack("<f", msg.param_value))[0]
            params[msg.param_id.rstrip("\x00")] = value
    return Capture(np.array(lpn), np.array(sp), params)


def capture_hovers(settle_s: float = 4.0) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The capture's hovers: every setpoint held for 8 s or more in the air, after ``settle_s``.

    Returns ``(t_vehicle_s (N,), pos_ned_m (N, 3), target_ned_m (3,))`` per hover.
    """
    cap = capture()
    sp, lpn = cap.setpoints, cap.lpn
    change = np.flatnonzero(np.any(np.abs(np.diff(sp[:, 1:], axis=0)) > 1e-4, axis=1)) + 1
    bounds = np.concatenate([[0], change, [len(sp)]])
    hovers = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        start, end, target = sp[a, 0], sp[b - 1, 0], sp[a, 1:]
        if end - start < 8.0 or target[2] > -1.0:
            continue
        inside = (lpn[:, 0] >= start + settle_s) & (lpn[:, 0] < end)
        hovers.append((lpn[inside, 1], lpn[inside, 2:5], target))
    return hovers


def sitl_hovers() -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """The first second of every PX4 SITL trial that hovered there (setpoints = start point).

    Returns ``(name, t_s (21,), pos_ned_m (21, 3), target_ned_m (3,))``; the name says GPS or
    vision by its folder.
    """
    out = []
    base = shared() / "data" / "px4-sitl"
    for path in sorted(glob.glob(str(base / "*" / "trial-*.csv"))):
        t = np.genfromtxt(path, delimiter=",", names=True)
        sp = np.column_stack([t["sp_north_m"], t["sp_east_m"], t["sp_down_m"]])
        ref = np.column_stack([t["ref_north_m"], t["ref_east_m"], t["ref_down_m"]])
        if not np.allclose(sp[:21], ref[0], atol=1e-3) or not np.allclose(ref[:21], ref[0]):
            continue  # learned setpoints move in the first second: not a hover
        pos = np.column_stack([t["pos_north_m"], t["pos_east_m"], t["pos_down_m"]])
        out.append((str(Path(path).relative_to(base)), t["t_s"][:21], pos[:21], ref[0]))
    return out


@functools.lru_cache(maxsize=1)
def capture_armed() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every LOCAL_POSITION_NED of the capture while PX4 was armed (take-off to landing).

    Returns ``(t_vehicle_s (N,), pos_ned_m (N, 3), vel_ned_m_s (N, 3))``, 30 Hz.
    """
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(shared() / "data" / "px4-sih-offboard.tlog"))
    rows, armed = [], False
    while (m := log.recv_match(type=["LOCAL_POSITION_NED", "HEARTBEAT"])) is not None:
        if m.get_srcSystem() != 1:
            continue
        if m.get_type() == "HEARTBEAT":
            armed = bool(m.base_mode & 128)
        elif armed:
            rows.append((m.time_boot_ms / 1e3, m.x, m.y, m.z, m.vx, m.vy, m.vz))
    a = np.array(rows)
    return a[:, 0], a[:, 1:4], a[:, 4:7]
