"""Navigation error of the mock drone: what its autopilot believes, against the truth (pure).

A PX4 vehicle does not fly on its true state but on its estimator's (EKF2): the position
controller drives the *estimate* to the setpoint, and the estimate is what it reports. With
motion capture the two agree to millimetres; with GPS they do not, and the vehicle wanders
with its estimate. :class:`Estimator` gives the mock that layer::

    pos_est = pos_true + sum of the processes' position errors
    vel_est = vel_true + sum of the processes' velocity errors

The controller of :class:`gcs.mock.physics.QuadPhysics` acts on ``(pos_est, vel_est)``;
:meth:`QuadPhysics.measure` reports them (plus the profile's fast measurement noise). An
estimator is a sum of :class:`ErrorProcess` objects, each with its own seeded random stream,
so that further ones (another aiding source, injected faults) add without touching the others.

:class:`AidedInertialError` is the error of an inertial solution aided by an absolute position
source (GPS), per axis ``i``, on the physics grid::

    v_err       Ornstein-Uhlenbeck (sigma_v, tau_v)        inertial velocity error
    g           Ornstein-Uhlenbeck (sigma_g, tau_g)        error of the aiding position (GPS)
    dp_err/dt = v_err - (p_err - g) / T                    aiding pulls the position back
    p_err <- g  at Poisson times of rate lambda            estimator reset onto the aiding

The velocity error is what makes a GPS-navigated PX4 vehicle hover off its setpoint in the
reported position: its velocity loop drives the *estimated* velocity to ``Kp (r - pos_est)``,
so a velocity error ``v_err`` holds the reported position about ``v_err / Kp`` off the setpoint
(a shared PX4 SITL hover starts 0.70 m off while reporting 0.58 m/s towards the point;
0.58 / ``MPC_XY_P`` 0.95 = 0.61 m).
The same error is what the reported data show as the difference between the reported
velocity and the derivative of the reported position: ``d(pos_est)/dt - vel_est`` equals
``-(p_err - g) / T``, which follows ``-v_err`` low-passed by ``T``. The truth is available for
the docs and tests (:attr:`Estimator.pos_err_m`).

Injected estimator faults (``gcs mock --drift/--divergence/--jump``,
:class:`gcs.mock.config.Faults`) are further error processes of the same sum
(:class:`InjectedFault`), timed on the vehicle's clock from its first arming
(:meth:`InjectedFault.start_clock`). Each moves the estimated
*position* only; the estimated velocity stays the inertial one, as when the position source
(motion capture, GPS, an external-vision height) goes wrong while the IMU does not:

- :class:`PositionDrift`: the position error grows at a constant velocity for a while, then
  stays;
- :class:`PositionDivergence`: it grows at a growing rate (``a t^2 / 2``), then stays: the
  height divergence once seen on PX4 SITL, where EKF2's height went 480 m below ground while
  the vehicle climbed, is one along down;
- :class:`PositionJump`: it steps once and stays (a mis-solved motion-capture frame, an
  estimator reset).

PX4 flies on its estimate, and so does the mock: while the controller can, it holds the
*estimate* at the setpoint and the true vehicle moves the other way; the reported velocity (the
truth's) then shows a motion the reported position does not.

:class:`VisionAidedError` is EKF2 on external vision only (an indoor arena, no GPS,
``profiles/mock-mocap.yaml``): the estimate *is* the fused vision. Each vision sample (the
server hands over what arrived as ODOMETRY or VISION_POSITION_ESTIMATE) is given the time
``arrival - EKF2_EV_DELAY`` and compared with the estimate at that time (EKF2 fuses on a
delayed horizon); the innovation pulls the estimate towards the sample with the time constant
``vision.time_constant_s``, or is rejected beyond ``vision.innovation_gate_m``. The first
sample resets the estimate onto the vision. Without samples for ``2 EV_MAX_INTERVAL`` (0.4 s)
fusion stops ("vision data stopped"), the estimate dead-reckons (drifts with an accelerometer
error), and ``EKF2_NOAID_TOUT`` later (less the 1 s of ``no_aid_timeout_max`` plus the 0.4 s)
the local position is invalid: PX4 sends no LOCAL_POSITION_NED and its commander takes the
failsafe (:mod:`gcs.mock.vehicle`). Before the first sample there is no local position at all.
A wrong ``EKF2_EV_DELAY`` shows as PX4's: the estimate leads (or lags) the truth by the
velocity times the difference between the set and the true delay.

Plain floats and the standard library only: the mock steps this at 200 Hz in real time.
"""

from __future__ import annotations

import math
import random
from collections import deque
from collections.abc import Callable, Sequence
from typing import Protocol

from gcs.mock.config import EstimatorConfig, Faults, VisionConfig

__all__ = [
    "ErrorProcess",
    "AidedInertialError",
    "Estimator",
    "make_estimator",
    "ESTIMATOR_SEED_OFFSET",
    "InjectedFault",
    "PositionDrift",
    "PositionDivergence",
    "PositionJump",
    "injected_faults",
    "VisionAidedError",
    "EV_MAX_INTERVAL_S",
    "NO_AID_TIMEOUT_S",
    "VISION_SEED_OFFSET",
]

ESTIMATOR_SEED_OFFSET = 0xE571
"""The estimator's random stream is ``random.Random(seed + ESTIMATOR_SEED_OFFSET)``, apart from
the gusts' and the measurement noise's, so that the mock without an estimator is unchanged."""


VISION_SEED_OFFSET = 0x7151
"""The vision process draws its dead-reckoning direction from ``seed + VISION_SEED_OFFSET``."""
EV_MAX_INTERVAL_S = 0.2
"""EKF2's ``EV_MAX_INTERVAL``: fusion stops ``2 x`` this after the last vision sample [s]."""
NO_AID_TIMEOUT_S = 1.0
"""EKF2's ``no_aid_timeout_max``: a source fused this recently still counts as aiding [s]."""
_HISTORY_S = 1.0  # how far back a delayed sample can be compared [s]


class ErrorProcess(Protocol):
    """One source of navigation error. The :class:`Estimator` sums the processes' errors.

    ``pos_err_m``: position error (north, east, down) [m]: estimate minus truth. ``vel_err_m_s``:
    velocity error (north, east, down) [m/s]. ``resets``: number of resets so far (estimate snapped
    onto the aiding source).
    """

    pos_err_m: list[float]
    vel_err_m_s: list[float]
    resets: int

    def step(self, dt_s: float) -> None:
        """Advance the error by ``dt_s``.

        ``dt_s``: step [s].
        """


class _OrnsteinUhlenbeck:
    """Exact discretisation of a stationary Ornstein-Uhlenbeck process, started stationary."""

    def __init__(self, sigma: float, tau_s: float, gauss: Callable[[float, float], float]) -> None:
        self.sigma, self.tau_s = sigma, tau_s
        self._gauss = gauss
        self.x = sigma * gauss(0.0, 1.0) if sigma > 0 else 0.0
        self._dt = math.nan
        self._a = self._b = 0.0

    def step(self, dt_s: float) -> float:
        if self.sigma <= 0:
            return 0.0
        if dt_s != self._dt:
            self._dt = dt_s
            self._a = math.exp(-dt_s / self.tau_s)
            self._b = self.sigma * math.sqrt(1.0 - self._a * self._a)
        self.x = self._a * self.x + self._b * self._gauss(0.0, 1.0)
        return self.x


class AidedInertialError:
    """Error of an inertial solution aided by a wandering absolute position source (GPS).

    See the module docstring for the model. Each axis (north, east, down) has its own
    velocity-error sigma and correlation time and its own aiding-error sigma; the aiding
    error's correlation time and the aiding time constant are common.

    ``cfg``: sigmas, correlation times, aiding time constant and reset rate. ``rng``: the process's
    own random stream.
    """

    def __init__(self, cfg: EstimatorConfig, rng: random.Random) -> None:
        self.cfg = cfg
        self._rng = rng
        gauss = rng.gauss
        self._vel = [
            _OrnsteinUhlenbeck(s, tau, gauss)
            for s, tau in zip(cfg.vel_sigma_ned_m_s, cfg.vel_tau_ned_s, strict=True)
        ]
        self._aid = [_OrnsteinUhlenbeck(s, cfg.aid_tau_s, gauss) for s in cfg.aid_sigma_ned_m]
        self.vel_err_m_s = [p.x for p in self._vel]
        self.aid_err_m = [p.x for p in self._aid]
        # start in the pull's equilibrium: p_err - g = T v_err (slowly varying v_err)
        t_aid = cfg.aid_time_constant_s
        self.pos_err_m = [
            g + t_aid * v for g, v in zip(self.aid_err_m, self.vel_err_m_s, strict=True)
        ]
        self.resets = 0

    def step(self, dt_s: float) -> None:
        """Advance the velocity, aiding and position errors by ``dt_s``; maybe reset.

        ``dt_s``: step [s].
        """
        t_aid = self.cfg.aid_time_constant_s
        pos, vel, aid = self.pos_err_m, self.vel_err_m_s, self.aid_err_m
        for i in range(3):
            vel[i] = self._vel[i].step(dt_s)
            aid[i] = self._aid[i].step(dt_s)
            pos[i] += (vel[i] - (pos[i] - aid[i]) / t_aid) * dt_s
        rate = self.cfg.reset_rate_1_s
        if rate > 0 and self._rng.random() < rate * dt_s:
            self.reset()

    def reset(self) -> None:
        """Snap the position error onto the aiding source's (EKF2's position reset to GPS)."""
        for i in range(3):
            self.pos_err_m[i] = self.aid_err_m[i]
        self.resets += 1


class Estimator:
    """The vehicle's navigation solution: truth plus the sum of its error processes.

    ``processes``: the error sources; stepped in this order.
    """

    def __init__(self, processes: Sequence[ErrorProcess]) -> None:
        self.processes = list(processes)
        self.pos_err_m = [0.0, 0.0, 0.0]
        self.vel_err_m_s = [0.0, 0.0, 0.0]
        self._sum()

    def _sum(self) -> None:
        for i in range(3):
            self.pos_err_m[i] = sum(p.pos_err_m[i] for p in self.processes)
            self.vel_err_m_s[i] = sum(p.vel_err_m_s[i] for p in self.processes)

    @property
    def resets(self) -> int:
        """Resets of all processes so far."""
        return sum(p.resets for p in self.processes)

    def add(self, process: ErrorProcess) -> None:
        """Add one more error process to the sum."""
        self.processes.append(process)
        self._sum()

    def step(self, dt_s: float) -> None:
        """Advance every process by ``dt_s``.

        ``dt_s``: step [s].
        """
        for p in self.processes:
            p.step(dt_s)
        self._sum()

    def apply(
        self, pos_ned_m: Sequence[float], vel_ned_m_s: Sequence[float], out_pos: list[float],
        out_vel: list[float],
    ) -> None:  # fmt: skip
        """Write the estimate of a true state into ``out_pos`` and ``out_vel`` (in place).

        ``pos_ned_m``: true position (north, east, down) [m]. ``vel_ned_m_s``: true velocity [m/s].
        ``out_pos``: receives the estimated position [m]. ``out_vel``: receives the estimated
        velocity [m/s].
        """
        for i in range(3):
            out_pos[i] = pos_ned_m[i] + self.pos_err_m[i]
            out_vel[i] = vel_ned_m_s[i] + self.vel_err_m_s[i]


def make_estimator(cfg: EstimatorConfig, seed: int) -> Estimator | None:
    """The estimator a profile asks for, or None for a vehicle that flies on its true state.

    ``cfg``: the profile's ``estimator`` section. ``seed``: the run's seed (``--seed``); the
    estimator draws from ``seed + ESTIMATOR_SEED_OFFSET``.

    Returns: None when ``cfg.enabled`` is false: no random number is drawn.
    """
    if not cfg.enabled:
        return None
    rng = random.Random(seed + ESTIMATOR_SEED_OFFSET)
    return Estimator([AidedInertialError(cfg, rng)])


class InjectedFault:
    """An injected position error, timed from the vehicle's first arming (an ErrorProcess).

    ``start_s``: when it begins, after the first arming [s, vehicle time]. ``duration_s``: how long
    it grows [s]; afterwards the error stays as it is. None: for ever. ``vector``: its size per NED
    axis (unit by kind: m/s, m/s^2 or m).

    ``origin_s``: vehicle time of the first arming (None before it).
    """

    kind = "fault"

    def __init__(self, start_s: float, duration_s: float | None, vector: Sequence[float]) -> None:
        self.start_s, self.duration_s = float(start_s), duration_s
        self.vector = tuple(float(x) for x in vector)
        self.origin_s: float | None = None
        self.t_s = 0.0
        self.pos_err_m = [0.0, 0.0, 0.0]
        self.vel_err_m_s = [0.0, 0.0, 0.0]
        self.resets = 0

    def start_clock(self, t_s: float) -> None:
        """Start counting (the vehicle's first arming; later calls change nothing).

        ``t_s``: vehicle time [s].
        """
        if self.origin_s is None:
            self.origin_s = t_s

    @property
    def onset_s(self) -> float | None:
        """Vehicle time at which the fault begins (None before the first arming)."""
        return None if self.origin_s is None else self.origin_s + self.start_s

    def _size(self, elapsed_s: float) -> float:
        """Error per unit of ``vector`` after ``elapsed_s`` of growth."""
        raise NotImplementedError

    def step(self, dt_s: float) -> None:
        """Advance by ``dt_s``; the error follows the kind's law once the fault has begun.

        ``dt_s``: step [s].
        """
        self.t_s += dt_s
        onset = self.onset_s
        if onset is None or self.t_s < onset - 1e-9:
            return
        elapsed = self.t_s - onset
        if self.duration_s is not None:
            elapsed = min(elapsed, self.duration_s)
        k = self._size(elapsed)
        for i in range(3):
            self.pos_err_m[i] = k * self.vector[i]

    def record(self) -> dict[str, object]:
        """The fault for the statistics file.

        Returns: ``kind``, ``start_s``, ``duration_s``, ``vector``, ``onset_vehicle_s``.
        """
        return {
            "kind": self.kind,
            "start_s": self.start_s,
            "duration_s": self.duration_s,
            "vector": list(self.vector),
            "onset_vehicle_s": self.onset_s,
        }


class PositionDrift(InjectedFault):
    """The estimated position walks away at ``vector`` [m/s] for ``duration_s`` (see above)."""

    kind = "drift"

    def _size(self, elapsed_s: float) -> float:
        return elapsed_s


class PositionDivergence(InjectedFault):
    """The estimated position runs away as ``vector t^2 / 2`` ([m/s^2]) for ``duration_s``."""

    kind = "divergence"

    def _size(self, elapsed_s: float) -> float:
        return 0.5 * elapsed_s * elapsed_s


class PositionJump(InjectedFault):
    """The estimated position steps by ``vector`` [m] and stays."""

    kind = "jump"

    def _size(self, elapsed_s: float) -> float:
        return 1.0


def injected_faults(faults: Faults) -> list[InjectedFault]:
    """The estimator faults a run's :class:`Faults` ask for.

    ``faults``: the run's faults.

    Returns: drift, divergence and jump, those given; empty for none.
    """
    out: list[InjectedFault] = []
    if faults.drift_start_s is not None and faults.drift_ned_m_s is not None:
        out.append(
            PositionDrift(faults.drift_start_s, faults.drift_duration_s, faults.drift_ned_m_s)
        )
    if faults.divergence_start_s is not None and faults.divergence_ned_m_s2 is not None:
        out.append(
            PositionDivergence(
                faults.divergence_start_s, faults.divergence_duration_s, faults.divergence_ned_m_s2
            )
        )
    if faults.jump_at_s is not None and faults.jump_ned_m is not None:
        out.append(PositionJump(faults.jump_at_s, None, faults.jump_ned_m))
    return out


class VisionAidedError:
    """EKF2 on external vision only: the estimate is the fused vision (an ErrorProcess).

    See the module docstring for the model. The process keeps a short history of the truth
    and of its own error, so that a sample is compared with the estimate at its (delayed)
    sample time; :meth:`fuse` takes the samples, :meth:`xy_valid` says whether PX4 would
    report a local position.

    ``cfg``: time constant, gate, reset time and dead-reckoning error. ``true_pos_ned_m``: the
    physics' true position, read (never written) at every step. ``rng``: the process's own random
    stream (direction of the dead-reckoning error).

    ``fused``, ``rejected``, ``resets``: samples fused, samples rejected by the gate, resets onto
    the vision. ``last_sample_s``: vehicle time of the last sample's arrival, fused or rejected
    (None before the first). ``events``: what happened, for the commander to say (``"vision data
    stopped"``, ...).
    """

    def __init__(self, cfg: VisionConfig, true_pos_ned_m: list[float], rng: random.Random) -> None:
        self.cfg = cfg
        self._truth = true_pos_ned_m
        angle = rng.uniform(0.0, 2.0 * math.pi)
        a = cfg.dead_reckoning_accel_m_s2
        self._drift = (a * math.cos(angle), a * math.sin(angle), 0.0)
        self.pos_err_m = [0.0, 0.0, 0.0]
        self.vel_err_m_s = [0.0, 0.0, 0.0]
        self.resets = 0
        self.fused = 0
        self.rejected = 0
        self.t_s = 0.0
        self.fusing = False
        self.last_sample_s: float | None = None
        self._last_accept_s: float | None = None
        self._axes: tuple[bool, bool, bool] = (False, False, False)
        self._history: deque[tuple[float, tuple[float, ...], tuple[float, ...]]] = deque()
        self.events: list[str] = []

    def step(self, dt_s: float) -> None:
        """Advance by ``dt_s``: stop fusing after 0.4 s without samples, then dead-reckon.

        ``dt_s``: step [s].
        """
        self.t_s += dt_s
        if (
            self.fusing
            and self.last_sample_s is not None
            and self.t_s - self.last_sample_s > 2 * EV_MAX_INTERVAL_S
        ):
            self.fusing = False
            self.events.append("vision data stopped")
        if not self.fusing and self.last_sample_s is not None:
            for i in range(3):
                self.vel_err_m_s[i] += self._drift[i] * dt_s
                self.pos_err_m[i] += self.vel_err_m_s[i] * dt_s
        history = self._history
        history.append((self.t_s, tuple(self._truth), tuple(self.pos_err_m)))
        while history and history[0][0] < self.t_s - _HISTORY_S:
            history.popleft()

    def _at(self, t_s: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Truth and own error at ``t_s`` (the nearest recorded step not after it)."""
        if not self._history:
            return tuple(self._truth), tuple(self.pos_err_m)
        for t, truth, err in reversed(self._history):
            if t <= t_s + 1e-9:
                return truth, err
        _, truth, err = self._history[0]
        return truth, err

    def fuse(
        self,
        t_arrival_s: float,
        pos_ned_m: tuple[float, float, float],
        delay_s: float,
        ev_ctrl: int,
    ) -> bool:
        """Fuse one vision sample, as EKF2 would.

        ``t_arrival_s``: vehicle time the sample arrived [s] (the physics has been stepped to it).
        ``pos_ned_m``: the measured position, local NED [m]. ``delay_s``: ``EKF2_EV_DELAY`` [s]: the
        sample is compared with the estimate this long ago. ``ev_ctrl``: ``EKF2_EV_CTRL``: bit 0
        fuses the horizontal position, bit 1 the height.

        Returns True when the sample was fused (False: rejected by the gate, or nothing to fuse).
        """
        axes = (bool(ev_ctrl & 1), bool(ev_ctrl & 1), bool(ev_ctrl & 2))
        if not any(axes) or not all(math.isfinite(x) for x in pos_ned_m):
            return False
        truth, err = self._at(t_arrival_s - delay_s)
        if not self.fusing or axes != self._axes:
            self._reset(pos_ned_m, truth, axes)
            self.last_sample_s = self._last_accept_s = t_arrival_s
            return True
        innov = [pos_ned_m[i] - truth[i] - err[i] for i in range(3)]
        gate = self.cfg.innovation_gate_m
        if any(on and abs(v) > gate for on, v in zip(axes, innov, strict=True)):
            self.rejected += 1
            self.last_sample_s = t_arrival_s
            assert self._last_accept_s is not None
            if t_arrival_s - self._last_accept_s > self.cfg.reset_after_s:
                self._reset(pos_ned_m, truth, axes)
                self._last_accept_s = t_arrival_s
                self.events.append("vision position reset (innovations rejected)")
                return True
            return False
        dt = t_arrival_s - (self.last_sample_s or t_arrival_s)
        gain = 1.0 - math.exp(-max(dt, 0.0) / self.cfg.time_constant_s)
        for i in range(3):
            if axes[i]:
                self.pos_err_m[i] += gain * innov[i]
        self.fused += 1
        self.last_sample_s = self._last_accept_s = t_arrival_s
        return True

    def _reset(
        self, pos_ned_m: tuple[float, float, float], truth: tuple[float, ...],
        axes: tuple[bool, bool, bool],
    ) -> None:  # fmt: skip
        """Start (or restart) fusion: the estimate at the sample's time becomes the sample."""
        for i in range(3):
            if axes[i]:
                self.pos_err_m[i] = pos_ned_m[i] - truth[i]
            self.vel_err_m_s[i] = 0.0
        if not self.fusing:
            self.events.append("vision fusion started")
        self.fusing, self._axes = True, axes
        self.resets += 1
        self.fused += 1

    def xy_valid(self, t_s: float, noaid_timeout_s: float) -> bool:
        """Whether EKF2 would report a horizontal local position at ``t_s``.

        EKF2 counts the vision as aiding while its fusion is on and a sample was fused within
        ``no_aid_timeout_max`` (1 s); while aiding it keeps ``_time_last_horizontal_aiding`` at
        now less that 1 s, and declares the position invalid ``EKF2_NOAID_TOUT`` after it
        (``updateHorizontalDeadReckoningstatus``). The aiding ends when the fusion stops (last
        sample + 0.4 s: invalid at ``last sample + 0.4 s - 1 s + EKF2_NOAID_TOUT``) or 1 s
        after the last accepted sample while every sample is rejected (invalid at ``last
        accepted + EKF2_NOAID_TOUT``), whichever comes first. Never before the first sample.

        ``t_s``: vehicle time [s]. ``noaid_timeout_s``: ``EKF2_NOAID_TOUT`` [s].
        """
        if self.last_sample_s is None or self._last_accept_s is None or not self._axes[0]:
            return False
        aiding_end_s = self._last_accept_s + NO_AID_TIMEOUT_S
        if not self.fusing:
            aiding_end_s = min(aiding_end_s, self.last_sample_s + 2 * EV_MAX_INTERVAL_S)
        return t_s - (aiding_end_s - NO_AID_TIMEOUT_S) <= noaid_timeout_s
