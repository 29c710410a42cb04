"""PX4's geofence in the mock drone: the fence transfer and the breach check (pure logic).

Read from PX4 v1.16's sources, then written anew:

- **Transfer** (``src/modules/mavlink/mavlink_mission.cpp``, ``MAV_MISSION_TYPE_FENCE`` only):
  :class:`FenceTransfer`. Upload: MISSION_COUNT -> MISSION_REQUEST_INT(0) -> MISSION_ITEM_INT(0)
  -> ... -> MISSION_ACK (ACCEPTED, or the reason). A count above :data:`MAX_FENCE_ITEMS` is
  NO_SPACE; a count of 0 clears; a repeated count before the first item re-requests item 0; an
  item out of sequence is ignored; an item of another mission type is an ERROR; a frame that is
  not global is UNSUPPORTED_FRAME; a polygon vertex whose ``param1`` (vertex count) is below 3
  is an ERROR and ends the transfer. A request is repeated every :data:`RETRY_S`; a transfer
  silent for :data:`PROTOCOL_TIMEOUT_S` is dropped ("Operation timeout"). Download:
  MISSION_REQUEST_LIST -> MISSION_COUNT -> MISSION_REQUEST_INT(k) -> MISSION_ITEM_INT(k) ...
  -> the client's MISSION_ACK. MISSION_CLEAR_ALL clears (ACCEPTED) when idle. Other mission
  types (missions, rally points) are answered UNSUPPORTED: the mock stores fences only.
- **Activation** (``src/modules/navigator/geofence.cpp``, ``_updateFence``):
  :meth:`Geofence.load`. A polygon or circle that does not contain home is discarded ("Geofence
  invalid, doesn't contain Home position"), and so is one that does not contain the current
  position while the vehicle is in the air and ``GF_ACTION`` is not 0 ("... doesn't contain
  current vehicle position"). The transfer is ACCEPTED all the same, as on PX4.
- **Breach** (``Navigator::geofence_breach_check``, every :data:`CHECK_PERIOD_S`, only with
  ``GF_ACTION`` not 0): :func:`breach_kinds` on the *estimated* global position, as PX4's
  default ``GF_SOURCE`` 0: farther than ``GF_MAX_HOR_DIST`` from home, higher than
  ``GF_MAX_VER_DIST`` above home, outside an inclusion polygon or circle (PNPOLY on latitude
  and longitude, as PX4), inside an exclusion one. A polygon has no altitude: there is no floor.

What the commander does with a breach is in :mod:`gcs.mock.vehicle`.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

from gcs.core.frames import EARTH_RADIUS_M

__all__ = [
    "FenceItem",
    "FenceTransfer",
    "Geofence",
    "Reply",
    "breach_kinds",
    "MAV_MISSION_TYPE_FENCE",
    "MAX_FENCE_ITEMS",
    "RETRY_S",
    "PROTOCOL_TIMEOUT_S",
    "CHECK_PERIOD_S",
]

MAV_MISSION_TYPE_FENCE = 1
MAX_FENCE_ITEMS = 64
"""Largest fence PX4 SITL stores (its dataman's fence slots) [items]."""
RETRY_S = 0.25
"""PX4's ``MAVLINK_MISSION_RETRY_TIMEOUT_DEFAULT``: a request is sent again after this [s]."""
PROTOCOL_TIMEOUT_S = 5.0
"""PX4's ``MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT``: a silent transfer is dropped [s]."""
CHECK_PERIOD_S = 0.2
"""PX4's navigator checks the geofence this often [s]."""

# MAV_CMD and MAV_FRAME values
FENCE_RETURN_POINT = 5000
POLYGON_INCLUSION = 5001
POLYGON_EXCLUSION = 5002
CIRCLE_INCLUSION = 5003
CIRCLE_EXCLUSION = 5004
_FENCE_COMMANDS = (
    FENCE_RETURN_POINT, POLYGON_INCLUSION, POLYGON_EXCLUSION, CIRCLE_INCLUSION, CIRCLE_EXCLUSION
)  # fmt: skip
_GLOBAL_FRAMES = (0, 3, 5, 6)  # GLOBAL, GLOBAL_RELATIVE_ALT, GLOBAL_INT, GLOBAL_RELATIVE_ALT_INT
# MAV_MISSION_RESULT values
ACCEPTED, ERROR, UNSUPPORTED_FRAME, UNSUPPORTED, NO_SPACE = 0, 1, 2, 3, 4
OPERATION_CANCELLED = 15


def _distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Horizontal distance between two nearby points [m] (local flat earth)."""
    dn = math.radians(lat2 - lat1) * EARTH_RADIUS_M
    de = math.radians(lon2 - lon1) * EARTH_RADIUS_M * math.cos(math.radians(lat1))
    return math.hypot(dn, de)


@dataclass(frozen=True)
class FenceItem:
    """One MISSION_ITEM_INT of a fence.

    ``frame``: MAV_FRAME. ``command``: MAV_CMD (5000-5004). ``param1``: vertex count of a polygon,
    radius of a circle [m]. ``x``, ``y``: latitude and longitude [1e-7 deg]. ``z``: altitude [m]
    (unused by PX4's fence).
    """

    seq: int
    frame: int
    command: int
    param1: float
    x: int
    y: int
    z: float = 0.0

    @property
    def lat_lon(self) -> tuple[float, float]:
        """Latitude and longitude [deg]."""
        return self.x * 1e-7, self.y * 1e-7


@dataclass(frozen=True)
class Reply:
    """What the transfer asks the server to send.

    ``kind``: ``"request"`` (MISSION_REQUEST_INT of ``value``), ``"ack"`` (MISSION_ACK of result
    ``value``), ``"count"`` (MISSION_COUNT of ``value``), ``"item"`` (MISSION_ITEM_INT ``item``),
    ``"text"`` (STATUSTEXT ``text`` of severity ``value``) or ``"stored"`` (a new fence, ``items``,
    is in place). ``value``: as ``kind`` says. ``item``: for ``"item"``. ``text``: for ``"text"``.
    ``items``: for ``"stored"``.
    """

    kind: str
    value: int = 0
    target: tuple[int, int] = (0, 0)
    item: FenceItem | None = None
    text: str = ""
    items: tuple[FenceItem, ...] = ()
    mission_type: int = MAV_MISSION_TYPE_FENCE


class FenceTransfer:
    """PX4's mission manager for ``MAV_MISSION_TYPE_FENCE`` (see the module docstring).

    Every ``on_*`` method takes the vehicle time and the sender and returns the replies.
    """

    def __init__(self) -> None:
        self.items: tuple[FenceItem, ...] = ()
        self.state = "idle"  # idle | getlist | sendlist
        self.partner = (0, 0)
        self._count = 0
        self._seq = 0
        self._buffer: list[FenceItem] = []
        self._last_recv_s = 0.0
        self._last_sent_s = 0.0
        self.uploads = 0
        self.clears = 0

    @property
    def opaque_id(self) -> int:
        """A checksum of the stored fence (0 for none), as PX4's ``opaque_id``."""
        if not self.items:
            return 0
        text = repr([(i.command, i.frame, i.param1, i.x, i.y) for i in self.items])
        return zlib.crc32(text.encode()) or 1

    def _reject(self, sender: tuple[int, int], mission_type: int) -> list[Reply]:
        return [Reply("ack", UNSUPPORTED, sender, mission_type=mission_type)]

    def on_count(
        self, t_s: float, sender: tuple[int, int], count: int, mission_type: int
    ) -> list[Reply]:
        """MISSION_COUNT: an upload begins (or, with 0, the fence is cleared).

        ``t_s``: vehicle time [s].
        """
        if mission_type != MAV_MISSION_TYPE_FENCE:
            return self._reject(sender, mission_type)
        self._last_recv_s = t_s
        if self.state == "getlist":
            if sender != self.partner:
                return [Reply("ack", ERROR, sender)]
            if self._seq == 0:  # our request was lost: ask again
                return self._request(t_s)
            return [
                Reply("text", 2, sender, text="WPM: REJ. CMD: Busy"),
                Reply("ack", ERROR, sender),
            ]
        if self.state != "idle":
            return [
                Reply("text", 2, sender, text="WPM: IGN MISSION_COUNT: Busy"),
                Reply("ack", ERROR, sender),
            ]
        self.partner = sender
        if count > MAX_FENCE_ITEMS:
            return [Reply("ack", NO_SPACE, sender)]
        if count == 0:
            return self._store((), sender)
        self.state, self._count, self._seq, self._buffer = "getlist", count, 0, []
        return self._request(t_s)

    def _request(self, t_s: float) -> list[Reply]:
        self._last_sent_s = t_s
        return [Reply("request", self._seq, self.partner)]

    def _store(
        self,
        items: tuple[FenceItem, ...],
        sender: tuple[int, int],
        mission_type: int = MAV_MISSION_TYPE_FENCE,
    ) -> list[Reply]:
        self.items = items
        self.state = "idle"
        if items:
            self.uploads += 1
        else:
            self.clears += 1
        ack = Reply("ack", ACCEPTED, sender, mission_type=mission_type)
        return [Reply("stored", target=sender, items=items), ack]

    def on_item(
        self, t_s: float, sender: tuple[int, int], item: FenceItem, mission_type: int
    ) -> list[Reply]:
        """MISSION_ITEM_INT: the next fence item of an upload.

        ``t_s``: vehicle time [s].
        """
        if sender != self.partner:
            return [Reply("text", 2, sender, text="REJ. MIS ITEM: partner id mismatch")]
        if mission_type != MAV_MISSION_TYPE_FENCE:
            return [Reply("ack", ERROR, sender, mission_type=mission_type)]
        if self.state == "idle":
            if self._seq == item.seq + 1:  # our ACK was lost: the last item again
                return [Reply("ack", ACCEPTED, sender)]
            return [
                Reply("text", 2, sender, text="IGN MISSION_ITEM: No transfer"),
                Reply("ack", ERROR, sender),
            ]
        if self.state != "getlist":
            return [
                Reply("text", 2, sender, text="IGN MISSION_ITEM: Busy"),
                Reply("ack", ERROR, sender),
            ]
        self._last_recv_s = t_s
        if item.seq != self._seq:
            return []  # out of sequence: ignored
        result = _item_problem(item)
        if result is not None:
            self.state = "idle"
            text = (
                "IGN MISSION_ITEM: Invalid item" if result != ERROR else "Fence: too few vertices"
            )
            return [Reply("text", 2, sender, text=text), Reply("ack", result, sender)]
        self._buffer.append(item)
        self._seq += 1
        if self._seq == self._count:
            return self._store(tuple(self._buffer), sender)
        return self._request(t_s)

    def on_request_list(
        self, t_s: float, sender: tuple[int, int], mission_type: int
    ) -> list[Reply]:
        """MISSION_REQUEST_LIST: a download begins.

        ``t_s``: vehicle time [s].
        """
        if mission_type != MAV_MISSION_TYPE_FENCE:
            return self._reject(sender, mission_type)
        if self.state == "sendlist" and self._seq == len(self.items):
            self.state = "idle"  # done, the client's ACK was lost
        if self.state not in ("idle", "sendlist"):
            return [
                Reply("text", 6, sender, text="Mission download request ignored, already active")
            ]
        self.state, self.partner, self._seq = "sendlist", sender, 0
        self._last_recv_s = self._last_sent_s = t_s
        return [Reply("count", len(self.items), sender)]

    def on_request(
        self, t_s: float, sender: tuple[int, int], seq: int, mission_type: int
    ) -> list[Reply]:
        """MISSION_REQUEST_INT: the client asks for item ``seq`` of a download.

        ``t_s``: vehicle time [s].
        """
        if (
            self.state != "sendlist"
            or sender != self.partner
            or mission_type != MAV_MISSION_TYPE_FENCE
        ):
            return []
        self._last_recv_s = t_s
        if seq == self._seq and seq < len(self.items):
            self._seq += 1
        elif seq != self._seq - 1 or seq >= len(self.items):
            self.state = "idle"
            return [
                Reply("ack", ERROR, sender),
                Reply("text", 2, sender, text="WPM: REJ. CMD: Req. WP was unexpected"),
            ]
        self._last_sent_s = t_s
        return [Reply("item", seq, sender, item=self.items[seq])]

    def on_ack(
        self, t_s: float, sender: tuple[int, int], result: int, mission_type: int
    ) -> list[Reply]:
        """MISSION_ACK from the client: a download is over, or the client cancels an upload.

        ``t_s``: vehicle time [s].
        """
        if sender != self.partner or mission_type != MAV_MISSION_TYPE_FENCE:
            return []
        if self.state == "sendlist" or (self.state == "getlist" and result == OPERATION_CANCELLED):
            self.state = "idle"
        return []

    def on_clear(self, t_s: float, sender: tuple[int, int], mission_type: int) -> list[Reply]:
        """MISSION_CLEAR_ALL: remove the fence (when no transfer is going on).

        ``t_s``: vehicle time [s]. ``mission_type``: MAV_MISSION_TYPE (fence, or 255: all).
        """
        if mission_type not in (MAV_MISSION_TYPE_FENCE, 255):
            return self._reject(sender, mission_type)
        if self.state != "idle":
            return [Reply("text", 2, sender, text="WPM: IGN CLEAR CMD: Busy")]
        return self._store((), sender, mission_type)

    def tick(self, t_s: float) -> list[Reply]:
        """Retries and timeouts of a transfer in progress.

        ``t_s``: vehicle time [s].
        """
        if self.state == "idle":
            return []
        if t_s - self._last_recv_s > PROTOCOL_TIMEOUT_S:
            self.state = "idle"
            return [Reply("text", 2, self.partner, text="Operation timeout")]
        if self.state == "getlist" and t_s - self._last_sent_s > RETRY_S:
            return self._request(t_s)
        return []


def _item_problem(item: FenceItem) -> int | None:
    """The MAV_MISSION_RESULT an item is refused with, or None."""
    if item.frame not in _GLOBAL_FRAMES:
        return UNSUPPORTED_FRAME
    if item.command not in _FENCE_COMMANDS:
        return UNSUPPORTED
    if item.command in (POLYGON_INCLUSION, POLYGON_EXCLUSION) and item.param1 < 3:
        return ERROR
    return None


@dataclass(frozen=True)
class _Area:
    command: int
    vertices: tuple[tuple[float, float], ...]  # polygon (lat, lon) [deg]; one for a circle
    radius_m: float = 0.0

    def contains(self, lat: float, lon: float) -> bool:
        if self.command in (CIRCLE_INCLUSION, CIRCLE_EXCLUSION):
            c_lat, c_lon = self.vertices[0]
            return _distance_m(c_lat, c_lon, lat, lon) < self.radius_m
        inside = False  # PNPOLY on latitude and longitude, as PX4's Geofence::insidePolygon
        n = len(self.vertices)
        for i in range(n):
            lat_i, lon_i = self.vertices[i]
            lat_j, lon_j = self.vertices[i - 1]
            if (lon_i >= lon) != (lon_j >= lon) and (
                lat <= (lat_j - lat_i) * (lon - lon_i) / (lon_j - lon_i) + lat_i
            ):
                inside = not inside
        return inside

    def passes(self, lat: float, lon: float) -> bool:
        """Inside an inclusion area, outside an exclusion one."""
        inclusion = self.command in (POLYGON_INCLUSION, CIRCLE_INCLUSION)
        return self.contains(lat, lon) == inclusion


class Geofence:
    """The fence in force: the areas of the stored items that passed PX4's checks."""

    def __init__(self) -> None:
        self.areas: tuple[_Area, ...] = ()

    def load(
        self,
        items: tuple[FenceItem, ...],
        home: tuple[float, float],
        here: tuple[float, float],
        in_air: bool,
        action: int,
    ) -> list[tuple[int, str]]:
        """Take a newly stored fence (PX4's ``_updateFence``); return the status texts.

        ``home``: home latitude and longitude [deg]. ``here``: the estimated position's latitude and
        longitude [deg]. ``action``: ``GF_ACTION``.
        """
        areas, texts, seq = [], [], 0
        while seq < len(items):
            item = items[seq]
            if item.command == FENCE_RETURN_POINT:
                seq += 1
                continue
            if item.command in (CIRCLE_INCLUSION, CIRCLE_EXCLUSION):
                area = _Area(item.command, (item.lat_lon,), float(item.param1))
                seq += 1
            else:
                count = max(int(item.param1), 1)
                vertices = tuple(i.lat_lon for i in items[seq : seq + count])
                area = _Area(item.command, vertices)
                seq += count
            if not area.passes(*home):
                texts.append((2, "Geofence invalid, doesn't contain Home position"))
            elif action != 0 and in_air and not area.passes(*here):
                texts.append((2, "Geofence invalid, doesn't contain current vehicle position"))
            else:
                areas.append(area)
        self.areas = tuple(areas)
        return texts

    def inside(self, lat: float, lon: float) -> bool:
        """Inside every inclusion area and outside every exclusion one (an empty fence: True).

        ``lat``, ``lon``: the position [deg].
        """
        return all(area.passes(lat, lon) for area in self.areas)


def breach_kinds(
    fence: Geofence,
    position: tuple[float, float, float],
    home: tuple[float, float, float],
    max_hor_dist_m: float,
    max_ver_dist_m: float,
) -> tuple[str, ...]:
    """Which of PX4's geofence checks a position fails.

    ``position``: latitude, longitude [deg], altitude AMSL [m] (PX4 checks the estimate). ``home``:
    home: latitude, longitude [deg], altitude AMSL [m]. ``max_hor_dist_m``: ``GF_MAX_HOR_DIST`` (0:
    off) [m]. ``max_ver_dist_m``: ``GF_MAX_VER_DIST`` (0: off) [m].

    Returns: any of ``"max_dist"``, ``"max_alt"``, ``"fence"``; empty inside.
    """
    lat, lon, alt = position
    kinds = []
    if max_hor_dist_m > 0 and _distance_m(home[0], home[1], lat, lon) >= max_hor_dist_m:
        kinds.append("max_dist")
    if max_ver_dist_m > 0 and alt - home[2] >= max_ver_dist_m:
        kinds.append("max_alt")
    if not fence.inside(lat, lon):
        kinds.append("fence")
    return tuple(kinds)
