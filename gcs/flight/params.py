"""What a vehicle keeps in store: its parameters, the global origin and the geofence.

Reads and writes through MAVSDK's Param, Telemetry, MavlinkDirect and Geofence plugins, each
guarded by the command timeout of :class:`gcs.flight.link.Link`. What the geofence holds is
decided in :mod:`gcs.flight.geofence`.

:class:`Params` is one part of :class:`gcs.flight.vehicle.Vehicle`.
"""

from __future__ import annotations

import json
import logging
import math

from mavsdk.asyncio.plugins.geofence import (
    FenceType,
    GeofenceAsync,
    GeofenceData,
    Point,
    Polygon,
)
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkMessage
from mavsdk.asyncio.plugins.param import ParamAsync

from gcs.errors import VehicleError
from gcs.flight.link import Link

__all__ = ["Params"]

_log = logging.getLogger(__name__)


class Params(Link):
    """Parameters, global origin and geofence of :class:`gcs.flight.vehicle.Vehicle`."""

    async def read_int_params(self, names: tuple[str, ...]) -> dict[str, int | None]:
        """Read integer parameters of the autopilot; None for each one it does not answer.

        Parameters
        ----------
        names : tuple of str
            PX4 parameter names.

        Returns
        -------
        dict of str to int or None
        """
        if self._system is None:
            raise VehicleError("reading parameters: not connected")
        param = ParamAsync(self._system)
        values: dict[str, int | None] = {}
        try:
            for name in names:
                try:
                    values[name] = await self._command(
                        f"read {name}", lambda name=name: param.get_param_int(name)
                    )
                except VehicleError as exc:
                    _log.warning("%s", exc)
                    values[name] = None
        finally:
            param.destroy()
        return values

    async def set_params(self, values: dict[str, int | float]) -> None:
        """Set autopilot parameters (an int as INT32, a float as REAL32), one after the other.

        Parameters
        ----------
        values : dict of str to int or float
            PX4 parameter names and values.

        Raises
        ------
        VehicleError
            A parameter was refused or not answered.
        """
        if self._system is None:
            raise VehicleError("setting parameters: not connected")
        param = ParamAsync(self._system)
        try:
            for name, value in values.items():
                if isinstance(value, int):
                    call = lambda n=name, v=value: param.set_param_int(n, v)  # noqa: E731
                else:
                    call = lambda n=name, v=value: param.set_param_float(n, float(v))  # noqa: E731
                await self._command(f"set {name}", call)
        finally:
            param.destroy()

    async def read_float_param(self, name: str) -> float | None:
        """Read one float parameter of the autopilot; None if it does not answer.

        Parameters
        ----------
        name : str
            PX4 parameter name.

        Returns
        -------
        float or None
        """
        if self._system is None:
            raise VehicleError("reading parameters: not connected")
        param = ParamAsync(self._system)
        try:
            return float(await self._command(f"read {name}", lambda: param.get_param_float(name)))
        except VehicleError as exc:
            _log.warning("%s", exc)
            return None
        finally:
            param.destroy()

    async def read_all_params(self) -> dict[str, float | None]:
        """Read every parameter of the autopilot at once (one list request).

        Returns
        -------
        dict of str to float or None
            Integer and float parameters by name.
        """
        if self._system is None:
            raise VehicleError("reading parameters: not connected")
        param = ParamAsync(self._system)
        try:
            found = await self._command("read all parameters", param.get_all_params)
        finally:
            param.destroy()
        values: dict[str, float | None] = {p.name: float(p.value) for p in found.int_params}
        values |= {p.name: float(p.value) for p in found.float_params}
        return values

    async def gps_global_origin(self) -> tuple[float, float, float]:
        """The global position of the local NED frame's origin (PX4's GPS_GLOBAL_ORIGIN).

        Returns
        -------
        tuple of float
            Latitude [deg], longitude [deg], altitude AMSL [m].

        Raises
        ------
        VehicleError
            Not answered, or not a finite position.
        """
        telemetry = self._require(self._telemetry)
        origin = await self._command("read the global origin", telemetry.get_gps_global_origin)
        values = (origin.latitude_deg, origin.longitude_deg, origin.altitude_m)
        if not all(math.isfinite(float(x)) for x in values):
            raise VehicleError(f"read the global origin: not a position {values}")
        return (float(values[0]), float(values[1]), float(values[2]))

    async def set_global_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Set the global position of the local NED origin (MAVLink ``SET_GPS_GLOBAL_ORIGIN``).

        PX4 without GPS (motion capture) has no global origin until one is set; EKF2 takes
        it once, and PX4 answers with ``GPS_GLOBAL_ORIGIN`` (read it with
        :meth:`gps_global_origin`).

        Parameters
        ----------
        lat_deg, lon_deg : float
            WGS84 latitude and longitude [deg].
        alt_m : float
            Altitude AMSL [m].

        Raises
        ------
        VehicleError
            Not connected, or MAVSDK refused the message.
        """
        direct = self._require(self._direct)
        system = self._require(self._system)
        fields = {
            "target_system": await system.get_system_id(),
            "latitude": round(lat_deg * 1e7),
            "longitude": round(lon_deg * 1e7),
            "altitude": round(alt_m * 1e3),
            "time_usec": 0,
        }
        message = MavlinkMessage("SET_GPS_GLOBAL_ORIGIN", 0, 0, fields["target_system"], 0,
                                 json.dumps(fields))  # fmt: skip
        await self._command("set the global origin", lambda: direct.send_message(message))

    async def upload_inclusion_polygon(self, vertices_deg: list[tuple[float, float]]) -> None:
        """Replace the autopilot's geofence by one inclusion polygon (MAVSDK's Geofence plugin).

        Parameters
        ----------
        vertices_deg : list of (float, float)
            The polygon's vertices, (latitude, longitude) [deg].

        Raises
        ------
        VehicleError
            The upload was refused or not answered.
        """
        if self._system is None:
            raise VehicleError("geofence upload: not connected")
        fence = GeofenceAsync(self._system)
        points = [Point(lat, lon) for lat, lon in vertices_deg]
        data = GeofenceData([Polygon(points, FenceType.INCLUSION)], [])
        try:
            await self._command("geofence upload", lambda: fence.upload_geofence(data))
        finally:
            fence.destroy()
