"""The safety watches of a vehicle: what ends a flight, and the waits that notice it.

From the arm command to the disarmed state every position sample goes through an
:class:`gcs.flight.fence.EstimateMonitor` (:mod:`gcs.flight.fence`); what it names, and what any
other watch reports (:meth:`Watches.trip`, :meth:`Watches.add_watch`: a motion-capture stream's
health, say), is a *breach*: every wait, move, hold and trial of the flight layer raises it at
once as a :class:`gcs.errors.VehicleError` (or ``TrialAborted``), and the campaign stops the
vehicle (:meth:`gcs.flight.landing.Landing.emergency_stop`). Every wait is an event wait on the
state mirror (:mod:`gcs.flight.link`) with a timeout, never a fixed sleep.

:class:`Watches` is one part of :class:`gcs.flight.vehicle.Vehicle`, which sets its state.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable

from mavsdk.asyncio.plugins.telemetry import FlightMode

from gcs.errors import VehicleError
from gcs.flight.fence import EstimateMonitor, Fence
from gcs.flight.link import Link, TelemetrySample

__all__ = ["Watches"]

_log = logging.getLogger(__name__)


class Watches(Link):
    """The breach, its watches and the guarded waits of :class:`gcs.flight.vehicle.Vehicle`."""

    fence: Fence | None
    breach: str | None  # the first breach seen; ends the flight
    _monitor: EstimateMonitor | None
    _watches: list[tuple[str, Callable[[], str | None]]]

    def _check_sample(self, sample: TelemetrySample) -> None:
        """Give a position sample to the estimate monitor; a breach it names trips the flight."""
        if self._monitor is not None:
            problem = self._monitor.update(sample.t_vehicle_s, sample.pos_ned_m, sample.vel_ned_m_s)
            if problem is not None and self.fence_active:
                self.trip("fence", problem)

    @property
    def fence_active(self) -> bool:
        """Whether breaches count now: from the arm command until the vehicle is disarmed."""
        return self.armed or self._arm_requested

    def trip(self, source: str, reason: str) -> None:
        """Report a breach: the flight stops at once (the first one is kept).

        The entry point of every watch: the estimate monitor calls it for each sample that
        breaks the fence, a motion-capture health check would call it with its own reason. Call
        it on the event loop (from another thread: ``loop.call_soon_threadsafe``).

        Parameters
        ----------
        source : str
            What saw it, e.g. ``"fence"`` or ``"mocap"``.
        reason : str
            One line naming what was seen.
        """
        if self.breach is None:
            self.breach = f"{source}: {reason}"
            _log.info("breach: %s", self.breach)
            self._notify()

    def add_watch(self, source: str, problem: Callable[[], str | None]) -> None:
        """Watch one more condition while the vehicle is armed (polled at every check).

        Parameters
        ----------
        source : str
            Its name in the breach line, e.g. ``"mocap"``.
        problem : callable
            Returns None while all is well, else one line (e.g. a motion-capture client's
            ``problem``); called on the event loop at every state change, so it must be fast.
        """
        self._watches.append((source, problem))

    def safety_problem(self) -> str | None:
        """The breach that ends the flight, or None (see :meth:`trip`).

        Returns
        -------
        str or None
        """
        if self.breach is None and self.fence_active:
            for source, problem in self._watches:
                reason = problem()
                if reason is not None:
                    self.trip(source, reason)
                    break
        return self.breach

    def _require_inside(self, what: str) -> None:
        """Refuse to start ``what`` from a measured position outside the arena plus margin."""
        if self.fence is None or self.latest is None:
            return
        problem = self.fence.position_problem(self.latest.pos_ned_m)
        if problem is not None:
            raise VehicleError(f"fence: {problem}; not {what}")

    def control_problem(self) -> str | None:
        """Why the vehicle is not under our offboard control right now, or None if it is.

        Returns
        -------
        str or None
            A breach (:meth:`safety_problem`), "link lost", a flight mode other than OFFBOARD,
            or stale position telemetry (older than ``settings.max_telemetry_age_s``).
        """
        breach = self.safety_problem()
        if breach is not None:
            return breach
        if not self.connected:
            return "link lost (no heartbeat for 3 s)"
        if self.flight_mode != FlightMode.OFFBOARD:
            return f"flight mode is {self.flight_mode.name}, not OFFBOARD"
        age_s = self.telemetry_age_s()
        if age_s > self.settings.max_telemetry_age_s:
            return f"position telemetry stale ({age_s:.2f} s old)"
        return None

    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
        """Wait (on the vehicle's state-change events, at least every telemetry-age limit)
        until ``predicate()`` holds, on the ground (a breach or a lost link ends it).

        Parameters
        ----------
        predicate : callable
            Checked on every state change.
        timeout_s : float
            Limit [s].
        what : str
            Named in the timeout's message.

        Raises
        ------
        VehicleError
            Not within ``timeout_s``, link lost, or a breach.
        """
        await self._wait_until(predicate, timeout_s, what, in_control=False)

    async def _wait_until(
        self,
        predicate: Callable[[], bool],
        timeout_s: float,
        what: str,
        *,
        in_control: bool,
        stopping: bool = False,
    ) -> None:
        """Wait (on state-change events) until ``predicate()`` holds.

        Raises :class:`_WaitTimeout` (a VehicleError) on timeout, VehicleError on link loss,
        on a breach (unless ``stopping``: the emergency stop itself) and, with ``in_control``,
        on any :meth:`control_problem`.
        """
        clock = self.local_clock
        deadline_s = clock.now() + timeout_s
        while True:
            # problems first: a breach seen with the sample that also ends the wait ends it
            problem = self.control_problem() if in_control else None
            if problem is None and not stopping:
                problem = self.safety_problem()
            if problem is not None:
                raise VehicleError(f"{problem} while waiting for {what}")
            if predicate():
                return
            if not self.connected:
                raise VehicleError(f"link lost (no heartbeat for 3 s) while waiting for {what}")
            remaining_s = deadline_s - clock.now()
            if remaining_s <= 0:
                raise _WaitTimeout(f"{what} did not happen within {timeout_s:g} s")
            # Wake up at least at the telemetry-age limit so that silence is noticed.
            changed = self._changed
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(min(remaining_s, self.settings.max_telemetry_age_s)):
                    await changed.wait()


class _WaitTimeout(VehicleError):
    """A wait of :meth:`Vehicle._wait_until` ran out of time (control was not lost)."""
