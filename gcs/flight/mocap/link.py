"""The motion capture of a flight: one stream read, forwarded, watched and cut into trials.

:class:`MocapLink` owns the :class:`~gcs.flight.mocap.client.MocapClient` of the flight and,
once a vehicle is connected, the :class:`~gcs.flight.mocap.forward.VisionForwarder` that feeds
it (in the client's thread: never on the event loop). The campaign asks it:

- :meth:`MocapLink.problem`: the stream's health now (stale, occluded, frozen, jump, or the
  reader ended), the watch it adds to the vehicle (:meth:`gcs.flight.vehicle.Vehicle.add_watch`)
  so that a bad stream aborts like a fence breach;
- :meth:`MocapLink.latest_ned`: where the mocap sees the vehicle (pre-flight agreement and the
  move checks);
- :meth:`MocapLink.start_journal` and :meth:`MocapLink.drain`: the raw samples from a trial's
  start (and the :attr:`MocapLink.max_gap_s` before it) to its end (one trial's raw file;
  nothing else is kept between trials).

:func:`trial_mocap` puts a trial's raw samples on the trial's grid (vehicle time, through the
trial's own clock fit) and measures how far the vehicle's estimate lags behind.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from gcs.core.frames import FrameMapping
from gcs.errors import MocapError
from gcs.flight.mocap.client import MocapClient, MocapSample, series_of
from gcs.flight.mocap.forward import VisionForwarder
from gcs.flight.mocap.health import HealthLimits, stream_problem
from gcs.flight.mocap.latency import estimate_lag_s
from gcs.flight.trial import TrialRecording, align_to_grid
from gcs.io.mocap_samples import MocapSeries, MocapTrial
from gcs.io.mocap_source import MocapSource
from gcs.io.settings import MocapSettings

__all__ = ["MocapLink", "trial_mocap", "HEALTH_WINDOW_S", "GRID_MAX_GAP_S"]

HEALTH_WINDOW_S = 0.5
"""The samples the health checks judge [s]."""
GRID_MAX_GAP_S = 0.1
"""A grid point between tracked samples further apart than this gets no mocap value [s]."""


class MocapLink:
    """One rigid body read, forwarded to a vehicle and watched, for one flight.

    Parameters
    ----------
    source : MocapSource
        System, server and rigid body.
    mapping : FrameMapping
        System axes to NED.
    settings : MocapSettings
        Forwarding and checks.
    limits : HealthLimits or None
        Stream health thresholds; None: the defaults, with ``settings.max_age_s``.
    connect_timeout_s : float
        How long to wait for the mocap server [s].
    """

    def __init__(
        self,
        source: MocapSource,
        mapping: FrameMapping,
        settings: MocapSettings,
        limits: HealthLimits | None = None,
        connect_timeout_s: float = 5.0,
    ) -> None:
        self.source = source
        self.mapping = mapping
        self.settings = settings
        self.limits = limits or HealthLimits(max_age_s=settings.max_age_s)
        self.client = MocapClient(
            source, on_sample=self._on_sample, connect_timeout_s=connect_timeout_s
        )
        self.forwarder: VisionForwarder | None = None

    def _on_sample(self, sample: MocapSample) -> None:
        forwarder = self.forwarder
        if forwarder is not None:
            forwarder.send(sample)

    # lifecycle ------------------------------------------------------------------------------

    def start(self) -> MocapLink:
        """Connect to the mocap server and wait for the stream.

        Returns
        -------
        MocapLink
            self

        Raises
        ------
        MocapError
            The server did not answer, or refused.
        """
        self.client.start()
        return self

    def stop(self) -> None:
        """Stop forwarding and reading (idempotent)."""
        self.detach()
        self.client.stop()

    def __enter__(self) -> MocapLink:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def attach(self, plugin: object) -> None:
        """Start forwarding to a vehicle (when the settings say so).

        Parameters
        ----------
        plugin : object
            The vehicle's blocking MAVSDK Mocap plugin
            (:meth:`gcs.flight.vehicle.Vehicle.mocap_plugin`).
        """
        if self.settings.forward:
            self.forwarder = VisionForwarder(
                plugin,
                self.mapping,
                self.settings.message,
                self.settings.position_std_m,
                math.radians(self.settings.angle_std_deg),
            )

    def detach(self) -> None:
        """Stop forwarding; waits for a send in progress (before the vehicle is closed)."""
        forwarder = self.forwarder
        if forwarder is not None:
            forwarder.stop()

    # what the campaign asks ----------------------------------------------------------------

    def problem(self) -> str | None:
        """The stream's problem now, or None (a watch for ``Vehicle.add_watch``).

        Returns
        -------
        str or None
        """
        ended = self.client.problem()
        if ended is not None:
            return ended
        now = time.monotonic()
        series = self.client.recent(HEALTH_WINDOW_S, now)
        if len(series) == 0 and (latest := self.client.latest()) is not None:
            # no frame in the window: the newest one says how stale the stream is, judged
            # against the profile's max_age_s (which may exceed the window)
            series = series_of([latest])
        return stream_problem(series, now, self.limits)

    @property
    def max_gap_s(self) -> float:
        """The longest gap between tracked samples the watch lets a trial fly through [s]:
        no frames for up to ``max_age_s``, or the body untracked for up to ``max_occluded_s``."""
        return max(self.limits.max_age_s, self.limits.max_occluded_s)

    def latest_ned(self) -> np.ndarray | None:
        """The newest tracked position in NED, or None if the newest sample is untracked.

        Returns
        -------
        numpy.ndarray or None
            Shape (3,) [m].
        """
        sample = self.client.latest()
        if sample is None or not sample.tracked:
            return None
        return self.mapping.position_to_ned(np.asarray(sample.pos_m))

    def require_tracked(self) -> np.ndarray:
        """The rigid body's NED position, refused if the stream is unhealthy.

        Returns
        -------
        numpy.ndarray
            Shape (3,) [m].

        Raises
        ------
        MocapError
            Stream problem or body not tracked, naming the bodies seen.
        """
        problem = self.problem()
        pos = self.latest_ned()
        if problem is None and pos is not None:
            return pos
        seen = ", ".join(repr(n) for n in self.client.names_seen) or "none"
        raise MocapError(
            f"mocap: rigid body {self.source.rigid_body!r} not usable "
            f"({problem or 'not tracked'}; bodies in the stream: {seen})"
        )

    def start_journal(self, now_s: float | None = None) -> None:
        """Keep the raw samples from :attr:`max_gap_s` before ``now_s`` on, for :meth:`drain`
        (a trial's start, two stream periods before its k = 0).

        The journal starts with the last :attr:`max_gap_s` of the stream so that the tracked
        sample before k = 0 is in it whenever the gap across k = 0 is one the grid bridges: a
        journal begun at the trial's start alone held nothing before k = 0 when the stream
        paused there (a mock Motive stalled 0.15-0.2 s on a loaded machine), and k = 0 and the
        grid points after it were left without mocap and the trial refused by learning. The
        end has :func:`gcs.flight.mocap.campaign.wait_past_end`.

        Parameters
        ----------
        now_s : float or None
            The start (``time.monotonic()`` if None).
        """
        self.client.start_journal(self.max_gap_s, now_s)

    def drain(self) -> MocapSeries:
        """Raw samples since :meth:`start_journal` (none kept after: a trial's end).

        Returns
        -------
        MocapSeries
        """
        return self.client.drain()

    def describe(self) -> dict[str, Any]:
        """What the flight used, for the session record.

        Returns
        -------
        dict
        """
        m = self.mapping
        stats = self.forwarder.stats() if self.forwarder is not None else None
        return {
            "url": self.source.url(),
            "mapping": {
                "up_axis": m.up_axis,
                "north_axis": m.north_axis,
                "right_handed": m.right_handed,
                "yaw_offset_deg": m.yaw_offset_deg,
                "origin_m": list(m.origin_m),
                "body_forward_axis": m.body_forward_axis,
            },
            "forward": self.settings.forward,
            "message": self.settings.message if self.settings.forward else None,
            "forwarded": None if stats is None else stats.sent,
            "forward_failed": None if stats is None else stats.failed,
            "forward_last_error": None if stats is None else stats.last_error,
            "forward_send_s_p50": None if stats is None else stats.send_s_p50,
            "samples": self.client.stats()["samples"],
        }


def trial_mocap(
    series: MocapSeries,
    mapping: FrameMapping,
    recording: TrialRecording,
    max_gap_s: float = GRID_MAX_GAP_S,
) -> MocapTrial:
    """A trial's raw mocap on its grid, and the estimate's lag behind it.

    Receipt times go to the trial's vehicle time through the trial's own clock fit
    (``recording.clock``), the clock the grid and the estimate are on. A grid time between
    tracked samples further apart than ``max_gap_s`` is left NaN; the campaign passes the
    longest gap its watch lets a trial fly through (:meth:`MocapLink.max_gap_s`), so that
    every trial the watch let finish is on the grid.

    Parameters
    ----------
    series : MocapSeries
        Raw samples received during the trial (and the last ``max_gap_s`` before it).
    mapping : FrameMapping
        System axes to NED.
    recording : TrialRecording
        The trial (grid, clock fit, raw estimate).
    max_gap_s : float
        Longest interval between tracked samples interpolated across [s].

    Returns
    -------
    MocapTrial
    """
    grid = recording.t_s
    pos = np.full((grid.size, 3), np.nan)
    clock = recording.clock
    tracked = series.tracked
    if clock is None or not np.isfinite(recording.t0_vehicle_s) or tracked.sum() < 2:
        return MocapTrial(series, pos, None)
    t_rel = clock.to_vehicle(series.t_receipt_s[tracked]) - recording.t0_vehicle_s
    ned = mapping.position_to_ned(series.pos_m[tracked])
    order = np.argsort(t_rel, kind="stable")
    t_rel, ned = t_rel[order], ned[order]
    pos, gap = align_to_grid(t_rel, ned, grid, max_gap_s)
    pos[gap] = np.nan
    lag = estimate_lag_s(t_rel, ned[:, :2], recording.raw_t_s, recording.raw_pos_ned_m[:, :2])
    return MocapTrial(series, pos, lag)
