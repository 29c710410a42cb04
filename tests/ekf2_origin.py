"""A vehicle on the ground whose local height follows PX4 v1.16's EKF2 rule for the global
origin, on a virtual clock (for :mod:`gcs.flight.prearm` and the mocap pre-flight).

The rule (``Ekf::setAltOrigin``, measured on the SIH firmware, docs/mocap.md): an origin taken
while EKF2 has a valid height leaves the local height where it is; one taken before (no
vision height fused yet) moves the local height down by the origin's altitude, for good; a
later origin moves it by the change of altitude.
"""

from __future__ import annotations

from collections.abc import Callable
from types import SimpleNamespace

import numpy as np

from gcs.errors import VehicleError
from gcs.flight.link import TelemetrySample

#: Where the mocap sees the vehicle standing (NED) [m].
STANDING_NED_M = np.array([0.3, -0.2, -0.05])


class OriginRuleVehicle:
    """The part of :class:`gcs.flight.vehicle.Vehicle` the origin and the agreement use.

    ``height_after_s``: virtual time at which EKF2 first fuses a vision height [s].
    ``origin``: the global origin it already has (None: none). ``shift_m``: how far down its
    local height already sits [m]. ``timeout_s``: ``flight.health_timeout_s``.
    """

    def __init__(
        self,
        height_after_s: float,
        origin: tuple[float, float, float] | None = None,
        shift_m: float = 0.0,
        timeout_s: float = 5.0,
    ) -> None:
        self.t_s = 0.0
        self.height_after_s = height_after_s
        self.origin = origin
        self.shift_m = shift_m
        self.settings = SimpleNamespace(health_timeout_s=timeout_s)

    @property
    def height_valid(self) -> bool:
        return self.t_s >= self.height_after_s

    @property
    def latest(self) -> TelemetrySample:
        pos = STANDING_NED_M + np.array([0.0, 0.0, self.shift_m])
        return TelemetrySample(self.t_s, tuple(pos), (0.0, 0.0, 0.0), self.t_s)

    async def gps_global_origin(self) -> tuple[float, float, float]:
        if self.origin is None:
            raise VehicleError("read the global origin: COMMAND_DENIED")
        return self.origin

    async def set_global_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        if self.origin is not None:
            self.shift_m += alt_m - self.origin[2]
        elif not self.height_valid:
            self.shift_m += alt_m
        self.origin = (lat_deg, lon_deg, alt_m)

    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
        end_s = self.t_s + timeout_s
        while not predicate():
            if self.t_s >= end_s:
                raise VehicleError(f"{what} did not happen within {timeout_s:g} s")
            self.t_s += 0.1


def standing_mocap(agreement_m: float = 0.15) -> SimpleNamespace:
    """The campaign's mocap link as the agreement uses it: the vehicle tracked where it stands."""
    return SimpleNamespace(
        require_tracked=lambda: STANDING_NED_M.copy(),
        settings=SimpleNamespace(agreement_m=agreement_m),
    )
