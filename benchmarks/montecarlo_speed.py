"""Benchmark of the Monte Carlo study (gcs.core.montecarlo.run_study).

Prints one JSON line per case::

    {"n": N, "blas_threads": "default"|"1", "threads": 1|2, "seconds": median, "runs": k,
     "trial_iterations": ..., "us_per_trial_iteration": ..., "load_avg_1min": ...}

Each case is the whole default study (4 levels x 2 algorithms x 100 plants x 10 repeats x 30
iterations, 31 trials each) with trial length N = 200 (the default), 400 and 800; the cost per
trial iteration should grow no faster than N^2 (dense fixed operators) - the N = 400 and 800
lines show it. At N = 200 the batches also run on as many threads as cores
(``run_study(threads=...)``, what ``gcs montecarlo`` does by default). Every case runs in a
fresh subprocess so that ``OPENBLAS_NUM_THREADS`` can be set before numpy is imported: on a
2-core machine shared with other jobs, OpenBLAS's two threads can be much slower than one
(busy-waiting threads); both are reported. The machine's 1-minute load average is recorded
next to each line.

``--placement [runs]`` times the command itself, start-up included: the default ``gcs
montecarlo`` (which decides between this process and a local cluster, docs/studies.md), then
``--workers 0`` and ``--workers 2``, interleaved, ``runs`` times each (default 3); it prints one
JSON line per case (median and every wall time, the decision line of the default, whether its
``--json`` rows equal those of ``--workers 0``) and one with the ratios to ``--workers 0``.

Usage: ``python benchmarks/montecarlo_speed.py`` (all cases),
``python benchmarks/montecarlo_speed.py --case N [runs [threads]]`` or
``python benchmarks/montecarlo_speed.py --placement [runs]``.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

CASES = [(200, 3), (400, 1), (800, 1)]


def run_case(n: int, runs: int, threads: int = 1) -> dict:
    from gcs.core.montecarlo import MontecarloSettings, run_study

    settings = MontecarloSettings(n_samples=n)
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        run_study(settings, threads=threads)
        times.append(time.perf_counter() - t0)
    trial_iterations = (
        len(settings.levels)
        * len(settings.algorithms)
        * settings.plants
        * settings.repeats
        * (settings.iterations + 1)
    )
    seconds = statistics.median(times)
    return {
        "n": n,
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
        "threads": threads,
        "seconds": round(seconds, 3),
        "runs": runs,
        "min_seconds": round(min(times), 3),
        "trial_iterations": trial_iterations,
        "us_per_trial_iteration": round(1e6 * seconds / trial_iterations, 2),
        "load_avg_1min": round(os.getloadavg()[0], 2),
    }


PLACEMENTS = {"default": [], "workers 0": ["--workers", "0"], "workers 2": ["--workers", "2"]}


def run_placements(runs: int) -> None:
    import tempfile

    times: dict[str, list[float]] = {name: [] for name in PLACEMENTS}
    rows: dict[str, object] = {}
    said = ""
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(runs):
            for name, extra in PLACEMENTS.items():
                out = Path(tmp) / f"{name.replace(' ', '-')}.json"
                t0 = time.perf_counter()
                done = subprocess.run(
                    [sys.executable, "-m", "gcs", "montecarlo", *extra, "--json", str(out)],
                    capture_output=True,
                    text=True,
                    check=True,
                    env=dict(os.environ, COLUMNS="200"),
                )
                times[name].append(time.perf_counter() - t0)
                rows[name] = json.loads(out.read_text())
                if name == "default":
                    said = next(
                        line for line in done.stderr.splitlines() if line.startswith(("in ", "on "))
                    )
    medians = {name: statistics.median(t) for name, t in times.items()}
    for name, t in times.items():
        line = {"case": f"gcs montecarlo ({name})", "median_s": round(medians[name], 2)}
        line |= {"wall_s": [round(x, 2) for x in t], "load_avg_1min": round(os.getloadavg()[0], 2)}
        if name == "default":
            line |= {"decision": said, "rows_equal_workers_0": rows[name] == rows["workers 0"]}
        print(json.dumps(line), flush=True)
    base = medians["workers 0"]
    ratios = {f"{name} / workers 0": round(m / base, 2) for name, m in medians.items()}
    print(json.dumps({"runs": runs, **ratios}), flush=True)


def main() -> None:
    if len(sys.argv) >= 2 and sys.argv[1] == "--placement":
        run_placements(int(sys.argv[2]) if len(sys.argv) > 2 else 3)
        return
    if len(sys.argv) >= 3 and sys.argv[1] == "--case":
        runs = int(sys.argv[3]) if len(sys.argv) > 3 else 1
        threads = int(sys.argv[4]) if len(sys.argv) > 4 else 1
        print(json.dumps(run_case(int(sys.argv[2]), runs, threads)), flush=True)
        return
    for threads in (None, "1"):
        env = dict(os.environ)
        env.pop("OPENBLAS_NUM_THREADS", None)
        if threads is not None:
            env["OPENBLAS_NUM_THREADS"] = threads
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
        cases = [(n, runs, 1) for n, runs in CASES] + [(CASES[0][0], CASES[0][1], cores)]
        for n, runs, threads in cases:
            out = subprocess.run(
                [sys.executable, __file__, "--case", str(n), str(runs), str(threads)],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            print(out.stdout.strip(), flush=True)


if __name__ == "__main__":
    main()
