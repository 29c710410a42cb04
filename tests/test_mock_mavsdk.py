"""The mock drone process flown through the real MAVSDK asyncio API over UDP loopback."""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import mavsdk
import numpy as np
import pytest
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, OffboardError, PositionNedYaw
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from pymavlink.dialects.v20 import common as mavlink2

from gcs.errors import VehicleError
from gcs.mock.config import Faults
from gcs.mock.process import MockProcess

pytestmark = pytest.mark.e2e


async def first(gen: AsyncIterator[Any], pred: Callable[[Any], bool], timeout_s: float) -> Any:
    """First item of an async generator that satisfies ``pred`` (events, no sleeps)."""

    async def scan() -> Any:
        async for item in gen:
            if pred(item):
                return item
        raise AssertionError("stream ended")

    return await asyncio.wait_for(scan(), timeout_s)


async def connect(url: str) -> tuple[Mavsdk, Any]:
    mavsdk.log_subscribe(lambda *a: True)
    m = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    await m.add_any_connection(url)
    system = await m.first_autopilot(5.0)
    assert system is not None
    return m, system


def plugins(system: Any) -> tuple[ActionAsync, OffboardAsync, TelemetryAsync]:
    return ActionAsync(system), OffboardAsync(system), TelemetryAsync(system)


# PX4 behaviour, quicker: low take-off, fast descent, short land detector and disarm delay
FAST = """
px4: {mis_takeoff_alt_m: 1.0, mpc_land_speed_m_s: 1.0, land_detect_s: 0.3, com_disarm_land_s: 0.5}
"""


def test_full_flight_through_mavsdk(tmp_path: Path) -> None:
    stats_path = tmp_path / "stats.json"
    profile = tmp_path / "fast.yaml"
    profile.write_text(FAST)

    async def fly(url: str) -> None:
        m, system = await connect(url)
        try:
            action, offboard, tel = (
                ActionAsync(system),
                OffboardAsync(system),
                TelemetryAsync(system),
            )
            assert (await system.autopilot_type()).name == "PX4"
            health = await first(
                tel.subscribe_health(), lambda h: h.is_armable and h.is_local_position_ok, 5.0
            )
            assert health.is_home_position_ok
            assert await action.get_takeoff_altitude() == pytest.approx(1.0)
            await tel.set_rate_position_velocity_ned(50.0)
            await action.arm()
            await first(tel.subscribe_armed(), bool, 3.0)
            await action.takeoff()
            await first(tel.subscribe_flight_mode(), lambda f: f.name == "HOLD", 10.0)
            # MAVSDK refuses offboard without a setpoint ...
            with pytest.raises(OffboardError) as err:
                await offboard.start()
            assert err.value.result.name == "NO_SETPOINT_SET"
            # ... and the vehicle accepts it with one
            await offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -1.0, 0.0))
            await offboard.start()
            await first(tel.subscribe_flight_mode(), lambda f: f.name == "OFFBOARD", 3.0)
            loop = asyncio.get_running_loop()
            t0 = loop.time()
            for k in range(150):  # 3 s at 50 Hz towards (0.6, -0.4)
                await offboard.set_position_ned(PositionNedYaw(0.6, -0.4, -1.0, 0.0))
                await asyncio.sleep(max(0.0, t0 + (k + 1) * 0.02 - loop.time()))
            pv = await tel.position_velocity_ned()
            assert abs(pv.position.north_m - 0.6) < 0.2 and abs(pv.position.east_m + 0.4) < 0.2
            odo = await first(tel.subscribe_odometry(), lambda o: o.time_usec > 0, 2.0)
            assert abs(odo.position_body.x_m - pv.position.north_m) < 0.1
            # stop sending: the vehicle is no longer in OFFBOARD after COM_OF_LOSS_T. MAVSDK
            # keeps re-sending the last setpoint at 20 Hz, so cut the stream the way a dead
            # GCS would: destroy the MAVSDK instance and watch with a fresh one.
            landed = (await first(tel.subscribe_landed_state(), lambda s: True, 2.0)).name
            assert landed == "IN_AIR"
        finally:
            m.destroy()
        m, system = await connect(url)
        try:
            action, tel = ActionAsync(system), TelemetryAsync(system)
            await first(tel.subscribe_flight_mode(), lambda f: f.name == "HOLD", 5.0)
            await action.land()
            await first(tel.subscribe_landed_state(), lambda s: s.name == "ON_GROUND", 15.0)
            await first(tel.subscribe_armed(), lambda a: not a, 5.0)
        finally:
            m.destroy()

    with MockProcess(profile, seed=3, stats_path=stats_path) as mock:
        assert mock.url.startswith("udpout://127.0.0.1:")
        asyncio.run(fly(mock.url))
    stats = mock.stats
    assert stats is not None and stats == json.loads(stats_path.read_text())
    arrivals = stats["setpoints"]["t_rx_monotonic_s"]
    assert len(arrivals) >= 150 and arrivals == sorted(arrivals)
    assert stats["setpoints"]["north_m"][-1] == pytest.approx(0.6)
    modes = [m["mode"] for m in stats["modes"]]
    assert "OFFBOARD" in modes and "LAND" in modes
    assert modes[modes.index("OFFBOARD") + 1] == "HOLD"  # the offboard-loss fallback
    # ... COM_OF_LOSS_T (1 s) after the last setpoint, on the vehicle's clock (the mock checks
    # at each physics step, which may run late by its largest lag)
    hold_t_s = stats["modes"][modes.index("OFFBOARD") + 1]["t_vehicle_s"]
    silent_s = hold_t_s - stats["setpoints"]["t_rx_vehicle_s"][-1]
    assert 1.0 < silent_s <= 1.0 + stats["max_physics_lag_s"] + 0.05, silent_s
    assert stats["modes"][-1]["armed"] is False
    assert stats["max_physics_lag_s"] < 0.5


def test_offboard_denied_on_the_wire_without_a_setpoint_stream() -> None:
    """DO_SET_MODE(OFFBOARD) while armed and without setpoints: TEMPORARILY_REJECTED."""
    import socket

    with MockProcess(seed=0) as mock:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.settimeout(3.0)
        mav = mavlink2.MAVLink(None, srcSystem=245, srcComponent=190)
        parser = mavlink2.MAVLink(None)
        addr = ("127.0.0.1", mock.port)

        def command(cmd: int, *p: float) -> int:
            params = list(p) + [math.nan] * (7 - len(p))
            sock.sendto(mav.command_long_encode(1, 1, cmd, 0, *params).pack(mav), addr)
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline:
                for msg in parser.parse_buffer(sock.recv(4096)) or []:
                    if msg.get_type() == "COMMAND_ACK" and msg.command == cmd:
                        return int(msg.result)
            raise AssertionError("no COMMAND_ACK")

        sock.sendto(mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav), addr)
        assert command(400, 1.0) == 0  # armed
        assert command(176, 129.0, 6.0, 0.0) == 1  # TEMPORARILY_REJECTED: no setpoints
        sp = mav.set_position_target_local_ned_encode(
            0, 1, 1, 1, 2552, 0.0, 0.0, -1.0, 0, 0, 0, 0, 0, 0, 0.0, 0.0
        )
        sock.sendto(sp.pack(mav), addr)
        assert command(176, 129.0, 6.0, 0.0) == 0  # accepted with a fresh setpoint
        assert command(31999, 0.0) == 3  # unknown command: UNSUPPORTED, but answered
        sock.close()


def test_bad_profile_gives_vehicle_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("physics:\n  dt_s: [1]\n")
    with pytest.raises(VehicleError, match="physics.dt_s"), MockProcess(config_path=bad):
        pass


def test_telemetry_dropout_fault_silences_positions(tmp_path: Path) -> None:
    """A dropout of 0.6 s silences the positions for 0.6 s of the vehicle's time, then they come
    again. Judged on each LOCAL_POSITION_NED's own ``time_boot_ms`` (read raw through MAVSDK's
    MavlinkDirect, as gcs reads it), not on when this process received it: on a loaded machine
    the last position before the silence can arrive late and shorten the pause seen here (once
    0.39 s of receipts)."""
    silence_ms = 600

    async def fly(url: str) -> list[int]:
        m, system = await connect(url)
        try:
            action, offboard, tel = plugins(system)
            direct = MavlinkDirectAsync(system)
            await first(tel.subscribe_health(), lambda h: h.is_armable, 5.0)
            stamps: list[int] = []

            async def collect() -> None:
                # until 0.3 s of positions have come after a pause of more than half the silence
                resumed_ms = None
                async for message in direct.subscribe_message("LOCAL_POSITION_NED"):
                    stamps.append(int(json.loads(message.fields_json)["time_boot_ms"]))
                    if len(stamps) > 1 and stamps[-1] - stamps[-2] > silence_ms / 2:
                        resumed_ms = stamps[-1]
                    if resumed_ms is not None and stamps[-1] - resumed_ms >= 300:
                        return

            collecting = asyncio.create_task(collect())
            await action.arm()
            await offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -1.0, 0.0))
            await offboard.start()  # the dropout's clock starts at the first OFFBOARD
            with contextlib.suppress(TimeoutError):  # judged below, with what came
                await asyncio.wait_for(collecting, 30.0)
            return stamps
        finally:
            m.destroy()

    with MockProcess(
        seed=0, faults=Faults(dropout_start_s=0.5, dropout_duration_s=silence_ms / 1000)
    ) as mock:
        stamps = asyncio.run(fly(mock.url))
    gaps = np.diff(stamps)
    # none sent within the silence: the last before it and the first after it are at least the
    # silence apart, less one period of the 50 Hz stream (and a millisecond of rounding)
    (pause,) = np.flatnonzero(gaps > silence_ms / 2)
    assert gaps[pause] >= silence_ms - 20 - 1, gaps.tolist()
    assert stamps[-1] - stamps[pause + 1] >= 300  # and positions came again after it
