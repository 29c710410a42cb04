"""The fence transfer of the mock drone (MAV_MISSION_TYPE_FENCE over the mission protocol).

A part of :class:`gcs.mock.server.MockServer`: the MISSION_* messages go to
:class:`gcs.mock.geofence.FenceTransfer` (pure logic) and its replies go out.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from gcs.mock.geofence import FenceItem, Reply
from gcs.mock.transport import Transport

__all__ = ["Missions"]

_MISSION_PLANNER = 190  # MAV_COMP_ID_MISSIONPLANNER, also addressed by mission messages


class Missions(Transport):
    """The fence transfer of :class:`gcs.mock.server.MockServer`."""

    def _for_missions(self, msg: Any) -> bool:
        return msg.target_system == self.sysid and msg.target_component in (
            0, 1, _MISSION_PLANNER,
        )  # fmt: skip

    def _mission_call(self, msg: Any, method: str, *args: Any) -> None:
        if not self._for_missions(msg):
            return
        v = self.vehicle
        v.update(self._t())
        sender = (msg.get_srcSystem(), msg.get_srcComponent())
        handler = getattr(self.fence_transfer, method)
        self._mission_replies(handler(v.t_s, sender, *args, msg.mission_type))
        self._after_update()

    def _on_mission_count(self, msg: Any) -> None:
        self._mission_call(msg, "on_count", msg.count)

    def _on_mission_item_int(self, msg: Any) -> None:
        item = FenceItem(msg.seq, msg.frame, msg.command, msg.param1, msg.x, msg.y, msg.z)
        self._mission_call(msg, "on_item", item)

    def _on_mission_request_list(self, msg: Any) -> None:
        self._mission_call(msg, "on_request_list")

    def _on_mission_request_int(self, msg: Any) -> None:
        self._mission_call(msg, "on_request", msg.seq)

    _on_mission_request = _on_mission_request_int  # answered with items in the INT form

    def _on_mission_ack(self, msg: Any) -> None:
        self._mission_call(msg, "on_ack", msg.type)

    def _on_mission_clear_all(self, msg: Any) -> None:
        self._mission_call(msg, "on_clear")

    def _mission_replies(self, replies: list[Reply]) -> None:
        for r in replies:
            target = r.target
            if r.kind == "request":
                self.mav.mission_request_int_send(*target, r.value, r.mission_type)
            elif r.kind == "ack":
                self.mav.mission_ack_send(*target, r.value, r.mission_type)
            elif r.kind == "count":
                self.mav.mission_count_send(*target, r.value, r.mission_type)
            elif r.kind == "item" and r.item is not None:
                i = r.item
                self.mav.mission_item_int_send(
                    *target, i.seq, i.frame, i.command, 0, 0, i.param1, 0.0, 0.0, 0.0,
                    i.x, i.y, i.z, r.mission_type,
                )  # fmt: skip
            elif r.kind == "text":
                self.vehicle.events.append((r.value, r.text))
            elif r.kind == "stored":
                self.vehicle.fence_stored(r.items)

    def _geofence_stats(self) -> dict[str, Any]:
        """The fence stored and in force, its parameters, uploads and breaches."""
        v, transfer = self.vehicle, self.fence_transfer
        return {
            "items": [dataclasses.asdict(i) for i in transfer.items],
            "areas_in_force": len(v.geofence.areas),
            "uploads": transfer.uploads,
            "clears": transfer.clears,
            "params": {n: v.params[n] for n in ("GF_ACTION", "GF_MAX_HOR_DIST", "GF_MAX_VER_DIST")},
            "breaches": v.gf_breaches,
        }
