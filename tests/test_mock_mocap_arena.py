"""The arena (``gcs.mock.mocap.arena``): the mock Motive serving a published true pose, read by
gcs's real mocap client over NatNet on loopback; its faults timed from the first OFFBOARD; its
command-line options."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import typer

from gcs.core.frames import mapping_for, quat_angle_rad, quat_to_matrix
from gcs.errors import MocapError
from gcs.flight.mocap.client import MocapClient
from gcs.io.mocap_source import parse_mocap_url
from gcs.mock.cli import arena_options
from gcs.mock.mocap.arena import (
    CARRY_S,
    Arena,
    ArenaFault,
    ArenaOptions,
    parse_arena_fault,
    quat_from_euler,
)

#: longest wait for an event that comes within a fraction of a second: a bound on a hang, not on
#: speed. These tests run in make test's quick part at nice 10, where a loaded machine can keep
#: the arena's and the client's threads off the CPU for seconds: with 5 s, a fresh-clone run
#: beside another suite (load about 10) waited in vain for 40 frames of the 200 Hz stream
WAIT_S = 60.0


def _rot(axis: int, angle: float) -> np.ndarray:
    """Right-handed rotation matrix about x (0), y (1) or z (2)."""
    c, s = math.cos(angle), math.sin(angle)
    return [
        np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    ][axis]


@pytest.mark.parametrize("angles", [(0.0, 0.0, 0.0), (0.1, -0.05, 0.5), (-0.4, 0.3, -2.9)])
def test_quat_from_euler_is_the_zyx_rotation(angles: tuple[float, float, float]) -> None:
    roll, pitch, yaw = angles
    expected = _rot(2, yaw) @ _rot(1, pitch) @ _rot(0, roll)
    q = np.array(quat_from_euler(roll, pitch, yaw))
    assert np.linalg.norm(q) == pytest.approx(1.0)
    np.testing.assert_allclose(quat_to_matrix(q), expected, atol=1e-12)


def test_nothing_is_tracked_before_a_pose_is_published_then_the_pose_in_room_axes() -> None:
    options = ArenaOptions(rate_hz=200.0, noise_m=2e-4, yaw_offset_deg=30.0, seed=4)
    arena = Arena(options).start()
    pos_ned, quat_ned = (1.0, -2.0, -1.5), quat_from_euler(0.1, -0.05, 0.5)
    try:
        with MocapClient(parse_mocap_url(arena.url)) as client:
            assert not client.wait_until(lambda s: True, WAIT_S).tracked
            arena.publish(pos_ned, quat_ned)
            first = client.wait_until(lambda s: s.tracked, WAIT_S)
            client.wait_until(lambda s: s.seq >= first.seq + 40, WAIT_S)
            got = client.recent(4.0)
    finally:
        arena.stop()
    room = mapping_for("optitrack", 30.0)
    tracked = got.tracked & (got.seq >= first.seq)
    assert tracked.sum() >= 40
    for pos, quat in zip(got.pos_m[tracked], got.quat_wxyz[tracked], strict=True):
        np.testing.assert_allclose(room.position_to_ned(pos), pos_ned, atol=1.5e-3)
        turn = float(quat_angle_rad(room.attitude_to_ned(quat), np.array(quat_ned)))
        assert math.degrees(turn) < 1.0
    # Motive's Y is up: the height is the room's second coordinate, whatever the yaw offset
    np.testing.assert_allclose(got.pos_m[tracked][:, 1], 1.5, atol=1.5e-3)


def test_a_pose_not_published_again_moves_on_at_its_velocity_for_at_most_carry_s() -> None:
    # the mock's loop published once and then missed its steps (a loaded machine): the body it
    # stands for keeps moving in the frames, as a real one would, and stops after CARRY_S
    arena = Arena(ArenaOptions(rate_hz=200.0, noise_m=0.0, yaw_offset_deg=30.0)).start()
    pos, vel = np.array([1.0, -2.0, -1.5]), np.array([1.0, -0.5, 0.2])
    try:
        t_pub_s = arena.server.now_s()
        arena.publish(pos, quat_from_euler(0.0, 0.0, 0.3), vel)
        t_after_s = arena.server.now_s()
        deadline = time.monotonic() + WAIT_S
        while not any(f.t_pose_s > t_after_s + CARRY_S + 0.1 for f in list(arena.server.sent)):
            assert time.monotonic() < deadline, "no frames"
            time.sleep(0.01)
    finally:
        arena.stop()
    room = mapping_for("optitrack", 30.0)
    frames = [f for f in arena.server.sent if f.t_pose_s > t_after_s]
    # how far each frame carried the pose: its position is pos + carried * vel. The publication
    # was stamped between t_pub_s and t_after_s (microseconds apart, or milliseconds when this
    # thread was preempted in between), so each frame's carry lies between the two bounds
    speed2 = float(vel @ vel)
    carried = []
    for f in frames:
        moved = room.position_to_ned(f.true_pos_m) - pos
        c = float(moved @ vel) / speed2
        np.testing.assert_allclose(moved, c * vel, atol=1e-9)  # along the velocity
        lo = min(f.t_pose_s - t_after_s, CARRY_S)
        hi = min(f.t_pose_s - t_pub_s, CARRY_S)
        assert lo - 1e-9 <= c <= hi + 1e-9, (f.t_pose_s, c, lo, hi)
        carried.append(c)
    # it moved on (a frame inside the carry; the first came 79 ms after the publication in a
    # run at a load of 10, the frames' thread at nice 10), then stood at CARRY_S
    assert min(carried) < CARRY_S - 1e-6, carried
    assert carried[-1] == pytest.approx(CARRY_S, abs=1e-9), carried


@pytest.mark.live  # frames lost to a fault window counted in real time
def test_faults_start_at_the_first_offboard_and_show_as_an_untracked_body() -> None:
    fault = ArenaFault("occlusion", 0.3, 0.4)
    options = ArenaOptions(rate_hz=200.0, faults=(fault,), seed=2)
    arena = Arena(options)
    arena.publish((0.0, 0.0, -1.0), (1.0, 0.0, 0.0, 0.0))
    arena.start()
    try:
        with MocapClient(parse_mocap_url(arena.url)) as client:
            first = client.wait_until(lambda s: s.tracked, WAIT_S)
            # longer than the fault's start after the server started: not timed from there
            client.wait_until(lambda s: s.t_receipt_s > first.t_receipt_s + 0.5, WAIT_S)
            offboard_server_s = arena.server.now_s()
            arena.on_first_offboard()
            arena.on_first_offboard()  # only the first counts
            lost = client.wait_until(lambda s: not s.tracked, WAIT_S)
            back = client.wait_until(lambda s: s.tracked, WAIT_S)
            got = client.recent(4.0)
            frames = list(arena.server.sent)
            stats = arena.stats()
    finally:
        arena.stop()
    window = (got.seq >= first.seq) & (got.seq < back.seq)
    assert got.tracked[window & (got.seq < lost.seq)].all()
    assert not got.tracked[window & (got.seq >= lost.seq)].any()
    # the server's frames: untracked exactly over [first OFFBOARD + 0.3, + 0.7) of its clock
    start_s, end_s = offboard_server_s + fault.start_s, offboard_server_s + 0.7
    for frame in frames:  # 10 ms of slack for the moment on_first_offboard read the clock
        if start_s + 0.01 <= frame.t_s < end_s - 0.01:
            assert not frame.tracked, frame.t_s
        elif not start_s - 0.01 <= frame.t_s < end_s + 0.01:
            assert frame.tracked, frame.t_s
    # and only there: how many frames a loaded machine lets the server make in the window is
    # not this test's business (the rates are the benchmarks')
    lost_frames = [f for f in frames if not f.tracked]
    assert lost_frames and all(start_s - 0.01 <= f.t_s < end_s + 0.01 for f in lost_frames)
    assert stats["faults_placed"] and stats["faults"][0]["kind"] == "occlusion"
    assert back.t_receipt_s > lost.t_receipt_s


def test_no_fault_acts_until_the_vehicle_enters_offboard() -> None:
    options = ArenaOptions(rate_hz=200.0, faults=(ArenaFault("dropout", 0.0, 5.0),))
    arena = Arena(options)
    arena.publish((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    arena.start()
    try:
        with MocapClient(parse_mocap_url(arena.url)) as client:
            first = client.wait_until(lambda s: s.tracked, WAIT_S)
            last = client.wait_until(lambda s: s.t_receipt_s > first.t_receipt_s + 0.3, WAIT_S)
            assert last.tracked and not arena.stats()["faults_placed"]
            arena.on_first_offboard()
            # the dropout acts: once the frames made before it have arrived (late on a loaded
            # machine), the 200 Hz stream falls silent
            heard_s, deadline_s = time.monotonic(), time.monotonic() + WAIT_S
            while True:
                try:
                    late = client.wait_until(lambda s, t=heard_s: s.t_receipt_s > t, 0.3)
                except MocapError as exc:
                    assert "no matching mocap sample" in str(exc)
                    break
                heard_s = late.t_receipt_s
                assert time.monotonic() < deadline_s, "the stream never fell silent"
    finally:
        arena.stop()


def test_options_round_trip_through_their_command_line() -> None:
    faults = (
        ArenaFault("occlusion", 2.0, 0.5),
        ArenaFault("dropout", 3.0, 0.25),
        ArenaFault("freeze", 4.5, 1.0),
        ArenaFault("jump", 6.0, 0.1, (0.3, 0.0, -0.2)),
    )
    options = ArenaOptions(rate_hz=240.0, noise_m=5e-4, yaw_offset_deg=-90.0, body="cf1",
                           faults=faults, seed=9)  # fmt: skip
    args = options.cli_args()
    assert args[0] == "--mocap"
    values = dict(zip(args[1:11:2], args[2:11:2], strict=True))
    parsed_faults = [
        parse_arena_fault(name.removeprefix("--mocap-"), value)
        for name, value in zip(args[11::2], args[12::2], strict=True)
    ]
    again = arena_options(
        float(values["--mocap-rate"]),
        float(values["--mocap-noise-mm"]),
        values["--mocap-room"],
        float(values["--mocap-yaw-offset-deg"]),
        values["--mocap-body"],
        9,
        {},
    )
    assert tuple(parsed_faults) == faults
    assert again == ArenaOptions(**{**options.__dict__, "faults": ()})


@pytest.mark.parametrize(
    ("kind", "text", "message"),
    [
        ("occlusion", "2", "START:DURATION"),
        ("occlusion", "2:x", "START:DURATION"),
        ("jump", "1:1", "START:DURATION:DX:DY:DZ"),
        ("dropout", "1:0", "duration must be positive"),
        ("freeze", "nan:1", "times finite"),
        ("smoke", "1:1", "unknown mocap fault"),
    ],
)
def test_bad_fault_options_are_refused_by_name(kind: str, text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_arena_fault(kind, text)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"room": "motion-capture"}, "motion-capture"),
        ({"rate_hz": 0.5}, "mocap rate"),
        ({"noise_mm": -1.0}, "mocap noise"),
        ({"faults": {"occlusion": ["1"]}}, "--mocap-occlusion must be START:DURATION"),
    ],
)
def test_bad_arena_options_are_usage_errors(overrides: dict, message: str) -> None:
    args = {"rate_hz": 120.0, "noise_mm": 0.2, "room": "optitrack", "yaw_offset_deg": 0.0,
            "body": "drone", "seed": 0, "faults": {}} | overrides  # fmt: skip
    with pytest.raises(typer.BadParameter, match=message):
        arena_options(**args)
