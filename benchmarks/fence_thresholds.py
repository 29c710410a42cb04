"""The live fence's thresholds against the real data we have: does it ever fire on them?

Runs :class:`gcs.flight.fence.EstimateMonitor` (the code that watches every flight) with the
default thresholds (``FlightSettings``, profile ``antx.yaml``'s arena and vehicle limits) over:

- **PX4 SITL, GPS** and **PX4 SITL, vision**: every trial of the shared run directories
  (the recorded PX4 v1.16 SITL runs: PX4 v1.16, SIH quadrotor, EKF2 on GPS or on a perfect external
  vision feed), reported position and velocity on the 0.05 s grid;
- **PX4 capture**: the recorded PX4 SITL MAVLink capture, every
  LOCAL_POSITION_NED PX4 sent while armed (30 Hz: take-off, eights, steps, hovers, landing);
- **mock-gps**: ``profiles/mock-gps.yaml`` flown offline (its physics and estimator, no
  network) as a flight session: take-off at ``MPC_TKO_SPEED``, the 4 s hold and 10 s hover
  measurement, four trials of the shared repeat experiment's eight, each after a 1 m/s move
  back, a settle and a 4 s hold, the two 60 s PRBS experiments of the shared ``identify/`` run
  (``gcs identify``), and a landing; reported state sampled at 50 Hz, seeds 0-9.

For each it prints the largest value of every watched statistic next to its threshold, the
breaches (there must be none), and for the margin the two figures it is set against: the largest
distance along an axis from the setpoint in a hover (the first second of every trial that starts
in one) and the largest distance outside the box of a trial's own setpoints.

Usage::

    .venv/bin/python benchmarks/fence_thresholds.py [--seeds 0-9] [--json]
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from mock_gps_calibration import parse_seeds  # noqa: E402
from px4_data import capture_armed, shared  # noqa: E402

from gcs.app.session import flight_fence  # noqa: E402
from gcs.flight.fence import DRIFT_WINDOW_S, EstimateMonitor, Fence  # noqa: E402
from gcs.io.config import load_profile  # noqa: E402
from gcs.mock.config import load_mock_config  # noqa: E402
from gcs.mock.physics import QuadPhysics, Target  # noqa: E402

SITL = shared() / "data" / "px4-sitl"
T_ILC_S = 0.05
SAMPLE_S = 0.02  # mock telemetry period (50 Hz)
STATS = ("outside_m", "speed_xy_m_s", "speed_z_m_s", "jump_m", "drift_m")


def _cols(t: np.ndarray, prefix: str, unit: str) -> np.ndarray:
    return np.column_stack([t[f"{prefix}_{a}_{unit}"] for a in ("north", "east", "down")])


def watch(fence: Fence, t_s: np.ndarray, pos: np.ndarray, vel: np.ndarray) -> dict:
    """Run the monitor over one recording: its peaks and every breach it names."""
    monitor = EstimateMonitor(fence)
    breaches = []
    for tk, pk, vk in zip(t_s, pos, vel, strict=True):
        if not (np.all(np.isfinite(pk)) and np.all(np.isfinite(vk))):
            continue
        problem = monitor.update(float(tk), pk, vk)
        if problem is not None:
            breaches.append(f"{tk:.2f} s: {problem}")
    return {"peaks": dict(monitor.peaks), "breaches": breaches}


def hover_and_box(pos: np.ndarray, sp: np.ndarray) -> tuple[float | None, float]:
    """Largest distance along an axis from the setpoint in the first second if it is a hover,
    and the largest distance outside the box of the trial's setpoints [m]."""
    ok = np.all(np.isfinite(pos), axis=1)
    pos, sp = pos[ok], sp[ok]
    hover = None
    if np.allclose(sp[:21], sp[0], atol=1e-3):
        hover = float(np.max(np.abs(pos[:21] - sp[0])))  # per axis, as the fence measures
    lo, hi = sp.min(axis=0), sp.max(axis=0)
    return hover, float(np.max(np.maximum(lo - pos, pos - hi)))


def shared_runs(fence: Fence, vision: bool) -> dict:
    """Every trial of the shared GPS (or vision) run directories."""
    out = {"recordings": 0, "duration_s": 0.0, "hover_m": [], "beyond_setpoints_m": []}
    results = []
    for d in sorted(p for p in SITL.iterdir() if p.is_dir()):
        if d.name.startswith("vision-") != vision:
            continue
        for path in sorted(glob.glob(str(d / "trial-*.csv"))):
            t = np.genfromtxt(path, delimiter=",", names=True)
            pos, vel, sp = _cols(t, "pos", "m"), _cols(t, "vel", "m_s"), _cols(t, "sp", "m")
            results.append(watch(fence, t["t_s"], pos, vel))
            hover, box = hover_and_box(pos, sp)
            if hover is not None:
                out["hover_m"].append(hover)
            out["beyond_setpoints_m"].append(box)
            out["recordings"] += 1
            out["duration_s"] += float(t["t_s"][-1])
    return _merge(out, results)


def capture(fence: Fence) -> dict:
    """The shared capture's LOCAL_POSITION_NED while armed."""
    t, pos, vel = capture_armed()
    out = {"recordings": 1, "duration_s": float(t[-1] - t[0])}
    return _merge(out, [watch(fence, t, pos, vel)])


def _merge(out: dict, results: list[dict]) -> dict:
    out["peaks"] = {k: max(r["peaks"][k] for r in results) for k in STATS}
    out["breaches"] = [b for r in results for b in r["breaches"]]
    return out


class MockSession:
    """mock-gps's physics flown like a ``gcs fly`` session, sampled at 50 Hz (no network)."""

    def __init__(self, cfg, seed: int) -> None:  # noqa: ANN001
        self.sim = QuadPhysics(cfg, seed=seed)
        self.rows: list[tuple] = []
        self.target = np.zeros(3)

    def run(self, duration_s: float, each=None) -> None:  # noqa: ANN001
        """Advance ``duration_s``, sampling; ``each(t)`` may command at every sample."""
        t0 = self.sim.t_s
        for k in range(1, int(round(duration_s / SAMPLE_S)) + 1):
            if each is not None:
                each(k * SAMPLE_S)
            self.sim.advance_to(t0 + k * SAMPLE_S)
            pos, vel = self.sim.measure()
            self.rows.append((self.sim.t_s, *pos, *vel))

    def command(self, target: Target) -> None:
        self.sim.command(self.sim.t_s, target)

    def takeoff(self, height_m: float, speed_m_s: float) -> None:
        self.sim.set_armed(True)
        self.target = np.array([0.0, 0.0, -height_m])
        self.command(Target(tuple(self.target), vel_up_max_m_s=speed_m_s))
        self.run(height_m / speed_m_s + 3.0)

    def goto(self, target: np.ndarray, speed_m_s: float = 1.0) -> None:
        start = self.target.copy()
        duration = max(1.875 * float(np.linalg.norm(target - start)) / speed_m_s, SAMPLE_S)

        def each(t: float) -> None:
            s = min(t / duration, 1.0)
            self.command(
                Target(tuple(start + (10 * s**3 - 15 * s**4 + 6 * s**5) * (target - start)))
            )

        self.run(duration, each)
        self.target = target

    def fly(self, setpoints: np.ndarray) -> None:
        def each(t: float) -> None:
            k = min(int(t / T_ILC_S), len(setpoints) - 1)
            self.command(Target(tuple(setpoints[k])))

        self.run(len(setpoints) * T_ILC_S, each)
        self.target = setpoints[-1]

    def land(self, speed_m_s: float) -> None:
        self.command(Target(tuple(self.target), vz_m_s=speed_m_s))
        self.run(-self.target[2] / speed_m_s + 2.0)


def mock_gps(fence: Fence, seeds: list[int]) -> dict:
    """mock-gps offline, one session per seed (see the module docstring)."""
    cfg = load_mock_config(ROOT / "profiles" / "mock-gps.yaml")
    sp = np.genfromtxt(SITL / "repeat" / "trial-000.csv", delimiter=",", names=True)
    setpoints = _cols(sp, "sp", "m")[:-1]
    excitations = [
        _cols(np.genfromtxt(path, delimiter=",", names=True), "sp", "m")[:-1]
        for path in sorted(glob.glob(str(SITL / "identify" / "trial-*.csv")))
    ]
    results, hover, box, duration = [], [], [], 0.0
    for seed in seeds:
        s = MockSession(replace(cfg), seed)
        s.takeoff(-setpoints[0, 2], cfg.px4.mpc_tko_speed_m_s)
        s.goto(setpoints[0])
        s.run(14.0)  # the hold and the hover measurement
        for _ in range(4):
            s.goto(setpoints[0])
            s.run(5.0)  # settle (about 1 s) and the 4 s hold
            first = len(s.rows)
            s.fly(setpoints)
            trial = np.array(s.rows[first:])
            grid = np.arange(len(setpoints)) * T_ILC_S
            pos = np.column_stack(
                [np.interp(grid, trial[:, 0] - trial[0, 0], trial[:, i]) for i in (1, 2, 3)]
            )
            h, b = hover_and_box(pos, setpoints)
            hover += [] if h is None else [h]
            box.append(b)
        for excitation in excitations:  # gcs identify's two 60 s PRBS experiments
            s.goto(excitation[0])
            s.run(5.0)
            s.fly(excitation)
        s.goto(setpoints[0])
        s.land(cfg.px4.mpc_land_speed_m_s)
        a = np.array(s.rows)
        results.append(watch(fence, a[:, 0], a[:, 1:4], a[:, 4:7]))
        duration += float(a[-1, 0])
    out = {
        "recordings": len(seeds),
        "duration_s": duration,
        "hover_m": hover,
        "beyond_setpoints_m": box,
    }
    return _merge(out, results)


def thresholds(fence: Fence) -> dict[str, float]:
    """The thresholds in the units of the peaks."""
    return {
        "outside_m": fence.margin_m,
        "speed_xy_m_s": fence.max_speed_xy_m_s,
        "speed_z_m_s": fence.max_speed_z_m_s,
        "jump_m": fence.jump_m,
        "drift_m": fence.drift_m,
    }


def table(fence: Fence, sources: dict[str, dict]) -> str:
    """A markdown table: the largest value per source and statistic, and the thresholds."""
    names = {
        "outside_m": "outside the arena [m]",
        "speed_xy_m_s": "horizontal speed [m/s]",
        "speed_z_m_s": "vertical speed [m/s]",
        "jump_m": "step beyond the velocity [m]",
        "drift_m": f"position against velocity in {DRIFT_WINDOW_S:g} s [m]",
    }
    limit = thresholds(fence)
    head = "| statistic | " + " | ".join(sources) + " | threshold |"
    lines = [head, "|" + "---|" * (len(sources) + 2)]
    for key, name in names.items():
        cells = [f"{src['peaks'][key]:.3f}" for src in sources.values()]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {limit[key]:.2f} |")
    for key, name in (
        ("hover_m", "hover: distance from the setpoint along an axis, first s of a trial [m]"),
        ("beyond_setpoints_m", "outside the box of the trial's setpoints [m]"),
    ):
        cells = [f"{max(src[key]):.3f}" if src.get(key) else "-" for src in sources.values()]
        lines.append(f"| {name} | " + " | ".join(cells) + " | (margin) |")
    counts = [f"{len(src['breaches'])}" for src in sources.values()]
    lines.append("| breaches | " + " | ".join(counts) + " | 0 |")
    extent = [f"{src['recordings']}, {src['duration_s']:.0f} s" for src in sources.values()]
    lines.append("| recordings, duration | " + " | ".join(extent) + " | |")
    return "\n".join(lines)


def main() -> None:
    """Print the table (or JSON)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0-9", help="mock-gps seeds (default 0-9)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = parser.parse_args()
    profile = load_profile(ROOT / "profiles" / "antx.yaml")
    fence = flight_fence(profile, profile.flight)
    sources = {
        "PX4 SITL, GPS": shared_runs(fence, vision=False),
        "PX4 SITL, vision": shared_runs(fence, vision=True),
        "PX4 capture": capture(fence),
        "mock-gps": mock_gps(fence, parse_seeds(args.seeds)),
    }
    if args.json:
        print(json.dumps({"thresholds": thresholds(fence), "sources": sources}, indent=1))
        return
    print(fence.describe())
    print(table(fence, sources))
    for name, src in sources.items():
        for breach in src["breaches"][:5]:
            print(f"BREACH {name}: {breach}")
    assert math.isfinite(fence.margin_m)


if __name__ == "__main__":
    main()
