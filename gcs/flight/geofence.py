"""The arena uploaded to the autopilot as its own geofence, so that it holds when gcs is gone.

gcs's fence (:mod:`gcs.flight.fence`) acts only while gcs is connected. PX4's geofence acts on
the vehicle: :func:`install_geofence` uploads the arena plus the fence's margin as one inclusion
polygon (MAVSDK's Geofence plugin: the MAVLink mission protocol with ``MAV_MISSION_TYPE_FENCE``)
and sets what PX4 does on a breach:

- **Where.** The local box becomes latitude/longitude vertices about the local frame's origin as
  PX4 reports it (``GPS_GLOBAL_ORIGIN``, MAVSDK ``Telemetry.get_gps_global_origin``), projected
  with PX4's own map projection. The origin, not home: local positions (what gcs flies and the
  arena is in) are relative to it, and home is wherever the vehicle was armed (the shared capture:
  0.35 m above the origin).
- **The vertical.** A polygon has no altitude. ``GF_MAX_VER_DIST`` bounds the height above
  home: the arena's ceiling plus the margin (home on the ground at the origin's height). PX4's
  fence has no floor: an estimate sinking below the ground (the EKF2 divergence once seen on
  PX4 SITL) is caught by gcs's fence only. ``GF_MAX_HOR_DIST`` is read and reported, not
  changed: the polygon is the horizontal fence.
- **The action.** ``GF_ACTION`` = 5, Land. Hold (2, PX4's default) keeps a vehicle whose
  estimate is wrong hovering where the estimate says, and with gcs gone it hovers until the
  battery fails; a landing ends on the ground whatever the estimate does horizontally (PX4's
  land mode descends on its vertical velocity and stops on ground contact). Return (3) climbs
  to ``RTL_RETURN_ALT`` (60 m by default) first, which no indoor arena has; Terminate (4) drops
  the vehicle.

A vehicle that refuses any of this (no global origin, upload or parameter refused) still flies,
with a warning: gcs's own fence watches every phase while connected, and a lost link is the
data-link-loss failsafe's (``NAV_DLL_ACT``, also said before take-off), the same policy as for
that parameter. Refusing to fly would make gcs unusable on autopilots whose fence differs
(ArduPilot's ``FENCE_*``) while protecting nothing more as long as gcs is connected.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from gcs.errors import VehicleError
from gcs.flight.fence import Fence, fence_polygon
from gcs.flight.vehicle import Vehicle

__all__ = ["GeofenceState", "install_geofence", "GF_ACTION", "GF_ACTION_NAMES", "vertical_limit_m"]

_log = logging.getLogger(__name__)

GF_ACTION = 5
"""The breach action gcs sets: Land (see the module docstring)."""
GF_ACTION_NAMES = {0: "none", 1: "warning", 2: "Hold", 3: "Return", 4: "Terminate", 5: "Land"}
"""PX4's ``GF_ACTION`` values (v1.14-v1.16)."""


@dataclass(frozen=True)
class GeofenceState:
    """What the vehicle's own geofence is, as far as gcs set it up.

    ``uploaded``: the polygon was accepted by the vehicle. ``origin_deg``: the local origin used:
    latitude, longitude [deg], altitude AMSL [m]. ``vertices_deg``: the polygon uploaded, (latitude,
    longitude) [deg]. ``gf_action``: ``GF_ACTION`` as set (None: not set). ``gf_max_ver_dist_m``:
    ``GF_MAX_VER_DIST`` as set [m] (None: not set). ``gf_max_hor_dist_m``: ``GF_MAX_HOR_DIST`` as
    read [m] (None: not read; 0: off). ``problem``: what failed, if anything.
    """

    uploaded: bool
    origin_deg: tuple[float, float, float] | None
    vertices_deg: tuple[tuple[float, float], ...]
    gf_action: int | None
    gf_max_ver_dist_m: float | None
    gf_max_hor_dist_m: float | None
    problem: str | None = None

    @property
    def ok(self) -> bool:
        """The polygon is on the vehicle and PX4 lands on a breach."""
        return self.uploaded and self.gf_action == GF_ACTION and self.problem is None

    def text(self, margin_m: float) -> str:
        """One line for the operator before take-off.

        ``margin_m``: the fence's margin [m], for the line.
        """
        if not self.uploaded:
            return (
                f"geofence not installed on the vehicle ({self.problem}): only gcs's fence "
                "watches the arena, and only while gcs is connected"
            )
        assert self.origin_deg is not None
        lat, lon, _ = self.origin_deg
        line = (
            f"geofence: the arena + {margin_m:g} m uploaded to the vehicle as an inclusion "
            f"polygon of {len(self.vertices_deg)} vertices around the local origin "
            f"({lat:.7f}, {lon:.7f}), replacing any fence stored there"
        )
        if self.gf_action is not None:
            name = GF_ACTION_NAMES.get(self.gf_action, "?")
            line += f"; GF_ACTION {self.gf_action} ({name})"
        if self.gf_max_ver_dist_m is not None:
            line += f", GF_MAX_VER_DIST {self.gf_max_ver_dist_m:g} m above home (no floor)"
        if self.gf_max_hor_dist_m is not None:
            hor = self.gf_max_hor_dist_m
            line += f", GF_MAX_HOR_DIST {hor:g} m" + (" (off)" if hor <= 0 else "")
        if self.problem is not None:
            line += f"; but {self.problem}"
        return line


def vertical_limit_m(fence: Fence) -> float:
    """``GF_MAX_VER_DIST`` for a fence: the arena's ceiling plus the margin, above home [m]."""
    return -fence.arena_ned_m[2][0] + fence.margin_m


async def install_geofence(vehicle: Vehicle, fence: Fence) -> GeofenceState:
    """Upload the arena plus margin as the vehicle's geofence and set its breach action.

    Never raises for a vehicle that refuses: the state says what failed.
    """
    try:
        origin = await vehicle.gps_global_origin()
    except VehicleError as exc:
        return GeofenceState(False, None, (), None, None, None, f"no global origin: {exc}")
    vertices = tuple(fence_polygon(fence, origin[0], origin[1]))
    try:
        await vehicle.upload_inclusion_polygon(list(vertices))
    except VehicleError as exc:
        return GeofenceState(False, origin, vertices, None, None, None, str(exc))
    ceiling_m = vertical_limit_m(fence)
    problem = None
    action: int | None = GF_ACTION
    ver: float | None = ceiling_m
    try:
        await vehicle.set_params({"GF_ACTION": GF_ACTION, "GF_MAX_VER_DIST": ceiling_m})
    except VehicleError as exc:
        _log.warning("%s", exc)
        problem, action, ver = f"{exc}: the vehicle's own breach action is unknown", None, None
    hor = await vehicle.read_float_param("GF_MAX_HOR_DIST")
    return GeofenceState(True, origin, vertices, action, ver, hor, problem)
