"""Live: the paper's method against the options beyond it, flown through MAVSDK on the mock.

Flies ``gcs fly --mock`` (the real command: MAVSDK, MAVLink over UDP, the mock drone in its
own process), one flight at a time, each under ``flock /tmp/gcs-live.lock``, and builds the
tables of docs/results.md, "Learning that knows its floor", from the run directories:

* ``--set indoor``: the default mock, ``--seeds 0,1,2,3``;
* ``--set no-gusts``: ``profiles/mock-no-gusts.yaml`` (gusts off, the rest as the default);
* ``--set gps``: ``profiles/mock-gps.yaml``, ``--seeds 0,1,2``.

Per seed, two runs of the default eight: ``profiles/antx.yaml`` (the paper's method, Table I,
trials j = 0..J) and ``profiles/antx-adaptive.yaml`` (trial 0, its repeats, then j = 1..J; the
floor from those flights; docs/results.md's tables were flown with one repeat, the profile's
default then). The paper's run flies no repeat: its rows are compared with the floor
measured in the adaptive run of the same seed and mock. A trial aborted by the watchdog (a
loaded machine) is flown again with ``--resume``. Runs already complete are not flown again:
delete a run directory to fly it anew.

Prints, per seed and method, e_pos,0 [m], e_pos,j / e_pos,0 [%] for j = 1..J, the floor
[mm and % of e_pos,0], median(j = 3..5) / floor, max(j >= 2) / floor, the setpoints' RMS
distance from the reference per trial [m], and the adaptive run's decisions (refresh,
safeguard, the first trial "converged"); ``--json`` writes it all. Nothing is asserted.

    .venv/bin/python benchmarks/live_learning_floor.py --set indoor --fly
    .venv/bin/python benchmarks/live_learning_floor.py --set gps --seeds 0,1,2 --fly
    .venv/bin/python benchmarks/live_learning_floor.py --set indoor   # tables only
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GCS = [sys.executable, "-m", "gcs"]
LOCK = "/tmp/gcs-live.lock"
SETS = {
    "indoor": None,
    "no-gusts": ROOT / "profiles" / "mock-no-gusts.yaml",
    "gps": ROOT / "profiles" / "mock-gps.yaml",
}
METHODS = {"paper": "antx", "adaptive": "antx-adaptive"}


def run_path(out: Path, which: str, method: str, seed: int) -> Path:
    return out / f"{which}-{method}-s{seed}"


def flights_needed(method: str, iterations: int) -> int:
    """Trials to fly for iterations j = 0..iterations - 1 (plus the adaptive run's repeats)."""
    from gcs.io.config import load_profile

    profile = load_profile(ROOT / "profiles" / f"{METHODS[method]}.yaml")
    return iterations + profile.learning.repeats


def fly(out: Path, which: str, method: str, seed: int, iterations: int, extra: list[str]) -> None:
    """Fly (or complete) one run; each ``gcs fly`` holds the live lock for its flight only."""
    from gcs.io.rundir import RunDir

    path = run_path(out, which, method, seed)
    want = flights_needed(method, iterations)
    mock = [] if SETS[which] is None else ["--mock-config", str(SETS[which])]
    for _ in range(4):
        done = RunDir.open(path).next_trial() if path.exists() else 0
        if done >= want:
            return
        if path.exists():
            where = ["--resume", str(path)]
        else:
            where = ["--run", str(path), "--profile", METHODS[method], "--trajectory", "eight"]
        cmd = ["flock", LOCK, *GCS, "fly", "--mock", "--seed", str(seed), *mock, *where,
               "--iter", str(want - done), *extra]  # fmt: skip
        started = time.monotonic()
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        took = time.monotonic() - started
        tail = (proc.stdout + proc.stderr).strip().splitlines()[-1:] or [""]
        print(f"  {path.name}: exit {proc.returncode} after {took:.0f} s: {tail[0]}", flush=True)
        (out / f"{path.name}.log").open("a").write(proc.stdout + proc.stderr)
    raise SystemExit(f"{path}: not complete after 4 attempts")


def summarise(path: Path) -> dict:
    """e_pos, setpoint RMS, iterations, floor and decisions of a run directory."""
    from gcs.app.report import run_learning, run_metrics
    from gcs.io.rundir import RunDir

    run = RunDir.open(path)
    rows = run_metrics(run)
    learning = run_learning(run)
    trials = learning.trials
    by_j: dict[int, dict] = {}
    for r in rows:
        t = trials[r.iteration]
        if t.repeat_of is None:
            by_j[t.iteration] = {"trial": r.iteration, "epos_m": r.epos_m, "sp_rms_m": t.sp_rms_m}
    out = {
        "run": str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path),
        "epos0_m": rows[0].epos_m,
        "epos_m": [by_j[j]["epos_m"] for j in sorted(by_j)],
        "sp_rms_m": [by_j[j]["sp_rms_m"] for j in sorted(by_j)],
        "floor": None,
    }
    if learning.floor is not None:
        f = learning.floor
        repeat = [r.epos_m for r in rows if trials[r.iteration].repeat_of is not None]
        out["floor"] = {"epos_m": f.epos_m, "scatter_m": f.scatter_m, "rms_m": f.rms_m,
                        "repeat_epos_m": repeat}  # fmt: skip
        conv = [t.iteration for t in trials.values() if t.verdict and t.verdict.converged]
        out["converged_at_j"] = conv[0] if conv else None
        out["decisions"] = {
            t.iteration: _decision(t.record) for t in trials.values() if t.record is not None
        }
    return out


def _decision(record: dict) -> dict:
    d = record["decision"]
    guard = d.get("safeguard") or {}
    return {
        "refresh": [
            round(ax["refresh"]["moved"], 3)
            if ax["refresh"] and ax["refresh"]["accepted"]
            else None
            for ax in d["axes"]
        ],
        "revert_to": guard.get("anchor_trial") if guard.get("action") == "revert" else None,
        "weight_newest": [
            round(ax["noise"]["weights"][-1], 2) if ax["noise"]["weights"] else None
            for ax in d["axes"]
        ],
    }


def table(results: dict, iterations: int) -> None:
    """Print the tables: e_pos % of e_pos,0, ratios to the floor, setpoint RMS."""
    js = range(1, iterations)
    print("seed | method | e_pos,0 [m] | floor [mm] (% e_pos,0) | " +
          " | ".join(f"j={j}" for j in js) + " | med(3..5)/floor | max(j>=2)/floor")  # fmt: skip
    for seed, by_method in sorted(results.items()):
        floor = (by_method.get("adaptive") or {}).get("floor")
        for method, s in by_method.items():
            e = np.array(s["epos_m"])
            pct = 100 * e / s["epos0_m"]
            cells = [f"{p:.2f}" for p in pct[1:]]
            if floor is None:
                print(f"{seed} | {method} | {s['epos0_m']:.3f} | - | " + " | ".join(cells))
                continue
            f = floor["epos_m"]
            med = np.median(e[3:6]) / f if e.size > 5 else float("nan")
            top = np.max(e[2:]) / f if e.size > 2 else float("nan")
            print(f"{seed} | {method} | {s['epos0_m']:.3f} | {1e3 * f:.1f} "
                  f"({100 * f / s['epos0_m']:.2f}) | " + " | ".join(cells)
                  + f" | {med:.2f} | {top:.2f}")  # fmt: skip
    print("setpoint RMS distance from the reference [m], j = 0..")
    for seed, by_method in sorted(results.items()):
        for method, s in by_method.items():
            print(f"{seed} | {method} | " + " ".join(f"{v:.2f}" for v in s["sp_rms_m"]))
    for seed, by_method in sorted(results.items()):
        a = by_method.get("adaptive")
        if a and a.get("floor"):
            f = a["floor"]
            print(
                f"seed {seed}: floor {1e3 * f['epos_m']:.1f} mm, scatter {1e3 * f['scatter_m']:.1f}"
                f" mm, RMS {1e3 * f['rms_m']:.1f} mm; converged at j = {a['converged_at_j']}; "
                f"decisions {a['decisions']}"
            )


def summary(results: dict) -> None:
    """Medians over the seeds, and the new options against the paper's in the same runs."""
    rows = {}
    for _, by_method in sorted(results.items()):
        floor = (by_method.get("adaptive") or {}).get("floor")
        for method, s in by_method.items():
            e = np.array(s["epos_m"])
            if floor is None or e.size < 6:
                continue
            f = floor["epos_m"]
            rows.setdefault(method, []).append(
                (np.median(e[3:6]) / f, np.max(e[2:]) / f, 100 * e[3] / s["epos0_m"],
                 np.median(e[3:6]), np.max(s["sp_rms_m"]))
            )  # fmt: skip
    names = ("med(3..5)/floor", "max(j>=2)/floor", "j=3 [%]", "med(3..5) [m]", "max sp RMS [m]")
    print("median over the seeds | " + " | ".join(names))
    for method, vals in rows.items():
        med = np.median(np.array(vals), axis=0)
        print(f"{method} ({len(vals)} seeds) | " + " | ".join(f"{v:.3g}" for v in med))
    if "paper" in rows and "adaptive" in rows and len(rows["paper"]) == len(rows["adaptive"]):
        ratio = [a[3] / p[3] for a, p in zip(rows["adaptive"], rows["paper"], strict=True)]
        each = " ".join(f"{r:.2f}" for r in ratio)
        print(f"new / paper, median(j = 3..5) per seed: {each}; median {np.median(ratio):.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", choices=sorted(SETS), default="indoor")
    parser.add_argument("--seeds", default=None, help="default 0,1,2,3 (gps: 0,1,2)")
    parser.add_argument("--iterations", type=int, default=8, help="j = 0..iterations - 1")
    parser.add_argument("--methods", default="paper,adaptive")
    parser.add_argument("--out", type=Path, default=ROOT / "logs" / "p5-live")
    parser.add_argument("--fly", action="store_true", help="fly the runs that are missing")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    seeds = args.seeds or ("0,1,2" if args.set == "gps" else "0,1,2,3")
    methods = args.methods.split(",")
    args.out.mkdir(parents=True, exist_ok=True)
    results: dict[int, dict] = {}
    for seed in (int(s) for s in seeds.split(",")):
        results[seed] = {}
        for method in methods:
            if args.fly:
                fly(args.out, args.set, method, seed, args.iterations, [])
            path = run_path(args.out, args.set, method, seed)
            if path.exists():
                results[seed][method] = summarise(path)
    table(results, args.iterations)
    summary(results)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
