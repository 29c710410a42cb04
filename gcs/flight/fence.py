"""The arena as a live fence: what may be sent, and when what is measured ends a flight (pure).

Two rules, both on the profile's arena (a box in local NED):

- **Setpoints.** Every position setpoint gcs sends lies inside the arena itself
  (:meth:`Fence.setpoint_problem`); :meth:`gcs.flight.vehicle.Vehicle.send_setpoint` refuses any
  other, for every caller. Where gcs must start from the measured position (the hover setpoint
  that precedes OFFBOARD), it takes the nearest point of the arena (:meth:`Fence.clamp`).
- **Measurements.** While the vehicle is armed, :class:`EstimateMonitor` watches every position
  sample the vehicle reports and names the first of:

  - *outside*: the position is further than ``margin_m`` outside the arena;
  - *speed*: the horizontal speed is above ``max_speed_xy_m_s`` or the vertical one above
    ``max_speed_z_m_s`` (the profile's vehicle limits times ``fence_speed_factor``);
  - *jump*: between two consecutive samples the position moved further from what its velocity
    says than ``jump_m`` (plus what an acceleration of :data:`MAX_ACCEL_M_S2` could add over a
    gap);
  - *drift*: over the last :data:`DRIFT_WINDOW_S` the position moved more than ``drift_m``
    against the integral of the velocity: the estimate contradicts itself.

  A sample that both leaves the arena and jumps names both (an estimate reset to a position
  outside: the vehicle may be where it was, its frame is not).

A measurement that breaks one of these is a *breach*: the flight layer stops at once (Hold,
land; :meth:`gcs.flight.vehicle.Vehicle.trip`). The thresholds are set from the shared PX4 SITL
data (GPS and vision) and the mock-gps profile, so that a vehicle that is merely poor is never
stopped; ``benchmarks/fence_thresholds.py`` prints the evidence and docs/flight.md ("Fence")
the figures.

The arena is uploaded to the autopilot as its geofence (:func:`fence_polygon`) through PX4's
own map projection (:func:`gcs.core.frames.ned_to_global`).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from gcs.core.frames import ned_to_global
from gcs.io.settings import FlightSettings

__all__ = [
    "Fence",
    "EstimateMonitor",
    "fence_polygon",
    "MAX_ACCEL_M_S2",
    "DRIFT_WINDOW_S",
    "DRIFT_MAX_STEP_S",
    "SETPOINT_TOLERANCE_M",
]

MAX_ACCEL_M_S2 = 20.0
"""Largest acceleration a multirotor can have [m/s^2] (about 2 g of thrust): what physics lets
the position move beyond its velocity over a telemetry gap, ``MAX_ACCEL_M_S2 dt^2 / 2``."""
DRIFT_WINDOW_S = 1.0
"""Window of the position-against-velocity check [s, vehicle time]."""
DRIFT_MAX_STEP_S = 0.25
"""Steps between samples longer than this are gaps: only the jump check looks at them [s]."""
SETPOINT_TOLERANCE_M = 1e-6
"""A setpoint may lie this far outside the arena (rounding of a solver's box constraint) [m]."""


def _ned(x: Any) -> np.ndarray:
    v = np.asarray(x, dtype=float).reshape(-1)
    if v.shape != (3,):
        raise ValueError(f"expected a NED point of 3 values, got shape {np.shape(x)}")
    return v


def format_ned(ned_m: np.ndarray) -> str:
    """A local NED position for a message: ``NED (n, e, d) m`` to the centimetre.

    ``ned_m``: north, east, down [m].
    """
    return "NED (" + ", ".join(f"{x:.2f}" for x in ned_m) + ") m"


@dataclass(frozen=True)
class Fence:
    """The arena and the limits a flight is watched against.

    ``arena_ned_m``: the arena box per NED axis [m]: setpoints lie inside it. ``margin_m``: how far
    outside the arena a measured position may be before the flight is stopped [m]
    (``flight.fence_margin_m``). ``max_speed_xy_m_s``: largest horizontal speed measured before the
    flight is stopped [m/s]. ``max_speed_z_m_s``: largest vertical speed (up or down) measured
    before the flight is stopped [m/s]. ``jump_m``: largest step of the position between two samples
    beyond what its velocity explains [m] (``flight.fence_jump_m``). ``drift_m``: largest movement
    of the position against the integral of its velocity within :data:`DRIFT_WINDOW_S` [m]
    (``flight.fence_drift_m``).
    """

    arena_ned_m: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    margin_m: float
    max_speed_xy_m_s: float
    max_speed_z_m_s: float
    jump_m: float
    drift_m: float

    def __post_init__(self) -> None:
        b = np.asarray(self.arena_ned_m, dtype=float)
        if b.shape != (3, 2) or not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
            raise ValueError(f"arena_ned_m must be 3 (min, max) pairs with min < max, got {b}")
        for name in ("margin_m", "max_speed_xy_m_s", "max_speed_z_m_s", "jump_m", "drift_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"fence {name} must be finite and positive, got {value}")

    @classmethod
    def around(
        cls,
        arena_ned_m: Any,
        settings: FlightSettings,
        max_speed_m_s: float,
        max_vertical_speed_m_s: float,
    ) -> Fence:
        """The fence of an arena with a profile's vehicle limits and flight settings.

        ``arena_ned_m``: (min, max) per NED axis [m]. ``settings``: ``fence_margin_m``,
        ``fence_speed_factor``, ``fence_jump_m``, ``fence_drift_m``. ``max_speed_m_s``: the
        vehicle's horizontal speed limit (profile ``vehicle.max_speed_m_s``) [m/s].
        ``max_vertical_speed_m_s``: the vehicle's vertical speed limit
        (``vehicle.max_vertical_speed_m_s``) [m/s].
        """
        b = np.asarray(arena_ned_m, dtype=float)
        if b.shape != (3, 2):  # a (2, 3) array read as pairs would be another box
            raise ValueError(f"arena_ned_m must have shape (3, 2), got {b.shape}")
        pairs = tuple((float(lo), float(hi)) for lo, hi in b)
        return cls(
            arena_ned_m=pairs,  # type: ignore[arg-type]
            margin_m=settings.fence_margin_m,
            max_speed_xy_m_s=settings.fence_speed_factor * max_speed_m_s,
            max_speed_z_m_s=settings.fence_speed_factor * max_vertical_speed_m_s,
            jump_m=settings.fence_jump_m,
            drift_m=settings.fence_drift_m,
        )

    @property
    def bounds(self) -> np.ndarray:
        """The arena, shape (3, 2): (min, max) per NED axis [m]."""
        return np.asarray(self.arena_ned_m, dtype=float)

    def outside_by(self, pos_ned_m: Any, *, floor: bool = True) -> float:
        """How far a point lies outside the arena (0 inside) [m], the largest axis.

        ``pos_ned_m``: local NED [m]. ``floor``: False leaves out the arena's floor (its largest
        down): a point below it counts as inside.
        """
        p, b = _ned(pos_ned_m), self.bounds
        if not floor:
            b[2, 1] = np.inf
        return float(max(0.0, np.max(b[:, 0] - p), np.max(p - b[:, 1])))

    def setpoint_problem(self, pos_ned_m: Any) -> str | None:
        """Why a setpoint may not be sent (outside the arena, or not finite), or None.

        ``pos_ned_m``: setpoint, local NED [m].
        """
        p = _ned(pos_ned_m)
        if not np.all(np.isfinite(p)):
            return f"setpoint {p.tolist()} is not finite"
        out = self.outside_by(p)
        if out > SETPOINT_TOLERANCE_M:
            return f"setpoint {format_ned(p)} is {out:.2f} m outside the arena {self.arena_text()}"
        return None

    def setpoints_problem(self, setpoints_ned_m: Any) -> str | None:
        """Why a sequence may not be flown (its first setpoint outside the arena), or None.

        ``setpoints_ned_m``: local NED [m].
        """
        sp = np.asarray(setpoints_ned_m, dtype=float).reshape(-1, 3)
        b = self.bounds
        bad = ~np.isfinite(sp).all(axis=1)
        tol = SETPOINT_TOLERANCE_M
        bad |= np.any((sp < b[:, 0] - tol) | (sp > b[:, 1] + tol), axis=1)
        if not bad.any():
            return None
        k = int(np.flatnonzero(bad)[0])
        return f"setpoint k = {k}: {self.setpoint_problem(sp[k])}"

    def position_problem(self, pos_ned_m: Any, *, floor: bool = True) -> str | None:
        """Why a measured position ends the flight (beyond the arena plus margin), or None.

        ``pos_ned_m``: measured position, local NED [m]. ``floor``: False leaves out the
        arena's floor (while PX4 lands, see :meth:`EstimateMonitor.update`).
        """
        p = _ned(pos_ned_m)
        out = self.outside_by(p, floor=floor)
        if out > self.margin_m or not np.all(np.isfinite(p)):
            return (
                f"the measured position {format_ned(p)} is {out:.2f} m outside the arena "
                f"{self.arena_text()} (margin {self.margin_m:g} m)"
            )
        return None

    def clamp(self, pos_ned_m: Any) -> np.ndarray:
        """The point of the arena nearest to a position.

        ``pos_ned_m``: local NED [m].
        """
        b = self.bounds
        return np.clip(_ned(pos_ned_m), b[:, 0], b[:, 1])

    def arena_text(self) -> str:
        """The arena as ``N [-3, 3] E [-3, 3] D [-3, 0] m``."""
        pairs = zip("NED", self.bounds, strict=True)
        return " ".join(f"{a} [{lo:g}, {hi:g}]" for a, (lo, hi) in pairs) + " m"

    def describe(self) -> str:
        """One line for the operator: what is watched and the limits."""
        return (
            f"fence: arena {self.arena_text()}, {self.margin_m:g} m margin, watched from arming "
            f"to disarming; stops at {self.max_speed_xy_m_s:.2f} m/s horizontally, "
            f"{self.max_speed_z_m_s:.2f} m/s vertically, a position jump of {self.jump_m:g} m, "
            f"or {self.drift_m:g} m of position against velocity within {DRIFT_WINDOW_S:g} s"
        )


class EstimateMonitor:
    """Watches the reported position and velocity sample by sample (see the module docstring).

    ``peaks``: the largest value of each statistic seen so far: ``outside_m`` (beyond the arena),
    ``speed_xy_m_s``, ``speed_z_m_s``, ``jump_m`` (step beyond the velocity, less what physics
    allows over a gap), ``drift_m`` (over the window); the thresholds' evidence.
    """

    def __init__(self, fence: Fence) -> None:
        self.fence = fence
        #: deepest estimate below the arena's floor while landing [m] (0: none)
        self.below_floor_landing_m = 0.0
        self._last: tuple[float, np.ndarray, np.ndarray] | None = None
        self._window: deque[tuple[float, np.ndarray]] = deque()
        self._sum = np.zeros(3)
        self.peaks = dict.fromkeys(
            ("outside_m", "speed_xy_m_s", "speed_z_m_s", "jump_m", "drift_m"), 0.0
        )

    def _peak(self, key: str, value: float) -> None:
        if value > self.peaks[key]:
            self.peaks[key] = value

    def update(
        self, t_vehicle_s: float, pos_ned_m: Any, vel_ned_m_s: Any, *, landing: bool = False
    ) -> str | None:
        """Take one sample; return what it breaks, or None.

        Samples older than the last one taken are ignored (a reordered datagram).

        ``t_vehicle_s``: the sample's vehicle time [s]. ``pos_ned_m``: reported position, local NED
        [m]. ``vel_ned_m_s``: reported velocity, local NED [m/s]. ``landing``: PX4 is landing
        on gcs's command. Then an estimate below the arena's floor is no breach (every other
        limit still is): PX4's Land descends on its vertical velocity and stops on ground
        contact whatever the position says, and the vehicle cannot be below the ground, so
        such a reading is the estimate's height drifting (seen on PX4 SITL on GPS: 1.5 m below
        the ground in the 10 s its land detector took), and the breach's answer, land, is what
        is happening. Under position control the same reading would make the vehicle climb,
        hence a breach in every other phase. The deepest such reading is kept
        (:attr:`below_floor_landing_m`).
        """
        p, v = _ned(pos_ned_m), _ned(vel_ned_m_s)
        last = self._last
        if last is not None and t_vehicle_s <= last[0]:
            return None
        self._last = (t_vehicle_s, p, v)
        self._peak("outside_m", self.fence.outside_by(p))
        if landing:
            below_m = float(p[2] - self.fence.bounds[2, 1])
            self.below_floor_landing_m = max(self.below_floor_landing_m, below_m)
        problem = self.fence.position_problem(p, floor=not landing) or self._speed_problem(v)
        if last is None:
            return problem
        dt = t_vehicle_s - last[0]
        residual = p - last[1] - 0.5 * (v + last[2]) * dt
        jump = self._jump_problem(residual, dt)
        if problem and jump:  # an estimate's reset that left the arena: both say what happened
            return f"{problem}, after {jump}"
        return problem or jump or self._drift_problem(t_vehicle_s, residual, dt)

    def _speed_problem(self, v: np.ndarray) -> str | None:
        f = self.fence
        xy, z = math.hypot(v[0], v[1]), abs(v[2])
        self._peak("speed_xy_m_s", xy)
        self._peak("speed_z_m_s", z)
        if xy > f.max_speed_xy_m_s:
            return f"horizontal speed {xy:.2f} m/s, above {f.max_speed_xy_m_s:.2f} m/s"
        if z > f.max_speed_z_m_s:
            way = "climbing" if v[2] < 0 else "descending"
            return f"{way} at {z:.2f} m/s, above {f.max_speed_z_m_s:.2f} m/s"
        return None

    def _jump_problem(self, residual: np.ndarray, dt: float) -> str | None:
        step = float(np.linalg.norm(residual))
        gap_m = 0.5 * MAX_ACCEL_M_S2 * dt * dt  # what physics allows over the step
        self._peak("jump_m", step - gap_m)
        allowed = self.fence.jump_m + gap_m
        if step > allowed:
            return (
                f"the position jumped {step:.2f} m beyond its velocity in {dt:.3f} s "
                f"(limit {allowed:.2f} m)"
            )
        return None

    def _drift_problem(self, t: float, residual: np.ndarray, dt: float) -> str | None:
        if dt > DRIFT_MAX_STEP_S:  # a gap: the sum starts again after it
            self._window.clear()
            self._sum = np.zeros(3)
            return None
        self._window.append((t, residual))
        self._sum = self._sum + residual
        while self._window and self._window[0][0] <= t - DRIFT_WINDOW_S:
            self._sum = self._sum - self._window.popleft()[1]
        moved = float(np.linalg.norm(self._sum))
        self._peak("drift_m", moved)
        if moved > self.fence.drift_m:
            return (
                f"the position moved {moved:.2f} m against its velocity within "
                f"{DRIFT_WINDOW_S:g} s (limit {self.fence.drift_m:g} m): the estimate "
                "contradicts itself"
            )
        return None


def fence_polygon(fence: Fence, lat0_deg: float, lon0_deg: float) -> list[tuple[float, float]]:
    """The arena plus margin, horizontally, as latitude/longitude vertices around the origin.

    ``lat0_deg``, ``lon0_deg``: the local frame's origin [deg] (PX4's GPS_GLOBAL_ORIGIN).

    Returns: four vertices (lat, lon) [deg], counter-clockwise seen from above: the corners (N min,
    E min), (N min, E max), (N max, E max), (N max, E min).
    """
    (n0, n1), (e0, e1) = (
        (lo - fence.margin_m, hi + fence.margin_m) for lo, hi in fence.arena_ned_m[:2]
    )
    corners = ((n0, e0), (n0, e1), (n1, e1), (n1, e0))
    return [ned_to_global(lat0_deg, lon0_deg, n, e) for n, e in corners]
