"""What gcs tells the operator about the vehicle before take-off (pure, no MAVSDK).

Link loss. gcs lands the vehicle on every stop it can command. When the link itself is gone
nothing it sends arrives: PX4 leaves OFFBOARD for its offboard-loss action after
``COM_OF_LOSS_T``, and after ``COM_DL_LOSS_T`` without a ground station's heartbeat it takes the
data-link-loss action ``NAV_DLL_ACT``. PX4's default for that is 0, disabled: the vehicle then
hovers in Hold until its battery failsafe. :func:`link_loss_warnings` says so before take-off,
once, so that the operator can set a landing action first.

Navigation source. What EKF2 fuses decides how well the vehicle repeats itself: with GPS the
reported position wanders by decimetres (the recorded PX4 v1.16 SITL runs), with motion capture
("external vision") by millimetres to centimetres. :func:`navigation_source` decodes PX4's
``EKF2_GPS_CTRL``, ``EKF2_EV_CTRL`` and ``EKF2_HGT_REF`` (PX4 v1.14-v1.16).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "LINK_LOSS_PARAMS",
    "NAV_DLL_ACT_NAMES",
    "NAV_PARAMS",
    "HGT_REF_NAMES",
    "NavigationSource",
    "link_loss_warnings",
    "navigation_source",
]

LINK_LOSS_PARAMS = ("NAV_DLL_ACT",)
"""The PX4 integer parameters :func:`link_loss_warnings` reads."""

NAV_DLL_ACT_NAMES = {
    0: "disabled",
    1: "Hold",
    2: "Return",
    3: "Land",
    5: "Terminate",
    6: "Disarm",
}
"""PX4's data-link-loss actions (``NAV_DLL_ACT`` values, PX4 v1.14-v1.16)."""


def link_loss_warnings(params: dict[str, int | None]) -> list[str]:
    """One line per way in which a lost link would leave the vehicle in the air.

    ``params``: the vehicle's values of :data:`LINK_LOSS_PARAMS`; None where it did not answer.

    Returns: warnings, one line each; empty when a lost link ends in a landing or a return.
    """
    action = params.get("NAV_DLL_ACT")
    if action is None:
        return ["could not read NAV_DLL_ACT: what a lost link makes the vehicle do is unknown"]
    if action in (0, 1):
        name = NAV_DLL_ACT_NAMES[action]
        return [
            f"NAV_DLL_ACT = {action} ({name}): if the link is lost the vehicle hovers in Hold "
            "until a battery failsafe; 3 (Land) or 2 (Return) ends it on the ground"
        ]
    if action not in NAV_DLL_ACT_NAMES:
        return [f"NAV_DLL_ACT = {action} is not a PX4 data-link-loss action gcs knows"]
    return []


NAV_PARAMS = ("EKF2_GPS_CTRL", "EKF2_HGT_REF", "EKF2_EV_CTRL")
"""The PX4 integer parameters :func:`navigation_source` reads. ``EKF2_EV_CTRL`` comes last: it
is the one PX4 before v1.14 lacks, and MAVSDK's parameter reads queue behind a read that goes
unanswered (measured on the replayed PX4 capture, tests/test_px4_replay.py)."""

HGT_REF_NAMES = {0: "barometer", 1: "GPS", 2: "range sensor", 3: "vision"}
"""PX4's ``EKF2_HGT_REF`` values."""

_GPS_BITS = ((0, "position"), (1, "altitude"), (2, "velocity"), (3, "heading"))
_EV_BITS = ((0, "position"), (1, "height"), (2, "velocity"), (3, "yaw"))


@dataclass(frozen=True)
class NavigationSource:
    """What PX4's EKF2 navigates on, from its parameters.

    ``gps``: GPS horizontal position or velocity is fused (None: unknown). ``vision``: external
    vision (motion capture, VIO) horizontal position or velocity is fused. ``height``: the height
    reference (``EKF2_HGT_REF``), e.g. ``"GPS"``; None if unknown. ``text``: one line for the
    operator. ``warning``: the line is a warning (unknown source, or nothing that holds the
    horizontal position).
    """

    gps: bool | None
    vision: bool | None
    height: str | None
    text: str
    warning: bool
    params: dict[str, int | None]

    @property
    def name(self) -> str:
        """``"GPS"``, ``"vision"``, ``"GPS + vision"``, ``"none"`` or ``"unknown"``."""
        if self.gps is None or self.vision is None:
            return "unknown"
        return {(True, False): "GPS", (False, True): "vision", (True, True): "GPS + vision"}.get(
            (self.gps, self.vision), "none"
        )


def _bits(value: int, names: tuple[tuple[int, str], ...]) -> str:
    used = [name for bit, name in names if value >> bit & 1]
    return ", ".join(used) if used else "off"


def navigation_source(params: dict[str, int | None]) -> NavigationSource:
    """Decode PX4's EKF2 aiding parameters into the navigation source, said in one line.

    ``params``: the vehicle's values of :data:`NAV_PARAMS`; None where it did not answer.

    Returns: ``gps`` if ``EKF2_GPS_CTRL`` fuses horizontal position (bit 0) or velocity (bit 2),
    ``vision`` likewise for ``EKF2_EV_CTRL``.
    """
    values = {name: params.get(name) for name in NAV_PARAMS}
    gps_ctrl, hgt_ref, ev_ctrl = (values[n] for n in NAV_PARAMS)
    if gps_ctrl is None or ev_ctrl is None:
        missing = ", ".join(n for n in ("EKF2_GPS_CTRL", "EKF2_EV_CTRL") if values[n] is None)
        text = (
            f"navigation source unknown: could not read {missing} (not PX4 v1.14 or later?); "
            "the hover measurement below tells how well the vehicle holds a point"
        )
        return NavigationSource(None, None, None, text, True, values)
    gps = bool(gps_ctrl & 0b101)
    vision = bool(ev_ctrl & 0b101)
    height = None if hgt_ref is None else HGT_REF_NAMES.get(hgt_ref, f"unknown ({hgt_ref})")
    detail = (
        f"EKF2_GPS_CTRL {gps_ctrl} ({_bits(gps_ctrl, _GPS_BITS)}), "
        f"EKF2_EV_CTRL {ev_ctrl} ({_bits(ev_ctrl, _EV_BITS)}), "
        f"height reference {height or 'unknown'}"
    )
    source = NavigationSource(gps, vision, height, "", False, values)
    if not (gps or vision):
        text = (
            f"navigation: neither GPS nor external vision ({detail}): nothing holds the "
            "horizontal position, expect it to drift"
        )
        return NavigationSource(gps, vision, height, text, True, values)
    text = f"navigation: {source.name} ({detail})"
    if gps and not vision:
        text += "; a GPS position often wanders by decimetres: the hover measured below says"
        text += " how much"
    return NavigationSource(gps, vision, height, text, False, values)
