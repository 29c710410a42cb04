"""The virtual-time event loop and the simulated link's own rules (gcs.sim)."""

from __future__ import annotations

import asyncio
import threading
import time

import pytest

from gcs.flight.backend import CommandRefused, is_registered, registered_link
from gcs.mock.config import Faults
from gcs.sim.drone import SimLink, SimulatedDrone
from gcs.sim.loop import VirtualTimeLoop, virtual_time


def test_virtual_time_jumps_to_the_next_timer_when_every_task_waits() -> None:
    async def main() -> tuple[float, float, list[str]]:
        loop = asyncio.get_running_loop()
        order: list[str] = []

        async def nap(name: str, delay_s: float) -> None:
            await asyncio.sleep(delay_s)
            order.append(name)

        start = loop.time()
        await asyncio.gather(nap("long", 3600.0), nap("short", 60.0))
        with pytest.raises(TimeoutError):
            async with asyncio.timeout(10.0):
                await asyncio.Event().wait()
        return start, loop.time(), order

    wall = time.monotonic()
    with virtual_time():
        start, end, order = asyncio.run(main())
    assert end - start == pytest.approx(3610.0)
    assert order == ["short", "long"]
    assert time.monotonic() - wall < 60.0  # an hour of virtual time, not of the wall clock


def test_virtual_time_stands_still_while_a_thread_works() -> None:
    release = threading.Event()

    async def main() -> tuple[float, float, int]:
        loop = asyncio.get_running_loop()
        assert isinstance(loop, VirtualTimeLoop)
        ticks = 0

        async def ticker() -> None:
            nonlocal ticks
            while True:
                await asyncio.sleep(0.01)
                ticks += 1

        task = asyncio.create_task(ticker())
        before = loop.time()
        work = asyncio.to_thread(release.wait, 5.0)
        threading.Timer(0.2, release.set).start()  # the thread works 0.2 s of wall time
        await work
        after = loop.time()
        task.cancel()
        return before, after, ticks

    with virtual_time():
        before, after, ticks = asyncio.run(main())
    assert after - before < 0.011 and ticks <= 1


def test_a_simulated_drone_is_reached_by_its_url_only_while_open() -> None:
    drone = SimulatedDrone()
    assert not is_registered(drone.url)
    with drone:
        assert is_registered(drone.url)
        assert isinstance(registered_link(drone.url), SimLink)
    assert not is_registered(drone.url)


def test_the_simulated_link_refuses_as_mavsdk_does() -> None:
    async def main(drone: SimulatedDrone) -> list[str]:
        link = SimLink(drone)
        assert await link.connect(drone.url, 1.0)
        results = []
        for call in (
            link.start_offboard,  # no setpoint yet
            lambda: link.get_param_int("MIS_TAKEOFF_ALT"),  # a float parameter
            lambda: link.get_param_float("NO_SUCH_PARAM"),
        ):
            try:
                await call()
                results.append("ok")
            except CommandRefused as exc:
                results.append(exc.result)
        assert await link.get_param_float("MIS_TAKEOFF_ALT") == pytest.approx(2.5)
        await link.set_param_float("MIS_TAKEOFF_ALT", 1.5)
        assert await link.get_param_float("MIS_TAKEOFF_ALT") == pytest.approx(1.5)
        await link.close()
        return results

    with SimulatedDrone() as drone, virtual_time():
        results = asyncio.run(main(drone))
    assert results == ["NO_SETPOINT_SET", "WRONG_TYPE", "TIMEOUT"]


def test_a_command_over_a_lost_link_times_out_and_the_link_is_declared_lost() -> None:
    async def main(drone: SimulatedDrone) -> tuple[str, bool, float]:
        link = SimLink(drone)
        await link.connect(drone.url, 1.0)
        drone.vehicle.first_offboard_t_s = drone.vehicle.t_s  # the loss counts from OFFBOARD
        drone.lose_link()
        loop = asyncio.get_running_loop()
        start = loop.time()
        try:
            await link.arm()
            result = "ok"
        except CommandRefused as exc:
            result = exc.result
        waited = loop.time() - start
        await asyncio.sleep(3.0)
        connected = await link.is_connected()
        await link.close()
        return result, connected, waited

    with SimulatedDrone(faults=Faults(link_loss_duration_s=60.0)) as drone, virtual_time():
        result, connected, waited = asyncio.run(main(drone))
    assert result == "TIMEOUT" and waited == pytest.approx(1.5)
    assert connected is False
