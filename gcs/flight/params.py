"""What a vehicle keeps in store: its parameters, the global origin and the geofence.

Reads and writes through the vehicle's link (:class:`gcs.flight.backend.VehicleLink`; MAVSDK's
Param, Telemetry, MavlinkDirect and Geofence plugins on the wire), each guarded by the command
timeout of :class:`gcs.flight.link.Link`. What the geofence holds is
decided in :mod:`gcs.flight.geofence`.

:class:`Params` is one part of :class:`gcs.flight.vehicle.Vehicle`: it needs only the connection
(:meth:`gcs.flight.link.Link.command`).
"""

from __future__ import annotations

import logging
import math

from gcs.errors import VehicleError
from gcs.flight.link import Link

__all__ = ["Params"]

_log = logging.getLogger(__name__)


class Params:
    """Parameters, global origin and geofence of :class:`gcs.flight.vehicle.Vehicle`.

    Parameters
    ----------
    mirror : Link
        The connection the reads and writes go through.
    """

    def __init__(self, mirror: Link) -> None:
        self._mirror = mirror

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
        if self._mirror.backend is None:
            raise VehicleError("reading parameters: not connected")
        link = self._mirror.backend
        values: dict[str, int | None] = {}
        for name in names:
            try:
                values[name] = await self._mirror.command(
                    f"read {name}", lambda name=name: link.get_param_int(name)
                )
            except VehicleError as exc:
                _log.warning("%s", exc)
                values[name] = None
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
        if self._mirror.backend is None:
            raise VehicleError("setting parameters: not connected")
        link = self._mirror.backend
        for name, value in values.items():
            if isinstance(value, int):
                call = lambda n=name, v=value: link.set_param_int(n, v)  # noqa: E731
            else:
                call = lambda n=name, v=value: link.set_param_float(n, float(v))  # noqa: E731
            await self._mirror.command(f"set {name}", call)

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
        if self._mirror.backend is None:
            raise VehicleError("reading parameters: not connected")
        link = self._mirror.backend
        try:
            return float(
                await self._mirror.command(f"read {name}", lambda: link.get_param_float(name))
            )
        except VehicleError as exc:
            _log.warning("%s", exc)
            return None

    async def read_all_params(self) -> dict[str, float | None]:
        """Read every parameter of the autopilot at once (one list request).

        Returns
        -------
        dict of str to float or None
            Integer and float parameters by name.
        """
        if self._mirror.backend is None:
            raise VehicleError("reading parameters: not connected")
        found = await self._mirror.command(
            "read all parameters", self._mirror.backend.get_all_params
        )
        return dict(found)

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
        link = self._mirror.link
        values = await self._mirror.command("read the global origin", link.get_gps_global_origin)
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
        link = self._mirror.link
        await self._mirror.command(
            "set the global origin", lambda: link.set_gps_global_origin(lat_deg, lon_deg, alt_m)
        )

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
        if self._mirror.backend is None:
            raise VehicleError("geofence upload: not connected")
        link = self._mirror.backend
        await self._mirror.command(
            "geofence upload", lambda: link.upload_inclusion_polygon(vertices_deg)
        )
