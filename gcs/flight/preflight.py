"""What the vehicle will do on its own when gcs can no longer reach it (pure, no MAVSDK).

gcs lands the vehicle on every stop it can command. When the link itself is gone nothing it
sends arrives: PX4 leaves OFFBOARD for its offboard-loss action after ``COM_OF_LOSS_T``, and
after ``COM_DL_LOSS_T`` without a ground station's heartbeat it takes the data-link-loss action
``NAV_DLL_ACT``. PX4's default for that is 0, disabled: the vehicle then hovers in Hold until
its battery failsafe. :func:`link_loss_warnings` says so before take-off, once, so that the
operator can set a landing action first.
"""

from __future__ import annotations

__all__ = ["LINK_LOSS_PARAMS", "NAV_DLL_ACT_NAMES", "link_loss_warnings"]

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

    Parameters
    ----------
    params : dict of str to int or None
        The vehicle's values of :data:`LINK_LOSS_PARAMS`; None where it did not answer.

    Returns
    -------
    list of str
        Warnings, one line each; empty when a lost link ends in a landing or a return.
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
