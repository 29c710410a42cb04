"""Hover statistics and verdicts of ``gcs.flight.hover`` on recorded and simulated hovers.

Prints one JSON line per hover: the first second of every trial of the recorded PX4 v1.16
SITL runs that starts in hover (GPS and vision), the hovers of 6-9 s in the recorded PX4 SITL
MAVLink capture (GPS), the indoor mock's physics hovering 10 s
(seeds 0-2), and synthetic drifting and oscillating vehicles; then the ranges per group. Needs
the recorded PX4 data (tests/px4_data.py finds it). Same data as tests/test_hover.py.

Usage: ``.venv/bin/python benchmarks/hover_stats.py``
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from px4_data import capture_hovers, sitl_hovers  # noqa: E402

from gcs.flight.hover import hover_stats, judge_hover  # noqa: E402
from gcs.io.settings import FlightSettings  # noqa: E402
from gcs.mock.config import MockConfig  # noqa: E402
from gcs.mock.physics import QuadPhysics, Target  # noqa: E402

SETTINGS = FlightSettings()
TARGET = np.array([0.0, 0.0, -1.5])


def mock_hover(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The indoor mock's physics hovering at TARGET, 4-14 s after starting there, 50 Hz."""
    physics = QuadPhysics(MockConfig(), seed, tuple(TARGET))
    physics.command(0.0, Target(tuple(TARGET), 0.0))
    t = np.arange(4.0, 14.0, 0.02)
    pos = []
    for tk in t:
        physics.advance_to(float(tk))
        pos.append(physics.measure()[0])
    return t, np.array(pos)


def synthetic() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Drifting and oscillating vehicles, 10 s at 50 Hz, 1 cm of noise."""
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 10.0, 0.02)
    out = []
    for name, north in [
        ("drift 0.4 m/s", 0.4 * t),
        ("drift 0.2 m/s", 0.2 * t),
        ("oscillation 0.2 m, 2 s", 0.2 * np.sin(np.pi * t)),
        ("oscillation 0.04 m, 2 s", 0.04 * np.sin(np.pi * t)),
        ("wander 0.3 m, 25 s", 0.3 * np.sin(2 * np.pi * t / 25)),
    ]:
        rel = np.column_stack([north, 0 * t, 0 * t]) + rng.normal(0, 0.01, (t.size, 3))
        out.append((name, t, TARGET + rel))
    return out


def row(group: str, name: str, t, pos, target) -> dict:  # type: ignore[no-untyped-def]
    stats = hover_stats(t, pos, target)
    verdict = judge_hover(stats, SETTINGS)
    return {
        "group": group,
        "hover": name,
        "verdict": verdict.kind,
        "duration_s": round(stats.duration_s, 2),
        "offset_m": round(stats.offset_m, 3),
        "p50_m": round(stats.distance_p50_m, 3),
        "max_m": round(stats.distance_max_m, 3),
        "noise_cm": round(100 * stats.noise_m, 2),
        "speed_p50_m_s": round(stats.speed_p50_m_s, 3),
        "speed_p95_m_s": round(stats.speed_p95_m_s, 3),
        "drift_m_s": round(stats.drift_m_s, 3),
        "oscillation_share": round(stats.oscillation_share, 2),
        "tolerance_m": round(verdict.tolerance_m, 3),
        "speed_tolerance_m_s": round(verdict.speed_tolerance_m_s, 3),
    }


def main() -> None:
    rows = []
    for name, t, pos, target in sitl_hovers():
        group = "px4-sitl vision" if name.startswith("vision") else "px4-sitl gps"
        rows.append(row(group, name, t, pos, target))
    for i, (t, pos, target) in enumerate(capture_hovers()):
        rows.append(row("px4 capture gps", f"hover {i}", t, pos, target))
    for seed in range(3):
        rows.append(row("indoor mock", f"seed {seed}", *mock_hover(seed), TARGET))
    for name, t, pos in synthetic():
        rows.append(row("synthetic", name, t, pos, TARGET))
    for r in rows:
        print(json.dumps(r))
    for group in dict.fromkeys(r["group"] for r in rows):
        if group == "synthetic":
            continue
        part = [r for r in rows if r["group"] == group]
        ranges = {
            key: [min(r[key] for r in part), max(r[key] for r in part)]
            for key in part[0]
            if isinstance(part[0][key], float)
        }
        verdicts = sorted({r["verdict"] for r in part})
        print(json.dumps({"group": group, "n": len(part), "verdicts": verdicts, **ranges}))


if __name__ == "__main__":
    main()
