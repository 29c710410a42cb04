"""The mock as an indoor arena, end to end: vision on the wire as PX4 takes it, and a flight
on vision only through the real ``mavsdk`` Mocap plugin, fed by gcs's real mocap client from
the mock's NatNet server (``gcs mock --config profiles/mock-mocap.yaml --mocap``)."""

from __future__ import annotations

import asyncio
import json
import math
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync, MavlinkMessage
from mavsdk.asyncio.plugins.mocap import MocapAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, PositionNedYaw
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.mocap.mocap import (
    AngleBody,
    AngularVelocityBody,
    Covariance,
    Odometry,
    PositionBody,
    Quaternion,
    SpeedBody,
    VisionPositionEstimate,
)
from pymavlink.dialects.v20 import common as mavlink2
from test_mock_mavsdk import connect, first

from gcs.core.frames import FrameMapping, mapping_for
from gcs.flight.mocap.client import MocapClient, MocapSample
from gcs.io.mocap_source import parse_mocap_url
from gcs.mock.estimator import EV_MAX_INTERVAL_S, NO_AID_TIMEOUT_S
from gcs.mock.mocap.arena import ArenaFault, ArenaOptions
from gcs.mock.process import MockProcess

pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[1]
ROOM = mapping_for("optitrack")  # the arena's default axes
NOAID_S = 2.0  # EKF2_NOAID_TOUT of these runs (PX4's 5 s would only make them longer)


def vision_profile(tmp_path: Path) -> Path:
    """profiles/mock-mocap.yaml with a low take-off, a quick landing and a short no-aid time."""
    data = yaml.safe_load((ROOT / "profiles" / "mock-mocap.yaml").read_text())
    data["px4"] |= {"mis_takeoff_alt_m": 1.0, "mpc_land_speed_m_s": 1.0, "land_detect_s": 0.3,
                    "com_disarm_land_s": 0.5, "ekf2_noaid_tout_s": NOAID_S}  # fmt: skip
    path = tmp_path / "arena.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def odometry(pos_ned: np.ndarray, quat_ned: np.ndarray, **kw: Any) -> Odometry:
    """MAVSDK's Odometry of a mocap pose (no velocity, unknown covariance)."""
    nan3 = (math.nan, math.nan, math.nan)
    return Odometry(
        time_usec=0,  # MAVSDK stamps it with the autopilot's time
        position_body=PositionBody(*(float(v) for v in pos_ned)),
        q=Quaternion(*(float(v) for v in quat_ned)),
        speed_body=SpeedBody(*nan3),
        angular_velocity_body=AngularVelocityBody(*nan3),
        pose_covariance=Covariance([math.nan]),
        velocity_covariance=Covariance([math.nan]),
        **kw,
    )


def as_vision(pos_ned: np.ndarray, quat_ned: np.ndarray) -> Odometry:
    """What EKF2 reads: LOCAL_FRD, estimator VISION (MAVSDK's defaults are not; see below)."""
    return odometry(
        pos_ned,
        quat_ned,
        frame_id=Odometry.MavFrame.LOCAL_FRD,
        estimator_type=Odometry.MavEstimatorType.VISION,
        quality_percent=100,
    )


def in_ned(sample: MocapSample, room: FrameMapping = ROOM) -> tuple[np.ndarray, np.ndarray]:
    return room.position_to_ned(np.array(sample.pos_m)), room.attitude_to_ned(
        np.array(sample.quat_wxyz)
    )


class Forwarder:
    """The test's own vision bridge: every tracked mocap sample goes out through MAVSDK."""

    def __init__(self, mocap: MocapAsync, send_vpe: bool = False) -> None:
        self.mocap, self.send_vpe = mocap, send_vpe
        self.queue: asyncio.Queue[MocapSample] = asyncio.Queue()
        self.sent = 0
        self.last_sent_s = math.nan
        self.latest: MocapSample | None = None

    def on_sample(self, loop: asyncio.AbstractEventLoop):
        return lambda s: loop.call_soon_threadsafe(self.queue.put_nowait, s)

    async def run(self) -> None:
        while True:
            sample = await self.queue.get()
            self.latest = sample
            if not sample.tracked:
                continue  # an occluded body: nothing to forward
            pos, quat = in_ned(sample)
            if self.send_vpe:
                yaw = math.atan2(
                    2 * (quat[0] * quat[3] + quat[1] * quat[2]),
                    1 - 2 * (quat[2] ** 2 + quat[3] ** 2),
                )
                vpe = VisionPositionEstimate(
                    0, PositionBody(*(float(v) for v in pos)), AngleBody(0.0, 0.0, yaw),
                    Covariance([math.nan]), 0,
                )  # fmt: skip
                await self.mocap.set_vision_position_estimate(vpe)
            else:
                await self.mocap.set_odometry(as_vision(pos, quat))
            self.sent += 1
            self.last_sent_s = time.monotonic()


def vision_rows(stats: dict) -> list[dict]:
    v = stats["vision"]
    keys = ("message", "frame_id", "estimator_type", "north_m", "east_m", "down_m", "fused",
            "t_rx_vehicle_s")  # fmt: skip
    return [dict(zip(keys, row, strict=True)) for row in zip(*(v[k] for k in keys), strict=True)]


def test_vision_on_the_wire_is_taken_as_px4s_mavlink_receiver_does(tmp_path: Path) -> None:
    """ODOMETRY by frame and estimator type, VISION_POSITION_ESTIMATE; telemetry without it."""
    stats_path = tmp_path / "stats.json"
    p = (0.03, -0.02, -0.01)  # NED; the vehicle sits at the origin: every sample is in the gate
    f, e = mavlink2, mavlink2
    cases = [  # frame, estimator, x y z as sent, fused, NED as PX4 reads it
        (f.MAV_FRAME_LOCAL_NED, e.MAV_ESTIMATOR_TYPE_VISION, p, True, p),
        (f.MAV_FRAME_LOCAL_FRD, e.MAV_ESTIMATOR_TYPE_VIO, p, True, p),
        (f.MAV_FRAME_LOCAL_ENU, e.MAV_ESTIMATOR_TYPE_UNKNOWN, (p[1], p[0], -p[2]), True, p),
        (f.MAV_FRAME_LOCAL_FLU, e.MAV_ESTIMATOR_TYPE_NAIVE, (p[0], -p[1], -p[2]), True, p),
        (14, e.MAV_ESTIMATOR_TYPE_VISION, p, False, None),  # MOCAP_NED: position left unset
        (f.MAV_FRAME_LOCAL_FRD, e.MAV_ESTIMATOR_TYPE_MOCAP, p, False, p),  # not EKF2's topic
        (f.MAV_FRAME_LOCAL_FRD, e.MAV_ESTIMATOR_TYPE_GPS, p, False, p),  # unsupported
    ]
    seen: dict[str, list[Any]] = {"LOCAL_POSITION_NED": [], "SYS_STATUS": [], "GPS_RAW_INT": []}
    with MockProcess(ROOT / "profiles" / "mock-mocap.yaml", stats_path=stats_path) as mock:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.settimeout(0.05)
        mav, parser = mavlink2.MAVLink(None, 245, 190), mavlink2.MAVLink(None)
        addr = ("127.0.0.1", mock.port)

        def listen(duration_s: float, tag: str) -> None:
            end = time.monotonic() + duration_s
            while time.monotonic() < end:
                try:
                    data = sock.recv(65536)
                except TimeoutError:
                    continue
                for msg in parser.parse_buffer(data) or []:
                    if msg.get_type() in seen:
                        seen[msg.get_type()].append((tag, msg))

        sock.sendto(mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav), addr)
        listen(0.6, "before")
        for k, (frame, estimator, xyz, _, _) in enumerate(cases):
            q = [1.0, 0.0, 0.0, 0.0]
            nan21 = [math.nan] + [0.0] * 20
            msg = mav.odometry_encode(1000 * k, frame, f.MAV_FRAME_BODY_FRD, *xyz, q,
                                      math.nan, math.nan, math.nan, 0.0, 0.0, 0.0, nan21, nan21,
                                      0, estimator, 100)  # fmt: skip
            sock.sendto(msg.pack(mav), addr)
        vpe = mav.vision_position_estimate_encode(9000, *p, 0.0, 0.0, 0.0, [math.nan] * 21, 0)
        sock.sendto(vpe.pack(mav), addr)
        listen(0.3, "after")
        sock.close()
    rows = vision_rows(mock.stats)
    assert [r["message"] for r in rows] == ["ODOMETRY"] * len(cases) + ["VISION_POSITION_ESTIMATE"]
    for row, (frame, estimator, _, fused, ned) in zip(rows, cases, strict=False):
        assert (row["frame_id"], row["estimator_type"], row["fused"]) == (frame, estimator, fused)
        got = (row["north_m"], row["east_m"], row["down_m"])
        if ned is None:
            assert all(math.isnan(v) for v in got)
        else:
            assert got == pytest.approx(ned, abs=1e-6)  # float32 on the wire
    assert rows[-1]["fused"] and rows[-1]["north_m"] == pytest.approx(p[0])
    texts = [s["text"] for s in mock.stats["statustexts"]]
    assert f"ODOMETRY: estimator_type {e.MAV_ESTIMATOR_TYPE_GPS} unsupported" in texts
    assert "EKF2: vision fusion started" in texts
    # no local position (nor GPS) before the vision, and the vision sensor unhealthy; then both
    bit = f.MAV_SYS_STATUS_SENSOR_VISION_POSITION
    assert not [m for tag, m in seen["LOCAL_POSITION_NED"] if tag == "before"]
    assert [m for tag, m in seen["LOCAL_POSITION_NED"] if tag == "after"]
    assert not seen["GPS_RAW_INT"]
    status = {tag: m for tag, m in seen["SYS_STATUS"]}
    assert status["before"].onboard_control_sensors_present & bit
    assert not status["before"].onboard_control_sensors_health & bit
    assert status["after"].onboard_control_sensors_health & bit
    assert not status["after"].onboard_control_sensors_present & f.MAV_SYS_STATUS_SENSOR_GPS


def test_vision_position_estimate_through_mavsdk_gives_the_mocap_position(tmp_path: Path) -> None:
    async def run(mock: MockProcess) -> tuple[np.ndarray, np.ndarray]:
        m, system = await connect(mock.url)
        tel, forwarder = TelemetryAsync(system), Forwarder(MocapAsync(system), send_vpe=True)
        loop = asyncio.get_running_loop()
        source = parse_mocap_url(mock.mocap_url)
        with MocapClient(source, on_sample=forwarder.on_sample(loop)) as client:
            health = await tel.health()
            assert not health.is_local_position_ok and not health.is_armable
            task = asyncio.create_task(forwarder.run())
            try:
                await first(tel.subscribe_health(), lambda h: h.is_local_position_ok, 5.0)
                await tel.set_rate_position_velocity_ned(50.0)
                pv = await first(tel.subscribe_position_velocity_ned(), lambda p: True, 2.0)
                sample = client.latest()
            finally:
                task.cancel()
                m.destroy()
        assert sample is not None and sample.tracked and forwarder.sent > 0
        reported = np.array([pv.position.north_m, pv.position.east_m, pv.position.down_m])
        return reported, in_ned(sample)[0]

    arena = ArenaOptions(rate_hz=100.0, seed=5)
    profile = vision_profile(tmp_path)
    with MockProcess(profile, seed=5, arena=arena, stats_path=tmp_path / "s.json") as mock:
        assert mock.mocap_url.startswith("optitrack://127.0.0.1:")
        reported, mocap = asyncio.run(run(mock))
    np.testing.assert_allclose(reported, mocap, atol=0.02)  # on the ground: noise only
    rows = vision_rows(mock.stats)
    assert {r["message"] for r in rows} == {"VISION_POSITION_ESTIMATE"}
    assert all(r["fused"] for r in rows)


def test_vision_only_flight_and_the_failsafe_when_the_body_is_occluded(tmp_path: Path) -> None:
    """No vision: nothing to fly. Forwarded: arm, take off, hold, OFFBOARD. The arena then
    occludes the body: the forwarding stops and PX4's failsafe lands and disarms."""
    occlusion = ArenaFault("occlusion", 1.0, 30.0)  # from 1 s after the first OFFBOARD
    arena = ArenaOptions(rate_hz=120.0, faults=(occlusion,), seed=11)
    stats_path = tmp_path / "stats.json"
    times: dict[str, float] = {}

    async def fly(mock: MockProcess) -> None:
        m, system = await connect(mock.url)
        action, offboard, tel = ActionAsync(system), OffboardAsync(system), TelemetryAsync(system)
        mocap = MocapAsync(system)
        forwarder = Forwarder(mocap, send_vpe=True)  # NED: PX4 aligns its heading to it
        loop = asyncio.get_running_loop()
        client = MocapClient(parse_mocap_url(mock.mocap_url), on_sample=forwarder.on_sample(loop))
        tasks: list[asyncio.Task] = []
        try:
            with pytest.raises(ActionError):  # no local position: arming refused
                await action.arm()
            client.start()
            pose = in_ned(client.wait_until(lambda s: s.tracked, 5.0))
            # MAVSDK's defaults (frame MOCAP_NED, estimator UNKNOWN sent as MOCAP) are not
            # what EKF2 reads: a position from them never appears
            for _ in range(5):
                await mocap.set_odometry(odometry(*pose))
            tasks.append(asyncio.create_task(forwarder.run()))
            await first(tel.subscribe_health(), lambda h: h.is_local_position_ok, 5.0)
            # no GPS: the local frame needs a global origin before PX4 can arm (PX4 v1.16)
            origin = {"target_system": 1, "latitude": 473977420, "longitude": 85455940,
                      "altitude": 488000, "time_usec": 0}  # fmt: skip
            direct = MavlinkDirectAsync(system)
            await direct.send_message(
                MavlinkMessage("SET_GPS_GLOBAL_ORIGIN", 0, 0, 1, 0, json.dumps(origin))
            )
            # PX4's checks pass 4.3 s after the first vision sample (EV_PREARM_DELAY_S)
            await first(tel.subscribe_health(), lambda h: h.is_armable, 10.0)
            await action.arm()
            await action.takeoff()
            await first(tel.subscribe_flight_mode(), lambda f: f.name == "TAKEOFF", 3.0)
            await first(tel.subscribe_flight_mode(), lambda f: f.name == "HOLD", 10.0)
            await tel.set_rate_position_velocity_ned(50.0)

            def on_vision(pv: object) -> bool:  # PX4's estimate is the pose forwarded to it
                p = pv.position  # type: ignore[attr-defined]
                here = np.array([p.north_m, p.east_m, p.down_m])
                latest = forwarder.latest
                return latest is not None and bool(np.allclose(here, in_ned(latest)[0], atol=0.05))

            def at_takeoff_altitude(pv: object) -> bool:  # within PX4's take-off acceptance
                return on_vision(pv) and abs(pv.position.down_m + 1.0) <= 0.1  # type: ignore[attr-defined]

            # the event, not one sample: under load a telemetry sample and the newest forwarded
            # pose can be tenths of a second apart, and a sample from the climb can come after
            # Hold (0.90 m seen, load 18), while the vehicle still settles at 1 m
            pv = await first(tel.subscribe_position_velocity_ned(), at_takeoff_altitude, 5.0)
            hover = np.array([pv.position.north_m, pv.position.east_m, pv.position.down_m])

            async def setpoints() -> None:
                while True:
                    await offboard.set_position_ned(PositionNedYaw(*hover, 0.0))
                    await asyncio.sleep(0.05)  # the stream's period, not a synchronisation

            await offboard.set_position_ned(PositionNedYaw(*hover, 0.0))
            tasks.append(asyncio.create_task(setpoints()))
            times["offboard_asked"] = time.monotonic()
            await offboard.start()  # returns on the ACK: the vehicle is in OFFBOARD
            times["offboard"] = time.monotonic()
            await first(tel.subscribe_flight_mode(), lambda f: f.name == "OFFBOARD", 3.0)

            async def land_seen() -> float:
                await first(tel.subscribe_flight_mode(), lambda f: f.name == "LAND", 10.0)
                return time.monotonic()

            # listening for Land from here, not from when the test sees the occlusion: the
            # failsafe's Land lasts about 1.8 s (landed, disarmed, back to OFFBOARD), and two
            # CI runs side by side (load 19) woke the occlusion's wait after it was over
            landing = asyncio.create_task(land_seen())
            tasks.append(landing)
            lost = await asyncio.to_thread(client.wait_until, lambda s: not s.tracked, 5.0)
            times["occluded"] = lost.t_receipt_s
            times["land"] = await landing
            times["last_sent"] = forwarder.last_sent_s
            await first(tel.subscribe_landed_state(), lambda s: s.name == "ON_GROUND", 10.0)
            await first(tel.subscribe_armed(), lambda a: not a, 5.0)
            times["disarmed"] = time.monotonic()
            after = client.recent(times["disarmed"] - times["occluded"])
            assert after.tracked.size > 0 and not after.tracked.any()  # untracked throughout
        finally:
            for task in tasks:
                task.cancel()
            client.stop()
            m.destroy()

    with MockProcess(vision_profile(tmp_path), seed=11, arena=arena, stats_path=stats_path) as mock:
        asyncio.run(fly(mock))
    stats = mock.stats
    # the occlusion began 1 s after OFFBOARD (receipt of the first untracked frame; how much
    # later a loaded machine delivers it is its timing, not the fault's), before the failsafe
    assert times["offboard_asked"] + 1.0 < times["occluded"] < times["land"]
    # PX4: fusion stops 0.4 s after the last sample, the position is invalid
    # EKF2_NOAID_TOUT - 1 s later; the vehicle's own clock, then what MAVSDK saw
    delay_s = 2 * EV_MAX_INTERVAL_S - NO_AID_TIMEOUT_S + NOAID_S
    rows = [r for r in vision_rows(stats) if r["fused"]]
    lpos = stats["vision"]["local_position"]
    invalid = [c["t_vehicle_s"] for c in lpos if not c["valid"]]
    assert len(invalid) == 1
    assert invalid[0] - rows[-1]["t_rx_vehicle_s"] == pytest.approx(delay_s, abs=0.02)
    # MAVSDK hears of it no sooner (the mock's clock runs at the wall's; 0.1 s for the stamps)
    assert times["land"] - times["last_sent"] > delay_s - 0.1
    texts = [s["text"] for s in stats["statustexts"]]
    assert "Failsafe activated: no local position, descending" in texts
    # MAVSDK's default Odometry went out as MAV_FRAME 14 / MAV_ESTIMATOR_TYPE_MOCAP, unused
    defaults = [r for r in vision_rows(stats) if r["estimator_type"] == 6]
    assert len(defaults) == 5 and not any(r["fused"] for r in defaults)
    assert {r["frame_id"] for r in defaults} == {14}
    used = [r for r in vision_rows(stats) if r["estimator_type"] != 6]
    assert {(r["frame_id"], r["estimator_type"]) for r in used} == {(1, -1)}  # VPE: LOCAL_NED
    modes = [(c["mode"], c["armed"]) for c in stats["modes"]]
    i = modes.index(("OFFBOARD", True))
    assert modes[i + 1] == ("LAND", True) and modes[-1][1] is False
    assert stats["arena"]["faults_placed"] and stats["arena"]["sent"] > 0
