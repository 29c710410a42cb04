"""Gaps in what the vehicle received, during the trials and between them (tests, benchmarks).

The mock drone records every setpoint and external-vision message it receives with its own
vehicle clock (``gcs-mock-stats/1``: ``setpoints.t_rx_vehicle_s``, ``vision.t_rx_vehicle_s``);
each trial's sidecar gives the trial's ``t0_vehicle_s`` on the same clock. A trial's window is
``[t0, t0 + N t_ilc_s]``; the window after it runs to the next trial's ``t0`` (the move, settle
and hold, and before them the hover while its recording was written and the next setpoints
learned), after the last trial to the first mode change (the landing).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gcs.io.rundir import RunDir


@dataclass(frozen=True)
class Gaps:
    """The largest inter-arrival gaps at the vehicle, in and between trials [s]."""

    vision_trial_s: float
    vision_between_s: float
    setpoint_trial_s: float
    setpoint_between_s: float
    hover_between_s: tuple[float, ...]  # end of trial j to start of trial j + 1 (vehicle time)
    vision_messages: int
    setpoints: int


Spans = list[tuple[float, float]]


def windows(run: RunDir, stats: dict) -> tuple[Spans, Spans]:
    """The trials' windows and the windows after each of them, in vehicle time [s]."""
    duration = run.n_samples * run.t_ilc_s
    starts = [float(run.read_status(j).extra["t0_vehicle_s"]) for j in run.complete_trials()]
    trials = [(t0, t0 + duration) for t0 in starts]
    after = [(end, nxt) for (_, end), nxt in zip(trials, starts[1:], strict=False)]
    end = trials[-1][1]
    changes = [m["t_vehicle_s"] for m in stats["modes"] if m["t_vehicle_s"] > end]
    if changes:  # the hover after the last trial, to the landing
        after.append((end, float(changes[0])))
    return trials, after


def largest_gap(t_s: np.ndarray, spans: Spans) -> float:
    """The largest gap between consecutive arrivals that overlaps any of ``spans`` [s]."""
    t = np.sort(np.asarray(t_s, dtype=float))
    gap = np.diff(t)
    best = 0.0
    for a, b in spans:
        inside = (t[1:] > a) & (t[:-1] < b)
        if inside.any():
            best = max(best, float(gap[inside].max()))
    return best


def gaps(run: RunDir, stats: dict) -> Gaps:
    """The largest vision and setpoint gaps at the vehicle, in and between the run's trials."""
    trials, after = windows(run, stats)
    vision = np.asarray(stats["vision"]["t_rx_vehicle_s"], dtype=float)
    setpoints = np.asarray(stats["setpoints"]["t_rx_vehicle_s"], dtype=float)
    hover = tuple(nxt[0] - prev[1] for prev, nxt in zip(trials, trials[1:], strict=False))
    return Gaps(
        largest_gap(vision, trials),
        largest_gap(vision, after),
        largest_gap(setpoints, trials),
        largest_gap(setpoints, after),
        hover,
        len(vision),
        len(setpoints),
    )
