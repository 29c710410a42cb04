"""The mock's geofence as pure logic: PX4's fence transfer, its activation and breach checks."""

from __future__ import annotations

import pytest

from gcs.core import frames
from gcs.mock.geofence import (
    ACCEPTED,
    ERROR,
    MAV_MISSION_TYPE_FENCE,
    MAX_FENCE_ITEMS,
    NO_SPACE,
    PROTOCOL_TIMEOUT_S,
    RETRY_S,
    UNSUPPORTED,
    UNSUPPORTED_FRAME,
    FenceItem,
    FenceTransfer,
    Geofence,
    breach_kinds,
)

GCS = (245, 190)
ORIGIN = (47.3977431, 8.5455947, 489.244)
FENCE = MAV_MISSION_TYPE_FENCE


def ned_to_global(origin, pos_ned_m):
    """Latitude, longitude [deg] and altitude AMSL [m] of a local point, as the mock's GPS."""
    lat, lon = frames.ned_to_global(origin[0], origin[1], pos_ned_m[0], pos_ned_m[1])
    return lat, lon, origin[2] - pos_ned_m[2]


def square(half_m: float, command: int = 5001, frame: int = 5) -> tuple[FenceItem, ...]:
    """A square polygon of half-side ``half_m`` around the origin, as MAVSDK sends it."""
    corners = [(-half_m, -half_m), (-half_m, half_m), (half_m, half_m), (half_m, -half_m)]
    items = []
    for seq, (n, e) in enumerate(corners):
        lat, lon, _ = ned_to_global(ORIGIN, (n, e, 0.0))
        items.append(FenceItem(seq, frame, command, 4.0, round(lat * 1e7), round(lon * 1e7)))
    return tuple(items)


def kinds(replies) -> list[tuple[str, int]]:
    return [(r.kind, r.value) for r in replies if r.kind != "text"]


def upload(transfer: FenceTransfer, items: tuple[FenceItem, ...]) -> list:
    """MAVSDK's upload: count, then each item when asked; the replies to the last item."""
    replies = transfer.on_count(0.0, GCS, len(items), FENCE)
    for item in items:
        assert kinds(replies) == [("request", item.seq)]
        replies = transfer.on_item(0.01 * (item.seq + 1), GCS, item, FENCE)
    return replies


def test_an_upload_is_requested_item_by_item_and_acknowledged() -> None:
    transfer = FenceTransfer()
    items = square(4.5)
    last = upload(transfer, items)
    assert kinds(last) == [("stored", 0), ("ack", ACCEPTED)]
    assert last[0].items == items and transfer.items == items and transfer.state == "idle"
    assert all(r.target == GCS and r.mission_type == FENCE for r in last)
    assert transfer.uploads == 1 and transfer.opaque_id != 0


def test_the_download_returns_what_was_uploaded() -> None:
    transfer = FenceTransfer()
    upload(transfer, square(2.0))
    assert kinds(transfer.on_request_list(1.0, GCS, FENCE)) == [("count", 4)]
    got = []
    for seq in range(4):
        (reply,) = transfer.on_request(1.0, GCS, seq, FENCE)
        got.append(reply.item)
    assert tuple(got) == transfer.items
    transfer.on_ack(1.1, GCS, ACCEPTED, FENCE)
    assert transfer.state == "idle"


def test_what_px4_refuses() -> None:
    transfer = FenceTransfer()
    assert kinds(transfer.on_count(0.0, GCS, MAX_FENCE_ITEMS + 1, FENCE)) == [("ack", NO_SPACE)]
    assert kinds(transfer.on_count(0.0, GCS, 3, 0)) == [("ack", UNSUPPORTED)]  # a mission
    # a frame that is not global, a polygon of two vertices: refused, the transfer ends
    for bad, result in (
        (FenceItem(0, 1, 5001, 4.0, 0, 0), UNSUPPORTED_FRAME),
        (FenceItem(0, 5, 5001, 2.0, 0, 0), ERROR),
    ):
        transfer.on_count(0.0, GCS, 4, FENCE)
        assert kinds(transfer.on_item(0.1, GCS, bad, FENCE)) == [("ack", result)]
        assert transfer.state == "idle" and transfer.items == ()
    # an item of another mission type while receiving the fence
    transfer.on_count(0.0, GCS, 4, FENCE)
    assert kinds(transfer.on_item(0.1, GCS, square(1.0)[0], 0)) == [("ack", ERROR)]


def test_lost_messages_are_recovered_as_px4_does() -> None:
    transfer = FenceTransfer()
    items = square(3.0)
    transfer.on_count(0.0, GCS, 4, FENCE)
    # our first request was lost: the count again asks for item 0 again
    assert kinds(transfer.on_count(0.1, GCS, 4, FENCE)) == [("request", 0)]
    # an item out of sequence is ignored; silence makes us ask again after RETRY_S
    assert transfer.on_item(0.15, GCS, items[2], FENCE) == []
    assert transfer.tick(0.15 + RETRY_S / 2) == []
    assert kinds(transfer.tick(0.15 + 1.5 * RETRY_S)) == [("request", 0)]
    # a transfer silent for PROTOCOL_TIMEOUT_S is dropped
    (text,) = transfer.tick(0.15 + PROTOCOL_TIMEOUT_S + 0.1)
    assert text.text == "Operation timeout" and transfer.state == "idle"


def test_a_count_of_zero_and_a_clear_remove_the_fence() -> None:
    transfer = FenceTransfer()
    upload(transfer, square(3.0))
    assert kinds(transfer.on_count(1.0, GCS, 0, FENCE)) == [("stored", 0), ("ack", ACCEPTED)]
    assert transfer.items == ()
    upload(transfer, square(3.0))
    assert kinds(transfer.on_clear(2.0, GCS, FENCE)) == [("stored", 0), ("ack", ACCEPTED)]
    assert transfer.items == () and transfer.clears == 2
    transfer.on_count(3.0, GCS, 4, FENCE)
    (busy,) = transfer.on_clear(3.1, GCS, FENCE)
    assert busy.kind == "text" and "Busy" in busy.text  # no ACK: MAVSDK times out


def test_a_fence_is_in_force_only_if_it_contains_home_and_the_vehicle_in_the_air() -> None:
    home = ned_to_global(ORIGIN, (0.0, 0.0, 0.0))[:2]
    far = ned_to_global(ORIGIN, (10.0, 0.0, -2.0))[:2]
    fence = Geofence()
    assert fence.load(square(4.5), home, home, in_air=False, action=5) == []
    assert len(fence.areas) == 1
    texts = fence.load(square(4.5), home, far, in_air=True, action=5)
    assert texts == [(2, "Geofence invalid, doesn't contain current vehicle position")]
    assert fence.areas == ()
    assert fence.load(square(4.5), home, far, in_air=True, action=0) == []  # no action: kept
    away = ned_to_global(ORIGIN, (20.0, 20.0, 0.0))[:2]
    texts = fence.load(square(4.5), away, away, in_air=False, action=5)
    assert texts == [(2, "Geofence invalid, doesn't contain Home position")]


@pytest.mark.parametrize(
    ("ned", "max_hor_m", "expected"),
    [
        ((0.0, 0.0, -2.0), 0.0, ()),
        ((4.4, -4.4, -2.0), 0.0, ()),
        ((4.6, 0.0, -2.0), 0.0, ("fence",)),
        ((0.0, -4.6, -2.0), 0.0, ("fence",)),
        ((0.0, 0.0, 480.0), 0.0, ()),  # no floor: a polygon has no altitude
        ((0.0, 0.0, -4.6), 0.0, ("max_alt",)),
        ((3.0, 3.0, -1.0), 4.0, ("max_dist",)),  # 4.2 m from home
        ((2.0, 3.0, -1.0), 4.0, ()),  # 3.6 m
    ],
)
def test_breach_checks_as_px4s_navigator(ned, max_hor_m, expected) -> None:
    fence = Geofence()
    home = ned_to_global(ORIGIN, (0.0, 0.0, 0.0))
    fence.load(square(4.5), home[:2], home[:2], in_air=False, action=5)
    position = ned_to_global(ORIGIN, ned)
    # GF_MAX_VER_DIST 4.5 m above home; GF_MAX_HOR_DIST as given (0: off)
    assert breach_kinds(fence, position, home, max_hor_m, 4.5) == expected
    assert breach_kinds(Geofence(), position, home, 0.0, 0.0) == ()  # nothing set: nothing


def test_exclusion_areas_and_circles() -> None:
    home = ned_to_global(ORIGIN, (0.0, 0.0, 0.0))
    lat, lon, _ = ned_to_global(ORIGIN, (10.0, 0.0, 0.0))
    circle = FenceItem(0, 5, 5003, 20.0, round(lat * 1e7), round(lon * 1e7))  # inclusion, 20 m
    hole = tuple(
        FenceItem(i.seq + 1, i.frame, 5002, i.param1, i.x, i.y) for i in square(1.0)
    )  # exclusion square of 2 m around the origin... which holds home: discarded
    fence = Geofence()
    texts = fence.load((circle, *hole), home[:2], home[:2], in_air=False, action=5)
    assert len(fence.areas) == 1 and texts == [
        (2, "Geofence invalid, doesn't contain Home position")
    ]
    inside = ned_to_global(ORIGIN, (25.0, 0.0, -2.0))
    outside = ned_to_global(ORIGIN, (31.0, 0.0, -2.0))
    assert breach_kinds(fence, inside, home, 0.0, 0.0) == ()
    assert breach_kinds(fence, outside, home, 0.0, 0.0) == ("fence",)
