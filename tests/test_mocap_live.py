"""The mocap client (``motioncapture`` library in its reader process) against the mock Motive
over real NatNet on loopback: poses through the frame mapping, rate, time stamps, faults found
by the health checks, a mirrored mapping caught, and the failure modes of the library."""

from __future__ import annotations

import math
import os
import re
import signal
import socket
import struct
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

from gcs.core.frames import FrameMapping, mapping_for, quat_angle_rad
from gcs.errors import MocapError
from gcs.flight.mocap.checks import move_direction_problem
from gcs.flight.mocap.client import MocapClient, MocapSample
from gcs.flight.mocap.health import (
    HealthLimits,
    frozen_problem,
    jump_problem,
    occlusion_problem,
    stale_problem,
    stream_problem,
)
from gcs.io.mocap_samples import MocapSeries
from gcs.io.mocap_source import MocapSource, parse_mocap_url
from gcs.mock.mocap import natnet
from gcs.mock.mocap.process import MocapServerProcess
from gcs.mock.mocap.scripted import Circle, Hover, in_room
from gcs.mock.mocap.server import CLOCK_HZ, FaultWindow, NatNetServer

# a real NatNet server and reader in real time (rates, stale and jump timing): out of test-fast
pytestmark = pytest.mark.live
ROOM = mapping_for("optitrack", yaw_offset_deg=30.0, origin_m=(0.5, 0.0, -0.25))
LIMITS = HealthLimits()
WAIT_S = 5.0  # longest wait for an event that should come within a fraction of a second


def serve(pose_ned=None, room: FrameMapping = ROOM, **kwargs) -> NatNetServer:
    return NatNetServer(in_room(pose_ned or Hover(), room), **kwargs).start()


def connect(server: NatNetServer, body: str | None = None) -> MocapClient:
    source = parse_mocap_url(server.url)
    if body is not None:
        source = MocapSource(source.system, source.host, source.port, body, source.interface_ip)
    return MocapClient(source)


@pytest.fixture
def hover() -> Iterator[tuple[NatNetServer, MocapClient]]:
    server = serve(rate_hz=200.0)
    client = connect(server).start()
    yield server, client
    client.stop()
    server.stop()


def _until(client: MocapClient, seq: int) -> MocapSeries:
    """The client's recent samples up to and including ``seq``."""
    series = client.recent(4.0)
    keep = series.seq <= seq
    return MocapSeries(
        series.seq[keep],
        series.t_receipt_s[keep],
        series.t_mocap_s[keep],
        series.tracked[keep],
        series.pos_m[keep],
        series.quat_wxyz[keep],
    )


def test_pose_round_trip_order_and_timestamps_at_240_hz() -> None:
    circle = Circle(radius_m=1.0, period_s=4.0)
    server = serve(circle, rate_hz=240.0, noise_m=3e-4)
    try:
        with MocapClient(parse_mocap_url(server.url)) as client:
            first = client.wait_until(lambda s: s.tracked, WAIT_S)
            client.start_journal()
            client.wait_until(lambda s: s.seq >= first.seq + 240, WAIT_S)
            got = client.drain()
    finally:
        server.stop()
    assert np.all(np.diff(got.seq) == 1)
    assert np.all(np.diff(got.t_receipt_s) > 0)
    # each sample is a distinct frame the server sent, in order, exactly as sent
    by_pos = {f.pos_m: f for f in server.sent}
    frames = [by_pos[tuple(float(v) for v in p)] for p in got.pos_m[got.tracked]]
    numbers = np.array([f.frame_number for f in frames])
    assert np.all(np.diff(numbers) > 0)
    # the receipt stamps are the shared monotonic clock's: each frame received after it left
    # (how late, under load, is measured in benchmarks/, not asserted: a 0.12 s stall of this
    # in-process server at the start once made the receipts span 0.99 s for 1.11 s of frames);
    # under load the library keeps only the newest frame when it falls behind
    sent_s = np.array([f.t_send_s for f in frames])
    # (how many frames arrive, and at what rate, are measured there too: a machine at load 8-15
    # delivered a third of them)
    assert np.all(got.t_receipt_s[got.tracked] >= sent_s)
    # poses: the client's samples, mapped to NED, are the circle within the noise
    errors, turns = [], []
    for frame, pos, quat in zip(
        frames, got.pos_m[got.tracked], got.quat_wxyz[got.tracked], strict=True
    ):
        truth_pos, truth_q = circle(frame.t_s)
        errors.append(np.linalg.norm(ROOM.position_to_ned(pos) - truth_pos))
        turns.append(math.degrees(float(quat_angle_rad(ROOM.attitude_to_ned(quat), truth_q))))
    assert len(errors) >= 200
    assert max(errors) < 2e-3  # 0.3 mm marker noise over five markers: ~0.2 mm per axis
    assert max(turns) < 1.0


@pytest.mark.parametrize("version", [(3, 0), (3, 1), (4, 0), (4, 1)])
def test_every_natnet_version_is_read_by_the_library(version: tuple[int, int]) -> None:
    server = serve(Hover((0.2, -0.4, -1.5)), version=version, rate_hz=100.0)
    try:
        with connect(server) as client:
            sample = client.wait_until(lambda s: s.tracked, WAIT_S)
            assert client.names_seen == ("drone",)
    finally:
        server.stop()
    np.testing.assert_allclose(ROOM.position_to_ned(np.array(sample.pos_m)), [0.2, -0.4, -1.5],
                               atol=2e-3)  # fmt: skip
    assert server.stats()["connects"] == 1 and server.stats()["modeldef_requests"] == 1


def test_occlusion_is_reported_by_the_health_check(hover) -> None:
    """An occlusion three times the limit, served over the wire: the frames of its window
    come untracked, and the check names how long the body has been lost by the receipt times
    of the frames (which a loaded machine may bunch: so the duration is computed from them
    here, not asserted as the window's length)."""
    server, client = hover
    start = client.wait_until(lambda s: s.tracked, WAIT_S)
    assert stream_problem(client.recent(0.5), start.t_receipt_s) is None
    occluded_s = 3 * LIMITS.max_occluded_s
    server.add_fault(FaultWindow("occlusion", server.now_s() + 0.05, occluded_s))
    lost = client.wait_until(lambda s: not s.tracked, WAIT_S)
    back = client.wait_until(lambda s: s.tracked, WAIT_S)
    window = _until(client, back.seq - 1)
    assert lost.seq in window.seq and not window.tracked[-1]
    last_tracked = np.flatnonzero(window.tracked)[-1]
    assert not window.tracked[last_tracked + 1 :].any()  # every frame since, untracked
    lost_s = float(window.t_receipt_s[-1] - window.t_receipt_s[last_tracked])
    reason = occlusion_problem(window, float(window.t_receipt_s[-1]), LIMITS)
    if lost_s > LIMITS.max_occluded_s:
        assert reason == f"rigid body lost (not tracked for {lost_s:.2f} s)"
    else:  # frames held back until the body was nearly back: not yet a loss
        assert reason is None


def test_dropout_is_reported_as_stale(hover) -> None:
    server, client = hover
    client.wait_until(lambda s: s.tracked, WAIT_S)
    server.add_fault(FaultWindow("dropout", server.now_s() + 0.05, 0.6))
    previous = [client.latest()]

    def after_gap(s: MocapSample) -> bool:
        gap = s.t_receipt_s - previous[0].t_receipt_s
        previous[0] = s
        return gap > 0.5

    resumed = client.wait_until(after_gap, WAIT_S)
    before = _until(client, resumed.seq - 1)
    reason = stale_problem(before, resumed.t_receipt_s - 1e-3, LIMITS)
    assert reason is not None and reason.startswith("mocap stream stale (0.")


def test_frozen_stream_is_reported(hover) -> None:
    server, client = hover
    client.wait_until(lambda s: s.tracked, WAIT_S)
    server.add_fault(FaultWindow("freeze", server.now_s() + 0.05, 0.3))
    run = [0, client.latest()]

    def thawed(s: MocapSample) -> bool:
        same = (s.pos_m, s.quat_wxyz) == (run[1].pos_m, run[1].quat_wxyz)
        done = run[0] >= 10 and not same
        run[0] = run[0] + 1 if same else 0
        run[1] = s
        return done

    thaw = client.wait_until(thawed, WAIT_S)
    reason = frozen_problem(_until(client, thaw.seq - 1), LIMITS)
    assert reason is not None and "identical frames over 0." in reason
    assert frozen_problem(_until(client, thaw.seq - 60), LIMITS) is None  # before the freeze


def test_jump_is_reported(hover) -> None:
    server, client = hover
    first = client.wait_until(lambda s: s.tracked, WAIT_S)
    # 1.5 m: beyond what the vehicle can move (10 m/s, 30 m/s^2) in any receipt interval up
    # to 0.13 s, so that a reader descheduled for a few tens of milliseconds on a loaded
    # machine (the interval the jump is judged over) still sees it as a jump
    server.add_fault(FaultWindow("jump", server.now_s() + 0.05, 0.1, (1.5, 0.0, 0.0)))
    jumped = client.wait_until(
        lambda s: s.tracked and abs(s.pos_m[0] - first.pos_m[0]) > 1.0, WAIT_S
    )
    assert jump_problem(_until(client, jumped.seq - 1), LIMITS) is None
    reason = jump_problem(_until(client, jumped.seq), LIMITS)
    found = re.match(r"mocap position jumped (\d+\.\d+) m", reason or "")
    assert found is not None and abs(float(found[1]) - 1.5) < 0.01, reason  # 0.2 mm noise


def test_server_that_stops_leaves_the_reader_blocked_and_the_stream_stale(hover) -> None:
    server, client = hover
    client.wait_until(lambda s: s.tracked, WAIT_S)
    server.stop()
    stopped = time.monotonic()
    with pytest.raises(MocapError, match="no matching mocap sample"):
        client.wait_until(lambda s: s.t_receipt_s > stopped + 0.01, 0.4)
    assert client.problem() is None  # the library just waits: only the age tells
    reason = stream_problem(client.recent(2.0), time.monotonic())
    assert reason is not None and reason.startswith("mocap stream stale")


def test_mirrored_mapping_sends_an_east_move_west() -> None:
    def east(t_s: float):
        return np.array([0.0, 0.5 * t_s, -1.0]), np.array([1.0, 0.0, 0.0, 0.0])

    server = serve(east, room=mapping_for("optitrack"), rate_hz=100.0)
    mirrored = FrameMapping(up_axis="+y", north_axis="+x", right_handed=False)
    try:
        with connect(server) as client:
            a = client.wait_until(lambda s: s.tracked, WAIT_S)
            b = client.wait_until(lambda s: s.tracked and s.t_receipt_s > a.t_receipt_s + 0.5,
                                  WAIT_S)  # fmt: skip
    finally:
        server.stop()
    pa, pb = np.array(a.pos_m), np.array(b.pos_m)
    truth = mapping_for("optitrack").position_to_ned(np.vstack([pa, pb]))
    moved = truth[1] - truth[0]
    assert moved[1] > 0.2  # the vehicle really went east
    wrong = mirrored.position_to_ned(pb) - mirrored.position_to_ned(pa)
    reason = move_direction_problem(moved, moved, wrong)
    assert reason is not None and "frame mapping is wrong" in reason
    assert move_direction_problem(moved, moved, moved) is None


def test_no_server_times_out_without_freezing_this_process() -> None:
    import socket

    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))  # a port that receives and never answers
    ticks: list[float] = []
    stop = threading.Event()

    def tick() -> None:
        while not stop.wait(0.01):
            ticks.append(time.monotonic())

    ticker = threading.Thread(target=tick)
    ticker.start()
    source = MocapSource("optitrack", "127.0.0.1", silent.getsockname()[1], "drone", "127.0.0.1")
    t0 = time.monotonic()
    try:
        with pytest.raises(MocapError, match=r"no answer from optitrack server 127\.0\.0\.1"):
            MocapClient(source, connect_timeout_s=1.0).start()
        t_end = time.monotonic()
    finally:
        stop.set()
        ticker.join()
        silent.close()
    assert 1.0 <= t_end - t0 < 4.0
    # this process kept running while the client waited: the ticker ran through the wait (a
    # wait that held the interpreter for its second would let it tick once at most); how
    # often it ran depends on the machine's load, so only that it ran is asserted
    assert sum(t0 < t < t_end for t in ticks) >= 5


def test_refused_connection_fails_at_once_with_the_library_s_reason() -> None:
    import socket

    with socket.socket() as closed:  # a TCP port nobody listens on (QTM's protocol is TCP)
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]
    source = MocapSource("qualisys", "127.0.0.1", port, "drone", "0.0.0.0")
    t0 = time.monotonic()
    with pytest.raises(MocapError, match="qualisys connect failed: Error connecting QTM"):
        MocapClient(source, connect_timeout_s=10.0).start()
    assert time.monotonic() - t0 < 5.0  # the reason, not the timeout


def test_a_failing_callback_ends_the_stream_with_its_reason() -> None:
    server = serve(rate_hz=100.0)

    def broken(sample: MocapSample) -> None:
        raise ZeroDivisionError("boom")

    source = parse_mocap_url(server.url)
    try:
        client = MocapClient(source, on_sample=broken).start()
        with pytest.raises(MocapError, match="ZeroDivisionError"):
            client.wait_until(lambda s: False, WAIT_S)
        client.stop()
    finally:
        server.stop()
    assert client.cpu_seconds()["reader"] >= 0  # the reader was ended, its CPU kept


def test_unknown_rigid_body_is_never_tracked_and_the_names_say_why() -> None:
    server = serve(rate_hz=100.0)
    try:
        with connect(server, body="Drone") as client:
            first = client.wait_until(lambda s: True, WAIT_S)
            last = client.wait_until(lambda s: s.t_receipt_s > first.t_receipt_s + 0.3, WAIT_S)
            series = client.recent(2.0)
            assert client.names_seen == ("drone",)
    finally:
        server.stop()
    assert not series.tracked.any()
    reason = occlusion_problem(series, last.t_receipt_s, LIMITS)
    assert reason is not None and "not tracked in any frame" in reason


def test_reader_crash_ends_the_stream_with_a_reason(hover) -> None:
    _, client = hover
    client.wait_until(lambda s: s.tracked, WAIT_S)
    os.kill(client.reader_pid, signal.SIGSEGV)
    with pytest.raises(MocapError, match="ended by signal 11"):
        client.wait_until(lambda s: False, WAIT_S)
    assert client.problem() == "mocap reader ended by signal 11"


def test_server_program_and_its_ready_url() -> None:
    with MocapServerProcess(["--rate", "100", "--natnet", "3.1", "--circle", "1:4"]) as mock:
        client = MocapClient(parse_mocap_url(mock.url)).start()
        try:
            sample = client.wait_until(lambda s: s.tracked, WAIT_S)
        finally:
            client.stop()
    ned = mapping_for("optitrack").position_to_ned(np.array(sample.pos_m))
    assert math.hypot(ned[0], ned[1]) == pytest.approx(1.0, abs=2e-3)
    assert ned[2] == pytest.approx(-1.0, abs=2e-3)
    assert '"connects": 1' in mock.stderr_text


def natnet_frames(url: str, count: int) -> list[bytes]:
    """``count`` frames of the server at ``url`` as sent: a plain socket joined to its group
    on the data port its ``NAT_SERVERINFO`` names (no library: the stamps are read too)."""
    source = parse_mocap_url(url)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as cmd:
        cmd.settimeout(WAIT_S)
        cmd.sendto(natnet.packet(natnet.NAT_CONNECT, b""), (source.host, source.port))
        info = cmd.recv(65535)
    _, data_port, _ = struct.unpack_from("<QH?", info, 268)
    group = ".".join(str(b) for b in info[279:283])
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("0.0.0.0", data_port))
        mreq = socket.inet_aton(group) + socket.inet_aton(source.interface_ip)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, mreq)
        sock.settimeout(WAIT_S)
        return [sock.recv(65535) for _ in range(count)]


def test_server_program_serves_the_pose_of_its_latency_before_and_stamps_it() -> None:
    """``--latency-ms 40``: each NatNet 3.1 frame (read byte by byte) carries the circle as it
    was 40 ms before the frame's instant (its timestamp, frames over the rate), and the
    frame's own stamps put mid-exposure 40 ms before the data-received instant, so the
    system latency a NatNet client computes (transmit - mid-exposure) is at least 40 ms."""
    args = ["--rate", "100", "--natnet", "3.1", "--circle", "1:2", "--noise-mm", "0"]
    with MocapServerProcess([*args, "--latency-ms", "40"]) as mock:
        frames = natnet_frames(mock.url, 50)
    room = mapping_for("optitrack")
    circle = Circle(radius_m=1.0, period_s=2.0)
    body = 4 + 4 + 4 + len(b"drone\0") + 4 + 5 * 12 + 4 + 4  # one marker set, one body
    for data in frames:
        assert natnet.message_id(data) == natnet.NAT_FRAMEOFDATA
        _, x, y, z, *_, params = struct.unpack_from("<i3f4ffh", data, body)
        t_s, exposure, received, transmit = struct.unpack_from("<dQQQ", data, len(data) - 38)
        assert params & 1
        pos = room.position_to_ned(np.array([x, y, z]))
        np.testing.assert_allclose(pos, circle(t_s - 0.040)[0], atol=1e-5)
        assert np.linalg.norm(pos - circle(t_s)[0]) > 0.1  # 3.1 m/s: 12.6 cm in 40 ms
        assert (received - exposure) / CLOCK_HZ == pytest.approx(0.040, abs=1e-6)
        assert 0.040 <= (transmit - exposure) / CLOCK_HZ < 1.0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--natnet", "2.9"], "--natnet must be one of"),
        (["--latency-ms", "51"], "--latency-ms"),
        (["--latency-ms", "-1"], "--latency-ms"),
    ],
)
def test_server_program_refuses_bad_options(args: list[str], message: str) -> None:
    with pytest.raises(MocapError, match=message):
        MocapServerProcess(args).__enter__()
