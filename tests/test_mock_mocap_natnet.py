"""NatNet packets of the mock Motive, checked byte by byte against the documented layouts; the
server's frames under a latency (pose and time stamps), stepped without real time."""

from __future__ import annotations

import math
import socket
import struct
import time

import numpy as np
import pytest

from gcs.core.frames import mapping_for, matrix_to_quat, quat_angle_rad, quat_to_matrix
from gcs.mock.mocap import natnet
from gcs.mock.mocap.scripted import Circle, in_room
from gcs.mock.mocap.server import CLOCK_HZ, DEFAULT_MARKERS_M, NatNetServer, solve_rigid_body

MODEL = natnet.RigidBodyModel("drone", 7, DEFAULT_MARKERS_M)
STAMPS = natnet.FrameStamps(12.25, 1_000, 2_000, 3_000)
POS = np.array([1.0, 2.0, 3.0])
QUAT = np.array([0.5, 0.5, 0.5, 0.5])


def frame(version, tracked=True) -> bytes:
    markers = DEFAULT_MARKERS_M @ quat_to_matrix(QUAT).T + POS
    state = natnet.RigidBodyState(tracked, POS, QUAT, 0.0005, markers)
    return natnet.frame_of_data(version, 42, [MODEL], [state], STAMPS)


def test_server_info_is_the_packed_sender_server() -> None:
    data = natnet.server_info((4, 1), (3, 1, 0, 0), 10_000_000, 51234, "239.255.42.99")
    assert len(data) == 4 + 256 + 4 + 4 + 8 + 2 + 1 + 4
    assert struct.unpack_from("<HH", data) == (natnet.NAT_SERVERINFO, len(data) - 4)
    assert data[4:11] == b"Motive\0"
    assert tuple(data[260:264]) == (3, 1, 0, 0)
    assert tuple(data[264:268]) == (4, 1, 0, 0)
    assert struct.unpack_from("<QH?", data, 268) == (10_000_000, 51234, True)
    assert tuple(data[279:283]) == (239, 255, 42, 99)
    unicast = natnet.server_info((3, 0), (2, 3, 0, 0), 1, 1511, None)
    assert unicast[278] == 0 and unicast[279:] == bytes(4)


def test_rigid_body_description_per_version() -> None:
    d40 = natnet.model_definitions((4, 0), [MODEL])
    d41 = natnet.model_definitions((4, 1), [MODEL])
    d31 = natnet.model_definitions((3, 1), [MODEL])
    assert struct.unpack_from("<HHii", d40) == (natnet.NAT_MODELDEF, len(d40) - 4, 1, 1)
    body40 = d40[12:]
    # name, id, parent, offset, marker count, offsets, active labels, names (4.x)
    assert body40.startswith(b"drone\0")
    assert struct.unpack_from("<ii3fi", body40, 6) == (7, -1, 0.0, 0.0, 0.0, 5)
    offsets = np.frombuffer(body40, "<f4", 15, 6 + 24)
    np.testing.assert_array_equal(offsets, DEFAULT_MARKERS_M.astype(np.float32).ravel())
    assert body40.endswith(b"Marker1\0Marker2\0Marker3\0Marker4\0Marker5\0")
    # 3.x: no marker names; 4.1: a byte count after the dataset type
    assert len(d31) == len(d40) - len(b"Marker1\0") * 5
    assert struct.unpack_from("<iii", d41, 4) == (1, 1, len(body40))
    assert d41[16:] == body40


def test_frame_layout_3_0_3_1_4_0_identical_4_1_adds_sizes_assets_and_precision_time() -> None:
    f30, f31, f40, f41 = (frame(v) for v in [(3, 0), (3, 1), (4, 0), (4, 1)])
    assert f30 == f31 == f40
    # seven counted lists get a byte count, plus the asset list (count, bytes) and the
    # precision timestamp (seconds, fraction)
    assert len(f41) == len(f40) + 7 * 4 + 8 + 8
    for f in (f40, f41):
        assert struct.unpack_from("<HHi", f) == (natnet.NAT_FRAMEOFDATA, len(f) - 4, 42)
        assert struct.unpack_from("<hi", f, len(f) - 6) == (0, 0)  # params, end-of-data tag
    tail40 = len(f40) - 6 - 24 - 8
    assert struct.unpack_from("<dQQQ", f40, tail40) == (12.25, 1_000, 2_000, 3_000)
    tail41 = len(f41) - 6 - 8 - 24 - 8
    assert struct.unpack_from("<dQQQII", f41, tail41) == (12.25, 1_000, 2_000, 3_000, 12, 2**30)


def _rigid_body_block(f: bytes) -> tuple:
    # 3.x/4.0: frame number; 1 marker set ("drone", 5 markers); 0 legacy markers; 1 body
    offset = 4 + 4 + 4 + len(b"drone\0") + 4 + 5 * 12 + 4
    assert struct.unpack_from("<i", f, offset) == (1,)
    return struct.unpack_from("<i3f4ffh", f, offset + 4)


def test_rigid_body_in_the_frame_and_tracking_flag() -> None:
    rid, x, y, z, qx, qy, qz, qw, err, params = _rigid_body_block(frame((3, 1)))
    assert rid == 7 and (x, y, z) == (1.0, 2.0, 3.0)
    assert (qw, qx, qy, qz) == (0.5, 0.5, 0.5, 0.5)
    assert err == pytest.approx(0.0005) and params & 1 == 1
    lost = frame((3, 1), tracked=False)
    # untracked: no marker set for it (count 0), no legacy markers, one body, flag cleared
    assert struct.unpack_from("<iiii", lost, 4) == (42, 0, 0, 1)
    params_lost = struct.unpack_from("<i3f4ffh", lost, 4 + 16)[-1]
    assert params_lost & 1 == 0


def test_unknown_version_refused() -> None:
    with pytest.raises(ValueError, match="not implemented"):
        natnet.server_info((2, 9), (1, 0, 0, 0), 1, 1, None)
    with pytest.raises(ValueError, match="shape"):
        natnet.RigidBodyModel("x", 1, np.zeros((2, 3)))


def test_message_id_and_packet() -> None:
    assert natnet.message_id(natnet.packet(natnet.NAT_KEEPALIVE, b"")) == natnet.NAT_KEEPALIVE
    assert natnet.message_id(b"\x00") is None
    with pytest.raises(ValueError, match="uint16"):
        natnet.packet(natnet.NAT_MODELDEF, bytes(70_000))


def test_solver_recovers_the_pose_exactly_without_noise_and_within_noise_with_it() -> None:
    rng = np.random.default_rng(3)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    pos = np.array([0.3, 1.2, -2.0])
    world = DEFAULT_MARKERS_M @ quat_to_matrix(q).T + pos
    p, qq, err = solve_rigid_body(DEFAULT_MARKERS_M, world)
    np.testing.assert_allclose(p, pos, atol=1e-12)
    assert float(quat_angle_rad(qq, q)) < 1e-7 and err < 1e-12
    noisy = world + rng.normal(0, 1e-3, world.shape)
    p, qq, err = solve_rigid_body(DEFAULT_MARKERS_M, noisy)
    assert np.linalg.norm(p - pos) < 3e-3 and 2e-4 < err < 3e-3
    assert np.degrees(float(quat_angle_rad(qq, q))) < 3.0
    assert matrix_to_quat(quat_to_matrix(qq))[0] >= 0


@pytest.mark.parametrize("latency_ms", [0.0, 8.0, 50.0])
def test_each_frame_carries_the_circle_as_it_was_its_latency_before_and_stamps_it(
    latency_ms: float,
) -> None:
    """The frame at server time t (frame k at 120 Hz: k / 120 s) shows the circle at
    t - latency (analytic, in the room's axes; no noise: the solve is exact to float32), its
    mid-exposure stamp is the latency before the frame's instant, its data-received stamp
    the instant, its transmit stamp not earlier."""
    latency = latency_ms / 1000.0
    circle = Circle(radius_m=1.0, period_s=2.0)  # 3.1 m/s: 25 mm in 8 ms
    room = mapping_for("optitrack", yaw_offset_deg=30.0)
    epoch = time.monotonic() - 5.0  # the frames' instants lie in the past
    server = NatNetServer(
        in_room(circle, room), rate_hz=120.0, noise_m=0.0, latency_s=latency, epoch_s=epoch
    )
    try:
        for k in range(240):
            server.send_frame(k, epoch + k / 120.0)
    finally:
        server.close()
    frames = list(server.sent)
    assert [f.frame_number for f in frames] == list(range(240))
    for f in frames:
        assert f.t_s == pytest.approx(f.frame_number / 120.0, abs=1e-9)
        pos, quat = circle(f.t_s - latency)
        np.testing.assert_allclose(room.position_to_ned(np.array(f.pos_m)), pos, atol=2e-6)
        assert float(quat_angle_rad(room.attitude_to_ned(np.array(f.quat_wxyz)), quat)) < 1e-5
        if latency > 0:  # the latency is visible: the circle now is elsewhere
            now_pos, _ = circle(f.t_s)
            assert np.linalg.norm(now_pos - pos) > 0.9 * math.pi * latency
        stamps = f.stamps
        assert stamps.timestamp_s == pytest.approx(f.t_s, abs=1e-9)
        assert stamps.mid_exposure_ticks / CLOCK_HZ == pytest.approx(
            epoch + f.t_s - latency, abs=1e-6
        )
        assert stamps.data_received_ticks / CLOCK_HZ == pytest.approx(epoch + f.t_s, abs=1e-6)
        system_latency_s = (stamps.transmit_ticks - stamps.mid_exposure_ticks) / CLOCK_HZ
        assert system_latency_s >= latency


def test_a_negative_or_absurd_latency_is_refused() -> None:
    for latency_s in (-0.001, 1.5, math.nan):
        with pytest.raises(ValueError, match="latency_s"):
            NatNetServer(lambda t: None, latency_s=latency_s)


def test_a_server_never_gets_a_data_port_another_reusable_socket_holds() -> None:
    # Servers and their clients bind the data port with SO_REUSEADDR. Set before binding to
    # port 0, Linux may hand out a port such a socket already holds: two servers would share a
    # port and each client would read the other vehicle's frames (a "jump" of a metre). A
    # thousand held ports out of the ephemeral range make that near certain over 300 servers.
    held = []
    try:
        for _ in range(1000):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            held.append(sock)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(("127.0.0.1", 0))
        taken = {sock.getsockname()[1] for sock in held}
        shared = []
        for _ in range(300):
            server = NatNetServer(lambda t: None)
            try:
                if server.data_port in taken:
                    shared.append(server.data_port)
                # a client beside it still binds the port, as beside a real Motive
                client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                client.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                client.bind(("0.0.0.0", server.data_port))
                client.close()
            finally:
                server.close()
        assert shared == []
    finally:
        for sock in held:
            sock.close()
