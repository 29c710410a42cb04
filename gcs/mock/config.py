"""Configuration of the mock drone: physics, controller, disturbances, noise, rates, PX4 params.

:class:`MockConfig` holds everything that describes the simulated vehicle; it is read from a
YAML profile (``profiles/mock.yaml`` writes out every default) by :func:`load_mock_config`.
:class:`Faults` holds the injected link and weather faults of one run; they come from the
command line (``gcs mock --loss ... --gust ...``).

Times in :class:`Faults` (dropout, link loss, gust) count in seconds from the moment the
vehicle **first enters OFFBOARD**, so that a fault lands at the same point of a trial whatever
the connection and take-off took. Packet loss and added latency apply from the start. The
estimator faults (drift, divergence, jump) count from the first **arming**, so that one can
strike during take-off, before any OFFBOARD (as an EKF2 divergence on PX4 SITL once did).

Units are SI; frames are local NED (north, east, down) with the origin at the take-off spot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gcs.errors import ProfileError
from gcs.io.fields import Fields, Rule, ranged
from gcs.io.yamlfile import read_yaml

__all__ = [
    "PhysicsConfig",
    "ControllerConfig",
    "DisturbanceConfig",
    "NoiseConfig",
    "EstimatorConfig",
    "VisionConfig",
    "RatesConfig",
    "Px4Config",
    "MockConfig",
    "Faults",
    "load_mock_config",
    "mock_config_from_dict",
    "MODES",
    "DLL_ACTIONS",
]

MODES = ("HOLD", "POSCTL")
"""Flight modes the mock may boot in (PX4 v1.16 without RC boots in HOLD, with RC in POSCTL)."""

DLL_ACTIONS = (0, 1, 3)
"""``NAV_DLL_ACT`` values the mock models: disabled, Hold, Land."""
_DLL = "disabled, Hold or Land: the actions the mock models"


@dataclass(frozen=True)
class PhysicsConfig:
    """Rigid-body translational model.

    Parameters
    ----------
    dt_s : float
        Integration step [s]; the mock steps the physics on this grid against the monotonic
        clock (0.005 s = 200 Hz).
    gravity_m_s2 : float
        Gravitational acceleration [m/s^2].
    drag_lin_1_s : float
        Linear (rotor) drag coefficient per unit mass [1/s], acting on the air-relative velocity.
    drag_quad_1_m : float
        Quadratic drag coefficient per unit mass [1/m]: ``a = -k |v_air| v_air``.
    tilt_lag_s : float
        Time constant of the first-order lag from the commanded to the achieved acceleration
        (attitude loop plus thrust response) [s].
    thrust_max_g : float
        Maximum total thrust in units of the weight (hover = 1).
    thrust_min_g : float
        Minimum total thrust while armed in units of the weight (idle).
    input_delay_s : float
        Transport delay from the reception of a setpoint to its use by the position controller
        [s] (link, estimator and mocap latency of a real system).
    """

    dt_s: float = ranged(0.005, ge=0.0005, le=0.005, unit="s")
    gravity_m_s2: float = 9.81
    drag_lin_1_s: float = 0.10
    drag_quad_1_m: float = 0.25
    tilt_lag_s: float = ranged(0.08, gt=0)
    thrust_max_g: float = ranged(2.03, gt=1)
    thrust_min_g: float = ranged(0.24, ge=0, lt=1)
    input_delay_s: float = 0.19


@dataclass(frozen=True)
class ControllerConfig:
    """PX4-like cascaded controller: position P, velocity PID, acceleration and tilt limits.

    x and y have slightly different gains on purpose: the identified model of eq. (11) is the
    same for both axes, the mock's axes are not (as on a real, not perfectly symmetric vehicle).

    Parameters
    ----------
    pos_p_x_1_s, pos_p_y_1_s, pos_p_z_1_s : float
        Position loop gains [1/s] (PX4 ``MPC_XY_P``, ``MPC_Z_P``).
    vel_p_x_1_s, vel_p_y_1_s, vel_p_z_1_s : float
        Velocity loop proportional gains [1/s] (PX4 ``MPC_XY_VEL_P_ACC``, ``MPC_Z_VEL_P_ACC``).
    vel_i_xy_1_s2, vel_i_z_1_s2 : float
        Velocity loop integral gains [1/s^2] (PX4 ``MPC_XY_VEL_I_ACC``, ``MPC_Z_VEL_I_ACC``).
    vel_d_xy : float
        Velocity loop derivative gain [-] (PX4 ``MPC_XY_VEL_D_ACC``), on the measured
        acceleration.
    vel_int_max_m_s2 : float
        Anti-windup bound of each horizontal velocity integrator's contribution [m/s^2].
    vel_int_max_z_m_s2 : float
        The same for the vertical one [m/s^2] (PX4 bounds it by g).
    vel_max_xy_m_s : float
        Horizontal speed limit [m/s] (``MPC_XY_VEL_MAX``).
    vel_max_up_m_s, vel_max_down_m_s : float
        Vertical speed limits [m/s] (``MPC_Z_VEL_MAX_UP``, ``MPC_Z_VEL_MAX_DN``).
    acc_max_xy_m_s2 : float
        Horizontal acceleration limit [m/s^2] (``MPC_ACC_HOR_MAX``).
    tilt_max_deg : float
        Tilt limit [deg] (``MPC_TILTMAX_AIR``); bounds the horizontal acceleration by
        ``g tan(tilt)``.
    thrust_xy_margin : float
        Share of the maximum thrust kept for horizontal control when the vertical demand
        saturates (``MPC_THR_XY_MARG``); beyond it the vertical thrust has priority and the
        horizontal gets what is left of ``physics.thrust_max_g``.
    yaw_lag_s : float
        Time constant of the yaw response [s].
    spoolup_s : float
        Motor spool-up after arming before a take-off may start [s] (``MPC_SPOOLUP_TIME``;
        PX4: 1).
    takeoff_ramp_s : float
        Time over which the climb limit ramps from zero thrust to the climb speed at take-off
        [s] (``MPC_TKO_RAMP_T``; PX4: 3). With ``spoolup_s`` both zero (the default) the
        vehicle leaves the ground at once, as the mock always did.
    """

    pos_p_x_1_s: float = 1.25
    pos_p_y_1_s: float = 0.93
    pos_p_z_1_s: float = 1.0
    vel_p_x_1_s: float = 1.65
    vel_p_y_1_s: float = 1.62
    vel_p_z_1_s: float = 4.0
    vel_i_xy_1_s2: float = 0.1
    vel_i_z_1_s2: float = 2.0
    vel_d_xy: float = 0.0
    vel_int_max_m_s2: float = 2.0
    vel_int_max_z_m_s2: float = 9.81
    vel_max_xy_m_s: float = 12.0
    vel_max_up_m_s: float = 3.0
    vel_max_down_m_s: float = 1.5
    acc_max_xy_m_s2: float = 5.0
    tilt_max_deg: float = ranged(45.0, gt=0, lt=80)
    thrust_xy_margin: float = ranged(0.3, ge=0, lt=1)
    yaw_lag_s: float = ranged(0.3, gt=0)
    spoolup_s: float = 0.0
    takeoff_ramp_s: float = 0.0


@dataclass(frozen=True)
class DisturbanceConfig:
    """Repeatable aerodynamic field and non-repeatable gusts.

    Parameters
    ----------
    field_amplitude_m_s2 : float
        Peak amplitude of each of the sine terms of the position-dependent disturbance field
        [m/s^2] (per horizontal axis; the vertical field is a third of it).
    field_terms : int
        Number of sine terms per axis.
    field_wavelength_min_m, field_wavelength_max_m : float
        Range of the spatial wavelengths of the field [m].
    field_seed : int
        Seed of the field's directions and phases. Fixed by the profile (not by ``--seed``): the
        same trajectory meets the same disturbance in every trial and every run.
    gust_sigma_m_s2 : float
        Standard deviation of the Ornstein-Uhlenbeck gust acceleration [m/s^2] (per axis;
        seeded by ``--seed``, different in every trial).
    gust_tau_s : float
        Correlation time of the gusts [s].
    """

    field_amplitude_m_s2: float = 0.12
    field_terms: int = 3
    field_wavelength_min_m: float = ranged(1.5, gt=0)
    field_wavelength_max_m: float = 5.0
    field_seed: int = 7
    gust_sigma_m_s2: float = 0.04
    gust_tau_s: float = ranged(1.5, gt=0)


@dataclass(frozen=True)
class NoiseConfig:
    """Fast measurement noise added to the reported state only (the controller does not see it).

    Parameters
    ----------
    pos_sigma_m : float
        Motion-capture position noise, standard deviation per axis [m].
    vel_sigma_m_s : float
        Velocity noise, standard deviation per axis [m/s].
    att_sigma_rad : float
        Attitude noise, standard deviation per angle [rad].
    """

    pos_sigma_m: float = 0.002
    vel_sigma_m_s: float = 0.01
    att_sigma_rad: float = 0.002


Ned = tuple[float, float, float]
"""Three values for the north, east and down axes."""


@dataclass(frozen=True)
class EstimatorConfig:
    """Navigation error: the controller acts on, and the mock reports, an estimate.

    Off by default (the indoor mock flies on its true state, a motion-capture vehicle). On, the
    estimate is the truth plus the error of an inertial solution aided by a wandering absolute
    position source, as PX4's EKF2 with GPS (``gcs.mock.estimator.AidedInertialError``), per
    axis::

        v_err  Ornstein-Uhlenbeck (vel_sigma, vel_tau)            inertial velocity error
        g      Ornstein-Uhlenbeck (aid_sigma, aid_tau_s)          aiding (GPS) position error
        dp_err/dt = v_err - (p_err - g) / aid_time_constant_s
        p_err <- g at Poisson times of rate reset_rate_1_s      (estimator reset)

    Seeded by ``--seed`` through its own random stream. ``profiles/mock-gps.yaml`` calibrates it
    on the shared PX4 SITL data (``benchmarks/mock_gps_calibration.py``, ``docs/mock.md``).

    Parameters
    ----------
    enabled : bool
        Fly on the estimate (True) or on the true state (False, the default).
    vel_sigma_ned_m_s : tuple of float
        Standard deviation of the velocity error, north, east, down [m/s].
    vel_tau_ned_s : tuple of float
        Correlation time of the velocity error, north, east, down [s].
    aid_sigma_ned_m : tuple of float
        Standard deviation of the aiding position error, north, east, down [m].
    aid_tau_s : float
        Correlation time of the aiding position error [s].
    aid_time_constant_s : float
        Time constant with which the aiding pulls the position estimate back [s].
    reset_rate_1_s : float
        Mean number of resets per second (0 = none): the position error jumps onto the aiding
        error.
    """

    enabled: bool = False
    vel_sigma_ned_m_s: Ned = (0.0, 0.0, 0.0)
    vel_tau_ned_s: Ned = ranged((10.0, 10.0, 10.0), gt=0)
    aid_sigma_ned_m: Ned = (0.0, 0.0, 0.0)
    aid_tau_s: float = ranged(60.0, gt=0)
    aid_time_constant_s: float = 0.5
    reset_rate_1_s: float = 0.0


@dataclass(frozen=True)
class VisionConfig:
    """External vision only, as EKF2 in an indoor arena (``profiles/mock-mocap.yaml``).

    Off by default. On, the vehicle has no GPS: its horizontal position estimate exists only
    while external vision (MAVLink ``ODOMETRY`` or ``VISION_POSITION_ESTIMATE``, e.g. forwarded
    by ``gcs fly --mocap``) arrives and is fused, as PX4's EKF2 does with ``EKF2_GPS_CTRL 0``
    and ``EKF2_EV_CTRL`` set (:class:`gcs.mock.estimator.VisionAidedError`). Which axes are fused,
    the delay the samples are compared at and the dead-reckoning timeout are PX4's parameters
    (``px4.ekf2_ev_ctrl``, ``px4.ekf2_ev_delay_ms``, ``px4.ekf2_noaid_tout_s``).

    Parameters
    ----------
    enabled : bool
        Navigate on external vision only (True) or as before (False, the default).
    time_constant_s : float
        Time constant with which the estimate is pulled onto the vision measurements [s]
        (EKF2's correction of the delayed state, propagated by the output predictor).
    innovation_gate_m : float
        A sample further than this from the estimate (per axis, at its delayed time) is
        rejected [m]: EKF2's ``EKF2_EVP_GATE`` (5) times its minimum observation noise
        ``EKF2_EVP_NOISE`` (0.1 m).
    reset_after_s : float
        After this long with every sample rejected the estimate is reset onto the vision
        [s] (EKF2's ``reset_timeout_max``, 7 s).
    dead_reckoning_accel_m_s2 : float
        Accelerometer error integrated while no vision is fused (inertial dead reckoning):
        the estimate drifts away as ``a t^2 / 2`` [m/s^2]; its horizontal direction is drawn
        from the run's seed.
    """

    enabled: bool = False
    time_constant_s: float = ranged(0.1, gt=0)
    innovation_gate_m: float = ranged(0.5, gt=0)
    reset_after_s: float = 7.0
    dead_reckoning_accel_m_s2: float = 0.05


@dataclass(frozen=True)
class RatesConfig:
    """Default stream rates [Hz] (0 disables); MAVSDK's SET_MESSAGE_INTERVAL overrides them.

    PX4 v1.16 SIH measured rates are given in ``docs/mock.md``; the position streams run at
    50 Hz here (PX4: 30 Hz until the GCS asks for more).

    Parameters
    ----------
    heartbeat_hz, sys_status_hz, extended_sys_state_hz, local_position_ned_hz, odometry_hz,
    attitude_hz, attitude_quaternion_hz, global_position_int_hz, home_position_hz,
    battery_status_hz, vfr_hud_hz, gps_raw_int_hz, position_target_local_ned_hz, ping_hz,
    system_time_hz : float
        Rate of the message of that name [Hz].
    """

    heartbeat_hz: float = ranged(1.0, gt=0, why="MAVSDK needs it")
    sys_status_hz: float = 5.0
    extended_sys_state_hz: float = 1.0
    local_position_ned_hz: float = 50.0
    odometry_hz: float = 50.0
    attitude_hz: float = 100.0
    attitude_quaternion_hz: float = 50.0
    global_position_int_hz: float = 50.0
    home_position_hz: float = 0.5
    battery_status_hz: float = 0.5
    vfr_hud_hz: float = 10.0
    gps_raw_int_hz: float = 8.0
    position_target_local_ned_hz: float = 10.0
    ping_hz: float = 1.0
    system_time_hz: float = 1.0


@dataclass(frozen=True)
class Px4Config:
    """PX4 commander behaviour and the parameters the mock models (PX4 names in brackets).

    Parameters
    ----------
    system_id : int
        MAVLink system id of the vehicle (``MAV_SYS_ID``); the component id is always 1.
    initial_mode : str
        Mode after boot: ``HOLD`` (PX4 v1.16 without RC, as in the SIH capture) or ``POSCTL``.
    mis_takeoff_alt_m : float
        Take-off altitude above home [m] (``MIS_TAKEOFF_ALT``).
    com_of_loss_t_s : float
        Offboard-loss timeout [s] (``COM_OF_LOSS_T``); after it the vehicle falls back to Hold.
    offboard_min_stream_s : float
        How long setpoints must already stream before OFFBOARD is granted [s]. PX4 v1.16 grants
        it on the first fresh setpoint (0.0; the capture shows 2.5 ms); older docs say ~1 s.
    offboard_resume : bool
        Return to OFFBOARD by itself when setpoints come back after an offboard-loss fallback,
        as long as the operator has not chosen another mode (PX4's mode-fallback semantics).
    com_disarm_land_s : float
        Auto-disarm delay after landing [s] (``COM_DISARM_LAND``).
    com_disarm_prflt_s : float
        Auto-disarm delay when armed on the ground without taking off [s]
        (``COM_DISARM_PRFLT``).
    land_detect_s : float
        Time the vehicle must rest on the ground before the land detector reports it [s].
    mpc_land_speed_m_s : float
        Descent speed in LAND [m/s] (``MPC_LAND_SPEED``).
    mpc_tko_speed_m_s : float
        Climb speed in TAKEOFF [m/s] (``MPC_TKO_SPEED``).
    nav_dll_act : int
        Data-link-loss action (``NAV_DLL_ACT``): 0 disabled (PX4's default), 1 Hold, 3 Land;
        the mock models these three.
    com_dl_loss_t_s : float
        Data-link-loss timeout [s] (``COM_DL_LOSS_T``): time without a ground station's
        heartbeat, once one was heard, before ``nav_dll_act`` is taken.
    battery_drain_pct_s : float
        Battery percentage consumed per second while armed [%/s].
    home_lat_deg, home_lon_deg, home_alt_m : float
        Global origin of the local frame (WGS84 degrees, AMSL metres).
    ekf2_gps_ctrl : int
        ``EKF2_GPS_CTRL``, GPS aiding bitmask (0 position, 1 altitude, 2 velocity, 3 dual
        antenna heading): what a GCS reads as the navigation source; the physics does not
        change with it. Default 7, as in the SIH capture (PX4's default).
    ekf2_ev_ctrl : int
        ``EKF2_EV_CTRL``, external vision aiding bitmask (0 horizontal position, 1 vertical
        position, 2 velocity, 3 yaw). Default 0 (PX4's default; the capture does not read it).
    ekf2_hgt_ref : int
        ``EKF2_HGT_REF``, height reference: 0 barometer, 1 GPS, 2 range sensor, 3 vision.
        Default 1, as in the SIH capture.
    ekf2_ev_delay_ms : float
        ``EKF2_EV_DELAY``: how much older than its arrival an external-vision sample is
        taken to be [ms] (PX4's default 175, meant for cameras; a motion-capture chain is a
        few ms). With :class:`VisionConfig` on, the mock compares each sample with its
        estimate that long ago, as EKF2 does.
    ekf2_noaid_tout_s : float
        ``EKF2_NOAID_TOUT`` [s] (PX4 stores microseconds, 5 000 000): how long EKF2 dead
        reckons without aiding before the local position is declared invalid.
    gf_action : int
        ``GF_ACTION``, geofence breach action: 0 none, 1 warning, 2 Hold (PX4's default),
        5 Land; 3 (Return) and 4 (Terminate) are not modelled and land.
    gf_max_hor_dist_m : float
        ``GF_MAX_HOR_DIST``: largest distance from home (0: off, PX4's default) [m].
    gf_max_ver_dist_m : float
        ``GF_MAX_VER_DIST``: largest height above home (0: off, PX4's default) [m].
    """

    system_id: int = ranged(1, ge=1, le=250)
    initial_mode: str = ranged("HOLD", choices=MODES)
    mis_takeoff_alt_m: float = ranged(2.5, gt=0)
    com_of_loss_t_s: float = 1.0
    offboard_min_stream_s: float = 0.0
    offboard_resume: bool = True
    com_disarm_land_s: float = 2.0
    com_disarm_prflt_s: float = 10.0
    land_detect_s: float = 1.0
    mpc_land_speed_m_s: float = ranged(0.7, gt=0)
    mpc_tko_speed_m_s: float = ranged(1.5, gt=0)
    nav_dll_act: int = ranged(0, choices=DLL_ACTIONS, why=_DLL)
    com_dl_loss_t_s: float = ranged(10.0, gt=0)
    battery_drain_pct_s: float = 0.05
    home_lat_deg: float = ranged(47.3977431, ge=-90, le=90)
    home_lon_deg: float = ranged(8.5455947, ge=-180, le=180)
    home_alt_m: float = ranged(489.244)
    ekf2_gps_ctrl: int = ranged(7, ge=0, le=15, why="a bitmask")
    ekf2_ev_ctrl: int = ranged(0, ge=0, le=15, why="a bitmask")
    ekf2_hgt_ref: int = ranged(1, choices=(0, 1, 2, 3))
    ekf2_ev_delay_ms: float = ranged(175.0, ge=0, le=300, unit="ms")
    ekf2_noaid_tout_s: float = ranged(5.0, ge=0.5, le=10, unit="s")
    gf_action: int = ranged(2, ge=0, le=5, why="PX4's GF_ACTION")
    gf_max_hor_dist_m: float = 0.0
    gf_max_ver_dist_m: float = 0.0


@dataclass(frozen=True)
class MockConfig:
    """Everything that describes the simulated vehicle.

    Parameters
    ----------
    physics : PhysicsConfig
        Rigid-body model.
    controller : ControllerConfig
        Cascaded controller gains and limits.
    disturbance : DisturbanceConfig
        Repeatable field and gusts.
    noise : NoiseConfig
        Measurement noise.
    estimator : EstimatorConfig
        Navigation error (off: the vehicle flies on its true state).
    vision : VisionConfig
        External vision only: no local position without it (off by default).
    rates : RatesConfig
        Default telemetry rates.
    px4 : Px4Config
        Commander behaviour and parameters.
    """

    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    disturbance: DisturbanceConfig = field(default_factory=DisturbanceConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    vision: VisionConfig = field(default_factory=VisionConfig)
    rates: RatesConfig = field(default_factory=RatesConfig)
    px4: Px4Config = field(default_factory=Px4Config)


@dataclass(frozen=True)
class Faults:
    """Injected faults of one run. Times are seconds after the vehicle first enters OFFBOARD.

    Times count on the vehicle's clock, which runs at ``clock_rate`` times the wall clock.

    Parameters
    ----------
    loss_fraction : float
        Fraction of UDP datagrams dropped, independently in each direction, from the start.
    latency_ms : float
        Added one-way latency of every datagram in each direction [ms], from the start.
    dropout_start_s, dropout_duration_s : float or None
        Telemetry dropout window: no streamed telemetry (heartbeats, ACKs and replies still go
        out) from ``start`` for ``duration`` seconds.
    link_loss_at_s : float or None
        From this time on nothing is sent or received any more.
    link_loss_duration_s : float or None
        How long the link loss lasts [s]; None: the link is gone for good.
    gust_start_s, gust_duration_s : float or None
        Wind gust window.
    gust_vn_m_s, gust_ve_m_s : float
        Wind speed north and east during the gust [m/s]; it acts through the drag.
    clock_rate : float
        Vehicle time per wall-clock second, like a simulator under load (PX4 SITL lockstep
        was seen at 0.72-0.9): the physics, the PX4 timeouts, the stream rates and every time
        stamp sent run on ``clock_rate x`` the wall clock. The link's latency stays wall time.
    drift_start_s, drift_duration_s : float or None
        Estimator drift: from ``start`` (after the first **arming**) for ``duration`` seconds
        the estimated position walks away from the truth at ``drift_ned_m_s``, then stays off
        (:class:`gcs.mock.estimator.PositionDrift`).
    drift_ned_m_s : tuple of float or None
        Its velocity (north, east, down) [m/s].
    divergence_start_s, divergence_duration_s : float or None
        Estimator divergence: from ``start`` (after the first arming) for ``duration`` seconds
        the estimated position runs away as ``a t^2 / 2``, then stays off.
    divergence_ned_m_s2 : tuple of float or None
        Its ``a`` (north, east, down) [m/s^2]; the PX4 SITL incident was one along down.
    jump_at_s : float or None
        Estimator jump: at this time (after the first arming) the estimated position steps.
    jump_ned_m : tuple of float or None
        The step (north, east, down) [m].
    """

    loss_fraction: float = 0.0
    latency_ms: float = 0.0
    dropout_start_s: float | None = None
    dropout_duration_s: float | None = None
    link_loss_at_s: float | None = None
    link_loss_duration_s: float | None = None
    gust_start_s: float | None = None
    gust_duration_s: float | None = None
    gust_vn_m_s: float = 0.0
    gust_ve_m_s: float = 0.0
    clock_rate: float = 1.0
    drift_start_s: float | None = None
    drift_duration_s: float | None = None
    drift_ned_m_s: tuple[float, float, float] | None = None
    divergence_start_s: float | None = None
    divergence_duration_s: float | None = None
    divergence_ned_m_s2: tuple[float, float, float] | None = None
    jump_at_s: float | None = None
    jump_ned_m: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if not 0.0 <= self.loss_fraction < 1.0:
            raise ValueError(f"loss fraction must be in [0, 1), got {self.loss_fraction}")
        if not 0.0 <= self.latency_ms <= 10_000.0:
            raise ValueError(f"latency must be in [0, 10000] ms, got {self.latency_ms}")
        for name in (
            "dropout_duration_s", "gust_duration_s", "link_loss_duration_s", "drift_duration_s",
            "divergence_duration_s", "drift_start_s", "divergence_start_s", "jump_at_s",
        ):  # fmt: skip
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if not 0.1 <= self.clock_rate <= 10.0:
            raise ValueError(f"clock rate must be in [0.1, 10], got {self.clock_rate}")
        if (self.dropout_start_s is None) != (self.dropout_duration_s is None):
            raise ValueError("dropout needs both a start and a duration")
        if (self.gust_start_s is None) != (self.gust_duration_s is None):
            raise ValueError("gust needs both a start and a duration")
        for what, start, vector in (
            ("drift", self.drift_start_s, self.drift_ned_m_s),
            ("divergence", self.divergence_start_s, self.divergence_ned_m_s2),
            ("jump", self.jump_at_s, self.jump_ned_m),
        ):
            if (start is None) != (vector is None):
                raise ValueError(f"{what} needs both a time and a vector")
            if vector is not None and not (
                len(vector) == 3 and all(math.isfinite(x) for x in vector)
            ):
                raise ValueError(f"{what} vector must be three finite numbers, got {vector}")

    def dropout_active(self, t_offboard_s: float | None) -> bool:
        """Whether the telemetry dropout window covers a time.

        Parameters
        ----------
        t_offboard_s : float or None
            Seconds since the first entry into OFFBOARD (None before it).

        Returns
        -------
        bool
        """
        if t_offboard_s is None or self.dropout_start_s is None:
            return False
        return 0.0 <= t_offboard_s - self.dropout_start_s < (self.dropout_duration_s or 0.0)

    def link_lost(self, t_offboard_s: float | None) -> bool:
        """Whether the link is gone at a time.

        Parameters
        ----------
        t_offboard_s : float or None
            Seconds since the first entry into OFFBOARD (None before it).

        Returns
        -------
        bool
        """
        if t_offboard_s is None or self.link_loss_at_s is None:
            return False
        since = t_offboard_s - self.link_loss_at_s
        return since >= 0.0 and (
            self.link_loss_duration_s is None or since < self.link_loss_duration_s
        )

    def wind_ned_m_s(self, t_offboard_s: float | None) -> tuple[float, float]:
        """Wind of the gust fault at a time.

        Parameters
        ----------
        t_offboard_s : float or None
            Seconds since the first entry into OFFBOARD (None before it).

        Returns
        -------
        tuple of float
            Wind north and east [m/s]; zero outside the gust window.
        """
        if t_offboard_s is None or self.gust_start_s is None:
            return (0.0, 0.0)
        if 0.0 <= t_offboard_s - self.gust_start_s < (self.gust_duration_s or 0.0):
            return (self.gust_vn_m_s, self.gust_ve_m_s)
        return (0.0, 0.0)


def mock_config_from_dict(data: Any, where: str = "<dict>") -> MockConfig:
    """Build a :class:`MockConfig` from a parsed YAML mapping.

    Every number is finite and, unless its field declares another range, ``>= 0``.

    Parameters
    ----------
    data : mapping or None
        Parsed profile; missing sections and fields take their defaults.
    where : str
        Name of the source used in error messages (normally the file path).

    Returns
    -------
    MockConfig

    Raises
    ------
    ProfileError
        On an unknown, ill-typed or out-of-range field, naming ``where`` and the dotted field.
    """
    f = Fields({} if data is None else data, where, "", ProfileError)
    cfg = f.read(MockConfig, Rule(ge=0))
    for rule in _CROSS_FIELD:
        refusal = rule(cfg)
        if refusal:
            raise f.fail(*refusal)
    return cfg


def _pull_on_the_physics_grid(cfg: MockConfig) -> tuple[str, str] | None:
    if cfg.estimator.aid_time_constant_s >= 2 * cfg.physics.dt_s:
        return None
    why = "must be >= 2 physics.dt_s (the pull is integrated on the physics grid)"
    return "estimator.aid_time_constant_s", why


def _resets_within_a_step(cfg: MockConfig) -> tuple[str, str] | None:
    if cfg.estimator.reset_rate_1_s * cfg.physics.dt_s <= 1.0:
        return None
    return "estimator.reset_rate_1_s", "must be <= 1 / physics.dt_s"


def _wavelengths_ordered(cfg: MockConfig) -> tuple[str, str] | None:
    d = cfg.disturbance
    if d.field_wavelength_max_m >= d.field_wavelength_min_m:
        return None
    return "disturbance.field_wavelength_max_m", "must be >= field_wavelength_min_m"


def _one_navigation_error(cfg: MockConfig) -> tuple[str, str] | None:
    if not (cfg.vision.enabled and cfg.estimator.enabled):
        return None
    why = "and estimator.enabled cannot both be true (GPS wander or vision, not both)"
    return "vision.enabled", why


#: Rules between fields: each gives the field and what is wrong, or None.
_CROSS_FIELD = (
    _pull_on_the_physics_grid,
    _resets_within_a_step,
    _wavelengths_ordered,
    _one_navigation_error,
)


def load_mock_config(path: str | Path | None) -> MockConfig:
    """Read a mock profile (YAML); every missing field takes its default.

    Parameters
    ----------
    path : str, Path or None
        Profile file; None gives the defaults.

    Returns
    -------
    MockConfig

    Raises
    ------
    ProfileError
        If the file cannot be read, is malformed YAML, or has an unknown or ill-typed field;
        the message names the file and the field.
    """
    if path is None:
        return MockConfig()
    return mock_config_from_dict(read_yaml(Path(path), ProfileError), str(path))
