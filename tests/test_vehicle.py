"""The vehicle: exactly what a campaign needs, each call handed to the part that does it."""

from __future__ import annotations

import ast
import asyncio
import inspect
from pathlib import Path

import pytest

import gcs
from gcs.errors import VehicleError
from gcs.flight.fence import Fence
from gcs.flight.vehicle import CampaignVehicle, Vehicle
from gcs.io.settings import FlightSettings

SETTINGS = FlightSettings()
FENCE = Fence.around(
    [[-3.0, 3.0], [-3.0, 3.0], [-3.0, 0.0]], SETTINGS, max_speed_m_s=3.0, max_vertical_speed_m_s=1.5
)

# the campaign and the steps it hands its vehicle to
CALLERS = (
    "flight/campaign.py",
    "flight/trial.py",
    "flight/prearm.py",
    "flight/geofence.py",
    "flight/checklist.py",
    "flight/mocap/campaign.py",
)


def _public(cls: type) -> set[str]:
    return {name for name in dir(cls) if not name.startswith("_")}


def _vehicle_attributes(path: Path) -> set[str]:
    """Every ``vehicle.x`` and ``<...>.vehicle.x`` a module reads or calls."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Attribute):
            owner = node.value
            if (isinstance(owner, ast.Name) and owner.id == "vehicle") or (
                isinstance(owner, ast.Attribute) and owner.attr == "vehicle"
            ):
                found.add(node.attr)
    return found


def test_the_vehicle_offers_exactly_the_protocol_each_member_its_own() -> None:
    assert _public(Vehicle) == _public(CampaignVehicle)
    for name in sorted(_public(CampaignVehicle)):
        wanted, offered = getattr(CampaignVehicle, name), getattr(Vehicle, name)
        assert offered is not wanted, f"Vehicle.{name} is the protocol's stub"
        if isinstance(wanted, property):
            assert isinstance(offered, property) and offered.fset is None, name
        else:
            assert inspect.signature(offered) == inspect.signature(wanted), name


@pytest.mark.parametrize("caller", CALLERS)
def test_what_the_campaign_and_its_steps_use_is_in_the_protocol(caller: str) -> None:
    used = _vehicle_attributes(Path(gcs.__file__).parent / caller)
    assert used, f"{caller} no longer uses a vehicle: drop it from CALLERS"
    assert used <= _public(CampaignVehicle), sorted(used - _public(CampaignVehicle))


def test_a_breach_reported_to_the_vehicle_ends_its_control() -> None:
    vehicle = Vehicle(SETTINGS, FENCE)
    assert vehicle.breach is None and vehicle.fence is FENCE and vehicle.settings is SETTINGS
    vehicle.trip("mocap", "stream stale")
    vehicle.trip("fence", "something else")  # the first breach is the one kept
    assert vehicle.breach == "mocap: stream stale" == vehicle.control_problem()


def test_an_emergency_stop_ends_the_setpoint_stream_for_good_even_unconnected() -> None:
    async def stop_then_send() -> str:
        vehicle = Vehicle(SETTINGS, FENCE)
        outcome = await vehicle.emergency_stop("test")
        await vehicle.send_setpoint([0.0, 0.0, -1.0])  # inside the arena
        return outcome

    with pytest.raises(VehicleError, match="stopped by an emergency stop"):
        asyncio.run(stop_then_send())
    assert asyncio.run(Vehicle(SETTINGS, FENCE).emergency_stop("test")) == "not connected"


def test_an_unconnected_vehicle_names_that_instead_of_commanding() -> None:
    vehicle = Vehicle(SETTINGS, FENCE)
    with pytest.raises(VehicleError, match="^not connected$"):
        _ = vehicle.link
    with pytest.raises(VehicleError, match="^reading parameters: not connected$"):
        asyncio.run(vehicle.read_int_params(("NAV_DLL_ACT",)))
    with pytest.raises(VehicleError, match="^land: not connected$|^not connected$"):
        asyncio.run(vehicle.land_and_disarm())
