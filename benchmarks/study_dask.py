"""Benchmark of ``gcs study`` on Dask: workers, the cost per plant-iteration, the growth in N.

Printed, not asserted. Three parts, each a JSON line (and the machine's 1-minute load average,
since the machine may be shared):

1. ``workers``: one study (the antx profile at t_ilc_s = 0.02 s on the default eight,
   N = 700; settings wdu 0.01 and 0.1; +-20 %) of ``--plant-runs`` plant-runs of
   ``--iterations`` learned trials, on a LocalCluster of 1 worker and then of 2 workers in the
   same run: wall times (cluster start-up apart), their ratio, and whether the two JSON
   documents are identical.
2. ``per_plant_iteration``: the study's cost per plant-iteration (1 worker's wall time / plant
   iterations) against ``gcs montecarlo``'s batched study at N = 600 (its wall time / (plants
   x repeats x iterations)), both in this machine's conditions.
3. ``growth``: cost per plant-iteration of the study, in this process, at N = 700, 1200 and
   2450 (eights of 2, 4 and 9 loops, same sample time), and of ``gcs montecarlo``'s study
   at N = 600, 1200 and 2400 (dense N x N operators).

Usage: ``python benchmarks/study_dask.py [--plant-runs 2000] [--iterations 2] [--skip-workers]``;
``--overhead-only`` runs the plant-runs in this process and on one local worker (Dask's
overhead, same run).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the Dask workers run
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

ROOT = Path(__file__).resolve().parents[1]


def load() -> float:
    return os.getloadavg()[0]


def write_inputs(tmp: Path, loops: int) -> tuple[Path, Path]:
    import yaml

    profile = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    profile["name"] = "antx-50hz"
    profile["t_ilc_s"] = 0.02
    profile["flight"]["stream_rate_hz"] = 100
    traj = yaml.safe_load((ROOT / "trajectories" / "eight.yaml").read_text())
    traj["name"] = f"eight-{loops}"
    traj["loops"] = loops
    p, t = tmp / "antx-50hz.yaml", tmp / f"eight-{loops}.yaml"
    p.write_text(yaml.safe_dump(profile))
    t.write_text(yaml.safe_dump(traj))
    return p, t


def plan_of(tmp: Path, loops: int, plants: int, iterations: int, chunk: int):  # noqa: ANN201
    from gcs.app.study_chunks import build_plan, definition_document
    from gcs.io.study import study_from_dict

    p, t = write_inputs(tmp, loops)
    data = {
        "name": f"bench-{loops}",
        "profile": str(p),
        "trajectory": str(t),
        "seed": 1,
        "plants": plants,
        "iterations": iterations,
        "chunk_plants": chunk,
        "uncertainty": {"levels": [0.2], "noise_std_m": 0.01, "disturbance_rms_m": 0.05},
        "grid": {"wdu": [0.01, 0.1]},
    }
    spec = study_from_dict(copy.deepcopy(data), str(tmp / "study.yaml"))
    plan = build_plan(spec)
    return spec, plan, definition_document(spec, plan)


def run_on(workers: int, spec, plan, document, out: Path) -> tuple[float, float, str]:  # noqa: ANN001
    from gcs.app.study_chunks import open_output, run_study_chunks, study_document, summarise_study
    from gcs.app.study_cluster import Cluster, connect

    start = time.perf_counter()
    with connect(Cluster(workers=workers)) as client:
        up = time.perf_counter() - start
        output = open_output(out, document)
        t0 = time.perf_counter()
        results = run_study_chunks(plan, output, client)
        wall = time.perf_counter() - t0
    outcome = summarise_study(plan, results)
    return wall, up, json.dumps(study_document(document, plan, outcome), indent=1)


def montecarlo_cost(n: int, plants: int) -> float:
    from gcs.core.montecarlo import MontecarloSettings, run_study

    s = MontecarloSettings(
        levels=(0.2,), plants=plants, repeats=1, n_samples=n, algorithms=("smoother",)
    )
    t0 = time.perf_counter()
    run_study(s)
    return (time.perf_counter() - t0) / (plants * s.repeats * s.iterations)


def study_cost(tmp: Path, loops: int, plants: int, iterations: int) -> tuple[int, float]:
    from gcs.app.study_chunks import open_output, run_study_chunks
    from gcs.app.study_cluster import Cluster, connect

    spec, plan, document = plan_of(tmp, loops, plants, iterations, plants)
    out = tmp / f"growth-{loops}"
    t0 = time.perf_counter()
    with connect(Cluster(workers=0)) as client:
        run_study_chunks(plan, open_output(out, document), client)
    runs = len(plan.settings) * plan.plants
    return plan.n_samples, (time.perf_counter() - t0) / (runs * plan.iterations)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--plant-runs", type=int, default=2000)
    parser.add_argument("--iterations", type=int, default=2)
    parser.add_argument("--chunk", type=int, default=25)
    parser.add_argument("--skip-workers", action="store_true")
    parser.add_argument(
        "--overhead-only",
        action="store_true",
        help="only Dask's overhead: --plant-runs in this process, then on one local worker",
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        if args.overhead_only:
            plants = max(args.plant_runs // 2, 1)
            spec, plan, document = plan_of(tmp, 2, plants, args.iterations, args.chunk)
            here = run_on(0, spec, plan, document, tmp / "here")
            one = run_on(1, spec, plan, document, tmp / "one")
            print(json.dumps({
                "part": "overhead", "n": plan.n_samples, "plant_runs": 2 * plants,
                "chunks": 2 * plan.chunks, "in_process_s": round(here[0], 2),
                "one_worker_s": round(one[0], 2), "startup_s": round(one[1], 2),
                "ratio": round(one[0] / here[0], 3), "identical_json": here[2] == one[2],
                "load_avg_1min": load(),
            }))  # fmt: skip
            return
        plants = max(args.plant_runs // 2, 1)  # two settings
        spec, plan, document = plan_of(tmp, 2, plants, args.iterations, args.chunk)
        one = None
        if not args.skip_workers:
            one = run_on(1, spec, plan, document, tmp / "one")
            two = run_on(2, spec, plan, document, tmp / "two")
            print(json.dumps({
                "part": "workers", "n": plan.n_samples, "plant_runs": 2 * plants,
                "iterations": args.iterations, "chunks": 2 * plan.chunks,
                "one_worker_s": round(one[0], 2), "two_workers_s": round(two[0], 2),
                "ratio": round(one[0] / two[0], 3),
                "startup_s": [round(one[1], 2), round(two[1], 2)],
                "identical_json": one[2] == two[2], "load_avg_1min": load(),
            }))  # fmt: skip
            sys.stdout.flush()
        if one is not None:
            study_pi = one[0] / (2 * plants * args.iterations)
            mc_pi = montecarlo_cost(600, 100)
            print(json.dumps({
                "part": "per_plant_iteration", "study_ms": round(1e3 * study_pi, 3),
                "montecarlo_ms": round(1e3 * mc_pi, 4), "ratio": round(study_pi / mc_pi, 1),
                "n_study": plan.n_samples, "n_montecarlo": 600, "load_avg_1min": load(),
            }))  # fmt: skip
            sys.stdout.flush()
        growth = []
        for loops, n_mc in ((2, 600), (4, 1200), (9, 2400)):
            n, cost = study_cost(tmp, loops, 2, args.iterations)
            mc = montecarlo_cost(n_mc, 20)
            growth.append(
                {"n": n, "study_ms": round(1e3 * cost, 2), "n_montecarlo": n_mc,
                 "montecarlo_ms": round(1e3 * mc, 3)}
            )  # fmt: skip
        base = growth[0]
        for g in growth:
            g["study_x"] = round(g["study_ms"] / base["study_ms"], 2)
            g["montecarlo_x"] = round(g["montecarlo_ms"] / base["montecarlo_ms"], 2)
        print(json.dumps({"part": "growth", "rows": growth, "load_avg_1min": load()}))


if __name__ == "__main__":
    main()
