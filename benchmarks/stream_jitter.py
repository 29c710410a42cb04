"""Setpoint stream jitter as seen by the vehicle, per stream rate (mock drone, real MAVSDK).

For each configuration, starts the mock drone, flies one ~20 s trial (a slow circle) through
``fly_campaign`` and prints one JSON line: p50/p99/max of the setpoint inter-arrival times the
mock recorded within the trial window, the number of arrivals and of near-duplicates (MAVSDK's
own re-send slipping in), the largest send delay behind the deadline on the GCS side, and the
share of grid samples interpolated across a telemetry gap.

Usage: ``.venv/bin/python benchmarks/stream_jitter.py [--duration 20]``
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
from pathlib import Path

import numpy as np

from gcs.flight.campaign import CampaignPlan, FlightSession, run_campaign
from gcs.flight.fence import Fence
from gcs.flight.trial import TrialRecording
from gcs.io.settings import FlightSettings
from gcs.mock.config import Faults
from gcs.mock.process import MockProcess

# (stream rate [Hz], t_ilc [s]); 50 Hz is not a multiple of 1/0.05 s, so it runs at t_ilc 0.02 s
CONFIGS = [(20.0, 0.05), (40.0, 0.05), (60.0, 0.05), (50.0, 0.02)]


class CircleSource:
    """One slow circle (radius 0.5 m, 2 m up); keeps the recording."""

    def __init__(self, duration_s: float, t_ilc_s: float) -> None:
        phase = np.linspace(0.0, 2.0 * np.pi, round(duration_s / t_ilc_s))
        self.setpoints = np.stack(
            [0.5 * np.sin(phase), 0.5 * (1 - np.cos(phase)), -2.0 + 0 * phase], axis=1
        )
        self.recording: TrialRecording | None = None

    def setpoints_for(self, j: int) -> np.ndarray:
        """Return the circle (any ``j``)."""
        return self.setpoints

    def hover_point_for(self, j: int) -> np.ndarray:
        """Hover at the circle's first point."""
        return self.setpoints[0]

    def record(self, j: int, recording: TrialRecording) -> None:
        """Keep the recording."""
        self.recording = recording

    def record_incomplete(self, j: int, recording: TrialRecording, reason: str) -> None:
        """Keep the partial recording."""
        self.recording = recording

    def record_session(self, session: FlightSession) -> None:
        """Nothing to keep: the hover measurement is not what this benchmark is about."""


def setpoint_arrivals_s(stats_path: Path) -> np.ndarray:
    """Setpoint arrival times [s, CLOCK_MONOTONIC] from the mock's stats file."""
    stats = json.loads(stats_path.read_text())
    return np.asarray(stats["setpoints"]["t_rx_monotonic_s"], dtype=float)


def run_one(rate_hz: float, t_ilc_s: float, duration_s: float, workdir: Path) -> dict:
    """Fly one trial at ``rate_hz`` and measure the stream the mock received."""
    settings = FlightSettings(
        stream_rate_hz=rate_hz, settle_time_s=0.5, settle_tolerance_m=0.2, hover_measure_s=2.0
    )
    source = CircleSource(duration_s, t_ilc_s)
    stats_path = workdir / f"stats-{rate_hz:g}-{t_ilc_s:g}.json"
    with MockProcess(config_path=None, seed=0, faults=Faults(), stats_path=stats_path) as mock:
        fence = Fence.around([[-3, 3], [-3, 3], [-3, 0]], settings, 3.0, 1.5)  # antx's arena
        run_campaign(CampaignPlan(mock.url, 0, 1, t_ilc_s, settings, fence), source)
    rec = source.recording
    assert rec is not None and rec.complete
    arrivals = setpoint_arrivals_s(stats_path)
    t0, t_end = rec.t0_monotonic_s, rec.t0_monotonic_s + rec.n_setpoints * t_ilc_s
    window = arrivals[(arrivals >= t0 - 1e-3) & (arrivals < t_end)]
    gaps_ms = np.diff(window) * 1e3
    return {
        "stream_rate_hz": rate_hz,
        "t_ilc_s": t_ilc_s,
        "arrivals": int(window.size),
        "expected": round(duration_s * rate_hz),
        "interarrival_p50_ms": round(float(np.percentile(gaps_ms, 50)), 2),
        "interarrival_p99_ms": round(float(np.percentile(gaps_ms, 99)), 2),
        "interarrival_max_ms": round(float(gaps_ms.max()), 2),
        # arrivals closer than half a stream period: MAVSDK's own 20 Hz re-send slipping in
        "near_duplicates": int(np.sum(gaps_ms < 500.0 / rate_hz)),
        "max_send_late_ms": round(rec.max_send_late_s * 1e3, 2),
        "interpolated_share": round(rec.interpolated_share, 4),
    }


def main() -> None:
    """Run every configuration and print one JSON line each."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0, help="trial length [s]")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    with tempfile.TemporaryDirectory() as tmp:
        for rate_hz, t_ilc_s in CONFIGS:
            print(json.dumps(run_one(rate_hz, t_ilc_s, args.duration, Path(tmp))), flush=True)


if __name__ == "__main__":
    sys.exit(main())
