"""Benchmark of the study engine: a chunk of plants learning batched against a Learner per plant.

Printed, not asserted. For every setting of a study file (default the documented example
``docs/studies/antx-wdu.yaml``), one chunk of plants at every level flies
:func:`gcs.core.study.fly_plants` batched and with a Learner per plant, alternately, in this
process: CPU and wall time of each (medians over ``--rounds``), their ratio, the largest
difference of e_pos and of the last setpoints between the two, and the machine's 1-minute
load average (the machine may be shared: the CPU times are the figures to compare).

Usage: ``python benchmarks/study_engine.py [--study docs/studies/antx-wdu.yaml]
[--plants 8] [--rounds 1]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the Dask workers run
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    import numpy as np

    from gcs.app.study_chunks import build_plan
    from gcs.core.study import fly_plants
    from gcs.io.study import load_study

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", type=Path, default=ROOT / "docs/studies/antx-wdu.yaml")
    parser.add_argument("--plants", type=int, default=8)
    parser.add_argument("--rounds", type=int, default=1)
    args = parser.parse_args()
    plan = build_plan(load_study(args.study))
    plants = range(min(args.plants, plan.plants))
    totals = {"batched": [0.0, 0.0], "per_plant": [0.0, 0.0]}
    for setting in plan.settings:
        for level in range(len(plan.uncertainty.levels)):
            times: dict[str, list[tuple[float, float]]] = {"batched": [], "per_plant": []}
            results = {}
            for _ in range(args.rounds):
                for name, batched in (("batched", True), ("per_plant", False)):
                    cpu, wall = time.process_time(), time.perf_counter()
                    results[name] = fly_plants(plan, setting, level, plants, batched=batched)
                    times[name].append((time.process_time() - cpu, time.perf_counter() - wall))
            med = {
                k: [statistics.median(t[i] for t in v) for i in (0, 1)] for k, v in times.items()
            }
            for k in totals:
                totals[k][0] += med[k][0]
                totals[k][1] += med[k][1]
            pairs = list(zip(results["batched"], results["per_plant"], strict=True))
            line = {
                "setting": setting.name,
                "level": plan.uncertainty.levels[level],
                "plants": len(plants),
                "batched_cpu_s": round(med["batched"][0], 3),
                "per_plant_cpu_s": round(med["per_plant"][0], 3),
                "cpu_ratio": round(med["per_plant"][0] / med["batched"][0], 2),
                "batched_wall_s": round(med["batched"][1], 3),
                "per_plant_wall_s": round(med["per_plant"][1], 3),
                "max_epos_diff_m": float(
                    max(np.nanmax(np.abs(a.epos_m - b.epos_m)) for a, b in pairs)
                ),
                "max_setpoint_diff_m": float(
                    max(np.max(np.abs(a.setpoints_m - b.setpoints_m)) for a, b in pairs)
                ),
                "limit_active": round(float(np.mean([a.limit_active for a, _ in pairs])), 3),
                "load_1min": round(os.getloadavg()[0], 2),
            }
            print(json.dumps(line), flush=True)
    print(
        json.dumps(
            {
                "total_batched_cpu_s": round(totals["batched"][0], 2),
                "total_per_plant_cpu_s": round(totals["per_plant"][0], 2),
                "cpu_ratio": round(totals["per_plant"][0] / totals["batched"][0], 2),
                "total_batched_wall_s": round(totals["batched"][1], 2),
                "total_per_plant_wall_s": round(totals["per_plant"][1], 2),
                "load_1min": round(os.getloadavg()[0], 2),
            }
        )
    )


if __name__ == "__main__":
    main()
