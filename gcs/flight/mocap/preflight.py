"""Does the vehicle's EKF2 agree with what gcs will do with the motion capture? (pure)

PX4 (v1.14-v1.16) fuses external vision as its parameters say:

- ``EKF2_EV_CTRL`` bits: 0 horizontal position, 1 vertical position, 2 velocity, 3 yaw;
- ``EKF2_HGT_REF``: the height reference, 0 barometer, 1 GPS, 2 range sensor, 3 vision;
- ``EKF2_GPS_CTRL`` bits: 0 position, 1 altitude, 2 velocity, 3 heading;
- ``EKF2_EV_DELAY``: how old a vision sample is when it arrives [ms];
- ``EKF2_EVP_NOISE``: the smallest position noise EKF2 grants a vision sample [m] (PX4's
  default 0.1 m; with ``EKF2_EV_NOISE_MD`` 1 the noise it grants every sample).

:func:`ekf2_findings` reads them against the plan: when gcs forwards the mocap, vision must be
fused for the horizontal position (else the vehicle flies on something else: refused), a GPS
height reference indoors without GPS is refused, the barometer as reference is a warning (it
drifts indoors by decimetres), GPS fused alongside is a warning, and the delay is reported
(PX4 stamps each pose when it arrives: gcs does not synchronise clocks with PX4, so the delay
is the mocap's own latency plus the link from gcs to the vehicle: a few milliseconds; more than
50 ms is a warning). When a bridge other than gcs feeds the vehicle, vision not being fused
is a warning only.

The noise EKF2 grants the mocap. gcs sends each pose with its covariance
(``mocap.position_std_m``, 5 mm); EKF2 takes the larger of that, ``EKF2_EVP_NOISE`` and 1 cm
(with ``EKF2_EV_NOISE_MD`` 1, ``EKF2_EVP_NOISE`` alone). At PX4's default of 0.1 m it weighs a
millimetre-accurate mocap as a decimetre-noisy one and leans on its inertial prediction
between them: on the lab rig of the real-firmware tests (PX4 v1.16 SIH) the vehicle's
scatter from flight to flight on the same setpoints was 1.6 times that with 0.01 m
(docs/learning-floor.md). More than twice what gcs sends (or 1 cm) is a warning naming the fix.

The heading. MAVSDK sends ``ODOMETRY`` only in frame ``LOCAL_FRD`` (its other choice,
``MOCAP_NED``, is dropped by PX4's receiver); PX4 v1.16 takes an FRD vision yaw as relative
and aligns its heading to north only from a magnetometer or GPS. With neither
(``EKF2_MAG_TYPE`` 5, no GPS heading) it never publishes a global position and denies arming
for as long as one waits (measured on the SIH firmware). ``VISION_POSITION_ESTIMATE`` is NED:
PX4 aligns its heading to the vision yaw. So forwarding ``odometry`` to such a vehicle is
refused, naming ``mocap.message: vision_position_estimate``.

The barometer. With ``EKF2_BARO_CTRL`` 0 and no GPS, vision is the only height source: once the
mocap is lost PX4's failsafe descends blind and its land detector never sees the landing (flown
on the SIH firmware: still armed and "in air" a minute later). That is a warning: keep the
barometer fused (``EKF2_BARO_CTRL`` 1) beside the vision height reference.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "EKF2_INT_PARAMS",
    "EKF2_FLOAT_PARAMS",
    "EKF2_MIN_EV_NOISE_M",
    "Finding",
    "ekf2_findings",
    "ev_noise_granted",
]

EKF2_INT_PARAMS = (
    "EKF2_GPS_CTRL",
    "EKF2_HGT_REF",
    "EKF2_EV_CTRL",
    "EKF2_MAG_TYPE",
    "EKF2_BARO_CTRL",
    "EKF2_EV_NOISE_MD",
)
_OPTIONAL = ("EKF2_MAG_TYPE", "EKF2_BARO_CTRL", "EKF2_EV_NOISE_MD", "EKF2_EVP_NOISE")
EKF2_FLOAT_PARAMS = ("EKF2_EV_DELAY", "EKF2_EVP_NOISE")
MAX_EV_DELAY_MS = 50.0
#: the smallest vision noise EKF2 takes whatever it is told [m] (PX4 v1.16's ev_pos_control)
EKF2_MIN_EV_NOISE_M = 0.01


@dataclass(frozen=True)
class Finding:
    """One line about the vehicle's settings.

    Parameters
    ----------
    text : str
        One line, naming the parameter, its value and the fix.
    level : str
        ``"info"``, ``"warning"`` or ``"refuse"`` (the flight does not take off).
    """

    text: str
    level: str = "info"


def ekf2_findings(
    params: dict[str, float | int | None],
    forward: bool,
    message: str = "vision_position_estimate",
    position_std_m: float = 0.005,
) -> list[Finding]:
    """Judge EKF2's vision settings for a flight on motion capture.

    Parameters
    ----------
    params : dict
        Values of :data:`EKF2_INT_PARAMS` and :data:`EKF2_FLOAT_PARAMS`; None where the
        vehicle did not answer.
    forward : bool
        gcs forwards the mocap as external vision (else another bridge does).
    message : str
        What gcs forwards: ``odometry`` (frame ``LOCAL_FRD``) or ``vision_position_estimate``.
    position_std_m : float
        The position noise gcs sends with each pose (``mocap.position_std_m``) [m].

    Returns
    -------
    list of Finding
        The report line first (``info``), then warnings and refusals.
    """
    ev, hgt, gps = (params.get(n) for n in ("EKF2_EV_CTRL", "EKF2_HGT_REF", "EKF2_GPS_CTRL"))
    delay = params.get("EKF2_EV_DELAY")

    def show(value: float | int | None) -> str:
        return "unreadable" if value is None else f"{value:g}"

    out = [
        Finding(
            f"EKF2: EV_CTRL {show(ev)}, HGT_REF {show(hgt)}, GPS_CTRL {show(gps)}, "
            f"EV_DELAY {show(delay)} ms"
        )
    ]
    needed = [n for n in EKF2_INT_PARAMS + EKF2_FLOAT_PARAMS if n not in _OPTIONAL]
    missing = [n for n in needed if params.get(n) is None]
    mag = params.get("EKF2_MAG_TYPE")
    gps_heading = gps is not None and int(gps) >> 3 & 1
    if forward and message == "odometry" and mag is not None and int(mag) == 5 and not gps_heading:
        out.append(
            Finding(
                "mocap.message is odometry, which MAVSDK sends in frame LOCAL_FRD: without a "
                "magnetometer (EKF2_MAG_TYPE = 5) or GPS heading PX4 never aligns its heading to "
                "north and denies arming; set mocap.message: vision_position_estimate (NED)",
                "refuse",
            )
        )
    if missing:
        out.append(Finding(f"could not read {', '.join(missing)}: not checked", "warning"))
    who = "gcs forwards the mocap" if forward else "the mocap bridge feeds vision"
    level = "refuse" if forward else "warning"
    if ev is not None and not int(ev) & 1:
        out.append(
            Finding(
                f"EKF2_EV_CTRL = {ev:g} does not fuse vision position (bit 0) but {who}: set "
                "EKF2_EV_CTRL to 15 (position, height, velocity, yaw) or at least 1",
                level,
            )
        )
    gps_used = gps is not None and int(gps) & 0b111
    if hgt is not None and int(hgt) == 1 and not gps_used:
        out.append(
            Finding(
                f"EKF2_HGT_REF = 1 (GPS) without GPS fused (EKF2_GPS_CTRL = {show(gps)}): set "
                "EKF2_HGT_REF to 3 (vision)",
                "refuse",
            )
        )
    elif hgt is not None and int(hgt) == 3 and ev is not None and not int(ev) & 2:
        out.append(
            Finding(
                f"EKF2_HGT_REF = 3 (vision) but EKF2_EV_CTRL = {ev:g} does not fuse vision "
                "height (bit 1): set EKF2_EV_CTRL to 15",
                level,
            )
        )
    elif hgt is not None and int(hgt) == 0:
        out.append(
            Finding(
                "EKF2_HGT_REF = 0 (barometer): indoors its height drifts by decimetres; "
                "EKF2_HGT_REF = 3 uses the mocap's",
                "warning",
            )
        )
    if gps_used:
        out.append(
            Finding(
                f"EKF2_GPS_CTRL = {gps:g} fuses GPS alongside vision: indoors set it to 0",
                "warning",
            )
        )
    baro = params.get("EKF2_BARO_CTRL")
    if baro is not None and int(baro) == 0 and not gps_used:
        out.append(
            Finding(
                "EKF2_BARO_CTRL = 0: if the mocap is lost the vehicle has no height left, "
                "descends blind and may never detect its landing (PX4 v1.16 SIH stayed armed); "
                "EKF2_BARO_CTRL 1 keeps the barometer as a second height source",
                "warning",
            )
        )
    granted = ev_noise_granted(params, position_std_m)
    told = max(position_std_m, EKF2_MIN_EV_NOISE_M)
    if forward and granted is not None and granted > 2.0 * told:
        out.append(
            Finding(
                f"EKF2_EVP_NOISE = {params['EKF2_EVP_NOISE']:g} m: EKF2 weighs each mocap pose "
                f"as {granted:g} m noisy (gcs sends {position_std_m:g} m) and follows it "
                f"loosely; set EKF2_EVP_NOISE to {EKF2_MIN_EV_NOISE_M:g} (PX4's smallest)",
                "warning",
            )
        )
    if delay is not None and not 0.0 <= float(delay) <= MAX_EV_DELAY_MS:
        out.append(
            Finding(
                f"EKF2_EV_DELAY = {delay:g} ms: PX4 stamps each pose when it arrives, so the "
                f"delay should be the mocap's latency and the link's (a few ms, at most "
                f"{MAX_EV_DELAY_MS:g})",
                "warning",
            )
        )
    return out


def ev_noise_granted(
    params: dict[str, float | int | None], position_std_m: float = 0.005
) -> float | None:
    """The position noise EKF2 grants a vision sample that gcs sends (PX4 v1.14-v1.16).

    Parameters
    ----------
    params : dict
        ``EKF2_EVP_NOISE`` [m] and ``EKF2_EV_NOISE_MD`` (0 when absent: PX4's default).
    position_std_m : float
        The noise sent with each pose [m].

    Returns
    -------
    float or None
        ``EKF2_EVP_NOISE`` with noise mode 1, else the largest of it, ``position_std_m`` and
        :data:`EKF2_MIN_EV_NOISE_M` [m]; None when ``EKF2_EVP_NOISE`` was not read.
    """
    evp = params.get("EKF2_EVP_NOISE")
    if evp is None:
        return None
    if int(params.get("EKF2_EV_NOISE_MD") or 0) == 1:
        return max(float(evp), EKF2_MIN_EV_NOISE_M)
    return max(float(evp), position_std_m, EKF2_MIN_EV_NOISE_M)
