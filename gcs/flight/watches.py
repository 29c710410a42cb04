"""The safety watches of a vehicle: what ends a flight, and the waits that notice it.

From the arm command to the disarmed state every position sample goes through an
:class:`gcs.flight.fence.EstimateMonitor` (:mod:`gcs.flight.fence`); what it names, and what any
other watch reports (:meth:`Watches.trip`, :meth:`Watches.add_watch`: a motion-capture stream's
health, say), is a *breach*: every wait, move, hold and trial of the flight layer raises it at
once as a :class:`gcs.errors.VehicleError` (or ``TrialAborted``), and the campaign stops the
vehicle (:meth:`gcs.flight.landing.Landing.emergency_stop`). Every wait is an event wait on the
state mirror (:class:`gcs.flight.link.Link`) with a timeout, never a fixed sleep.

:class:`Watches` is one part of :class:`gcs.flight.vehicle.Vehicle`: it reads the state mirror
and owns the breach; the mirror hands it each position sample (:meth:`Watches.check_sample`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from mavsdk.asyncio.plugins.telemetry import FlightMode

from gcs.errors import VehicleError
from gcs.flight.fence import EstimateMonitor, Fence
from gcs.flight.link import Link, TelemetrySample
from gcs.io.settings import FlightSettings

__all__ = ["WaitTimeout", "Watches"]

_log = logging.getLogger(__name__)


class Watches:
    """The breach, its watches and the guarded waits of :class:`gcs.flight.vehicle.Vehicle`.

    Parameters
    ----------
    mirror : Link
        The connection and its state mirror (read, and woken on a breach).
    settings : FlightSettings
        The telemetry-age limit.
    fence : Fence or None
        The arena and the limits watched while armed; None: no estimate monitor.
    """

    def __init__(self, mirror: Link, settings: FlightSettings, fence: Fence | None) -> None:
        self._mirror = mirror
        self.settings = settings
        self.fence = fence
        self.breach: str | None = None  # the first breach seen; ends the flight
        #: PX4 is landing on our command: the estimate monitor leaves out the arena's floor
        #: (:meth:`gcs.flight.fence.EstimateMonitor.update` says why)
        self.landing = False
        self._monitor = EstimateMonitor(fence) if fence is not None else None
        self._watches: list[tuple[str, Callable[[], str | None]]] = []

    def check_sample(self, sample: TelemetrySample) -> None:
        """Give a position sample to the estimate monitor; a breach it names trips the flight.

        Parameters
        ----------
        sample : TelemetrySample
            As received (before the mirror keeps it).
        """
        if self._monitor is not None:
            problem = self._monitor.update(
                sample.t_vehicle_s, sample.pos_ned_m, sample.vel_ned_m_s, landing=self.landing
            )
            if problem is not None and self.fence_active:
                self.trip("fence", problem)

    @property
    def below_floor_landing_m(self) -> float:
        """Deepest estimate below the arena's floor while landing [m] (0: none, no fence)."""
        return 0.0 if self._monitor is None else self._monitor.below_floor_landing_m

    @property
    def fence_active(self) -> bool:
        """Whether breaches count now: from the arm command until the vehicle is disarmed."""
        return self._mirror.armed or self._mirror.arm_requested

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
            self._mirror.notify()

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

    def require_inside(self, what: str) -> None:
        """Refuse to start ``what`` from a measured position outside the arena plus margin.

        Parameters
        ----------
        what : str
            What would start, for the error's line (``"arming"``).

        Raises
        ------
        VehicleError
            The latest position is outside the arena plus its margin.
        """
        latest = self._mirror.latest
        if self.fence is None or latest is None:
            return
        problem = self.fence.position_problem(latest.pos_ned_m)
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
        mirror = self._mirror
        if not mirror.connected:
            return "link lost (no heartbeat for 3 s)"
        if mirror.flight_mode != FlightMode.OFFBOARD:
            return f"flight mode is {mirror.flight_mode.name}, not OFFBOARD"
        age_s = mirror.telemetry_age_s()
        if age_s > self.settings.max_telemetry_age_s:
            return f"position telemetry stale ({age_s:.2f} s old)"
        return None

    async def wait_until(
        self,
        predicate: Callable[[], bool],
        timeout_s: float,
        what: str,
        *,
        in_control: bool = False,
        stopping: bool = False,
    ) -> None:
        """Wait (on the mirror's state-change events, at least every telemetry-age limit) until
        ``predicate()`` holds; a breach or a lost link ends it.

        Parameters
        ----------
        predicate : callable
            Checked on every state change.
        timeout_s : float
            Limit [s].
        what : str
            Named in the timeout's message.
        in_control : bool
            Also end on any :meth:`control_problem` (offboard lost, stale telemetry).
        stopping : bool
            The emergency stop's own waits: a breach does not end them.

        Raises
        ------
        WaitTimeout
            Not within ``timeout_s`` (a VehicleError; control was not lost).
        VehicleError
            Link lost, a breach (unless ``stopping``), or with ``in_control`` a control problem.
        """
        mirror = self._mirror
        clock = mirror.local_clock
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
            if not mirror.connected:
                raise VehicleError(f"link lost (no heartbeat for 3 s) while waiting for {what}")
            remaining_s = deadline_s - clock.now()
            if remaining_s <= 0:
                raise WaitTimeout(f"{what} did not happen within {timeout_s:g} s")
            # Wake up at least at the telemetry-age limit so that silence is noticed.
            await mirror.wait_change(min(remaining_s, self.settings.max_telemetry_age_s))


class WaitTimeout(VehicleError):
    """A wait of :meth:`Watches.wait_until` ran out of time (control was not lost)."""
