"""The real-vehicle checklist: the PX4 parameters gcs advises, read from the vehicle and judged.

One table per way of navigating (docs/real-vehicle.md explains every row): outdoors on GPS
(``"gps"``) and indoors on motion capture forwarded as external vision (``"mocap"``). Each
row names a PX4 v1.16 parameter, the value advised and why; :func:`judge` gives each one
``ok``, ``warn`` or ``refuse`` with the fix. The EKF2 vision rows are judged by
:func:`gcs.flight.mocap.preflight.ekf2_findings` and the data-link-loss row by
:func:`gcs.flight.preflight.link_loss_warnings`, the checks the flight itself runs before
take-off: one source for both. ``gcs fly --check`` prints the result against the connected
vehicle (:func:`read_params`, :func:`checklist_lines`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from gcs.flight.mocap.preflight import EKF2_FLOAT_PARAMS, EKF2_INT_PARAMS, ekf2_findings
from gcs.flight.preflight import link_loss_warnings
from gcs.io.settings import FlightSettings

__all__ = [
    "NAVIGATIONS",
    "Item",
    "Verdict",
    "checklist",
    "judge",
    "checklist_lines",
    "refusal",
    "read_params",
]

NAVIGATIONS = ("gps", "mocap")
LEVELS = ("ok", "warn", "refuse")

Judgement = tuple[str, str]  # (level, what to do); ("ok", "") when nothing


@dataclass(frozen=True)
class Item:
    """One row of the checklist.

    ``param``: PX4 parameter name. ``advised``: the value advised, in words (e.g. ``"3 (Land) or 2
    (Return)"``). ``judge``: ``judge(value, params) -> (level, note)``: ``value`` is the vehicle's
    (None when it did not answer), ``params`` every value read; ``level`` one of ``ok``, ``warn``,
    ``refuse``, ``note`` the fix.
    """

    param: str
    advised: str
    why: str
    judge: Callable[[float | None, dict[str, float | None]], Judgement]


@dataclass(frozen=True)
class Verdict:
    """A checklist row judged against the vehicle.

    ``param``: PX4 parameter name. ``found``: the vehicle's value (None: not read). ``level``:
    ``ok``, ``warn`` or ``refuse``. ``note``: what to do (empty when ok).
    """

    param: str
    found: float | None
    advised: str
    level: str
    note: str


def _int(value: float | None) -> int | None:
    return None if value is None else int(value)


def _one_of(ok: dict[int, str], warn: dict[int, str], fix: str) -> Callable[..., Judgement]:
    """A judge for an enumerated parameter: ``ok`` values, ``warn`` values with a reason."""

    def judge(value: float | None, params: dict[str, float | None]) -> Judgement:
        v = _int(value)
        if v in ok:
            return "ok", ""
        reason = warn.get(v, "not a value gcs knows") if v is not None else ""
        return "warn", f"{reason}; {fix}" if reason else fix

    return judge


def _link_loss(value: float | None, params: dict[str, float | None]) -> Judgement:
    lines = link_loss_warnings({"NAV_DLL_ACT": _int(value)})
    return ("warn", lines[0]) if lines else ("ok", "")


def _offboard_loss_time(value: float | None, params: dict[str, float | None]) -> Judgement:
    if value is not None and 0.0 < value <= 2.0:
        return "ok", ""
    return "warn", "set COM_OF_LOSS_T to 1 s: long enough for a late setpoint, short for a lost one"


def _rc_override(value: float | None, params: dict[str, float | None]) -> Judgement:
    if value is not None and int(value) & 2:
        return "ok", ""
    return "warn", (
        "set COM_RC_OVERRIDE to 3 so that moving the sticks takes over from offboard (else "
        "the pilot must switch modes to take over)"
    )


def _gps_ctrl_outdoors(value: float | None, params: dict[str, float | None]) -> Judgement:
    v = _int(value)
    if v is not None and v & 1 and v & 4:
        return "ok", ""
    if v is not None and not v & 0b101:
        return "refuse", (
            "EKF2_GPS_CTRL fuses neither GPS position nor velocity: nothing holds the horizontal "
            "position; set EKF2_GPS_CTRL to 7"
        )
    return "warn", "set EKF2_GPS_CTRL to 7 (position, altitude, velocity)"


def _hgt_ref_outdoors(value: float | None, params: dict[str, float | None]) -> Judgement:
    v = _int(value)
    if v in (0, 1):
        return "ok", ""
    ev = _int(params.get("EKF2_EV_CTRL"))
    if v == 3 and not (ev or 0) & 2:
        return "refuse", "EKF2_HGT_REF = 3 (vision) without vision height: set EKF2_HGT_REF to 1"
    return "warn", "set EKF2_HGT_REF to 1 (GPS) or 0 (barometer)"


def _ev_ctrl_outdoors(value: float | None, params: dict[str, float | None]) -> Judgement:
    if _int(value) == 0:
        return "ok", ""
    return "warn", "EKF2_EV_CTRL fuses external vision on a GPS flight: set it to 0"


def _from_findings(param: str) -> Callable[..., Judgement]:
    """A judge for an EKF2 vision parameter: the pre-flight check's own finding about it."""

    def judge(value: float | None, params: dict[str, float | None]) -> Judgement:
        if value is None:
            return "warn", f"could not read {param}: not checked"
        ekf2 = {n: params.get(n) for n in EKF2_INT_PARAMS + EKF2_FLOAT_PARAMS}
        for finding in ekf2_findings(ekf2, forward=True):
            if finding.level != "info" and finding.text.startswith(param):
                return ("refuse" if finding.level == "refuse" else "warn"), finding.text
        return "ok", ""

    return judge


_LINK_AND_RC = (
    Item("NAV_DLL_ACT", "3 (Land) or 2 (Return)",
         "what PX4 does when the ground station's link is lost (PX4's default 0 does nothing: "
         "the vehicle hovers until its battery fails)", _link_loss),
    Item("COM_OBL_RC_ACT", "4 (Land) or 3 (Return)",
         "what PX4 does when the offboard setpoints stop (gcs crashed, the computer slept)",
         _one_of({3: "", 4: ""},
                 {0: "0 (Position) hands the vehicle to the sticks: only with a pilot ready",
                  1: "1 (Altitude) needs a pilot on the sticks",
                  2: "2 (Stabilized) needs a pilot on the sticks",
                  5: "5 (Hold) hovers until someone acts",
                  6: "6 (Terminate) drops the vehicle", 7: "7 (Disarm) drops the vehicle"},
                 "set COM_OBL_RC_ACT to 4 (Land)")),
    Item("COM_OF_LOSS_T", "1 s (PX4's default)",
         "how long PX4 waits for the next setpoint before it takes the offboard-loss action",
         _offboard_loss_time),
    Item("COM_RC_IN_MODE", "0 (RC transmitter) or 3 (RC or joystick, first kept)",
         "a pilot with a transmitter can take over at any time",
         _one_of({0: "", 2: "", 3: ""},
                 {1: "1 (joystick only): no RC transmitter to take over with",
                  4: "4 (stick input disabled): nobody can take over"},
                 "set COM_RC_IN_MODE to 0 and bind a transmitter")),
    Item("COM_RC_OVERRIDE", "3 (sticks override auto and offboard modes)",
         "moving the sticks takes the vehicle back from gcs at once", _rc_override),
    Item("GF_ACTION", "2 (Hold), 3 (Return) or 5 (Land)",
         "PX4's own geofence, set up by gcs from the arena, stops a breach even if gcs does not",
         _one_of({2: "", 3: "", 5: ""},
                 {0: "0 (None): a breach of PX4's geofence does nothing",
                  1: "1 (Warning): a breach only warns", 4: "4 (Terminate) drops the vehicle"},
                 "set GF_ACTION to 2 (Hold) or 5 (Land)")),
)  # fmt: skip

_GPS = (
    Item("EKF2_GPS_CTRL", "7 (position, altitude, velocity)",
         "EKF2 holds the horizontal position on GPS", _gps_ctrl_outdoors),
    Item("EKF2_HGT_REF", "1 (GPS) or 0 (barometer)",
         "the height reference outdoors", _hgt_ref_outdoors),
    Item("EKF2_EV_CTRL", "0 (no external vision)",
         "nothing sends vision outdoors; fusing it anyway waits for data that never comes",
         _ev_ctrl_outdoors),
)  # fmt: skip

_MOCAP = (
    Item("EKF2_EV_CTRL", "15 (position, height, velocity, yaw), at least 1",
         "EKF2 must fuse the motion capture gcs forwards as external vision",
         _from_findings("EKF2_EV_CTRL")),
    Item("EKF2_HGT_REF", "3 (vision)",
         "the mocap's height; the barometer drifts indoors by decimetres",
         _from_findings("EKF2_HGT_REF")),
    Item("EKF2_GPS_CTRL", "0 (no GPS)",
         "indoors GPS is absent or reflected; fused beside vision it pulls the estimate",
         _from_findings("EKF2_GPS_CTRL")),
    Item("EKF2_EV_DELAY", "the mocap's latency and the link's: a few ms (at most 50)",
         "PX4 stamps each pose when it arrives (gcs does not synchronise clocks with it), "
         "so the delay is the mocap's own plus the link from gcs to the vehicle",
         _from_findings("EKF2_EV_DELAY")),
    Item("EKF2_MAG_TYPE", "5 (None)",
         "indoors steel and motors disturb the magnetometer; the yaw comes from the mocap",
         _one_of({5: ""}, {0: "0 (Automatic) fuses the magnetometer",
                           1: "1 (magnetic heading) fuses the magnetometer"},
                 "set EKF2_MAG_TYPE to 5 and EKF2_EV_CTRL bit 3 (yaw)")),
    Item("EKF2_BARO_CTRL", "1 (on, beside the vision height reference)",
         "a second height source: if the mocap is lost PX4 still knows its height and can "
         "detect its landing (without it PX4 v1.16 SIH descended blind and stayed armed)",
         _from_findings("EKF2_BARO_CTRL")),
    Item("EKF2_EVP_NOISE", "0.01 m (PX4's smallest)",
         "the least noise EKF2 grants each mocap pose, whatever gcs sends with it; PX4's "
         "0.1 m follows a millimetre mocap loosely",
         _from_findings("EKF2_EVP_NOISE")),
)  # fmt: skip


def checklist(navigation: str) -> tuple[Item, ...]:
    """The checklist of one way of navigating.

    ``navigation``: ``"gps"`` or ``"mocap"``.

    Returns: the navigation rows first, then link loss, offboard loss, RC takeover and geofence.
    """
    if navigation not in NAVIGATIONS:
        raise ValueError(f"navigation must be one of {', '.join(NAVIGATIONS)}, got {navigation!r}")
    return (_GPS if navigation == "gps" else _MOCAP) + _LINK_AND_RC


def judge(params: dict[str, float | None], navigation: str) -> list[Verdict]:
    """Judge the vehicle's parameters against the checklist.

    ``params``: the vehicle's values by name; a missing name or None is "not read" (a warning).
    ``navigation``: ``"gps"`` or ``"mocap"``.

    Returns: one per row of :func:`checklist`, in its order.
    """
    out = []
    for item in checklist(navigation):
        value = params.get(item.param)
        if value is None:
            level, note = "warn", f"could not read {item.param}: not checked"
        else:
            level, note = item.judge(value, params)
        out.append(Verdict(item.param, value, item.advised, level, note))
    return out


def checklist_lines(verdicts: list[Verdict]) -> list[str]:
    """The verdicts as lines: ``ok``/``warn``/``refuse``, parameter, found, advised, fix."""
    lines = []
    for v in verdicts:
        found = "not read" if v.found is None else f"{v.found:g}"
        line = f"{v.level:<6} {v.param}: found {found}, advised {v.advised}"
        lines.append(line + (f" - {v.note}" if v.note else ""))
    return lines


def refusal(verdicts: list[Verdict]) -> str | None:
    """One line naming every refused parameter and its fix, or None when none is refused."""
    refused = [v for v in verdicts if v.level == "refuse"]
    if not refused:
        return None
    return "the vehicle's parameters are refused: " + "; ".join(v.note for v in refused)


async def read_params(url: str, settings: FlightSettings) -> dict[str, float | None]:
    """Connect to the vehicle at ``url`` and read all its parameters (nothing is sent).

    Returns: every parameter the vehicle has, by name.
    """
    from gcs.flight.vehicle import Vehicle

    vehicle = Vehicle(settings)
    try:
        await vehicle.connect(url)
        return await vehicle.read_all_params()
    finally:
        await vehicle.close()
