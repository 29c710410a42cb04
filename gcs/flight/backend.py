"""What the flight layer needs from a link to the vehicle: the seam at the MAVSDK boundary.

:class:`VehicleLink` is that link as a protocol: connect and close, the state streams the
vehicle's mirror is made of (:mod:`gcs.flight.link`), the commands (arm, take-off, land,
offboard), the setpoint, parameters, the global origin and the geofence, and the local
:class:`gcs.flight.clock.Clock` its samples are received on.
:class:`gcs.flight.mavsdk_link.MavsdkLink` implements it over MAVSDK (a real PX4, PX4 SITL,
or the mock over UDP); a simulated link on a virtual clock (:mod:`gcs.sim`) implements it
in-process, so that whole flights run in virtual time in the tests.

Which link a URL opens is decided by its scheme (:func:`registered_link`): the MAVSDK schemes by
default, others where a caller registered them (:func:`register_scheme`; the tests register
``sim``).

A command the vehicle refuses raises :class:`CommandRefused` naming the result (MAVSDK's
``COMMAND_DENIED`` and the like); a command that is never answered simply does not return
(the flight layer bounds every command by its timeout).
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Any, Protocol

from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState

from gcs.flight.clock import Clock

__all__ = [
    "CommandRefused",
    "LinkUnreachable",
    "PositionReport",
    "VehicleLink",
    "is_registered",
    "registered_link",
    "register_scheme",
    "unregister_scheme",
]


class CommandRefused(Exception):
    """The vehicle (or the link) refused a command.

    ``result``: the result's name, e.g. ``"COMMAND_DENIED"``.
    """

    def __init__(self, result: str) -> None:
        super().__init__(result)
        self.result = result


class LinkUnreachable(Exception):
    """The connection could not be opened at all (a bad URL, a port in use)."""


@dataclass(frozen=True)
class PositionReport:
    """One LOCAL_POSITION_NED as received (the vehicle's own time stamp, raw).

    ``time_boot_s``: the vehicle's stamp (``time_boot_ms / 1000``) [s]. ``pos_ned_m``: position,
    local NED [m] (NaN: no position). ``vel_ned_m_s``: velocity, local NED [m/s].
    """

    time_boot_s: float
    pos_ned_m: tuple[float, float, float]
    vel_ned_m_s: tuple[float, float, float]


class VehicleLink(Protocol):
    """One connection to one autopilot, as the flight layer uses it.

    Every stream is an async iterator that runs until the link is closed (or its task is
    cancelled); each call opens a new one. Every command raises :class:`CommandRefused`
    when refused.
    """

    clock: Clock
    """The local clock samples are received on and the flight layer runs on."""

    async def connect(self, url: str, timeout_s: float) -> bool:
        """Open ``url`` and wait for an autopilot; False if none answered within ``timeout_s``.

        ``timeout_s``: limit [s].

        Raises ``LinkUnreachable``: the URL cannot be opened.
        """
        ...

    async def close(self) -> None:
        """Release the connection (the vehicle is left as it is)."""
        ...

    async def is_connected(self) -> bool:
        """Whether the autopilot is heard from now."""
        ...

    # -- the state streams
    def positions(self) -> AsyncIterator[PositionReport]:
        """Every LOCAL_POSITION_NED received."""
        ...

    def connection_states(self) -> AsyncIterator[bool]:
        """Heartbeats heard (True) or lost for 3 s (False), on each change."""
        ...

    def flight_modes(self) -> AsyncIterator[FlightMode]:
        """The flight mode, as reported."""
        ...

    def armed_states(self) -> AsyncIterator[bool]:
        """Armed or not, as reported."""
        ...

    def landed_states(self) -> AsyncIterator[LandedState]:
        """The landed state, as reported."""
        ...

    def local_position_health(self) -> AsyncIterator[bool]:
        """Whether the autopilot reports a valid local position."""
        ...

    def armable_states(self) -> AsyncIterator[bool]:
        """Whether the autopilot's pre-arm checks pass."""
        ...

    def arming_problems(self) -> AsyncIterator[list[str]]:
        """The messages of the failing health and arming checks, on each report."""
        ...

    def status_texts(self) -> AsyncIterator[str]:
        """Every STATUSTEXT."""
        ...

    def battery_levels(self) -> AsyncIterator[float]:
        """Remaining charge [%] (negative or NaN: not reported)."""
        ...

    # -- commands
    async def set_position_rate(self, rate_hz: float) -> None:
        """Ask for LOCAL_POSITION_NED at ``rate_hz``.

        ``rate_hz``: rate [Hz].
        """
        ...

    async def set_landed_state_rate(self, rate_hz: float) -> None:
        """Ask for the landed state at ``rate_hz``.

        ``rate_hz``: rate [Hz].
        """
        ...

    async def set_takeoff_altitude(self, altitude_m: float) -> None:
        """Take-off altitude above home [m].

        ``altitude_m``: altitude [m].
        """
        ...

    async def arm(self) -> None:
        """Arm."""
        ...

    async def disarm(self) -> None:
        """Disarm."""
        ...

    async def takeoff(self) -> None:
        """Take off (Takeoff mode)."""
        ...

    async def land(self) -> None:
        """Land here."""
        ...

    async def start_offboard(self) -> None:
        """Switch to OFFBOARD (setpoints must be flowing)."""
        ...

    async def stop_offboard(self) -> None:
        """Leave OFFBOARD for Hold."""
        ...

    async def set_position_ned(
        self, north_m: float, east_m: float, down_m: float, yaw_deg: float
    ) -> None:
        """Send one position setpoint (kept re-sent by the link, as MAVSDK does, at 20 Hz).

        ``north_m``, ``east_m``, ``down_m``: position, local NED [m]. ``yaw_deg``: heading [deg], in
        [-180, 180).
        """
        ...

    # -- what the vehicle keeps
    async def get_param_int(self, name: str) -> int:
        """Read an integer parameter.

        ``name``: PX4 parameter name.
        """
        ...

    async def get_param_float(self, name: str) -> float:
        """Read a float parameter.

        ``name``: PX4 parameter name.
        """
        ...

    async def set_param_int(self, name: str, value: int) -> None:
        """Write an integer parameter.

        ``name``: PX4 parameter name.
        """
        ...

    async def set_param_float(self, name: str, value: float) -> None:
        """Write a float parameter.

        ``name``: PX4 parameter name.
        """
        ...

    async def get_all_params(self) -> dict[str, float]:
        """Every parameter, by name."""
        ...

    async def get_gps_global_origin(self) -> tuple[float, float, float]:
        """Latitude, longitude [deg] and altitude AMSL [m] of the local origin."""
        ...

    async def set_gps_global_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Send SET_GPS_GLOBAL_ORIGIN.

        ``lat_deg``, ``lon_deg``: WGS84 [deg]. ``alt_m``: AMSL [m].
        """
        ...

    async def upload_inclusion_polygon(self, vertices_deg: list[tuple[float, float]]) -> None:
        """Replace the geofence by one inclusion polygon of (lat, lon) vertices [deg].

        ``vertices_deg``: (latitude, longitude) [deg].
        """
        ...

    def mocap_plugin(self) -> Any:
        """MAVSDK's blocking Mocap plugin (external vision out), for the mocap forwarder."""
        ...


LinkFactory = Callable[[str], VehicleLink]
_SCHEMES: dict[str, LinkFactory] = {}


def register_scheme(scheme: str, factory: LinkFactory) -> None:
    """Open URLs ``scheme://...`` with ``factory(url)`` instead of MAVSDK.

    ``scheme``: URL scheme, e.g. ``"sim"``. ``factory``: takes the URL, returns a
    :class:`VehicleLink` (not yet connected).
    """
    _SCHEMES[scheme] = factory


def unregister_scheme(scheme: str) -> None:
    """Forget a scheme of :func:`register_scheme` (no error if unknown)."""
    _SCHEMES.pop(scheme, None)


def is_registered(url: str) -> bool:
    """Whether ``url``'s scheme was registered (:func:`register_scheme`)."""
    return "://" in url and url.split("://", 1)[0] in _SCHEMES


def registered_link(url: str) -> VehicleLink | None:
    """The link (not yet connected) of a registered scheme for ``url``, or None (then MAVSDK's)."""
    scheme = url.split("://", 1)[0] if "://" in url else ""
    factory = _SCHEMES.get(scheme)
    return None if factory is None else factory(url)
