"""The typed sections of a profile: ``flight``, ``identification`` and ``mocap``.

Frozen dataclasses, built and validated once by :func:`gcs.io.config.profile_from_dict` (the
refusals name the file and the field) and handed down as ``Profile.flight``,
``Profile.identification`` and ``Profile.mocap``: no layer below parses YAML again. They live in
the io layer so that the flight layer, the mock and the commands can all take them.

Every field of the ``mocap`` section is optional; with no section at all, ``--mocap URL`` uses
the defaults of the URL's system (:data:`gcs.core.frames.SYSTEM_FRAMES`)::

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

from gcs.core.frames import FrameMapping, mapping_for
from gcs.errors import ProfileError
from gcs.io.fields import check, ranged
from gcs.io.mocap_source import MocapSource, parse_mocap_url
from gcs.io.records import MEASUREMENTS

__all__ = [
    "FlightSettings",
    "IdentifySettings",
    "MocapSettings",
    "AXES",
    "EXCITATIONS",
    "MESSAGES",
]

#: Identifiable axes: name -> column in the NED arrays (x north, y east, z down).
AXES = {"x": 0, "y": 1, "z": 2}
#: Excitations of ``identification.excitation``.
EXCITATIONS = ("prbs", "multisine")


@dataclass(frozen=True)
class FlightSettings:
    """How the flight layer streams, waits and watches.

    Parameters
    ----------
    stream_rate_hz : float
        Rate at which position setpoints are sent [Hz]. Must be an integer multiple ``m`` of
        ``1 / t_ilc_s`` (checked by :meth:`sends_per_sample`): each trial setpoint is then sent
        ``m`` times within its sample period. The default 60 Hz is 3 sends per sample at
        ``t_ilc_s = 0.05`` (50 Hz would be 2.5, which breaks the zero-order hold). At 20 Hz
        MAVSDK's own 20 Hz re-send interleaves with ours (up to ~10 % near-duplicates).
    telemetry_rate_hz : float
        Rate requested for LOCAL_POSITION_NED (``position_velocity_ned``) [Hz].
    connect_timeout_s : float
        How long to wait for an autopilot to appear on the link [s].
    health_timeout_s : float
        How long to wait for a valid local position estimate [s].
    takeoff_timeout_s : float
        How long arming plus take-off to the requested altitude may take [s].
    land_timeout_s : float
        How long landing (until the landed state is ON_GROUND) may take [s].
    command_timeout_s : float
        Guard around each single MAVSDK command (arm, land, offboard start/stop...) [s]. MAVSDK
        itself gives up after 2 s without an ACK; this bounds the wait if it does not.
    settle_tolerance_m : float
        Smallest settle tolerance on the distance from the target [m]. The tolerance in use
        is derived from the hover measured before the first trial (``gcs.flight.hover``:
        1.5 times the largest distance seen), never below this. Also the altitude
        tolerance of the take-off.
    settle_speed_m_s : float
        Smallest settle tolerance on the speed (displacement over 1 s) [m/s]; the one in use
        is 1.5 times the measured hover's 95th-percentile speed, never below this.
    settle_time_s : float
        A hover counts as settled when distance and speed have stayed within their
        tolerances for this long without interruption [s, vehicle time].
    settle_timeout_s : float
        Time allowed for settling after a move [s]. When it runs out the hover of that time
        is judged like the first one: a vehicle that hovers is flown on (with its tolerances
        widened to the new measurement, and a warning); one that drifts, oscillates or
        hovers beyond ``hover_max_offset_m`` is an error.
    hover_measure_s : float
        Length of the hover measured at the start point before the first trial of a
        session, after the ``hover_before_trial_s`` hold [s, vehicle time]. It gives the
        settle tolerances and the wander reported to the operator. GPS wander has
        correlation times of several seconds: measure at least 10 s on such a vehicle.
    hover_max_offset_m : float
        A vehicle whose hover gets further than this from its setpoint is refused [m]. The
        GPS-navigated PX4 SITL vehicle of the recorded PX4 v1.16 SITL runs reached 0.98 m.
    hover_max_drift_m_s : float
        A hover whose least-squares trend moves away from the setpoint faster than this is
        refused as drifting [m/s]. PX4 SITL with GPS (``shared/``): up to 0.14 m/s over its
        8 s hovers, up to 0.22 m/s over the 1 s hovers that start its trials.
    hover_max_oscillation_m : float
        A hover with a sustained oscillation (three or more cycles in the window, half of
        the motion or more) of larger amplitude than this is refused [m].
    hover_before_trial_s : float
        Hover at the start point for this long after settling, before each trial starts [s]
        (0 = start at once). ILC assumes every trial starts from the same state (the paper's
        initial reset condition, eq. 1); a position tolerance cannot see the velocity, the
        attitude or the position controller's integrators, which still carry the previous
        trial. The default makes the hold at least 5 s with ``settle_time_s``, more than the
        2 % settling time ``4 / (zeta wn) = 4.6 s`` of eq. (11)'s loop; raise it for slower
        loops. Measured on the mock without gusts (docs/flight.md): with a 1 s hold the
        start state varied by 2 cm and learning stalled at 2.3 % instead of 0.9 %.
    transit_speed_m_s : float
        Peak speed of moves between trials (to the start point) [m/s].
    max_setpoint_late_s : float
        A trial stops when a setpoint is sent later than this after its deadline [s]: its
        stream, and so its data, are spoiled. The vehicle stays under offboard control (PX4
        holds the last setpoint, which MAVSDK re-sends at 20 Hz from its own thread, and
        leaves offboard only after ``COM_OF_LOSS_T``, 1 s by default), so the trial is flown
        again (``paused_trial_retries``).
    paused_trial_retries : int
        How many times a trial stopped by a late setpoint is flown again, from its start
        point, before the flight ends with an emergency stop (0: at once). Each stopped
        attempt is kept in the run's ``aborted/`` folder.
    max_telemetry_age_s : float
        A trial (or a move, or a hover) aborts when the newest position sample is older than
        this [s].
    link_regain_s : float
        How long an emergency stop waits for a lost link to come back (to land the vehicle)
        before leaving it to its own failsafe [s].
    yaw_deg : float
        Constant yaw of all position setpoints [deg, NED, 0 = north].
    min_battery_pct : float
        Take off and start each trial only with at least this much charge left, as the
        battery reports it [%] (0 = no check; a battery that reports no level is not checked).
        Below it the campaign lands with a one-line error and keeps the completed trials:
        swap the battery and ``--resume``. The default leaves a trial and a landing of margin
        above PX4's own low-battery failsafe (``BAT_LOW_THR`` 15 %, ``BAT_CRIT_THR`` 7 %),
        which would otherwise end a trial half-way.
    fence_margin_m : float
        From arming to disarming the flight is stopped (Hold, land) when the measured position
        is further than this outside the arena along an axis [m] (setpoints themselves always
        lie inside it; ``gcs.flight.fence``). The default is ``hover_max_offset_m``: a vehicle
        whose hover the hover check accepts is not stopped hovering anywhere in the arena.
        Hovers measured (``benchmarks/fence_thresholds.py``): PX4 SITL on GPS up to 0.79 m off
        the setpoint along an axis, mock-gps 0.88 m, PX4 SITL on vision 0.14 m; with motion
        capture 0.3 m is plenty. The arena plus this margin is also the geofence uploaded to
        the autopilot.
    fence_speed_factor : float
        The flight is stopped when the measured speed exceeds this factor times the profile's
        vehicle limits (``vehicle.max_speed_m_s`` horizontally,
        ``vehicle.max_vertical_speed_m_s`` vertically): a vehicle overshoots the speed of what
        it tracks (PX4 SITL: 2.55 m/s on an eight of 2.13 m/s, 1.2 times).
    fence_jump_m : float
        The flight is stopped when the position steps between two samples this much further
        than its velocity explains [m]. PX4 SITL (GPS, vision, the capture while armed) and
        mock-gps: at most 2.9 cm.
    fence_drift_m : float
        The flight is stopped when the position moves this much against the integral of its
        velocity within 1 s [m]: the estimate contradicts itself. A GPS-aided EKF2 does so by
        itself by up to 0.87 m in 1 s (PX4 SITL), mock-gps by 1.09 m; with a perfect vision
        feed 0.30 m. Only a faster drift can be told from GPS wander by the estimate alone;
        on a motion-capture vehicle 0.6 m is safe.
    """

    stream_rate_hz: float = ranged(60.0, ge=2, unit="Hz", why="PX4 leaves offboard below 2 Hz")
    telemetry_rate_hz: float = ranged(50.0, gt=0)
    connect_timeout_s: float = ranged(10.0, gt=0)
    health_timeout_s: float = ranged(30.0, gt=0)
    takeoff_timeout_s: float = ranged(30.0, gt=0)
    land_timeout_s: float = ranged(60.0, gt=0)
    command_timeout_s: float = ranged(5.0, gt=0)
    settle_tolerance_m: float = ranged(0.05, gt=0)
    settle_speed_m_s: float = ranged(0.1, gt=0)
    settle_time_s: float = ranged(1.0, gt=0)
    settle_timeout_s: float = ranged(20.0, gt=0)
    hover_measure_s: float = ranged(10.0, ge=1, unit="s")
    hover_max_offset_m: float = ranged(1.5, gt=0)
    hover_max_drift_m_s: float = ranged(0.3, gt=0)
    hover_max_oscillation_m: float = ranged(0.1, gt=0)
    hover_before_trial_s: float = ranged(4.0, ge=0)
    transit_speed_m_s: float = ranged(1.0, gt=0)
    max_setpoint_late_s: float = ranged(0.1, gt=0)
    paused_trial_retries: int = ranged(2, ge=0)
    max_telemetry_age_s: float = ranged(0.5, gt=0)
    link_regain_s: float = ranged(10.0, gt=0)
    yaw_deg: float = 0.0
    min_battery_pct: float = ranged(30.0, ge=0, le=100, unit="%")
    fence_margin_m: float = ranged(1.5, gt=0)
    fence_speed_factor: float = ranged(1.5, ge=1, why="the vehicle's own limits")
    fence_jump_m: float = ranged(0.5, gt=0)
    fence_drift_m: float = ranged(2.0, gt=0)

    def __post_init__(self) -> None:
        check(self, "flight", ProfileError)

    @property
    def telemetry_gap_s(self) -> float:
        """Neighbouring samples further apart than this (2 telemetry periods) form a gap [s]."""
        return 2.0 / self.telemetry_rate_hz

    def sends_per_sample(self, t_ilc_s: float) -> int:
        """Number of sends ``m`` of each setpoint within one ILC sample period.

        Parameters
        ----------
        t_ilc_s : float
            ILC sample time [s].

        Returns
        -------
        int
            ``m = stream_rate_hz * t_ilc_s``, at least 1.

        Raises
        ------
        ProfileError
            If ``stream_rate_hz`` is not an integer multiple of ``1 / t_ilc_s``.
        """
        if not (math.isfinite(t_ilc_s) and t_ilc_s > 0):
            raise ProfileError(f"field 't_ilc_s' must be > 0, got {t_ilc_s}")
        m_float = self.stream_rate_hz * t_ilc_s
        m = round(m_float)
        if m < 1 or abs(m_float - m) > 1e-6 * max(1.0, m_float):
            raise ProfileError(
                f"field 'flight.stream_rate_hz' is {self.stream_rate_hz:g} Hz, not an integer "
                f"multiple of 1/t_ilc_s = {1.0 / t_ilc_s:g} Hz"
            )
        return m


@dataclass(frozen=True)
class IdentifySettings:
    """The profile's ``identification`` section (defaults in brackets).

    Parameters
    ----------
    excitation : str
        ``"prbs"`` [default] or ``"multisine"``.
    amplitude_m : float
        Excitation level per horizontal axis [m] [0.3]: the PRBS level, or the multisine's
        peak.
    vertical_amplitude_m : float
        The same for z (down) [m] [0.3]: the vertical loop has its own range (the floor, the
        sink-rate limit), so it is not the horizontal amplitude.
    bandwidth_hz : float or None
        PRBS band [Hz] [1.0] (clock ``2.5 x bandwidth``); PRBS only.
    f_min_hz, f_max_hz : float or None
        Multisine band [Hz] (required for, and only for, ``multisine``).
    duration_s : float
        Length of each of the two experiments [s] [60].
    past, future : int
        PBSID windows [samples] [20, 10].
    order : int or None
        Model order; None chooses it from the singular values [None].
    max_delay : int
        Longest input delay searched [samples] [10].
    seed : int
        Base seed of the excitation [1]: experiment e, axis a (x = 0, y = 1) uses
        ``seed + 2 e + a``; z uses ``seed + 4 + e`` (seeds of its own, none of x's or y's).
    center_ned_m : tuple of float
        Hover point the excitation is added to, local NED [m] [(0, 0, -1.5)].
    """

    excitation: str = ranged("prbs", choices=EXCITATIONS)
    amplitude_m: float = ranged(0.3, gt=0)
    bandwidth_hz: float | None = ranged(1.0, gt=0)
    f_min_hz: float | None = ranged(None, ge=0)
    f_max_hz: float | None = ranged(None, gt=0)
    duration_s: float = ranged(60.0, gt=0)
    past: int = ranged(20, ge=1)
    future: int = ranged(10, ge=2)
    order: int | None = ranged(None, ge=1)
    max_delay: int = ranged(10, ge=0)
    seed: int = 1
    center_ned_m: tuple[float, float, float] = (0.0, 0.0, -1.5)
    vertical_amplitude_m: float = ranged(0.3, gt=0)

    def n_samples(self, t_ilc_s: float) -> int:
        """Setpoints per experiment, ``round(duration_s / t_ilc_s)``.

        Parameters
        ----------
        t_ilc_s : float
            Sample time [s].

        Returns
        -------
        int
        """
        return int(round(self.duration_s / t_ilc_s))

    def seed_for(self, experiment: int, axis: str) -> int:
        """Excitation seed of one axis in one experiment (0 = fit, 1 = validation).

        Parameters
        ----------
        experiment : int
            0 (fitting) or 1 (validation).
        axis : str
            ``"x"``, ``"y"`` or ``"z"``.

        Returns
        -------
        int
        """
        if axis == "z":  # after x's and y's four seeds: x and y stay as they were
            return self.seed + 4 + experiment
        return self.seed + 2 * experiment + AXES[axis]

    def amplitude_for(self, axis: str) -> float:
        """Excitation level of one axis [m]: ``vertical_amplitude_m`` for z, else
        ``amplitude_m``.

        Parameters
        ----------
        axis : str
            ``"x"``, ``"y"`` or ``"z"``.

        Returns
        -------
        float
        """
        return self.vertical_amplitude_m if axis == "z" else self.amplitude_m


MESSAGES = ("vision_position_estimate", "odometry")
#: Axes of a mapping a ``mocap`` section may set explicitly.
MAPPING_AXES = ("up_axis", "north_axis", "body_forward_axis")


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
    max_age_s : float
        The stream is stale, and the flight ends, when its newest frame is older than this
        [s] (:class:`gcs.flight.mocap.health.HealthLimits`, where the default's reason is).
    """

    url: str | None = None
    frame: str | None = None
    overrides: dict = dataclasses.field(default_factory=dict)
    yaw_offset_deg: float = 0.0
    origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    forward: bool = True
    message: str = ranged("vision_position_estimate", choices=MESSAGES)
    position_std_m: float = ranged(0.005, gt=0)
    angle_std_deg: float = ranged(1.0, gt=0)
    measurement: str = ranged("mocap", choices=MEASUREMENTS)
    agreement_m: float = ranged(0.15, gt=0)
    check_move_m: float = ranged(0.3, ge=0)
    max_age_s: float = ranged(0.4, gt=0)

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
