"""The lab-floor goal over rounds of firmware flights, against two yardsticks.

Reads the runs that ``benchmarks/lab_floor_px4.py`` kept (any directories, searched below:
each round its own ``--out``) and judges every flight's learned trials j = 2..6 against the
goal of docs/learning-floor.md (every trial within 1.5 floors, their median within 1.25):

- in floors of the flight's own trial 0 and its repeats (as the benchmark and the lab-floor
  test judge one flight);
- in floors of its point: the median of the own floors of every flight at the same point and
  trajectory, whatever the profile. A flight's trial 0 is a few flights of about 14 s of a
  vehicle that swings for seconds, so its floor scatters from flight to flight; the point's
  floor is the same yardstick for every flight.

Per setting (the profile spec and the point; a round's ``-kK`` is dropped): the flights, the
goal met, the median over j = 2..6, the trials above 1.5 floors and the largest, in both
yardsticks, and in how many distinct ways the flights opened (trial 0's flights: flights
whose e_pos there agree to :data:`ALIKE_M` on average replayed each other, docs/learning-floor.md
section 7), over the setting's flights and over the point's. Nothing is asserted.

    .venv/bin/python benchmarks/lab_floor_goal.py logs/anchor [--json goal.json]
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np
from estimate_replay import find_runs
from lab_floor_px4 import summary

#: The learned trials the goal judges, and its bounds [floors].
GOAL_J = range(2, 7)
GOAL_MAX = 1.5
GOAL_MEDIAN = 1.25
#: A run's name: the profile spec, then the point and trajectory (``-r...`` or ``-gps...``),
#: then perhaps a round ``-kK`` before the trajectory.
NAME = re.compile(r"^(?P<profile>.*?)-(?P<point>(?:r\d|gps).*)$")
ROUND = re.compile(r"-k\d+(?=-t|$)")


def flight(run: Path) -> dict | None:
    """One flight's setting, own floor [m], trial 0's e_pos [m] and e_pos [m] at j = 2..6;
    None for a run without every one of them."""
    s = summary(run)
    m = NAME.match(ROUND.sub("", run.name))
    by_j = {j: e for j, e in zip(s["iteration"], s["epos_m"], strict=True) if j in GOAL_J}
    if m is None or not s["floor_m"] or len(by_j) < len(GOAL_J):
        return None
    opening = [e for j, e in zip(s["iteration"], s["epos_m"], strict=True) if j == 0]
    return {
        "run": str(run), "profile": m["profile"], "point": m["point"], "floor_m": s["floor_m"],
        "opening_m": opening, "epos_m": [by_j[j] for j in GOAL_J],
    }  # fmt: skip


#: Two flights opened alike when trial 0's flights came out within this [m] of the other's on
#: average: over 24 flights of one point the mean differences of pairs were 0.9-2.5 mm, then
#: 3.9 mm and up, continuously (2026-12-07).
ALIKE_M = 0.003


def distinct_openings(openings: list[list[float]]) -> int:
    """How many ways ``openings`` (trial 0's e_pos [m] per flight) opened: groups of flights
    linked by openings alike (within :data:`ALIKE_M` on average)."""
    groups: list[list[np.ndarray]] = []
    for o in map(np.asarray, openings):
        linked = [
            g for g in groups
            if any(len(x) == len(o) and np.mean(np.abs(x - o)) <= ALIKE_M for x in g)
        ]  # fmt: skip
        merged = [o] + [x for g in linked for x in g]
        groups = [g for g in groups if not any(g is h for h in linked)] + [merged]
    return len(groups)


def judged(floors: list[list[float]]) -> dict:
    """The goal over flights given each one's e_pos at j = 2..6 in floors."""
    late = [x for f in floors for x in f]
    return {
        "goal_met": sum(bool(max(f) <= GOAL_MAX and np.median(f) <= GOAL_MEDIAN) for f in floors),
        "median": round(float(np.median(late)), 2),
        "above_max": sum(x > GOAL_MAX for x in late),
        "trials": len(late),
        "largest": round(max(late), 2),
    }


def table(flights: list[dict]) -> list[dict]:
    """Per setting, the goal against each flight's own floor and against its point's."""
    point_floor = {
        p: float(np.median([f["floor_m"] for f in flights if f["point"] == p]))
        for p in {f["point"] for f in flights}
    }
    rows = []
    for setting in sorted({(f["profile"], f["point"]) for f in flights}):
        fs = [f for f in flights if (f["profile"], f["point"]) == setting]
        pf = point_floor[setting[1]]
        rows.append(
            {
                "profile": setting[0],
                "point": setting[1],
                "flights": len(fs),
                "distinct_openings": distinct_openings([f["opening_m"] for f in fs]),
                "point_floor_m": round(pf, 4),
                "own_floor_m": [round(f["floor_m"], 4) for f in fs],
                "against_own": judged([[e / f["floor_m"] for e in f["epos_m"]] for f in fs]),
                "against_point": judged([[e / pf for e in f["epos_m"]] for f in fs]),
            }
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", help="directories holding the kept runs")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    runs = [r for r in find_runs(args.paths) if not r.name.endswith(("-identify", "-warm"))]
    flights = [f for f in map(flight, runs) if f is not None]
    if not flights:
        sys.exit(f"no flight with trials 0..{GOAL_J[-1]} under {' '.join(args.paths)}")
    rows = table(flights)
    for r in rows:
        floors_mm = [1e3 * f for f in r["own_floor_m"]]
        print(
            f"{r['profile']} at {r['point']}: {r['flights']} flights, "
            f"{r['distinct_openings']} distinct openings; own floors {min(floors_mm):.0f}-"
            f"{max(floors_mm):.0f} mm, the point's {1e3 * r['point_floor_m']:.0f} mm"
        )
        for key in ("own", "point"):
            g = r[f"against_{key}"]
            print(
                f"  against the {key:5s} floor: goal met {g['goal_met']} of {r['flights']}, "
                f"j = 2..6 median {g['median']:.2f}, above {GOAL_MAX} {g['above_max']} of "
                f"{g['trials']}, largest {g['largest']:.2f}"
            )
    if args.json:
        args.json.write_text(json.dumps({"flights": flights, "settings": rows}, indent=1))


if __name__ == "__main__":
    main()
