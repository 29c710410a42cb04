"""Translational quadrotor dynamics under a PX4-like cascaded controller (pure numerics).

Model, in the local NED frame, integrated with semi-implicit Euler on a fixed grid ``dt_s``::

    r(t)      = target received at t - input_delay_s           (transport delay)
    v_sp      = Kp (r - p)            limited to the speed limits
    a_sp      = Kv (v_sp - v) + Ki int(v_sp - v) - Kd a        limited by tilt and MPC_ACC_HOR_MAX
    thrust    = a_sp - g e_down        |thrust| <= thrust_max, vertical first (a horizontal
                                       margin kept), upward part >= thrust_min
    da/dt     = (a_sp - a) / tilt_lag_s                        (attitude and thrust response)
    dv/dt     = a - k1 (v - w) - k2 |v - w| (v - w) + d(p) + g(t)
    dp/dt     = v

with the wind ``w`` of an injected gust, a smooth position-dependent disturbance field ``d(p)``
(sums of sines, fixed by ``field_seed``: the same path meets the same disturbance in every
trial) and Ornstein-Uhlenbeck gusts ``g(t)`` (seeded per run). The ground is the plane
``down = 0``. The controller acts on the navigation state ``(nav_pos, nav_vel)``: the true
state itself by default (a motion-capture vehicle), or the estimate of a
:class:`gcs.mock.estimator.Estimator` when the profile enables one (a GPS-navigated vehicle,
which then wanders with its estimate). :meth:`QuadPhysics.measure` reports the navigation
state plus fast measurement noise. With ``spoolup_s`` or ``takeoff_ramp_s`` set, a take-off
follows PX4's take-off handling (no thrust during spool-up, then a ramp of the climb limit from
zero thrust, the vertical integrator winding up on the ground meanwhile).

The state is kept in plain floats (not NumPy) because the mock steps it at 250 Hz in real
time; :func:`step_response` and :func:`fit_step_response` give the small-signal closed loop
of each axis for the tests and the docs.
"""

from __future__ import annotations

import math
import random
from collections import deque
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from gcs.mock.config import DisturbanceConfig, MockConfig
from gcs.mock.estimator import (
    VISION_SEED_OFFSET,
    ErrorProcess,
    Estimator,
    VisionAidedError,
    make_estimator,
)

if TYPE_CHECKING:  # NumPy and SciPy are imported lazily: the real-time mock does not need them
    import numpy as np

_DISARMED, _SPOOLUP, _READY, _RAMP, _FLIGHT = range(5)  # PX4's TakeoffState, in its order

__all__ = [
    "Target",
    "QuadPhysics",
    "DisturbanceField",
    "StepFit",
    "EQ11",
    "eq11_step",
    "step_response",
    "fit_step_response",
    "second_order_step",
    "measure_axes",
]


@dataclass(frozen=True)
class Target:
    """What the commander asks of the position controller.

    ``pos_ned_m``: position setpoint (north, east, down) [m]. ``yaw_rad``: yaw setpoint [rad].
    ``vz_m_s``: if given, the vertical axis follows this velocity [m/s, down positive] instead of
    ``pos_ned_m[2]`` (used by LAND). ``vel_up_max_m_s``: climb-speed limit for this target [m/s]
    (used by TAKEOFF), below the configured one. ``hold_xy``: control the horizontal position
    (False: level attitude, no horizontal control, as PX4's Descend when it has no local position).
    """

    pos_ned_m: tuple[float, float, float]
    yaw_rad: float = 0.0
    vz_m_s: float | None = None
    vel_up_max_m_s: float | None = None
    hold_xy: bool = True


class DisturbanceField:
    """Smooth deterministic acceleration field of the horizontal position.

    ``cfg``: amplitude, number of terms, wavelengths and seed of the field.
    """

    def __init__(self, cfg: DisturbanceConfig) -> None:
        rng = random.Random(cfg.field_seed)
        self._terms: list[list[tuple[float, float, float, float]]] = []
        for axis in range(3):
            amp = cfg.field_amplitude_m_s2 / (3.0 if axis == 2 else 1.0)
            terms = []
            for _ in range(cfg.field_terms):
                angle = rng.uniform(0.0, 2.0 * math.pi)
                wavelength = rng.uniform(cfg.field_wavelength_min_m, cfg.field_wavelength_max_m)
                k = 2.0 * math.pi / wavelength
                terms.append((amp, k * math.cos(angle), k * math.sin(angle), rng.uniform(0, 6.3)))
            self._terms.append(terms)

    def __call__(self, north_m: float, east_m: float) -> tuple[float, float, float]:
        """Disturbance acceleration at a horizontal position.

        ``north_m``, ``east_m``: horizontal position [m].

        Returns: acceleration (north, east, down) [m/s^2].
        """
        out = []
        for terms in self._terms:
            s = 0.0
            for amp, kn, ke, phase in terms:
                s += amp * math.sin(kn * north_m + ke * east_m + phase)
            out.append(s)
        return (out[0], out[1], out[2])


class QuadPhysics:
    """Closed-loop translational dynamics of the vehicle, stepped on a fixed grid.

    ``seed``: seed of the gusts, the measurement noise and the estimator (not of the disturbance
    field); each has its own random stream. ``pos_ned_m``: initial position [m]; on the ground
    unless ``down < 0``.

    ``pos``, ``vel``: true position [m] and velocity [m/s], NED. ``nav_pos``, ``nav_vel``:
    navigation state the controller and the commander act on: the very ``pos`` and ``vel`` lists
    without an estimator, the estimate with one. ``estimator``: the navigation error (None: the
    vehicle flies on its true state). ``vision``: with ``cfg.vision.enabled``: the external-vision
    fusion among the estimator's processes (fed by the server through
    :meth:`VisionAidedError.fuse`).
    """

    def __init__(
        self, cfg: MockConfig, seed: int = 0, pos_ned_m: tuple[float, float, float] = (0, 0, 0)
    ) -> None:
        self.cfg = cfg
        p, c = cfg.physics, cfg.controller
        self.dt_s = p.dt_s
        self.t_s = 0.0
        self.pos = list(map(float, pos_ned_m))
        self.vel = [0.0, 0.0, 0.0]
        # achieved acceleration from thrust, gravity included: hover is zero
        self.acc = [0.0, 0.0, 0.0] if pos_ned_m[2] < 0 else [0.0, 0.0, p.gravity_m_s2]
        self.acc_dot = [0.0, 0.0, 0.0]
        self.vel_int = [0.0, 0.0, 0.0]
        self.yaw_rad = 0.0
        self.yaw_rate_rad_s = 0.0
        self.armed = pos_ned_m[2] < 0
        # PX4's take-off handling (spool-up, then a ramp of the climb limit); off when both
        # times are zero, and then the vehicle leaves the ground at once
        self._takeoff_handling = c.spoolup_s > 0 or c.takeoff_ramp_s > 0
        self._tko_state = _FLIGHT if self.armed else _DISARMED
        self._armed_t_s = 0.0
        self._ramp_progress = 0.0
        self.wind_ne_m_s = (0.0, 0.0)
        self.target = Target((self.pos[0], self.pos[1], self.pos[2]), 0.0)
        self._queue: deque[tuple[float, Target]] = deque()
        self._field = DisturbanceField(cfg.disturbance)
        self._rng = random.Random(seed)
        self._noise_rng = random.Random(seed + 0x5EED)
        self.estimator: Estimator | None = make_estimator(cfg.estimator, seed)
        self.vision: VisionAidedError | None = None
        if cfg.vision.enabled:
            rng = random.Random(seed + VISION_SEED_OFFSET)
            self.vision = VisionAidedError(cfg.vision, self.pos, rng)
            self.estimator = Estimator([self.vision])
        self.nav_pos, self.nav_vel = self.pos, self.vel
        if self.estimator is not None:
            self.nav_pos, self.nav_vel = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
            self.estimator.apply(self.pos, self.vel, self.nav_pos, self.nav_vel)
        self.gust = [0.0, 0.0, 0.0]
        self._kp = (c.pos_p_x_1_s, c.pos_p_y_1_s, c.pos_p_z_1_s)
        self._kv = (c.vel_p_x_1_s, c.vel_p_y_1_s, c.vel_p_z_1_s)
        self._ki = (c.vel_i_xy_1_s2, c.vel_i_xy_1_s2, c.vel_i_z_1_s2)
        self._acc_xy_max = min(
            c.acc_max_xy_m_s2, p.gravity_m_s2 * math.tan(math.radians(c.tilt_max_deg))
        )
        self._thrust_max_m_s2 = p.gravity_m_s2 * p.thrust_max_g  # thrust per unit mass
        self._thrust_xy_margin_m_s2 = self._thrust_max_m_s2 * c.thrust_xy_margin
        self._az_max = p.gravity_m_s2 * (1.0 - p.thrust_min_g)  # idle

    # -- inputs ---------------------------------------------------------------------------
    def command(self, t_s: float, target: Target) -> None:
        """Queue a target; the controller uses it ``input_delay_s`` after ``t_s``.

        ``t_s``: time of reception [s] on the physics clock.
        """
        self._queue.append((t_s + self.cfg.physics.input_delay_s, target))

    def add_error(self, process: ErrorProcess) -> None:
        """Add a navigation error (an injected estimator fault); an estimator is made if needed.

        Without one so far the navigation state becomes its own copy of the truth (the same
        numbers while the error is zero).
        """
        if self.estimator is None:
            self.estimator = Estimator([])
            self.nav_pos, self.nav_vel = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        self.estimator.add(process)
        self.estimator.apply(self.pos, self.vel, self.nav_pos, self.nav_vel)

    def set_armed(self, armed: bool) -> None:
        """Start or stop the motors; disarming resets the controller's integrators.

        ``armed``: motor state.
        """
        self.armed = armed
        self.vel_int = [0.0, 0.0, 0.0]
        if armed and self._tko_state == _DISARMED:
            self._tko_state = _SPOOLUP
            self._armed_t_s = self.t_s
        elif not armed:
            self._tko_state = _DISARMED

    def _takeoff(self, grounded: bool, tgt: Target, up_max: float) -> tuple[float, bool]:
        """PX4's take-off state machine for one step; the climb limit and whether it ramps.

        Spool-up for ``spoolup_s`` after arming; then, on the ground with a target above (or a
        climb asked), the climb limit ramps from ``-g / vel_p_z`` (zero thrust) to ``up_max``
        over ``takeoff_ramp_s``; landing again makes the vehicle ready for the next one.
        """
        c = self.cfg.controller
        state = self._tko_state
        if state == _SPOOLUP and self.t_s - self._armed_t_s >= c.spoolup_s - 1e-9:
            state = _READY
        if state == _READY:
            up = tgt.pos_ned_m[2] < self.nav_pos[2] if tgt.vz_m_s is None else tgt.vz_m_s < 0
            if grounded and up:
                state = _RAMP
                self._ramp_progress = 0.0
        limit = up_max
        start = -self.cfg.physics.gravity_m_s2 / max(self._kv[2], 0.01)
        if state < _RAMP:
            limit = start
        elif state == _RAMP:
            if c.takeoff_ramp_s > self.dt_s:
                self._ramp_progress += self.dt_s / c.takeoff_ramp_s
            else:
                self._ramp_progress = 1.0
            if self._ramp_progress >= 1.0:
                state = _FLIGHT
            else:
                limit = start + self._ramp_progress * (up_max - start)
        elif state == _FLIGHT and grounded and self.vel[2] >= 0.0 and self.acc[2] >= 0.0:
            state = _READY
        self._tko_state = state
        return min(limit, up_max), state == _RAMP

    @property
    def on_ground(self) -> bool:
        """True while resting on the ground plane."""
        return self.pos[2] >= 0.0 and self.vel[2] >= 0.0

    # -- integration ----------------------------------------------------------------------
    def advance_to(self, t_s: float) -> int:
        """Step the physics on its fixed grid up to ``t_s``.

        ``t_s``: time to reach [s]; the state ends at the last grid point not after it.
        """
        n = 0
        while self.t_s + self.dt_s <= t_s + 1e-9:
            self.step()
            n += 1
        return n

    def step(self) -> None:
        """Advance the state by one step ``dt_s``."""
        cfg, dt = self.cfg, self.dt_s
        p, c, d = cfg.physics, cfg.controller, cfg.disturbance
        g = p.gravity_m_s2
        self.t_s += dt
        queue = self._queue
        while queue and queue[0][0] <= self.t_s + 1e-9:
            self.target = queue.popleft()[1]
        tgt = self.target
        pos, vel, acc = self.pos, self.vel, self.acc
        nav_pos, nav_vel = self.nav_pos, self.nav_vel  # pos, vel themselves without estimator
        grounded = self.on_ground

        if self.armed:
            # position -> velocity setpoint
            kp = self._kp
            vsp = [kp[i] * (tgt.pos_ned_m[i] - nav_pos[i]) for i in range(3)]
            if tgt.vz_m_s is not None:
                vsp[2] = tgt.vz_m_s
            vxy = math.hypot(vsp[0], vsp[1])
            if vxy > c.vel_max_xy_m_s:
                s = c.vel_max_xy_m_s / vxy
                vsp[0] *= s
                vsp[1] *= s
            up_max = c.vel_max_up_m_s
            if tgt.vel_up_max_m_s is not None:
                up_max = min(up_max, tgt.vel_up_max_m_s)
            az_max = self._az_max
            ramping = False
            if self._takeoff_handling:
                up_max, ramping = self._takeoff(grounded, tgt, up_max)
                if self._tko_state != _FLIGHT:
                    az_max = g  # PX4 lets the thrust ramp from zero on take-off
            # PX4's order: the climb limit wins when the two cross (the ramp's start)
            vsp[2] = max(min(vsp[2], c.vel_max_down_m_s), -up_max)
            # velocity -> acceleration setpoint (PID, derivative on the measured acceleration)
            asp = [0.0, 0.0, 0.0]
            for i in range(3):
                err = vsp[i] - nav_vel[i]
                if i == 2 and ramping:  # PX4 integrates on the ground while the ramp runs,
                    a_now = self._kv[2] * err + self._ki[2] * self.vel_int[2]
                    if not (a_now >= az_max and err > 0):  # unless the thrust is at zero
                        lim = c.vel_int_max_z_m_s2 / self._ki[2] if self._ki[2] > 0 else 0.0
                        self.vel_int[2] = min(max(self.vel_int[2] + err * dt, -lim), lim)
                elif not grounded:
                    lim_a = c.vel_int_max_z_m_s2 if i == 2 else c.vel_int_max_m_s2
                    lim = lim_a / self._ki[i] if self._ki[i] > 0 else 0.0
                    self.vel_int[i] = min(max(self.vel_int[i] + err * dt, -lim), lim)
                a_i = acc[i] - (g if i == 2 else 0.0)
                asp[i] = self._kv[i] * err + self._ki[i] * self.vel_int[i]
                if i < 2:
                    asp[i] -= c.vel_d_xy * a_i
            if self._takeoff_handling and self._tko_state < _RAMP:
                asp = [0.0, 0.0, g]  # not taking off yet: no thrust, no integrator
                self.vel_int = [0.0, 0.0, 0.0]
            if not tgt.hold_xy:  # level: no horizontal control (PX4 Descend)
                asp[0] = asp[1] = 0.0
                self.vel_int[0] = self.vel_int[1] = 0.0
            axy = math.hypot(asp[0], asp[1])
            if axy > self._acc_xy_max:
                s = self._acc_xy_max / axy
                asp[0] *= s
                asp[1] *= s
                axy = self._acc_xy_max
            # thrust limits, vertical first (PX4's PositionControl): the upward thrust may use
            # what a horizontal margin leaves, the horizontal thrust what the vertical leaves
            thr_max = self._thrust_max_m_s2
            margin = min(axy, self._thrust_xy_margin_m_s2)
            up_max = math.sqrt(thr_max * thr_max - margin * margin)
            if g - asp[2] > up_max:
                asp[2] = g - up_max
            elif asp[2] > az_max:
                asp[2] = az_max
            xy_room = thr_max * thr_max - (g - asp[2]) ** 2
            if axy * axy > xy_room:
                s = math.sqrt(max(xy_room, 0.0)) / axy
                asp[0] *= s
                asp[1] *= s
            # yaw: first-order lag towards the setpoint, the short way round
            dyaw = math.remainder(tgt.yaw_rad - self.yaw_rad, 2.0 * math.pi)
            self.yaw_rate_rad_s = dyaw / c.yaw_lag_s
            self.yaw_rad = math.remainder(self.yaw_rad + self.yaw_rate_rad_s * dt, 2.0 * math.pi)
        else:
            asp = [0.0, 0.0, g]  # motors off: free fall
            self.yaw_rate_rad_s = 0.0

        # attitude / thrust lag
        tau = p.tilt_lag_s
        for i in range(3):
            self.acc_dot[i] = (asp[i] - acc[i]) / tau
            acc[i] += self.acc_dot[i] * dt

        # external forces
        wn, we = self.wind_ne_m_s
        air = (vel[0] - wn, vel[1] - we, vel[2])
        speed = math.sqrt(air[0] * air[0] + air[1] * air[1] + air[2] * air[2])
        drag = p.drag_lin_1_s + p.drag_quad_1_m * speed
        if grounded:
            dist = (0.0, 0.0, 0.0)
        else:
            dist = self._field(pos[0], pos[1])
            if d.gust_sigma_m_s2 > 0:
                a = dt / d.gust_tau_s
                b = d.gust_sigma_m_s2 * math.sqrt(2.0 * a)
                for i in range(3):
                    self.gust[i] += -a * self.gust[i] + b * self._rng.gauss(0.0, 1.0)
            dist = (dist[0] + self.gust[0], dist[1] + self.gust[1], dist[2] + self.gust[2])
        for i in range(3):
            vel[i] += (acc[i] - drag * air[i] + dist[i]) * dt
            pos[i] += vel[i] * dt

        # ground contact: no penetration, static friction
        if pos[2] >= 0.0 and vel[2] >= 0.0:
            pos[2] = 0.0
            vel[0] = vel[1] = vel[2] = 0.0
            if acc[2] >= 0.0:  # not lifting off: no horizontal push either
                acc[0] = acc[1] = 0.0

        if self.estimator is not None:
            self.estimator.step(dt)
            self.estimator.apply(pos, vel, self.nav_pos, self.nav_vel)

    # -- outputs --------------------------------------------------------------------------
    def attitude(self) -> tuple[float, float, float, float, float, float]:
        """Attitude implied by the thrust direction and yaw.

        Returns: ``(roll, pitch, yaw, rollspeed, pitchspeed, yawspeed)`` [rad, rad/s].
        """
        g = self.cfg.physics.gravity_m_s2
        cy, sy = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        ax, ay = self.acc[0], self.acc[1]
        lift = max(g - self.acc[2], 0.1)
        abx, aby = cy * ax + sy * ay, -sy * ax + cy * ay
        dbx = cy * self.acc_dot[0] + sy * self.acc_dot[1]
        dby = -sy * self.acc_dot[0] + cy * self.acc_dot[1]
        pitch = math.atan2(-abx, lift)
        roll = math.atan2(aby * math.cos(pitch), lift)
        return (roll, pitch, self.yaw_rad, dby / lift, -dbx / lift, self.yaw_rate_rad_s)

    def measure(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """Reported position and velocity: the navigation state plus measurement noise.

        Returns: noisy position [m] and velocity [m/s], NED (the true state's without an estimator,
        the estimate's with one).
        """
        n = self.cfg.noise
        gauss = self._noise_rng.gauss
        pos = tuple(x + gauss(0.0, n.pos_sigma_m) for x in self.nav_pos)
        vel = tuple(v + gauss(0.0, n.vel_sigma_m_s) for v in self.nav_vel)
        return pos, vel  # type: ignore[return-value]


# -- small-signal identification of the mock ------------------------------------------------


@dataclass(frozen=True)
class StepFit:
    """Second-order-plus-delay description ``K wn^2 e^{-Ls} / (s^2 + 2 zeta wn s + wn^2)``.

    ``wn_rad_s``: natural frequency [rad/s]. ``zeta``: damping ratio [-]. ``gain``: static gain [-].
    ``delay_s``: pure delay [s]. ``rms_residual_m``: RMS of the fit residual per unit step (0 for an
    exact model) [-].
    """

    wn_rad_s: float
    zeta: float
    gain: float
    delay_s: float
    rms_residual_m: float = 0.0


EQ11 = StepFit(
    wn_rad_s=math.sqrt(2.01), zeta=1.752 / (2.0 * math.sqrt(2.01)), gain=1.94 / 2.01, delay_s=0.25
)
"""Eq. (11) of the paper, Gx(s) = e^{-0.25 s} (0.08 s + 1.94) / (s^2 + 1.752 s + 2.01)."""


def eq11_step(t_s: np.ndarray) -> np.ndarray:
    """Unit-step response of the paper's eq. (11), zero included.

    ``t_s``: times [s], ascending, from 0.

    Returns: the response, shape (N,) [-].
    """
    import numpy as np
    import scipy.signal

    t = np.asarray(t_s, dtype=float)
    grid = np.linspace(0.0, max(float(t.max()), 1e-3), 4001)
    _, y = scipy.signal.step(([0.08, 1.94], [1.0, 1.752, 2.01]), T=grid)
    return np.interp(t - EQ11.delay_s, grid, y, left=0.0)


def second_order_step(t_s: np.ndarray, fit: StepFit) -> np.ndarray:
    """Unit-step response of a :class:`StepFit` model.

    ``t_s``: times [s].

    Returns: the response, shape (N,) [-].
    """
    import numpy as np

    t = np.maximum(np.asarray(t_s, dtype=float) - fit.delay_s, 0.0)
    wn, z = fit.wn_rad_s, fit.zeta
    if abs(z - 1.0) < 1e-6:
        z = 1.0 + 1e-6
    root = np.sqrt(complex(z * z - 1.0))
    p1, p2 = wn * (-z + root), wn * (-z - root)
    y = 1.0 + (p2 * np.exp(p1 * t) - p1 * np.exp(p2 * t)) / (p1 - p2)
    return fit.gain * np.real(y)


def step_response(
    cfg: MockConfig,
    axis: int,
    amplitude_m: float = 0.1,
    duration_s: float = 12.0,
    t_sample_s: float = 0.05,
) -> tuple[np.ndarray, np.ndarray]:
    """Small-signal step response of one axis, from the physics alone.

    The vehicle hovers at 2 m in equilibrium; at t = 0 the position setpoint of ``axis`` steps
    by ``amplitude_m`` (along down for axis 2: a negative step climbs). The repeatable field,
    the gusts, the estimator error and the noise are switched off; the nonlinearities (limits,
    drag) stay but are not reached at small amplitude.

    ``axis``: 0 for north (x), 1 for east (y), 2 for down (z). ``amplitude_m``: step size [m],
    non-zero. ``duration_s``: length of the response [s]. ``t_sample_s``: sample time of the
    returned response [s] (a multiple of ``cfg.physics.dt_s``).

    Returns: ``t_s``: sample times [s], from 0. ``y``: position change along ``axis`` divided by
    ``amplitude_m`` [-].
    """
    import numpy as np

    quiet = replace(
        cfg,
        disturbance=replace(cfg.disturbance, field_amplitude_m_s2=0.0, gust_sigma_m_s2=0.0),
        estimator=replace(cfg.estimator, enabled=False),
    )
    sim = QuadPhysics(quiet, seed=0, pos_ned_m=(0.0, 0.0, -2.0))
    start = (0.0, 0.0, -2.0)
    target = list(start)
    target[axis] += amplitude_m
    sim.command(0.0, Target((target[0], target[1], target[2]), 0.0))
    n = int(round(duration_s / t_sample_s)) + 1
    t = np.arange(n) * t_sample_s
    y = np.empty(n)
    for k, tk in enumerate(t):
        sim.advance_to(float(tk))
        y[k] = (sim.pos[axis] - start[axis]) / amplitude_m
    return t, y


def fit_step_response(t_s: np.ndarray, y: np.ndarray) -> StepFit:
    """Least-squares fit of a second-order-plus-delay model to a unit-step response.

    ``t_s``: sample times [s], from the step. ``y``: response to a unit step [-].

    Returns: fitted natural frequency, damping, gain, delay and RMS residual.
    """
    import numpy as np
    import scipy.optimize

    t = np.asarray(t_s, dtype=float)
    y = np.asarray(y, dtype=float)

    def residual(theta: np.ndarray) -> np.ndarray:
        return second_order_step(t, StepFit(*theta)) - y

    sol = scipy.optimize.least_squares(
        residual,
        x0=[1.4, 0.6, float(y[-1]), 0.2],
        bounds=([0.05, 0.05, 0.0, 0.0], [20.0, 3.0, 10.0, 2.0]),
    )
    rms = float(np.sqrt(np.mean(sol.fun**2)))
    return StepFit(*(float(v) for v in sol.x), rms_residual_m=rms)


def measure_axes(cfg: MockConfig, amplitude_m: float = 0.1) -> tuple[StepFit, StepFit]:
    """Fit the small-signal step responses of the mock's x and y closed loops.

    ``amplitude_m``: step size [m].

    Returns: fits for x (north) and y (east).
    """
    fx = fit_step_response(*step_response(cfg, 0, amplitude_m))
    fy = fit_step_response(*step_response(cfg, 1, amplitude_m))
    return fx, fy
