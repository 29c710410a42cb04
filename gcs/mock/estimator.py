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
  height divergence of issue P7, where EKF2's height went 480 m below ground while the vehicle
  climbed, is one along down;
- :class:`PositionJump`: it steps once and stays (a mis-solved motion-capture frame, an
  estimator reset).

PX4 flies on its estimate, and so does the mock: while the controller can, it holds the
*estimate* at the setpoint and the true vehicle moves the other way; the reported velocity (the
truth's) then shows a motion the reported position does not.

Plain floats and the standard library only: the mock steps this at 200 Hz in real time.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Sequence
from typing import Protocol

from gcs.mock.config import EstimatorConfig, Faults

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
]

ESTIMATOR_SEED_OFFSET = 0xE571
"""The estimator's random stream is ``random.Random(seed + ESTIMATOR_SEED_OFFSET)``, apart from
the gusts' and the measurement noise's, so that the mock without an estimator is unchanged."""


class ErrorProcess(Protocol):
    """One source of navigation error. The :class:`Estimator` sums the processes' errors.

    Attributes
    ----------
    pos_err_m : list of float
        Position error (north, east, down) [m]: estimate minus truth.
    vel_err_m_s : list of float
        Velocity error (north, east, down) [m/s].
    resets : int
        Number of resets so far (estimate snapped onto the aiding source).
    """

    pos_err_m: list[float]
    vel_err_m_s: list[float]
    resets: int

    def step(self, dt_s: float) -> None:
        """Advance the error by ``dt_s``.

        Parameters
        ----------
        dt_s : float
            Step [s].
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

    Parameters
    ----------
    cfg : EstimatorConfig
        Sigmas, correlation times, aiding time constant and reset rate.
    rng : random.Random
        The process's own random stream.
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

        Parameters
        ----------
        dt_s : float
            Step [s].
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

    Parameters
    ----------
    processes : sequence of ErrorProcess
        The error sources; stepped in this order.
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
        """Add one more error process to the sum.

        Parameters
        ----------
        process : ErrorProcess
            Stepped after the others.
        """
        self.processes.append(process)
        self._sum()

    def step(self, dt_s: float) -> None:
        """Advance every process by ``dt_s``.

        Parameters
        ----------
        dt_s : float
            Step [s].
        """
        for p in self.processes:
            p.step(dt_s)
        self._sum()

    def apply(
        self, pos_ned_m: Sequence[float], vel_ned_m_s: Sequence[float], out_pos: list[float],
        out_vel: list[float],
    ) -> None:  # fmt: skip
        """Write the estimate of a true state into ``out_pos`` and ``out_vel`` (in place).

        Parameters
        ----------
        pos_ned_m : sequence of float
            True position (north, east, down) [m].
        vel_ned_m_s : sequence of float
            True velocity [m/s].
        out_pos : list of float
            Receives the estimated position [m].
        out_vel : list of float
            Receives the estimated velocity [m/s].
        """
        for i in range(3):
            out_pos[i] = pos_ned_m[i] + self.pos_err_m[i]
            out_vel[i] = vel_ned_m_s[i] + self.vel_err_m_s[i]


def make_estimator(cfg: EstimatorConfig, seed: int) -> Estimator | None:
    """The estimator a profile asks for, or None for a vehicle that flies on its true state.

    Parameters
    ----------
    cfg : EstimatorConfig
        The profile's ``estimator`` section.
    seed : int
        The run's seed (``--seed``); the estimator draws from ``seed + ESTIMATOR_SEED_OFFSET``.

    Returns
    -------
    Estimator or None
        None when ``cfg.enabled`` is false: no random number is drawn.
    """
    if not cfg.enabled:
        return None
    rng = random.Random(seed + ESTIMATOR_SEED_OFFSET)
    return Estimator([AidedInertialError(cfg, rng)])


class InjectedFault:
    """An injected position error, timed from the vehicle's first arming (an ErrorProcess).

    Parameters
    ----------
    start_s : float
        When it begins, after the first arming [s, vehicle time].
    duration_s : float or None
        How long it grows [s]; afterwards the error stays as it is. None: for ever.
    vector : tuple of float
        Its size per NED axis (unit by kind: m/s, m/s^2 or m).

    Attributes
    ----------
    origin_s : float or None
        Vehicle time of the first arming (None before it).
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

        Parameters
        ----------
        t_s : float
            Vehicle time [s].
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

        Parameters
        ----------
        dt_s : float
            Step [s].
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

        Returns
        -------
        dict
            ``kind``, ``start_s``, ``duration_s``, ``vector``, ``onset_vehicle_s``.
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

    Parameters
    ----------
    faults : Faults
        The run's faults.

    Returns
    -------
    list of InjectedFault
        Drift, divergence and jump, those given; empty for none.
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
