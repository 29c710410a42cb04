"""Learning at the floor on real PX4 v1.16 firmware (SIH) in lab rigs as real labs are.

Each flight is a fresh PX4 set up for vision only (``tests/px4/test_px4_lab.py``'s
``LAB_PARAMS``) and a fresh rig (``tests/px4/lab_rig.py``: PX4's ground truth served as an
OptiTrack rigid body) under one point of the lab's conditions: frame rate, latency from motion
to frame (EKF2_EV_DELAY told or left at 0), marker noise and the room's heading, and where
given the SIH vehicle's own mass and drag (``SIH_MASS``, ``SIH_KDV``; PX4 v1.16's SIH has no
wind or gust). Then the
README's flight, ``gcs fly --mocap ... --profile P --iter J`` on the default eight, with the
tests' watchdog limits. Per flight: e_pos of every trial in floors (the floor from trial 0 and
its repeat), what the learning step before each trial predicted of it and how far the flight
came out from that (``gcs report``'s prediction), the model refresh's changes and the
safeguard's decisions, from the run's records.

Points are given (``--point RATE:LATENCY:NOISE:HEADING:MATCH[:MASS:DRAG]``; ``--point
gps``: PX4's default airframe on GPS, no rig) or drawn across the ranges with a seed (``--draw
K --seed S``, ``--vehicle`` for the mass and drag too: printed, so any run can be flown
again). Flights of the same point replay each other on a quiet machine (the rig's marker noise
and PX4's own from every start are the same): ``--round K`` gives them an opening of their own,
the rig's noise seeded K and a ground wait drawn from K. A profile ``NAME+a.b=VALUE`` sets a
field of the shipped one (``antx-adaptive+learning.adaptive.repeats=3``). Run directories are kept
under ``--out``: a run there is resumed for the trials it lacks, or with ``--again K``
resumed flying trial K's setpoints again (the same setpoints twice: their floor); with
``--then-again K,K,...`` each flight is followed, on the same PX4 not restarted, by one flight
of one trial per K flying trial K's setpoints again (identical setpoints within one boot of the
firmware, learned ones as well as trial 0's), and with ``--warm N`` a new run flies after a
first flight of N trials of it on the same PX4 (``NAME-warm``: later in the firmware's boot;
``--boot-wait S``: S seconds on the ground after PX4 has started instead).
With
``--identify`` each new run's vehicle is identified first on the same PX4 and rig (``gcs
identify``, kept as ``NAME-id-identify``) and the run (``NAME-id``) flies the profile it wrote,
as the README advises for one's own vehicle. For every
group of flights of identical setpoints the table gives the floor of the group and of each
pair, the scatter within the trials and between the flights. The load average before and
after each flight is in its log: the rig and PX4 each take a good part of a core, so fly one
point at a time on a 2-core machine and nothing else beside it.

    .venv/bin/python benchmarks/lab_floor_px4.py --point 100:30:1:30:1 --profiles antx-adaptive
    .venv/bin/python benchmarks/lab_floor_px4.py --draw 6 --seed 1 --parallel 2
    .venv/bin/python benchmarks/lab_floor_px4.py --point 100:30:1:30:1 --identify
    .venv/bin/python benchmarks/lab_floor_px4.py --table        # the table of what was flown

Nothing is asserted.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from px4.flying import report_rows, sitl_profile  # noqa: E402
from px4.lab_rig import LabRig  # noqa: E402
from px4.sitl import STARTED_LINE, Px4Build, Px4Sitl, build_dir  # noqa: E402
from px4.test_px4_lab import LabConditions  # noqa: E402
from synthetic import CI_FLIGHT  # noqa: E402

from gcs.core.floor import floor_from_flights  # noqa: E402
from gcs.io.rundir import RunDir  # noqa: E402

FLY_TIMEOUT_S = 1800
#: the ranges the points are drawn from (docs/learning-floor.md says where they come from)
RANGES = {"rate_hz": (50.0, 360.0), "latency_ms": (0.0, 50.0), "noise_mm": (0.1, 2.0)}
#: the SIH vehicle's ranges, drawn with ``--vehicle`` from a stream of their own (the points of
#: a seed without it stay as they were): the mass against SIH's 20 N of thrust (a
#: thrust-to-weight ratio from 2.5 down to 1.4) and the linear drag around PX4's default 1
VEHICLE_RANGES = {"mass_kg": (0.8, 1.5), "drag_n_s_m": (0.5, 2.0)}


#: the point of a GPS flight: PX4's default airframe (SIH with GPS), no rig, no mocap
GPS = None


def parse_point(text: str) -> LabConditions | None:
    """``RATE:LATENCY:NOISE:HEADING:MATCH[:MASS:DRAG]`` (MASS, DRAG: the SIH vehicle's), or gps."""
    if text == "gps":
        return GPS
    rate, latency, noise, heading, match, *vehicle = text.split(":")
    mass, drag = (float(v) for v in vehicle) if vehicle else (None, None)
    return LabConditions(
        float(rate), float(latency), float(noise), float(heading), match == "1", mass, drag
    )


def draw_points(count: int, seed: int, vehicle: bool = False) -> list[LabConditions]:
    """``count`` points, uniform over :data:`RANGES`, any heading, EKF2_EV_DELAY told or not;
    with ``vehicle`` the SIH vehicle's mass and drag too (:data:`VEHICLE_RANGES`)."""
    rng = np.random.default_rng(seed)
    rng_vehicle = np.random.default_rng([seed, 1])
    points = []
    for _ in range(count):
        rate, latency, noise = (float(rng.uniform(*RANGES[k])) for k in RANGES)
        heading = float(rng.uniform(-180.0, 180.0))
        mass, drag = (
            (round(float(rng_vehicle.uniform(*VEHICLE_RANGES[k])), 2) for k in VEHICLE_RANGES)
            if vehicle
            else (None, None)
        )
        points.append(
            LabConditions(
                round(rate),
                round(latency),
                round(noise, 1),
                round(heading),
                bool(rng.integers(2)),
                mass,
                drag,
            )  # fmt: skip
        )
    return points


#: Longest ground wait [s] a round draws. PX4 seeds its random numbers with a constant at start,
#: so SIH's sensor noise is the same sequence from every start, drawn step by step of the
#: simulation: flown on a quiet machine, a round with the same rig seed replays an earlier one
#: (docs/learning-floor.md, "The vehicle's model across flights"). A wait on the ground starts
#: the flight at another point of that sequence.
ROUND_WAIT_S = 5.0


def round_wait_s(k: int) -> float:
    """The ground wait [s] of round ``k``: uniform in [0, :data:`ROUND_WAIT_S`) drawn from
    ``k``, to 10 ms; 0 for round 0 (the rounds flown before there were rounds)."""
    if k == 0:
        return 0.0
    return round(float(np.random.default_rng([k, 2]).uniform(0.0, ROUND_WAIT_S)), 2)


def name_of(point: LabConditions | None, profile: str, trajectory: Path | None = None) -> str:
    if point is GPS:
        return f"{profile}-gps" + (f"-t{trajectory.stem}" if trajectory else "")
    name = (
        f"{profile}-r{point.rate_hz:g}-l{point.latency_ms:g}-n{point.noise_mm:g}"
        f"-h{point.yaw_offset_deg:g}-m{int(point.match_ev_delay)}"
    )
    if point.mass_kg is not None or point.drag_n_s_m is not None:
        name += f"-kg{point.mass_kg or 1:g}-kdv{point.drag_n_s_m or 1:g}"
    if point.evp_noise_m is not None:
        name += f"-evp{point.evp_noise_m:g}"
    if point.marker_seed:
        name += f"-k{point.marker_seed}"
    return name + (f"-t{trajectory.stem}" if trajectory else "")


def profile_file(dest: Path, spec: str, mocap: bool = True) -> Path:
    """The shipped profile of ``spec`` (``NAME`` or ``NAME+a.b.c=VALUE+...``: fields set) with
    the tests' watchdog limits, written to ``dest``."""
    name, *fields = spec.split("+")
    values = {k: yaml.safe_load(v) for k, v in (f.split("=") for f in fields)}
    return sitl_profile(dest, name, limits=CI_FLIGHT, mocap={} if mocap else None, fields=values)


def flown(run: Path) -> int:
    """Complete trials of a run directory (0 when it holds none)."""
    try:
        return len(RunDir.open(run).complete_trials())
    except Exception:  # noqa: BLE001 - a run set up but never flown
        return 0


def run_gcs(args: list[str]) -> str:
    """Run ``gcs ARGS`` from the checkout, wide lines, and return its output (standard output
    then error); one that has not ended after ``FLY_TIMEOUT_S`` is stopped and its output so far
    returned with a line saying so."""
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "gcs", *args], cwd=ROOT, capture_output=True, text=True,
            timeout=FLY_TIMEOUT_S, env={**os.environ, "COLUMNS": "200", "PYTHONUNBUFFERED": "1"},
        )  # fmt: skip
    except subprocess.TimeoutExpired as exc:
        return f"{exc.stdout or ''}{exc.stderr or ''}\nno end after {FLY_TIMEOUT_S} s"
    return proc.stdout + proc.stderr


def fly(
    build: Px4Build,
    out: Path,
    point: LabConditions | None,
    profile: str,
    iterations: int,
    again: int | None = None,
    trajectory: Path | None = None,
    identify: bool = False,
    then_again: tuple[int, ...] = (),
    warm: int = 0,
    boot_wait_s: float = 0.0,
) -> None:
    """One flight into ``out/NAME`` (kept), its output in ``out/NAME.log``: a new run (on
    ``trajectory``, default the packaged eight), or the run resumed for ``iterations`` more
    trials (the first flying trial ``again``'s setpoints). With ``identify`` a new run's
    vehicle is first identified (``gcs identify`` on the same PX4 and rig, the run kept as
    ``out/NAME-identify``) and the run flies the identified profile (``NAME`` ends in ``-id``).
    Then, per trial K of ``then_again``, one more flight of one trial on the same PX4 and rig,
    not restarted: trial K's setpoints again (``gcs fly --resume RUN --iter 1 --again K``).
    Called again on the same ``out``, it flies only what did not end in a complete trial:
    the run's missing trials, then the missing flights of ``then_again``.
    With ``warm`` a new run is flown after a first flight of ``warm`` trials of the same
    profile and trajectory on the same PX4 (kept as ``out/NAME-warm``): the run's trials come
    that much later in the firmware's boot; with ``boot_wait_s`` the first flight waits that
    long on the ground after PX4 has started."""
    name = name_of(point, profile, trajectory) + ("-id" if identify else "")
    run = out / name
    # what is still to fly of a run already there: its trials, then the flights of
    # then_again that did not end in a complete trial (all again with --again)
    done = 0 if not run.exists() or again is not None else flown(run)
    left = iterations - done
    agains_left = then_again[max(0, done - iterations) :]
    if left <= 0 and not agains_left:
        return  # complete: no PX4 or rig started for it
    work = out / f".{name}-px4"
    work.mkdir(parents=True, exist_ok=True)
    params = {} if point is GPS else point.px4_params()
    if identify:  # SIH's battery runs down in the identification's two minutes and PX4 then
        # refuses to arm ("Battery unhealthy"): kept above 80 %, as a lab swaps the battery
        params = {**params, "SIM_BAT_MIN_PCT": 80.0}
    vehicle = Px4Sitl(build, work, params, ready=STARTED_LINE)
    t0 = time.monotonic()
    load = os.getloadavg()[0]
    try:
        vehicle.start()
        time.sleep(boot_wait_s)  # on the ground, disarmed: the firmware's boot, not an event
        with contextlib.ExitStack() as stack:
            source = ["--connect", vehicle.url]
            if point is not GPS:
                rig = stack.enter_context(LabRig(vehicle.instance, point.rig_args()))
                source += ["--mocap", rig.url]
            flown_profile = profile_file(work, profile, mocap=point is not GPS)
            text = ""
            if identify and not run.exists():
                identified = work / "identified.yaml"
                ident_run = str(out / f"{name}-identify")
                text = run_gcs(["identify", *source, "--profile", str(flown_profile),
                                "--run", ident_run, "--out", str(identified)])  # fmt: skip
                text += "\n"
                flown_profile = identified
            path = [] if trajectory is None else ["--trajectory", str(trajectory.resolve())]
            args = ["fly", *source, "--iter", str(iterations), "--profile", str(flown_profile),
                    "--run", str(run), *path]  # fmt: skip
            if warm and not run.exists():
                text += run_gcs(["fly", *source, "--iter", str(warm), "--profile",
                                 str(flown_profile), "--run", str(out / f"{name}-warm"),
                                 *path]) + "\n"  # fmt: skip
            if run.exists():
                args = ["fly", *source, "--resume", str(run), "--iter", str(left)]
                args += [] if again is None else ["--again", str(again)]
            if left > 0:
                text += run_gcs(args)
            for k in agains_left:
                text += "\n" + run_gcs(["fly", *source, "--resume", str(run), "--iter", "1",
                                         "--again", str(k)])  # fmt: skip
    finally:
        vehicle.stop()
    meta = {"load_before": round(load, 2), "load_after": round(os.getloadavg()[0], 2),
            "wall_s": round(time.monotonic() - t0, 1)}  # fmt: skip
    with (out / f"{name}.log").open("a") as log:
        log.write(text + "\n" + json.dumps(meta) + "\n")


def identical_groups(rd: RunDir) -> list[list[int]]:
    """Groups of two or more complete trials flown with identical setpoints (a repeat, a
    flight of ``--again K`` and trial K)."""
    groups: dict[bytes, list[int]] = {}
    for j in rd.complete_trials():
        sp = rd.read_trial(j).sp_ned_m[:-1, :2]
        groups.setdefault(np.ascontiguousarray(sp).tobytes(), []).append(j)
    return [g for g in groups.values() if len(g) >= 2]


def group_floors(rd: RunDir, epos_m: dict[int, float]) -> list[dict]:
    """Per group of identical setpoints: its floor and the scatter gcs estimates within the
    trials (:func:`gcs.core.floor.floor_from_flights`), the floor of each pair, and the
    e_pos of its flights (their spread is the scatter between flights)."""
    out = []
    for group in identical_groups(rd):
        pos = {j: rd.measured_trial(j).pos_ned_m[1:, :2] for j in group}
        floor = floor_from_flights(np.array([pos[j] for j in group]))
        pairs = {
            f"{a}/{b}": round(floor_from_flights(np.array([pos[a], pos[b]])).epos_m, 4)
            for i, a in enumerate(group)
            for b in group[i + 1 :]
        }
        e = [epos_m[j] for j in group]
        out.append({
            "trials": group, "floor_m": round(floor.epos_m, 4),
            "scatter_m": round(floor.scatter_m, 4),
            "scatter_within_m": round(floor.scatter_within_m, 4),
            "scatter_between_m": floor.scatter_between_m and round(floor.scatter_between_m, 4),
            "pair_floors_m": pairs,
            "epos_m": [round(x, 4) for x in e],
        })  # fmt: skip
    return out


def _round(value: float | None, digits: int) -> float | None:
    return None if value is None else round(value, digits)


def summary(run: Path) -> dict:
    """Per trial e_pos [m] and in floors, where it began (its distance from the start point),
    what the step before it predicted of it (e_pos [m],
    the flight's distance from the prediction in floors and what noise alone gives, setpoint
    samples at a limit), the
    refresh's changes, the safeguard's decisions and the floors of every group of identical
    setpoints."""
    rows = report_rows(run)
    rd = RunDir.open(run)
    floor = next((r.get("floor_m") for r in rows if r.get("floor_m")), None)
    decisions = []
    for j, record in sorted(rd.learn_records().items()):
        decision = record.get("decision") or {}
        refresh = {}
        for axis in decision.get("axes") or []:
            r = axis.get("refresh")
            if r is not None:
                refresh[axis["axis"]] = {
                    "accepted": r["accepted"], "moved": r["moved"],
                    "candidate_moved": r["candidate_moved"], "reason": r["reason"],
                }  # fmt: skip
        guard = decision.get("safeguard")
        decisions.append(
            {
                "after_trial": j,
                "refresh": refresh,
                "safeguard": guard
                and {k: guard[k] for k in ("action", "anchor_trial", "step", "reason")},
            }
        )
    return {
        "run": run.name,
        "trial": [r["trial"] for r in rows],
        "iteration": [r["iteration"] for r in rows],
        "epos_m": [r["epos_m"] and round(r["epos_m"], 4) for r in rows],
        "floor_m": floor,
        "floors": [r["epos_m"] and round(r["epos_m"] / floor, 2) for r in rows] if floor else None,
        # how far from the start point each trial began (the initial reset learning assumes)
        "start_offset_m": [_round(r.get("start_offset_m"), 3) for r in rows],
        # what the learning step before each trial predicted of it, and how far it flew from that
        "predicted_m": [_round(r.get("predicted_epos_m"), 4) for r in rows],
        "miss_floors": [_round(r.get("prediction_miss_ratio"), 2) for r in rows],
        "noise_floors": [_round(r.get("prediction_noise_ratio"), 2) for r in rows],
        "limits_active": [r.get("limits_active") for r in rows],
        "decisions": decisions,
        "identical": group_floors(rd, {r["trial"]: r["epos_m"] for r in rows}),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--point",
        action="append",
        default=[],
        help="RATE:LATENCY:NOISE:HEADING:MATCH[:MASS:DRAG], or gps",
    )
    parser.add_argument("--draw", type=int, default=0, help="points drawn across the ranges")
    parser.add_argument(
        "--vehicle", action="store_true", help="draw the SIH vehicle's mass and drag too"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--evp-noise",
        type=float,
        help="EKF2_EVP_NOISE [m] of every lab point (default: PX4's 0.1 m)",
    )
    parser.add_argument(
        "--profiles",
        default="antx-adaptive,antx",
        help="comma-separated; NAME+a.b=VALUE sets a field (learning.limits.max_step_m=0.2)",
    )
    parser.add_argument("--iter", type=int, default=8)
    parser.add_argument(
        "--trajectory", type=Path, help="trajectory file of new runs (default: the packaged eight)"
    )
    parser.add_argument("--parallel", type=int, default=1, help="PX4 instances at a time")
    parser.add_argument("--out", type=Path, default=ROOT / "logs" / "lab-floor")
    parser.add_argument("--table", action="store_true", help="only the table of what was flown")
    parser.add_argument(
        "--again", type=int, help="resume each run, flying trial K's setpoints again first"
    )
    parser.add_argument(
        "--then-again",
        default="",
        help="after each flight, on the same PX4 not restarted, one trial per K of K,K,...: "
        "trial K's setpoints again",
    )
    parser.add_argument(
        "--warm",
        type=int,
        default=0,
        help="before each new run, a flight of N trials of it on the same PX4 (NAME-warm)",
    )
    parser.add_argument(
        "--boot-wait",
        type=float,
        default=0.0,
        help="seconds PX4 waits on the ground after it has started, before the first flight",
    )
    parser.add_argument(
        "--round",
        type=int,
        default=0,
        help="an opening of its own: the rig's marker noise seeded K and a ground wait drawn "
        "from K added to --boot-wait (0: seed 0, no wait, as before)",
    )
    parser.add_argument(
        "--identify",
        action="store_true",
        help="identify each new run's vehicle first (gcs identify) and fly the identified profile",
    )
    args = parser.parse_args()
    args.out = args.out.resolve()  # PX4 resolves its paths from its own working directory
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.table:
        points = [parse_point(p) for p in args.point] + draw_points(
            args.draw, args.seed, args.vehicle
        )
        if args.evp_noise is not None:
            points = [
                p if p is GPS else dataclasses.replace(p, evp_noise_m=args.evp_noise)
                for p in points
            ]
        points = [p if p is GPS else dataclasses.replace(p, marker_seed=args.round) for p in points]
        boot_wait_s = args.boot_wait + round_wait_s(args.round)
        print(f"round {args.round}: marker seed {args.round}, ground wait {boot_wait_s:g} s")
        for p in points:
            print("point", json.dumps("gps" if p is GPS else p.__dict__), flush=True)
        build = Px4Build(build_dir()[0])
        build.runnable()
        plan = [(p, prof) for p in points for prof in args.profiles.split(",")]
        with ThreadPoolExecutor(args.parallel) as pool:
            list(
                pool.map(
                    lambda item: fly(
                        build,
                        args.out,
                        item[0],
                        item[1],
                        args.iter,
                        args.again,
                        args.trajectory,
                        args.identify,
                        tuple(int(k) for k in args.then_again.split(",") if k),
                        args.warm,
                        boot_wait_s,
                    ),
                    plan,
                )
            )
    for run in sorted(
        p
        for p in args.out.iterdir()
        if p.is_dir()
        and not p.is_symlink()
        and not p.name.startswith(".")
        and not p.name.endswith(("-identify", "-warm"))
    ):
        try:
            print(json.dumps(summary(run)), flush=True)
        except Exception as exc:  # noqa: BLE001 - a run that did not fly a trial is a line too
            print(json.dumps({"run": run.name, "error": f"{type(exc).__name__}: {exc}"[:200]}))


if __name__ == "__main__":
    main()
