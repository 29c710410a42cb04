"""Write trajectories/racetrack.csv: a planner's output for the ``samples`` trajectory source.

A racetrack (two 2 m straights joined by two half circles of 1 m radius) at 1.5 m altitude,
with a 0.3 m rise and fall of the altitude over the lap, flown once at up to 1.4 m/s with a
smooth speed ramp at either end, sampled at 100 Hz with half a second of hover at the start
and at the end. Deterministic: the same bytes on every run (``--check`` says whether the file
on disk is current).

Usage::

    python tools/make_samples.py            # (re)write trajectories/racetrack.csv
    python tools/make_samples.py --check    # exit 1 if the file differs from what it writes
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from gcs.core.trajectory import loop_phase

OUT = Path(__file__).resolve().parents[1] / "trajectories" / "racetrack.csv"
RATE_HZ = 100.0
STRAIGHT_M = 2.0  # length of each straight [m]
RADIUS_M = 1.0  # radius of each turn [m]
ALTITUDE_M = 1.5
RISE_M = 0.3  # altitude gained at half lap [m]
CRUISE_M_S = 1.4
RAMP_S = 2.0
HOVER_S = 0.5


def racetrack_point(sigma: np.ndarray) -> np.ndarray:
    """Point at arc length ``sigma`` along the racetrack (north, east) [m], shape (M, 2).

    Starts at the middle of the west straight heading north, turns clockwise (seen from
    above) round the north end, comes back down the east straight and round the south end.
    """
    half, r = STRAIGHT_M / 2.0, RADIUS_M
    lap = 2.0 * STRAIGHT_M + 2.0 * math.pi * r
    s = np.mod(sigma, lap)
    out = np.zeros((s.size, 2))
    bounds = np.cumsum([half, math.pi * r, STRAIGHT_M, math.pi * r, half])
    a = s < bounds[0]  # west straight, northwards
    out[a] = np.column_stack([s[a], np.full(a.sum(), -r)])
    b = (s >= bounds[0]) & (s < bounds[1])  # north turn
    th = (s[b] - bounds[0]) / r
    out[b] = np.column_stack([half + r * np.sin(th), -r * np.cos(th)])
    c = (s >= bounds[1]) & (s < bounds[2])  # east straight, southwards
    out[c] = np.column_stack([half - (s[c] - bounds[1]), np.full(c.sum(), r)])
    d = (s >= bounds[2]) & (s < bounds[3])  # south turn
    th = (s[d] - bounds[2]) / r
    out[d] = np.column_stack([-half - r * np.sin(th), r * np.cos(th)])
    e = s >= bounds[3]  # west straight again, back to the start
    out[e] = np.column_stack([-half + (s[e] - bounds[3]), np.full(e.sum(), -r)])
    return out


def samples() -> np.ndarray:
    """The racetrack's samples, columns t_s, north_m, east_m, down_m; shape (M, 4)."""
    lap = 2.0 * STRAIGHT_M + 2.0 * math.pi * RADIUS_M
    period = lap / CRUISE_M_S
    duration = 2.0 * HOVER_S + RAMP_S + period
    t = np.arange(int(round(duration * RATE_HZ)) + 1) / RATE_HZ
    phase, _, _ = loop_phase(t, period, 1, RAMP_S, HOVER_S)
    phase = np.minimum(phase, 2.0 * math.pi)
    ne = racetrack_point(phase / (2.0 * math.pi) * lap)
    down = -ALTITUDE_M - RISE_M * 0.5 * (1.0 - np.cos(phase))
    return np.column_stack([t, ne, down])


def csv_text(table: np.ndarray) -> str:
    """The CSV file's text: a comment, the header, one sample per line (um and ms)."""
    lines = [
        "# racetrack written by tools/make_samples.py: time [s], local NED position [m]",
        "t_s,north_m,east_m,down_m",
    ]
    lines += [f"{t:.2f},{n:.6f},{e:.6f},{d:.6f}" for t, n, e, d in table]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write (or with ``--check`` compare) trajectories/racetrack.csv.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        0, or 1 when ``--check`` finds the file stale.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare, do not write")
    args = parser.parse_args(argv)
    text = csv_text(samples())
    if args.check:
        current = OUT.read_text() if OUT.exists() else ""
        if current != text:
            print(f"{OUT} is stale: run python tools/make_samples.py", file=sys.stderr)
            return 1
        return 0
    tmp = OUT.with_suffix(".csv.tmp")
    tmp.write_text(text)
    tmp.replace(OUT)
    print(f"wrote {OUT} ({text.count(chr(10)) - 2} samples)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
