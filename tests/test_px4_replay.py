"""Real PX4 bytes through the real MAVSDK into gcs's vehicle mirror: the shared capture replayed.

``shared/data/px4-sih-offboard.tlog`` holds what PX4 v1.16 SITL sent to a MAVSDK client. A
hover of it (44.5-54.5 s: setpoint (0, 0, -2) held after an eight) is sent again, byte for byte
and on its original schedule sped up 4x, to a MAVSDK connection made by
:class:`gcs.flight.vehicle.Vehicle`; parameter reads are answered with the PARAM_VALUE bytes PX4
sent then. This checks gcs's parsing of PX4's own LOCAL_POSITION_NED (through MavlinkDirect),
the clock fit on PX4's ``time_boot_ms`` and the decoding of its parameters against the real
thing, as far as a capture can: commands are acknowledged by the replayer, not by PX4.
"""

from __future__ import annotations

import asyncio
import socket
import threading
import time

import numpy as np
import pytest
from px4_data import shared
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

from gcs.flight.clock import fit_clock
from gcs.flight.hover import hover_stats
from gcs.flight.link import sample_arrays
from gcs.flight.preflight import LINK_LOSS_PARAMS, NAV_PARAMS, navigation_source
from gcs.flight.vehicle import Vehicle
from gcs.io.settings import FlightSettings

pytestmark = pytest.mark.e2e
WINDOW_S = (44.5, 54.5)  # seconds after the capture's first message
SPEEDUP = 4.0


def capture_window() -> tuple[list[tuple[float, bytes]], dict[str, bytes], list]:
    """PX4's datagrams in the window (offset [s], bytes), its PARAM_VALUE bytes by name, and
    the window's LOCAL_POSITION_NED messages."""
    log = mavutil.mavlink_connection(str(shared() / "data" / "px4-sih-offboard.tlog"))
    packets, params, positions, t_first = [], {}, [], None
    while (msg := log.recv_match()) is not None:
        if msg.get_type() == "BAD_DATA" or msg.get_srcSystem() != 1:
            continue
        t_first = log.timestamp if t_first is None else t_first  # tlog time of msg
        offset = log.timestamp - t_first
        if msg.get_type() == "PARAM_VALUE":
            params[msg.param_id.rstrip("\x00")] = bytes(msg.get_msgbuf())
        elif WINDOW_S[0] <= offset < WINDOW_S[1]:
            packets.append((offset - WINDOW_S[0], bytes(msg.get_msgbuf())))
            if msg.get_type() == "LOCAL_POSITION_NED":
                positions.append(msg)
    return packets, params, positions


class Replayer:
    """Sends the capture to whoever talks to it first; answers parameter reads and commands."""

    def __init__(self, packets: list[tuple[float, bytes]], params: dict[str, bytes]) -> None:
        self.packets, self.params = packets, params
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.005)
        self.url = f"udpout://127.0.0.1:{self.sock.getsockname()[1]}"
        self.peer: tuple[str, int] | None = None
        self.asked: list[str] = []
        self.stop = threading.Event()
        self.done = threading.Event()
        self.parser = mavlink2.MAVLink(None)
        self.mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        self.thread = threading.Thread(target=self.run, daemon=True)

    def receive(self) -> None:
        try:
            data, peer = self.sock.recvfrom(4096)
        except (TimeoutError, BlockingIOError):
            return
        self.peer = peer
        for msg in self.parser.parse_buffer(data) or []:
            if msg.get_type() == "PARAM_REQUEST_READ":
                name = msg.param_id.rstrip("\x00")
                self.asked.append(name)
                if name in self.params:  # PX4's own bytes; unknown names stay unanswered
                    self.sock.sendto(self.params[name], peer)
            elif msg.get_type() == "COMMAND_LONG":  # PX4 acknowledges what MAVSDK asks
                ack = self.mav.command_ack_encode(msg.command, 0, 0, 0, 245, 190)
                self.sock.sendto(ack.pack(self.mav), peer)

    def run(self) -> None:
        while self.peer is None and not self.stop.is_set():
            self.receive()
        start, i = time.monotonic(), 0
        while i < len(self.packets) and not self.stop.is_set():
            due = start + self.packets[i][0] / SPEEDUP
            while (
                i < len(self.packets) and self.packets[i][0] / SPEEDUP <= time.monotonic() - start
            ):
                self.sock.sendto(self.packets[i][1], self.peer)
                i += 1
            if i < len(self.packets) and time.monotonic() < due:
                self.receive()
        self.done.set()
        while not self.stop.is_set():  # keep answering until the client is done
            self.receive()


def test_px4_capture_through_mavsdk_into_the_vehicle_mirror() -> None:
    packets, params, positions = capture_window()
    replayer = Replayer(packets, params)
    settings = FlightSettings(connect_timeout_s=5.0)

    async def listen() -> tuple[list, dict, object]:
        vehicle = Vehicle(settings)
        await vehicle.connect(replayer.url)
        try:
            with vehicle.record_telemetry() as samples:
                # in the campaign's order; MAVSDK retries the unanswered one (~3 s) first
                read = await vehicle.read_int_params(LINK_LOSS_PARAMS + NAV_PARAMS)
                await asyncio.to_thread(replayer.done.wait, 30.0)
                await asyncio.sleep(0.2)
                return list(samples), read, vehicle.clock.fit()
        finally:
            await vehicle.close()

    replayer.thread.start()
    try:
        samples, read, fit = asyncio.run(listen())
    finally:
        replayer.stop.set()
        replayer.thread.join(2.0)
    # PX4's values, decoded from its bytewise INT32 PARAM_VALUE as MAVSDK delivers them
    assert read["EKF2_GPS_CTRL"] == 7 and read["EKF2_HGT_REF"] == 1 and read["NAV_DLL_ACT"] == 0
    assert read["EKF2_EV_CTRL"] is None  # the capture has no answer for it: said, not guessed
    assert navigation_source(read).name == "unknown"
    assert navigation_source({**read, "EKF2_EV_CTRL": 0}).name == "GPS"
    # every LOCAL_POSITION_NED since the recording began arrived, with PX4's stamps and values
    t, pos = sample_arrays([s for s in samples if s.t_vehicle_s >= positions[0].time_boot_ms / 1e3])
    expected = [m for m in positions if m.time_boot_ms / 1e3 >= t[0]]
    assert len(t) >= 0.98 * len(expected) and len(expected) > 300
    sent = {m.time_boot_ms: (m.x, m.y, m.z) for m in positions}
    for tk, pk in zip(t, pos, strict=True):
        np.testing.assert_allclose(pk, sent[round(tk * 1000)], rtol=0, atol=1e-6)
    # the clock: PX4 ran at 0.993x the capture's wall clock; replayed 4x faster
    receipt = np.array(sorted(s.t_s for s in samples if s.t_vehicle_s >= t[0]))
    assert fit_clock(t, receipt).rate == pytest.approx(SPEEDUP * 0.9934, rel=0.01)
    assert fit is not None and fit.rate == pytest.approx(SPEEDUP * 0.9934, rel=0.01)
    # the hover statistics of the replayed stream are those of the capture
    offline = hover_stats(
        [m.time_boot_ms / 1e3 for m in expected], [(m.x, m.y, m.z) for m in expected],
        (0.0, 0.0, -2.0),
    )  # fmt: skip
    online = hover_stats(t, pos, (0.0, 0.0, -2.0))
    assert online.distance_max_m == pytest.approx(offline.distance_max_m, abs=0.01)
    assert online.offset_m == pytest.approx(offline.offset_m, abs=0.01)
