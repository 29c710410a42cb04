"""The ``mocap:`` section of a profile: which frame mapping, what is forwarded, what is learned.

Every field is optional; with no section at all, ``--mocap URL`` uses the defaults of the URL's
system (:data:`gcs.flight.mocap.frames.SYSTEM_FRAMES`)::

    mocap:
      url: optitrack://192.168.1.10/drone?interface=192.168.1.20   # --mocap overrides it
      frame: optitrack        # a named convention; default: the URL's system
      yaw_offset_deg: 0.0     # heading in NED of the convention's north axis
      origin_m: [0, 0, 0]     # system coordinates of the NED origin
      up_axis: +y             # overrides of the convention (rarely needed)
      north_axis: +x
      body_forward_axis: +x
      right_handed: true      # false is refused: it mirrors an axis (see below)
      forward: true           # send the pose to PX4 as external vision (false: a bridge does)
      message: vision_position_estimate   # or odometry (LOCAL_FRD: needs a magnetometer)
      position_std_m: 0.005   # standard deviation sent with the pose (covariance)
      angle_std_deg: 1.0
      measurement: mocap      # mocap | estimate: what learning and e_pos use
      agreement_m: 0.15       # pre-flight: estimate and mocap this close
      check_move_m: 0.3       # after take-off: one move per horizontal axis (0: none)

A left-handed mapping is refused: OptiTrack, Vicon, Qualisys and VRPN servers all stream
right-handed axes, so ``right_handed: false`` mirrors one axis of a real system, and a vehicle
that navigates on mirrored vision flies away from every setpoint on that axis.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from gcs.errors import ProfileError
from gcs.flight.mocap.frames import SYSTEM_FRAMES, FrameMapping, mapping_for
from gcs.flight.mocap.source import MocapSource, parse_mocap_url

__all__ = ["MESSAGES", "MEASUREMENTS", "MocapSettings", "mocap_settings"]

MESSAGES = ("vision_position_estimate", "odometry")
MEASUREMENTS = ("mocap", "estimate")
_AXES = ("up_axis", "north_axis", "body_forward_axis")


@dataclass(frozen=True)
class MocapSettings:
    """A profile's ``mocap`` section, checked.

    Parameters
    ----------
    url : str or None
        Default source (``--mocap`` overrides it).
    frame : str or None
        Named convention; None: the source's system.
    overrides : dict
        ``up_axis``, ``north_axis``, ``body_forward_axis`` given explicitly.
    yaw_offset_deg : float
        Heading in NED of the convention's north axis [deg].
    origin_m : tuple of float
        System coordinates of the NED origin [m].
    forward : bool
        Send the pose to PX4 as external vision.
    message : str
        ``odometry`` or ``vision_position_estimate``.
    position_std_m : float
        Position standard deviation sent with each pose [m].
    angle_std_deg : float
        Attitude standard deviation sent with each pose [deg].
    measurement : str
        ``mocap`` or ``estimate``: what learning and e_pos use when a trial has both.
    agreement_m : float
        Pre-flight: largest distance between estimate and mocap [m].
    check_move_m : float
        Length of the pre-flight move per horizontal axis [m]; 0 skips it.
    """

    url: str | None = None
    frame: str | None = None
    overrides: dict = dataclasses.field(default_factory=dict)
    yaw_offset_deg: float = 0.0
    origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    forward: bool = True
    message: str = "vision_position_estimate"
    position_std_m: float = 0.005
    angle_std_deg: float = 1.0
    measurement: str = "mocap"
    agreement_m: float = 0.15
    check_move_m: float = 0.3

    def mapping(self, source: MocapSource) -> FrameMapping:
        """The frame mapping for ``source`` (its system's convention unless ``frame`` is set).

        Parameters
        ----------
        source : MocapSource
            Where the poses come from.

        Returns
        -------
        FrameMapping
        """
        base = mapping_for(self.frame or source.system, self.yaw_offset_deg, self.origin_m)
        return dataclasses.replace(base, **self.overrides)

    def source(self, url: str | None) -> MocapSource | None:
        """The source to read: ``url`` (``--mocap``), else the section's own, else None.

        Parameters
        ----------
        url : str or None
            The command line's ``--mocap`` (not ``mock``).

        Returns
        -------
        MocapSource or None
        """
        chosen = url or self.url
        return None if chosen is None else parse_mocap_url(chosen)


def mocap_settings(section: Any, where: str) -> MocapSettings:
    """Check a profile's ``mocap`` section (unknown keys, types, ranges, mirrored mapping).

    Parameters
    ----------
    section : dict
        The parsed section (empty: defaults).
    where : str
        The profile's file, for messages.

    Returns
    -------
    MocapSettings

    Raises
    ------
    ProfileError
        One line naming the field.
    """
    if not isinstance(section, dict):
        raise ProfileError(f"{where}: field 'mocap' must be a mapping")
    d = MocapSettings()
    known = {f.name for f in dataclasses.fields(MocapSettings)} - {"overrides"}
    known |= set(_AXES) | {"right_handed"}
    for key in section:
        if key not in known:
            raise ProfileError(f"{where}: field 'mocap.{key}' is not known")

    def fail(key: str, message: str) -> ProfileError:
        return ProfileError(f"{where}: field 'mocap.{key}' {message}")

    def number(key: str, default: float, minimum: float = -math.inf) -> float:
        value = section.get(key, default)
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        if not ok or not math.isfinite(value) or value < minimum:
            raise fail(key, f"must be a finite number >= {minimum:g}, got {value!r}")
        return float(value)

    def positive(key: str, default: float) -> float:
        value = number(key, default, 0.0)
        if value <= 0:
            raise fail(key, f"must be > 0, got {value!r}")
        return value

    def choice(key: str, default: str, choices: tuple[str, ...]) -> str:
        value = section.get(key, default)
        if value not in choices:
            raise fail(key, f"must be one of {', '.join(choices)}, got {value!r}")
        return value

    def flag(key: str, default: bool) -> bool:
        value = section.get(key, default)
        if not isinstance(value, bool):
            raise fail(key, f"must be true or false, got {value!r}")
        return value

    url = section.get("url")
    if url is not None:
        if not isinstance(url, str):
            raise fail("url", f"must be a string, got {url!r}")
        try:
            parse_mocap_url(url)
        except ProfileError as exc:
            raise fail("url", f"is not usable: {exc}") from None
    frame = section.get("frame")
    if frame is not None and (not isinstance(frame, str) or frame.lower() not in SYSTEM_FRAMES):
        raise fail("frame", f"must be one of {', '.join(SYSTEM_FRAMES)}, got {frame!r}")
    if not flag("right_handed", True):
        raise fail(
            "right_handed",
            "is false: a left-handed mapping mirrors an axis of the room (OptiTrack, Vicon, "
            "Qualisys and VRPN all stream right-handed axes) and the vehicle would fly the "
            "wrong way on it; set up_axis and north_axis instead",
        )
    overrides = {}
    for key in _AXES:
        if key in section:
            if not isinstance(section[key], str):
                raise fail(key, f"must be one of +x -x +y -y +z -z, got {section[key]!r}")
            overrides[key] = section[key]
    origin = section.get("origin_m", [0.0, 0.0, 0.0])
    if (
        not isinstance(origin, list)
        or len(origin) != 3
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in origin)
        or not all(math.isfinite(v) for v in origin)
    ):
        raise fail("origin_m", f"must be 3 finite numbers, got {origin!r}")
    settings = MocapSettings(
        url=url,
        frame=None if frame is None else frame.lower(),
        overrides=overrides,
        yaw_offset_deg=number("yaw_offset_deg", d.yaw_offset_deg),
        origin_m=(float(origin[0]), float(origin[1]), float(origin[2])),
        forward=flag("forward", d.forward),
        message=choice("message", d.message, MESSAGES),
        position_std_m=positive("position_std_m", d.position_std_m),
        angle_std_deg=positive("angle_std_deg", d.angle_std_deg),
        measurement=choice("measurement", d.measurement, MEASUREMENTS),
        agreement_m=positive("agreement_m", d.agreement_m),
        check_move_m=number("check_move_m", d.check_move_m, 0.0),
    )
    try:  # the axes: each a signed axis, north and forward horizontal
        system = parse_mocap_url(url).system if url is not None else "optitrack"
        base = mapping_for(settings.frame or system)
        dataclasses.replace(base, **overrides)
    except ProfileError as exc:
        raise ProfileError(f"{where}: field 'mocap': {exc}") from None
    return settings
