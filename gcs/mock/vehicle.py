"""PX4 commander of the mock drone: arming, flight modes, offboard rules, land detector.

Pure logic on top of :class:`gcs.mock.physics.QuadPhysics`; no sockets. The server calls
:meth:`Vehicle.update` with the time since boot and forwards the decoded commands; the
vehicle answers with MAVLink result codes and leaves status texts in :attr:`Vehicle.events`.

Behaviour copied from PX4 v1.16 (commander sources and the SIH capture in
the recorded PX4 SITL MAVLink capture):

- Boot mode HOLD (AUTO.LOITER; PX4 without RC), or POSCTL by profile.
- Mode changes are always allowed while disarmed. While armed, OFFBOARD needs a fresh
  setpoint stream (last setpoint younger than ``COM_OF_LOSS_T``); otherwise the command is
  TEMPORARILY_REJECTED (MAVSDK reports COMMAND_DENIED).
- Arming is refused (TEMPORARILY_REJECTED) when the current mode cannot run (OFFBOARD
  without setpoints) or prevents arming (LAND); arming when armed is accepted and changes
  nothing; disarming in the air is refused unless forced (param2 = 21196).
- In OFFBOARD, no setpoint for ``COM_OF_LOSS_T`` makes the vehicle fall back to HOLD at its
  current position. The operator's choice stays OFFBOARD: if setpoints come back before
  another mode is chosen the vehicle resumes OFFBOARD (PX4 mode-fallback semantics).
- TAKEOFF climbs to ``MIS_TAKEOFF_ALT`` at ``MPC_TKO_SPEED``, then switches to HOLD.
- LAND descends at ``MPC_LAND_SPEED``; the land detector reports touchdown after
  ``land_detect_s`` of ground contact; auto-disarm ``COM_DISARM_LAND`` later, after which the
  mode returns to the last operator mode that allows arming (OFFBOARD in the capture).
- Armed on the ground without taking off: auto-disarm after ``COM_DISARM_PRFLT``.
- Data-link loss: armed and in the air, no ground-station heartbeat for ``COM_DL_LOSS_T``
  after one was heard takes ``NAV_DLL_ACT``: 0 nothing (PX4's default), 1 Hold (left for
  OFFBOARD again when setpoints return, like the offboard-loss fallback), 3 Land (stays
  landing). Other values, which PARAM_SET may store, are not modelled and land.
- Home is set at arming to the current position as the estimator has it; hold, take-off and
  land targets are estimated positions too (PX4 flies on its estimate).
- Geofence (:mod:`gcs.mock.geofence`, navigator and failsafe sources): every 0.2 s the
  estimated position is checked against the stored fence, ``GF_MAX_HOR_DIST`` and
  ``GF_MAX_VER_DIST`` (unless ``GF_ACTION`` is 0). Armed and in the air, a breach takes
  ``GF_ACTION``: 1 a warning, 2 Hold, 5 Land (3 Return and 4 Terminate are not modelled and
  land), with PX4's texts ("Geofence: approaching or outside geofence", "Failsafe activated").
  Hold can be left by a mode change (PX4 allows the user to take over); Land is taken again
  while the vehicle is still outside (PX4's failsafe re-engages), and neither resumes
  OFFBOARD by itself. Outside the fence arming is refused, as PX4's arming check does.
- Estimator faults (:mod:`gcs.mock.estimator`) start counting at the first arming.
- External vision only (``vision.enabled``, :class:`gcs.mock.estimator.VisionAidedError`): no
  local position until vision is fused; without one, arming, Takeoff, Hold and OFFBOARD
  (position setpoints) are refused, as PX4's mode requirements (``mode_requirements.cpp``)
  and its offboard check (position setpoints with ``local_position_invalid`` count as no
  offboard signal) make them. When the local position is lost armed in the air (EKF2
  declares it invalid ``EKF2_NOAID_TOUT`` after the aiding ended), PX4's failsafe falls
  through its actions (``failsafe/framework.cpp``): the offboard-loss fallback (Position
  mode) and Hold need a local position, Return a global one, Land the relaxed local one;
  Descend needs only the attitude. The mock takes that end of the chain: LAND mode (PX4
  reports Descend as AUTO.LAND) without horizontal control, level, at ``MPC_LAND_SPEED``,
  then the land detector and auto-disarm as usual.
- One failsafe is in force at a time (:class:`Failsafe`, PX4's failsafe framework takes the
  most severe action due): a failsafe gives way to one as severe or more, and each one's
  ending is its row in :data:`FAILSAFES`. Any failsafe's mode is entered when it is taken,
  in force or not (the last action wins the mode, as in PX4 when each fires in turn).
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

from gcs.core.frames import ned_to_global
from gcs.mock.config import MockConfig
from gcs.mock.estimator import InjectedFault
from gcs.mock.geofence import CHECK_PERIOD_S, FenceItem, Geofence, breach_kinds
from gcs.mock.physics import QuadPhysics, Target

__all__ = [
    "FAILSAFES",
    "Failsafe",
    "FailsafeRule",
    "Mode",
    "LandedState",
    "MavResult",
    "Vehicle",
    "Px4Params",
    "encode_param",
    "decode_param",
    "MODE_FROM_CUSTOM",
]


class Mode(enum.Enum):
    """PX4 flight modes the mock implements, valued ``(main mode, sub mode, base flags)``."""

    POSCTL = (3, 0, 1 | 8 | 16 | 64)
    HOLD = (4, 3, 1 | 4 | 8 | 16)
    TAKEOFF = (4, 2, 1 | 4 | 8 | 16)
    LAND = (4, 6, 1 | 4 | 8 | 16)
    OFFBOARD = (6, 0, 1 | 16)

    @property
    def custom_mode(self) -> int:
        """PX4 ``custom_mode`` of the HEARTBEAT: ``main << 16 | sub << 24``."""
        return (self.value[0] << 16) | (self.value[1] << 24)

    @property
    def base_mode(self) -> int:
        """HEARTBEAT ``base_mode`` while disarmed (add 128 when armed), as PX4 sends it."""
        return self.value[2]


MODE_FROM_CUSTOM = {(m.value[0], m.value[1]): m for m in Mode}


class Failsafe(enum.Enum):
    """The commander's failsafe in force (:data:`FAILSAFES` says what each does)."""

    NONE = "none"
    OFFBOARD_LOSS = "offboard loss"  # no setpoint for COM_OF_LOSS_T in OFFBOARD
    DATA_LINK_LOSS = "data-link loss"  # no ground station for COM_DL_LOSS_T, NAV_DLL_ACT 1
    GEOFENCE_HOLD = "geofence hold"  # a new breach, GF_ACTION 2
    GEOFENCE_LAND = "geofence land"  # still outside, GF_ACTION 3 or more
    NO_POSITION = "no local position"  # the local position lost in the air


@dataclass(frozen=True)
class FailsafeRule:
    """One failsafe: what it commands, what it gives way to, how it ends.

    Parameters
    ----------
    mode : Mode or None
        The mode it commands when taken (None: nothing in force).
    severity : int
        Taken over the failsafe in force when at least as severe as it (a less severe one still
        commands its mode, and leaves the more severe one in force).
    resumes : bool
        Ends by itself, OFFBOARD again, when the setpoints are back while the operator's mode is
        OFFBOARD, the data link is up and the profile's ``px4.offboard_resume`` says so.
    operator_ends : bool
        An accepted mode change (the operator's, or the data-link Land) ends it. Disarming
        ends every failsafe.
    """

    mode: Mode | None
    severity: int
    resumes: bool
    operator_ends: bool


FAILSAFES = {
    Failsafe.NONE: FailsafeRule(None, 0, resumes=False, operator_ends=True),
    Failsafe.OFFBOARD_LOSS: FailsafeRule(Mode.HOLD, 1, resumes=True, operator_ends=True),
    Failsafe.DATA_LINK_LOSS: FailsafeRule(Mode.HOLD, 1, resumes=True, operator_ends=True),
    Failsafe.GEOFENCE_HOLD: FailsafeRule(Mode.HOLD, 2, resumes=False, operator_ends=True),
    Failsafe.GEOFENCE_LAND: FailsafeRule(Mode.LAND, 2, resumes=False, operator_ends=True),
    # Descend (reported as AUTO.LAND): no resuming until disarmed, whatever mode follows
    Failsafe.NO_POSITION: FailsafeRule(Mode.LAND, 3, resumes=False, operator_ends=False),
}
"""The failsafes of the mock's commander, each entered by its trigger in :class:`Vehicle`."""

#: PX4 v1.16 SIH on external vision only: its health and arming checks pass this long after the
#: first vision sample (measured: 4.3 s, "Horizontal position unstable" until 2.2 s, then
#: "No valid position estimate"; docs/mock.md).
EV_PREARM_DELAY_S = 4.3


class LandedState(enum.IntEnum):
    """MAV_LANDED_STATE."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


_GF_TEXTS = {
    "fence": "Geofence: approaching or outside geofence",
    "max_alt": "Geofence: exceeding maximum altitude above Home",
    "max_dist": "Geofence: exceeding maximum distance to Home",
}
"""PX4's critical texts of the geofence checks (HealthAndArmingChecks/checks/geofenceCheck)."""


class MavResult(enum.IntEnum):
    """MAV_RESULT of a COMMAND_ACK."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4


MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9


def encode_param(value: float, param_type: int) -> float:
    """PX4 bytewise encoding of a parameter value into PARAM_VALUE's float field.

    Parameters
    ----------
    value : float
        Parameter value.
    param_type : int
        MAV_PARAM_TYPE (6 INT32: the int's bytes reinterpreted as a float; 9 REAL32).

    Returns
    -------
    float
    """
    if param_type == MAV_PARAM_TYPE_INT32:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_param(raw: float, param_type: int) -> float:
    """Inverse of :func:`encode_param`.

    Parameters
    ----------
    raw : float
        Float field of PARAM_SET / PARAM_VALUE.
    param_type : int
        MAV_PARAM_TYPE.

    Returns
    -------
    float
        Parameter value (integral for INT32).
    """
    if param_type == MAV_PARAM_TYPE_INT32:
        return float(struct.unpack("<i", struct.pack("<f", raw))[0])
    return float(raw)


class Px4Params:
    """PX4 parameters the mock serves, sorted by name as PX4 indexes them.

    The ones the mock models (``MIS_TAKEOFF_ALT``, ``COM_OF_LOSS_T``, ``COM_DISARM_LAND``,
    ``COM_DISARM_PRFLT``, ``MPC_LAND_SPEED``, ``MPC_TKO_SPEED``, ``NAV_DLL_ACT``,
    ``COM_DL_LOSS_T``, ``GF_ACTION``, ``GF_MAX_HOR_DIST``, ``GF_MAX_VER_DIST``) take effect
    when set. ``EKF2_GPS_CTRL``, ``EKF2_EV_CTRL`` and
    ``EKF2_HGT_REF`` come from the profile (``px4.ekf2_*``): they say what the vehicle navigates
    on, for a GCS to read. The others carry the values of the PX4 v1.16 SIH capture so that a
    GCS reading them sees a plausible vehicle; setting them has no effect.

    Parameters
    ----------
    cfg : MockConfig
        Source of the modelled values.
    """

    def __init__(self, cfg: MockConfig) -> None:
        p = cfg.px4
        real, integer = MAV_PARAM_TYPE_REAL32, MAV_PARAM_TYPE_INT32
        table = {
            "MIS_TAKEOFF_ALT": (real, p.mis_takeoff_alt_m),
            "COM_OF_LOSS_T": (real, p.com_of_loss_t_s),
            "COM_DISARM_LAND": (real, p.com_disarm_land_s),
            "COM_DISARM_PRFLT": (real, p.com_disarm_prflt_s),
            "MPC_LAND_SPEED": (real, p.mpc_land_speed_m_s),
            "MPC_TKO_SPEED": (real, p.mpc_tko_speed_m_s),
            "MAV_SYS_ID": (integer, p.system_id),
            "COM_OBL_RC_ACT": (integer, 0),
            "COM_RC_IN_MODE": (integer, 1),
            "NAV_RCL_ACT": (integer, 2),
            "COM_RCL_EXCEPT": (integer, 0),
            "NAV_DLL_ACT": (integer, p.nav_dll_act),
            "COM_DL_LOSS_T": (real, p.com_dl_loss_t_s),
            "COM_ARM_WO_GPS": (integer, 1),
            "EKF2_GPS_CTRL": (integer, p.ekf2_gps_ctrl),
            "EKF2_EV_CTRL": (integer, p.ekf2_ev_ctrl),
            "EKF2_HGT_REF": (integer, p.ekf2_hgt_ref),
            # no magnetometer indoors (PX4: 5, none); with GPS the default, automatic
            "EKF2_MAG_TYPE": (integer, 5 if cfg.vision.enabled else 0),
            "EKF2_BARO_CTRL": (integer, 1),  # PX4's default (the mock has no barometer model)
            "EKF2_EV_DELAY": (real, p.ekf2_ev_delay_ms),
            # as a lab sets them (docs/real-vehicle.md); the mock's vision model does not read them
            "EKF2_EVP_NOISE": (real, 0.01),
            "EKF2_EV_NOISE_MD": (integer, 0),
            "EKF2_NOAID_TOUT": (integer, round(p.ekf2_noaid_tout_s * 1e6)),
            "GF_ACTION": (integer, p.gf_action),
            "GF_MAX_HOR_DIST": (real, p.gf_max_hor_dist_m),
            "GF_MAX_VER_DIST": (real, p.gf_max_ver_dist_m),
            "MPC_XY_P": (real, 0.95),
            "MPC_Z_P": (real, 1.0),
            "MPC_XY_VEL_P_ACC": (real, 1.8),
            "MPC_XY_VEL_MAX": (real, cfg.controller.vel_max_xy_m_s),
            "MPC_ACC_HOR_MAX": (real, cfg.controller.acc_max_xy_m_s2),
            "MPC_TILTMAX_AIR": (real, cfg.controller.tilt_max_deg),
            "MPC_Z_VEL_MAX_UP": (real, cfg.controller.vel_max_up_m_s),
            "MPC_Z_VEL_MAX_DN": (real, cfg.controller.vel_max_down_m_s),
            "SYS_AUTOSTART": (integer, 10040),
        }
        self.names = sorted(table)
        self._values = {k: [t, float(v)] for k, (t, v) in table.items()}

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, name: str) -> float:
        return self._values[name][1]

    def get(self, name: str) -> tuple[int, int, float] | None:
        """Index, type and value of a parameter, or None if unknown.

        Parameters
        ----------
        name : str
            Parameter name.

        Returns
        -------
        tuple (index, MAV_PARAM_TYPE, value) or None
        """
        if name not in self._values:
            return None
        t, v = self._values[name]
        return self.names.index(name), t, v

    def set(self, name: str, raw: float) -> tuple[int, int, float] | None:
        """Set a parameter from its PARAM_SET float (bytewise for integers).

        Parameters
        ----------
        name : str
            Parameter name.
        raw : float
            PARAM_SET ``param_value``.

        Returns
        -------
        tuple (index, MAV_PARAM_TYPE, value) or None
            The stored parameter, or None if unknown or not finite.
        """
        if name not in self._values:
            return None
        t = self._values[name][0]
        value = decode_param(raw, t)
        if not math.isfinite(value):
            return None
        self._values[name][1] = value
        return self.get(name)


@dataclass
class ModeChange:
    """One mode change, for the stats file.

    Parameters
    ----------
    t_s : float
        Vehicle time [s].
    mode : str
        New mode name.
    armed : bool
        Arming state after the change.
    """

    t_s: float
    mode: str
    armed: bool


class Vehicle:
    """PX4-like commander driving the physics.

    Parameters
    ----------
    cfg : MockConfig
        Mock configuration.
    seed : int
        Seed of the gusts and the measurement noise.
    faults : sequence of InjectedFault
        Estimator faults, added to the estimator's sum; their clocks start at the first arming.
    """

    def __init__(
        self, cfg: MockConfig, seed: int = 0, faults: Sequence[InjectedFault] = ()
    ) -> None:
        self.cfg = cfg
        self.physics = QuadPhysics(cfg, seed)
        self.faults = list(faults)
        for fault in self.faults:
            self.physics.add_error(fault)
        self.first_armed_t_s: float | None = None
        self.geofence = Geofence()
        self.gf_breach: tuple[str, ...] = ()  # the kinds of the last check's breach
        self.gf_breaches: list[dict[str, object]] = []
        self._gf_next_check_s = 0.0
        self.params = Px4Params(cfg)
        self.armed = False
        self.mode = Mode[cfg.px4.initial_mode]
        self.user_mode = self.mode
        self._mode_after_disarm = self.mode
        self.failsafe = Failsafe.NONE
        self.landed = True
        self.took_off = False
        self.home_ned_m = (0.0, 0.0, 0.0)
        self.t_armed_s = 0.0
        self._armed_total_s = 0.0
        self._t_contact_s: float | None = None
        self._t_landed_s = 0.0
        self.last_setpoint_t_s = -math.inf
        self._stream_start_t_s = -math.inf
        self.setpoint: Target | None = None
        self.first_offboard_t_s: float | None = None
        self.last_gcs_heartbeat_t_s: float | None = None
        self.data_link_lost = False
        self.events: list[tuple[int, str]] = []
        self.mode_log: list[ModeChange] = []
        self.state_changed = False
        self.mode_log.append(ModeChange(0.0, self.mode.name, False))
        self.vision = self.physics.vision
        self._lpos_valid = self.vision is None
        # On vision only, as PX4 v1.16 without GPS or magnetometer: no global origin until one
        # is set (SET_GPS_GLOBAL_ORIGIN), no heading to north until a vision yaw in NED arrives
        # (ODOMETRY in LOCAL_FRD never aligns it), and the checks pass EV_PREARM_DELAY_S after
        # the first vision sample. With GPS the origin and the heading come from it.
        self.origin: tuple[float, float, float] | None = (
            (cfg.px4.home_lat_deg, cfg.px4.home_lon_deg, cfg.px4.home_alt_m)
            if self.vision is None
            else None
        )
        self.north_aligned = self.vision is None
        self.first_vision_t_s: float | None = None
        self.lpos_log: list[dict[str, object]] = []  # local position validity changes

    # -- queries --------------------------------------------------------------------------
    @property
    def t_s(self) -> float:
        """Vehicle time [s] (the physics clock)."""
        return self.physics.t_s

    def offboard_signal(self, t_s: float | None = None) -> bool:
        """Whether the setpoint stream counts as present for PX4's offboard check.

        Parameters
        ----------
        t_s : float or None
            Time [s]; the vehicle time if None.

        Returns
        -------
        bool
        """
        t = self.t_s if t_s is None else t_s
        fresh = t - self.last_setpoint_t_s <= self.params["COM_OF_LOSS_T"]
        long_enough = max(t - self._stream_start_t_s, 0.0) >= self.cfg.px4.offboard_min_stream_s
        return fresh and long_enough

    @property
    def local_position_valid(self) -> bool:
        """EKF2 reports a horizontal local position (always, without external vision only)."""
        return self._lpos_valid

    def _lpos_now(self, t_s: float) -> bool:
        if self.vision is None:
            return True
        return self.vision.xy_valid(t_s, self.params["EKF2_NOAID_TOUT"] / 1e6)

    def can_run(self, mode: Mode) -> bool:
        """PX4's ``canRun``: whether a mode may be engaged while armed.

        Parameters
        ----------
        mode : Mode
            Candidate mode.

        Returns
        -------
        bool
        """
        if mode in (Mode.OFFBOARD, Mode.HOLD, Mode.TAKEOFF) and not self.local_position_valid:
            return False
        return mode is not Mode.OFFBOARD or self.offboard_signal()

    def armed_seconds(self) -> float:
        """Total time spent armed since boot [s] (drives the battery model).

        Returns
        -------
        float
        """
        return self._armed_total_s + (self.t_s - self.t_armed_s if self.armed else 0.0)

    @property
    def armable(self) -> bool:
        """Pre-arm checks pass in the current mode (SYS_STATUS PREARM_CHECK health bit)."""
        return (
            self.can_run(self.mode)
            and self.mode is not Mode.LAND
            and not self._gf_denies
            and self.local_position_valid
            and self.navigation_problem() is None
        )

    def navigation_problem(self, t_s: float | None = None) -> str | None:
        """PX4's failing navigation check on vision only (None: passes, or GPS).

        Parameters
        ----------
        t_s : float, optional
            Vehicle time [s]; now if omitted.

        Returns
        -------
        str or None
            PX4's text for it.
        """
        if self.vision is None:
            return None
        t = self.t_s if t_s is None else t_s
        if self.first_vision_t_s is None or t - self.first_vision_t_s < EV_PREARM_DELAY_S:
            return "horizontal position unstable"
        if self.origin is None or not self.north_aligned:
            return "No valid global position estimate"
        return None

    def set_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> bool:
        """SET_GPS_GLOBAL_ORIGIN: the mock takes the first one and refuses later ones.

        PX4 v1.16's EKF2 takes later ones too and moves its local frame by the change of
        altitude (docs/mocap.md); gcs sets an origin only on a vehicle that has none, so the
        mock keeps the first and does not model that shift.

        Parameters
        ----------
        lat_deg, lon_deg : float
            WGS84 [deg].
        alt_m : float
            AMSL [m].

        Returns
        -------
        bool
            It was taken.
        """
        if self.origin is not None:
            return False
        self.origin = (lat_deg, lon_deg, alt_m)
        self.events.append((6, f"New NED origin (LLA): {lat_deg:.7f}, {lon_deg:.7f}, {alt_m:.3f}"))
        return True

    @property
    def _gf_denies(self) -> bool:
        """PX4's geofence arming check: outside the fence with a breach action set."""
        return bool(self.gf_breach) and int(self.params["GF_ACTION"]) != 0

    # -- geofence -------------------------------------------------------------------------
    def global_position(self, pos_ned_m: Sequence[float]) -> tuple[float, float, float]:
        """Latitude, longitude [deg] and altitude AMSL [m] of a local position.

        Parameters
        ----------
        pos_ned_m : sequence of float
            Local NED [m] (the origin is the profile's ``px4.home_*``).

        Returns
        -------
        tuple of float
        """
        p = self.cfg.px4
        lat0, lon0, alt0 = self.origin or (p.home_lat_deg, p.home_lon_deg, p.home_alt_m)
        lat, lon = ned_to_global(lat0, lon0, pos_ned_m[0], pos_ned_m[1])
        return lat, lon, alt0 - pos_ned_m[2]

    def fence_stored(self, items: tuple[FenceItem, ...]) -> None:
        """A fence transfer ended: put its items in force as PX4's navigator does.

        Parameters
        ----------
        items : tuple of FenceItem
            The fence (empty: cleared).
        """
        home = self.global_position(self.home_ned_m)
        here = self.global_position(self.physics.nav_pos)
        action = int(self.params["GF_ACTION"])
        texts = self.geofence.load(items, home[:2], here[:2], not self.landed, action)
        self.events.extend(texts)
        self._gf_next_check_s = self.t_s  # check at once

    def _check_geofence(self, t: float) -> None:
        """PX4's geofence check (every CHECK_PERIOD_S) and the commander's failsafe action."""
        if t < self._gf_next_check_s:
            return
        self._gf_next_check_s = t + CHECK_PERIOD_S
        action = int(self.params["GF_ACTION"])
        if action == 0:
            self.gf_breach = ()
            return
        kinds = breach_kinds(
            self.geofence,
            self.global_position(self.physics.nav_pos),
            self.global_position(self.home_ned_m),
            self.params["GF_MAX_HOR_DIST"],
            self.params["GF_MAX_VER_DIST"],
        )
        new = bool(kinds) and not self.gf_breach
        self.gf_breach = kinds
        if not kinds or not self.armed or self.landed:
            return
        if new:
            self.gf_breaches.append({"t_vehicle_s": t, "kinds": list(kinds), "action": action})
            for kind in kinds:
                self.events.append((2, _GF_TEXTS[kind]))
            self.events.append((2, "Failsafe activated"))
            if action == 2:
                self._take(Failsafe.GEOFENCE_HOLD)
        if action >= 3 and self.mode is not Mode.LAND:
            # Land (and the unmodelled Return, Terminate): taken again while still outside
            self._take(Failsafe.GEOFENCE_LAND)

    @property
    def landed_state(self) -> LandedState:
        """MAV_LANDED_STATE as PX4's EXTENDED_SYS_STATE reports it."""
        if self.landed:
            return LandedState.ON_GROUND
        if self.mode is Mode.TAKEOFF:
            return LandedState.TAKEOFF
        if self.mode is Mode.LAND:
            return LandedState.LANDING
        return LandedState.IN_AIR

    # -- inputs ---------------------------------------------------------------------------
    def on_setpoint(
        self, t_s: float, pos_ned_m: tuple[float, float, float], yaw_rad: float
    ) -> None:
        """A SET_POSITION_TARGET_LOCAL_NED position setpoint arrived.

        Parameters
        ----------
        t_s : float
            Arrival time [s] on the vehicle clock.
        pos_ned_m : tuple of float
            Position setpoint (north, east, down) [m].
        yaw_rad : float
            Yaw setpoint [rad]; NaN keeps the current yaw.
        """
        if t_s - self.last_setpoint_t_s > self.params["COM_OF_LOSS_T"]:
            self._stream_start_t_s = t_s
        self.last_setpoint_t_s = t_s
        yaw = yaw_rad if math.isfinite(yaw_rad) else self.physics.yaw_rad
        self.setpoint = Target(pos_ned_m, yaw)
        if self.mode is Mode.OFFBOARD and self.armed:
            self.physics.command(t_s, self.setpoint)

    def on_vision(
        self, t_s: float, pos_ned_m: tuple[float, float, float], north_referenced: bool = True
    ) -> bool:
        """An external-vision position arrived (ODOMETRY or VISION_POSITION_ESTIMATE, NED).

        Parameters
        ----------
        t_s : float
            Arrival time [s] on the vehicle clock (the physics has been stepped to it).
        pos_ned_m : tuple of float
            The position, local NED [m].
        north_referenced : bool
            Its yaw is a heading from north (NED frames; False for LOCAL_FRD and LOCAL_FLU,
            which PX4 takes as relative and never aligns to north without a magnetometer).

        Returns
        -------
        bool
            It was fused (False without external-vision navigation, or rejected).
        """
        if self.vision is None:
            return False
        if self.first_vision_t_s is None:
            self.first_vision_t_s = t_s
        self.north_aligned |= north_referenced
        delay_s = self.params["EKF2_EV_DELAY"] / 1000.0
        fused = self.vision.fuse(t_s, pos_ned_m, delay_s, int(self.params["EKF2_EV_CTRL"]))
        self._update_lpos(t_s)
        return fused

    def on_gcs_heartbeat(self, t_s: float) -> None:
        """A ground station's HEARTBEAT arrived: the data link is up.

        Parameters
        ----------
        t_s : float
            Arrival time [s] on the vehicle clock.
        """
        self.last_gcs_heartbeat_t_s = t_s
        if self.data_link_lost:
            self.data_link_lost = False
            self.events.append((6, "Data link regained"))

    def arm(self, arm: bool, force: bool = False) -> MavResult:
        """MAV_CMD_COMPONENT_ARM_DISARM.

        Parameters
        ----------
        arm : bool
            True to arm, False to disarm.
        force : bool
            param2 = 21196: skip the checks.

        Returns
        -------
        MavResult
        """
        if arm:
            if self.armed:
                return MavResult.ACCEPTED
            if not force and not self.armable:
                if self._gf_denies:
                    for kind in self.gf_breach:
                        self.events.append((2, _GF_TEXTS[kind]))
                    why = "Resolve system health failures first"
                elif not self.local_position_valid:
                    why = "no local position estimate (is vision fused?)"
                elif self.navigation_problem() is not None:
                    self.events.append((2, f"Preflight Fail: {self.navigation_problem()}"))
                    why = "Resolve system health failures first"
                else:
                    why = "mode not available" if self.mode is not Mode.LAND else "landing"
                self.events.append((2, f"Arming denied: {why}"))
                return MavResult.TEMPORARILY_REJECTED
            self.armed = True
            self.t_armed_s = self.t_s
            if self.first_armed_t_s is None:
                self.first_armed_t_s = self.t_s
                for fault in self.faults:
                    fault.start_clock(self.t_s)
            self.took_off = False
            nav = self.physics.nav_pos  # PX4 sets home where its estimator says it is
            self.home_ned_m = (nav[0], nav[1], nav[2])
            self.physics.set_armed(True)
            self._apply_mode_target()
            self.events.append((6, "Armed by external command"))
            self._log()
            return MavResult.ACCEPTED
        if not self.armed:
            return MavResult.ACCEPTED
        if not self.landed and not force:
            self.events.append((2, "Disarming denied: not landed"))
            return MavResult.TEMPORARILY_REJECTED
        self._disarm("Disarmed by external command")
        return MavResult.ACCEPTED

    def set_mode(self, mode: Mode) -> MavResult:
        """MAV_CMD_DO_SET_MODE (and NAV_TAKEOFF / NAV_LAND, which change the mode too).

        Parameters
        ----------
        mode : Mode
            Requested mode.

        Returns
        -------
        MavResult
        """
        if self.armed and not self.can_run(mode):
            self.events.append((4, f"Switching to {mode.name.title()} is currently not available"))
            return MavResult.TEMPORARILY_REJECTED
        self.user_mode = mode
        if mode is not Mode.LAND:
            self._mode_after_disarm = mode
        if FAILSAFES[self.failsafe].operator_ends:  # (a geofence Land is taken again if due)
            self.failsafe = Failsafe.NONE
        self._enter(mode)
        return MavResult.ACCEPTED

    def takeoff(self) -> MavResult:
        """MAV_CMD_NAV_TAKEOFF (altitude from ``MIS_TAKEOFF_ALT``).

        Returns
        -------
        MavResult
        """
        return self.set_mode(Mode.TAKEOFF)

    def land(self) -> MavResult:
        """MAV_CMD_NAV_LAND at the current position.

        Returns
        -------
        MavResult
        """
        result = self.set_mode(Mode.LAND)
        if result is MavResult.ACCEPTED:
            self.events.append((6, "Landing at current position"))
        return result

    # -- time -----------------------------------------------------------------------------
    def update(self, t_s: float) -> None:
        """Advance physics and commander to ``t_s``, one physics step at a time.

        Parameters
        ----------
        t_s : float
            Vehicle time to reach [s].
        """
        physics = self.physics
        while physics.t_s + physics.dt_s <= t_s + 1e-9:
            physics.step()
            self._commander()

    def _update_lpos(self, t: float) -> None:
        """Follow the local position's validity; take PX4's failsafe when it is lost flying."""
        if self.vision is not None:
            while self.vision.events:
                self.events.append((4, f"EKF2: {self.vision.events.pop(0)}"))
        valid = self._lpos_now(t)
        if valid == self._lpos_valid:
            return
        self._lpos_valid = valid
        self.lpos_log.append({"t_vehicle_s": t, "valid": valid})
        self.state_changed = True
        if valid:
            self.events.append((6, "Local position estimate valid"))
            if self.mode is Mode.LAND and self.armed:
                self._apply_mode_target()  # hold the horizontal position again
            return
        self.events.append((3, "Local position estimate invalid"))
        if not self.armed or self.landed:
            return
        if self.mode in (Mode.OFFBOARD, Mode.HOLD, Mode.TAKEOFF):
            # Position mode, Hold, Return and Land cannot run: Descend (reported as AUTO.LAND)
            self.events.append((2, "Failsafe activated: no local position, descending"))
        if self.mode in (Mode.OFFBOARD, Mode.HOLD, Mode.TAKEOFF, Mode.LAND):
            self._take(Failsafe.NO_POSITION)  # landing: on, now without horizontal control

    def _commander(self) -> None:
        t = self.t_s
        ph = self.physics
        self._update_lpos(t)
        # offboard loss, and the end of a failsafe that resumes
        if self.armed and self.mode is Mode.OFFBOARD and not self.offboard_signal(t):
            self.events.append((4, "Failsafe activated: no offboard signal, holding"))
            self._take(Failsafe.OFFBOARD_LOSS)
        elif FAILSAFES[self.failsafe].resumes and self._may_resume(t):
            self.failsafe = Failsafe.NONE
            self.events.append((6, "Offboard signal regained"))
            self._enter(Mode.OFFBOARD)
        self._check_data_link(t)
        self._check_geofence(t)
        # land detector
        if self.landed:
            if self.armed and ph.pos[2] < -0.1:
                self.landed = False
                self.took_off = True
                self._t_contact_s = None
                self.events.append((6, "Takeoff detected"))
                self._log()
        elif ph.on_ground:
            if self._t_contact_s is None:
                self._t_contact_s = t
            elif t - self._t_contact_s >= self.cfg.px4.land_detect_s:
                self.landed = True
                self._t_landed_s = t
                self.events.append((6, "Landing detected"))
                self._log()
        else:
            self._t_contact_s = None
        # take-off complete
        if (
            self.mode is Mode.TAKEOFF
            and self.armed
            and not self.landed
            and abs(ph.nav_pos[2] - ph.target.pos_ned_m[2]) < 0.1
            and abs(ph.nav_vel[2]) < 0.3
        ):
            self.user_mode = Mode.HOLD
            self._mode_after_disarm = Mode.HOLD
            self._enter(Mode.HOLD, keep_target=True)
        # auto-disarm
        if self.armed and self.landed:
            if self.took_off or self.mode is Mode.LAND:
                delay = self.params["COM_DISARM_LAND"]
                since = self._t_landed_s if self.took_off else self.t_armed_s
                if delay > 0 and t - since >= delay:
                    self._disarm("Disarmed by landing")
            else:
                delay = self.params["COM_DISARM_PRFLT"]
                if delay > 0 and t - self.t_armed_s >= delay:
                    self._disarm("Disarmed by auto preflight disarming")

    # -- internals ------------------------------------------------------------------------
    def _check_data_link(self, t: float) -> None:
        """PX4's data-link-loss failsafe (``COM_DL_LOSS_T``, ``NAV_DLL_ACT``)."""
        heard = self.last_gcs_heartbeat_t_s
        if (
            self.data_link_lost
            or heard is None
            or not self.armed
            or self.landed
            or t - heard <= self.params["COM_DL_LOSS_T"]
        ):
            return
        self.data_link_lost = True
        action = int(self.params["NAV_DLL_ACT"])
        if action == 0:
            self.events.append((4, "No connection to the ground control station"))
        elif action == 1:
            self.events.append((4, "Failsafe activated: no connection to ground control, holding"))
            self._take(Failsafe.DATA_LINK_LOSS)
        else:
            self.events.append((4, "Failsafe activated: no connection to ground control, landing"))
            self.set_mode(Mode.LAND)

    def _take(self, failsafe: Failsafe) -> None:
        """Take ``failsafe`` (in force unless a more severe one is) and enter its mode."""
        rule = FAILSAFES[failsafe]
        assert rule.mode is not None
        if rule.severity >= FAILSAFES[self.failsafe].severity:
            self.failsafe = failsafe
        self._enter(rule.mode)

    def _may_resume(self, t: float) -> bool:
        """A resuming failsafe may give OFFBOARD back now (PX4's mode fallback)."""
        return (
            self.user_mode is Mode.OFFBOARD
            and self.cfg.px4.offboard_resume
            and not self.data_link_lost
            and self.offboard_signal(t)
        )

    def _disarm(self, reason: str) -> None:
        self._armed_total_s += self.t_s - self.t_armed_s
        self.armed = False
        self.physics.set_armed(False)
        self.failsafe = Failsafe.NONE
        self.events.append((6, reason))
        self.user_mode = self._mode_after_disarm
        if not self._enter(self._mode_after_disarm):
            self._log()

    def _enter(self, mode: Mode, keep_target: bool = False) -> bool:
        """Switch the reported mode; return whether it changed."""
        changed = mode is not self.mode
        self.mode = mode
        if not keep_target:
            self._apply_mode_target()
        if changed:
            self._log()
        return changed

    def _apply_mode_target(self) -> None:
        """Give the physics the target of the current mode."""
        if not self.armed:
            return
        ph, t = self.physics, self.t_s
        here = (ph.nav_pos[0], ph.nav_pos[1], ph.nav_pos[2])  # hold where it believes it is
        mode = self.mode
        if mode is Mode.OFFBOARD and self.first_offboard_t_s is None:
            self.first_offboard_t_s = t
        if mode is Mode.OFFBOARD and self.setpoint is not None:
            ph.command(t, self.setpoint)
        elif mode is Mode.TAKEOFF:
            alt = self.params["MIS_TAKEOFF_ALT"]
            down = min(self.home_ned_m[2] - alt, here[2])
            ph.command(
                t,
                Target(
                    (here[0], here[1], down),
                    ph.yaw_rad,
                    vel_up_max_m_s=self.params["MPC_TKO_SPEED"],
                ),
            )
        elif mode is Mode.LAND:
            ph.command(
                t,
                Target(
                    here, ph.yaw_rad, vz_m_s=self.params["MPC_LAND_SPEED"],
                    hold_xy=self.local_position_valid,
                ),
            )  # fmt: skip
        else:  # HOLD, POSCTL without sticks: stay here
            ph.command(t, Target(here, ph.yaw_rad))

    def _log(self) -> None:
        self.state_changed = True
        self.mode_log.append(ModeChange(self.t_s, self.mode.name, self.armed))
