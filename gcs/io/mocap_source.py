"""Where the motion capture comes from: system, server, rigid body (``--mocap URL``).

URL form: ``SYSTEM://HOST[:PORT]/RIGID_BODY[?interface=IP]``, for example
``optitrack://192.168.1.10/drone?interface=192.168.1.20`` or ``vicon://10.0.0.5:801/cf1``.

=========  ============  ==================================================================
system     default port  what the ``motioncapture`` library is given
=========  ============  ==================================================================
optitrack  1510          ``hostname``, ``port_command``, ``interface_ip`` (NatNet, Motive)
vicon      801           ``hostname`` as ``HOST:PORT`` (Vicon DataStream SDK)
qualisys   22222         ``hostname``, ``port`` (QTM real-time protocol)
vrpn       3883          ``hostname`` as ``HOST:PORT`` (VRPN tracker server)
=========  ============  ==================================================================

``interface`` is the local address on which an OptiTrack client joins Motive's multicast
group (the network card facing Motive; ``0.0.0.0`` lets the system choose, which fails when
that is not the card facing Motive). The data port and the group come from the server
(``NAT_SERVERINFO``), so they are not part of the URL.
"""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from gcs.errors import ProfileError

__all__ = ["DEFAULT_PORTS", "MocapSource", "parse_mocap_url"]

DEFAULT_PORTS = {"optitrack": 1510, "vicon": 801, "qualisys": 22222, "vrpn": 3883}
_NAME = re.compile(r"^[^\s/?#]+$")


@dataclass(frozen=True)
class MocapSource:
    """A motion-capture server and the rigid body to read from it.

    ``system``: ``optitrack``, ``vicon``, ``qualisys`` or ``vrpn``. ``rigid_body``: name of the
    rigid body as the mocap software calls it. ``interface_ip``: local address used to join the
    multicast group (OptiTrack only).
    """

    system: str
    host: str
    port: int
    rigid_body: str
    interface_ip: str = "0.0.0.0"

    def __post_init__(self) -> None:
        if self.system not in DEFAULT_PORTS:
            known = ", ".join(DEFAULT_PORTS)
            raise ProfileError(f"mocap: unknown system {self.system!r} (known: {known})")
        if not 0 < self.port < 65536:
            raise ProfileError(f"mocap: port must be within 1..65535, got {self.port}")
        if not self.host:
            raise ProfileError("mocap: the server address is missing")
        if not _NAME.match(self.rigid_body):
            raise ProfileError(f"mocap: bad rigid body name {self.rigid_body!r}")
        if self.system == "optitrack":  # the library takes a numeric address, not a name
            _ipv4(self.host, "host")
        _ipv4(self.interface_ip, "interface")

    def library_config(self) -> dict[str, str]:
        """The ``(type, config)`` arguments of ``motioncapture.connect``, config part.

        Returns: keys as the library's ``MotionCapture::connect`` reads them.
        """
        if self.system == "optitrack":
            return {
                "hostname": self.host,
                "port_command": str(self.port),
                "interface_ip": self.interface_ip,
            }
        if self.system == "qualisys":
            return {"hostname": self.host, "port": str(self.port)}
        return {"hostname": f"{self.host}:{self.port}"}

    def url(self) -> str:
        """The URL that :func:`parse_mocap_url` turns back into this source."""
        query = f"?interface={self.interface_ip}" if self.interface_ip != "0.0.0.0" else ""
        return f"{self.system}://{self.host}:{self.port}/{self.rigid_body}{query}"


def _ipv4(text: str, field: str) -> None:
    try:
        ipaddress.IPv4Address(text)
    except ValueError:
        raise ProfileError(f"mocap: {field} must be an IPv4 address, got {text!r}") from None


def parse_mocap_url(url: str) -> MocapSource:
    """Parse ``SYSTEM://HOST[:PORT]/RIGID_BODY[?interface=IP]``.

    Raises ``ProfileError``: one line naming what is wrong.
    """
    parts = urlsplit(url)
    system = parts.scheme.lower()
    if system not in DEFAULT_PORTS:
        known = ", ".join(f"{s}://" for s in DEFAULT_PORTS)
        raise ProfileError(f"mocap URL {url!r}: scheme must be one of {known}")
    try:
        port = parts.port or DEFAULT_PORTS[system]
    except ValueError:
        raise ProfileError(f"mocap URL {url!r}: bad port") from None
    body = parts.path.lstrip("/")
    if not body:
        raise ProfileError(f"mocap URL {url!r}: the rigid body name is missing (.../NAME)")
    query = parse_qs(parts.query, strict_parsing=False)
    unknown = set(query) - {"interface"}
    if unknown:
        raise ProfileError(f"mocap URL {url!r}: unknown option(s) {', '.join(sorted(unknown))}")
    interface = query.get("interface", ["0.0.0.0"])[-1]
    return MocapSource(system, parts.hostname or "", port, body, interface)
