"""The real-firmware tests' lab rig (tests/px4/lab_rig.py): PX4 SIH's HIL_STATE_QUATERNION over
UDP to a NED pose, served as it was at the time asked (interpolated between the states around
it, carried forward past the newest), through the mock Motive with a latency, and as a program
with the mock Motive's options.

Here in tests/ rather than beside the rig: they need no PX4 build (a synthetic SIH stream on
loopback), and tests/px4/ is collected only when one is there."""

from __future__ import annotations

import contextlib
import math
import socket
import struct
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
import typer
from px4.lab_rig import (
    SIH_DISPLAY_PORT,
    LabRig,
    SihTruth,
    rig_command,
    sih_display_port,
    state_time,
)
from pymavlink.dialects.v20 import common as mavlink2
from test_mocap_live import WAIT_S, natnet_frames

from gcs.core.frames import mapping_for, quat_angle_rad
from gcs.errors import MocapError
from gcs.mock.mocap.cli import mocap_command
from gcs.mock.mocap.server import CLOCK_HZ, NatNetServer

LAT0, LON0, ALT0 = 47.397742, 8.545594, 488.0
R = 6_378_137.0
# 1e-7 deg of latitude and longitude (1.1 cm, 0.75 cm) and 1 mm of altitude in the message
RESOLUTION_M = 0.02


def yaw_quat(yaw_rad: float) -> list[float]:
    return [math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2)]


def state(
    mav: mavlink2.MAVLink,
    north: float,
    east: float,
    up: float,
    vn: float = 0.0,
    ve: float = 0.0,
    vd: float = 0.0,
    yaw_rad: float = math.radians(30.0),
) -> bytes:
    lat = LAT0 + math.degrees(north / R)
    lon = LON0 + math.degrees(east / (R * math.cos(math.radians(LAT0))))
    msg = mav.hil_state_quaternion_encode(
        0, yaw_quat(yaw_rad), 0.0, 0.0, 0.0,
        round(lat * 1e7), round(lon * 1e7), round((ALT0 + up) * 1e3),
        round(vn * 100), round(ve * 100), round(vd * 100), 0, 0, 0, 0, 0,
    )  # fmt: skip
    return msg.pack(mav)


class Spiral:
    """The synthetic vehicle: a climbing circle from the origin, nose along its path, a state
    every 40 ms of its time (PX4 SIH's 25 Hz)."""

    radius_m = 3.0
    period_s = 3.0
    climb_m_s = 0.5
    step_s = 0.04

    def truth(self, tau: float) -> tuple[np.ndarray, float]:
        """Position from the first state [m, NED] and heading [rad] at time ``tau``."""
        phi = 2 * math.pi * tau / self.period_s
        pos = [
            self.radius_m * (math.cos(phi) - 1),
            self.radius_m * math.sin(phi),
            -self.climb_m_s * tau,
        ]
        return np.array(pos), phi + math.pi / 2

    def velocity(self, tau: float) -> np.ndarray:
        phi = 2 * math.pi * tau / self.period_s
        w = 2 * math.pi / self.period_s
        return np.array(
            [-self.radius_m * w * math.sin(phi), self.radius_m * w * math.cos(phi), -self.climb_m_s]
        )

    def message(self, mav: mavlink2.MAVLink, i: int) -> bytes:
        tau = i * self.step_s
        (north, east, down), yaw = self.truth(tau)
        vn, ve, vd = self.velocity(tau)
        return state(mav, north, east, -down, vn, ve, vd, yaw)


@contextlib.contextmanager
def streamed(count: int, epoch_s: float = 0.0) -> Iterator[tuple[SihTruth, Spiral]]:
    """A SihTruth that has received ``count`` states of the spiral over loopback."""
    spiral = Spiral()
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    with (
        SihTruth(0, max_age_s=0.5, epoch_s=epoch_s) as truth,  # a free port, held from here
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out,
    ):
        port = truth.port
        for i in range(count):
            out.sendto(spiral.message(mav, i), ("127.0.0.1", port))
        assert truth.wait_received(count, 5.0)
        assert len(truth.states) == count
        yield truth, spiral


def test_instance_ports() -> None:
    assert sih_display_port(0) == SIH_DISPLAY_PORT == 19410 and sih_display_port(3) == 19413
    with pytest.raises(ValueError):
        sih_display_port(-1)


def test_states_become_ned_poses_from_the_first_one_carried_forward_with_their_velocity() -> None:
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    with (
        SihTruth(0, max_age_s=WAIT_S) as truth,  # not out of view after a stall here
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out,
    ):
        port = truth.port
        assert truth(time.monotonic()) is None  # nothing yet: out of view
        out.sendto(state(mav, 0.0, 0.0, 0.0), ("127.0.0.1", port))
        assert truth.wait_first(5.0)
        sent = time.monotonic()
        out.sendto(state(mav, 2.0, -1.0, 1.5, vn=1.0), ("127.0.0.1", port))
        assert truth.wait_received(2, 5.0)
        now = time.monotonic()
        pose = truth(now)  # epoch 0: the time asked is the monotonic clock's
        assert pose is not None
        pos, quat = pose
        age = now - truth.latest.t_s
        ahead = min(age, SihTruth.MAX_EXTRAPOLATION_S)  # then held: PX4's clock may stop
        np.testing.assert_allclose(pos, [2.0 + ahead, -1.0, -1.5], atol=RESOLUTION_M)
        assert time.monotonic() - sent < 5.0
        np.testing.assert_allclose(
            quat, [math.cos(math.radians(15)), 0, 0, math.sin(math.radians(15))], atol=1e-6
        )
        truth.max_age_s = 0.0
        assert truth(time.monotonic()) is None  # too old: out of view


def test_a_time_between_two_states_is_served_as_the_truth_was_then() -> None:
    """Between the receipts of states i and i+1, a fraction w of the way: the spiral at
    (i + w) x 40 ms of its own time, within the message's resolution and the chord's sag
    (2.6 mm here), while the states are 25 cm apart."""
    with streamed(12) as (truth, spiral):
        receipts = [s.t_s for s in truth.states]
        assert all(b > a for a, b in zip(receipts, receipts[1:], strict=False))
        checked = 0
        for i in range(len(receipts) - 1):
            for w in (0.0, 0.25, 0.5, 0.9):
                t = receipts[i] + w * (receipts[i + 1] - receipts[i])
                pose = truth.pose_at(t)
                assert pose is not None
                pos, yaw = spiral.truth((i + w) * spiral.step_s)
                np.testing.assert_allclose(pose[0], pos, atol=RESOLUTION_M)
                assert quat_angle_rad(pose[1], np.array(yaw_quat(yaw))) < 1e-4
                checked += 1
        assert checked == 44


def test_past_the_newest_state_it_is_carried_forward_with_its_velocity_for_at_most_0_1_s() -> None:
    with streamed(5) as (truth, spiral):
        newest = truth.states[-1].t_s
        pos4, yaw4 = spiral.truth(4 * spiral.step_s)
        v4 = spiral.velocity(4 * spiral.step_s)
        most = SihTruth.MAX_EXTRAPOLATION_S
        for ahead, carried in ((0.03, 0.03), (0.05, 0.05), (0.3, most), (0.5, most)):
            pose = truth.pose_at(newest + ahead)
            assert pose is not None
            np.testing.assert_allclose(pose[0], pos4 + v4 * carried, atol=RESOLUTION_M)
            assert quat_angle_rad(pose[1], np.array(yaw_quat(yaw4))) < 1e-4
        assert truth.pose_at(newest + 0.51) is None  # older than max_age_s: out of view
        assert truth.pose_at(truth.states[0].t_s - 1e-3) is None  # before the first


def test_the_server_serves_the_truth_as_it_was_its_latency_before_each_frame() -> None:
    """The rig's wiring: the server and the receiver share an epoch; the frame at t carries
    the pose at t - 30 ms (between two states: the spiral then), and its mid-exposure stamp
    is 30 ms before the frame's instant."""
    latency = 0.03
    epoch = time.monotonic() - 10.0  # server time 0, ten seconds ago
    points = [(i, w) for i in range(7) for w in (0.2, 0.7)]  # state i, a fraction w to i+1
    with streamed(8, epoch_s=epoch) as (truth, spiral):
        receipts = [s.t_s for s in truth.states]
        server = NatNetServer(truth, noise_m=0.0, latency_s=latency, epoch_s=epoch)
        try:
            for k, (i, w) in enumerate(points):
                t_grid = receipts[i] + w * (receipts[i + 1] - receipts[i]) + latency
                server.send_frame(k, t_grid)
        finally:
            server.close()
    frames = list(server.sent)
    assert len(frames) == len(points)
    for frame, (i, w) in zip(frames, points, strict=True):
        pos, _ = spiral.truth((i + w) * spiral.step_s)
        np.testing.assert_allclose(frame.pos_m, pos, atol=RESOLUTION_M)
        assert frame.t_pose_s == pytest.approx(frame.t_s - latency, abs=1e-9)
        exposure_s = frame.stamps.mid_exposure_ticks / CLOCK_HZ
        assert exposure_s == pytest.approx(epoch + frame.t_s - latency, abs=1e-6)
        assert frame.stamps.data_received_ticks / CLOCK_HZ == pytest.approx(
            epoch + frame.t_s, abs=1e-6
        )


def test_a_state_that_arrives_late_is_dated_near_when_it_was_made() -> None:
    """States made every 40 ms; state 10 reaches the rig 50 ms late and 11 on time. Dated at
    their receipts, the served body would jump by its speed times 50 ms; dated by
    state_time, state 10 is 5 ms late (a tenth), and a stop of 0.5 s restarts the clock."""
    period = 0.04
    made = [k * period for k in range(20)]
    receipts = [t + (0.05 if k == 10 else 0.0) for k, t in enumerate(made)]
    dated: list[float] = []
    for k, r in enumerate(receipts):
        dated.append(state_time(dated[-1] if dated else None, r, period if k else None))
    assert dated[:10] == pytest.approx(made[:10], abs=1e-12)
    assert dated[10] - made[10] == pytest.approx(0.1 * 0.05, abs=1e-12)
    assert max(abs(d - m) for d, m in zip(dated[11:], made[11:], strict=True)) < 0.005
    assert all(b > a for a, b in zip(dated, dated[1:], strict=False))
    assert state_time(dated[-1], dated[-1] + period + 0.5, period) == dated[-1] + period + 0.5
    assert state_time(None, 3.0, period) == 3.0 and state_time(1.0, 3.0, None) == 3.0


def test_a_burst_of_states_is_dated_in_order_and_never_after_its_receipt() -> None:
    """States made every 40 ms, the first five on time, then ten held up by a stall and
    received 20 us apart: each is dated at most at its receipt and after the one before (the
    clock pulled a tenth of the way would otherwise run ahead of the receipts and back)."""
    receipts = [k * 0.04 for k in range(5)] + [0.36 + k * 20e-6 for k in range(10)]
    dated: list[float] = []
    for k, r in enumerate(receipts):
        intervals = np.diff(receipts[: k + 1])
        period = float(intervals.mean()) if intervals.size else None
        dated.append(state_time(dated[-1] if dated else None, r, period))
    assert all(d <= r for d, r in zip(dated, receipts, strict=True))
    assert all(b > a for a, b in zip(dated, dated[1:], strict=False))


def _free_udp(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


@pytest.mark.live  # a real rig process and NatNet in real time
def test_the_rig_serves_the_truth_as_it_was_its_latency_before() -> None:
    """The rig's program, ``N --latency-ms 40``, fed a synthetic SIH stream (25 Hz on N's
    display port, a vehicle going north at 2 m/s, stamped with this machine's monotonic clock
    as it is sent): each tracked frame shows the vehicle where it was at the frame's
    mid-exposure stamp, 40 ms before the frame's instant. The receiver times states by their
    receipt, so the figure is the median over the frames (a latency ignored would be 8 cm
    off); one frame alone is as late as the machine delivered its state."""
    instance = next(n for n in range(200, 300) if _free_udp(sih_display_port(n)))
    speed, lat0, lon0, alt0 = 2.0, 47.397742, 8.545594, 488.0
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    stop = threading.Event()
    t_first: list[float] = []

    def stream() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
            while not stop.is_set():
                now = time.monotonic()
                t_first[:1] = t_first[:1] or [now]
                lat = lat0 + math.degrees(speed * (now - t_first[0]) / 6_378_137.0)
                msg = mav.hil_state_quaternion_encode(
                    0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, round(lat * 1e7),
                    round(lon0 * 1e7), round(alt0 * 1e3), round(speed * 100), 0, 0, 0, 0, 0, 0, 0,
                )  # fmt: skip
                out.sendto(msg.pack(mav), ("127.0.0.1", sih_display_port(instance)))
                stop.wait(0.04)

    args = ["--rate", "100", "--natnet", "3.1", "--noise-mm", "0", "--latency-ms", "40"]
    with LabRig(instance, args) as mock:
        sender = threading.Thread(target=stream, daemon=True)
        sender.start()
        try:
            frames = natnet_frames(mock.url, 150)
        finally:
            stop.set()
            sender.join(WAIT_S)
    room = mapping_for("optitrack")
    body = 4 + 4 + 4 + len(b"drone\0") + 4 + 5 * 12 + 4 + 4  # one marker set, one body
    errors = []
    for data in frames:
        if struct.unpack_from("<i", data, 8)[0] == 0:  # no marker set: not tracked (yet)
            continue
        _, x, y, z, *_, params = struct.unpack_from("<i3f4ffh", data, body)
        assert params & 1
        _, exposure, received, _ = struct.unpack_from("<dQQQ", data, len(data) - 38)
        assert (received - exposure) / CLOCK_HZ == pytest.approx(0.040, abs=1e-6)
        north = room.position_to_ned(np.array([x, y, z]))[0]
        errors.append(north - speed * (exposure / CLOCK_HZ - t_first[0]))
    assert len(errors) >= 100
    # the rule is the median's; a single frame is off by how late its state was received
    # (0.42 m, a state 0.21 s late, beside two CI runs): the machine's timing, not the rig's
    assert abs(float(np.median(errors))) < 0.03


def _options(command) -> dict[str, dict]:
    """Each parameter of a command as typer parses it: flags, type, range, default."""
    app = typer.Typer(add_completion=False)
    app.command()(command)
    return {
        p.name: {
            "opts": p.opts,
            "argument": isinstance(p, typer.core.TyperArgument),
            "type": p.type_descriptor.annotation,
            "min": p.min,
            "max": p.max,
            "default": p.default,
            "required": p.required,
            "multiple": p.multiple,
        }
        for p in typer.main.get_command(app).params
    }


def test_the_rig_takes_the_mock_motives_options_as_they_are() -> None:
    """Every option of the rig is the mock Motive's (``python -m gcs.mock.mocap``): same flag,
    type, range and default; the rig adds only the PX4 instance."""
    rig, motive = _options(rig_command), _options(mocap_command)
    instance = rig.pop("instance")
    assert instance["argument"] and instance["required"] and instance["min"] == 0
    assert set(rig) == {
        "body", "rate_hz", "natnet", "noise_mm", "seed", "port", "room", "yaw_offset_deg",
        "latency_ms",
    }  # fmt: skip
    for name, option in rig.items():
        assert option == motive[name], name


@pytest.mark.live  # starts the rig's process
def test_the_rig_refuses_a_bad_option_before_it_serves() -> None:
    with pytest.raises(MocapError, match="--latency-ms"):
        LabRig(0, ["--latency-ms", "51"]).__enter__()
