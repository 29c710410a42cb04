"""Replay of a study's input updates: this code against another commit, on the same QPs.

Printed, not asserted. The study's learning (default the documented example
``docs/studies/antx-wdu.yaml``: 96 plant-runs at N = 280, most of their updates hitting a
limit) runs once in this process, chunk after chunk as ``gcs study`` cuts it, with every
:class:`gcs.core.update.InputUpdate` built, forked and solved recorded (the model, reference,
weights and limits; each trial's disturbance estimate and last input; the setpoints). The
recording is then replayed in subprocesses, alternately with this tree and with the other
commit (default ``4a34af6``, before Clarabel's solver was kept; a detached checkout under the
system's temporary directory), ``--rounds`` of each: the same updates in the same order, the
forks as the batch made them. Per code: CPU seconds (``time.process_time``; the machine may be
shared, wall times are not comparable) of building the updates and of the solves, by method
(``direct``, ``active-set``, ``clarabel``), medians over the rounds; ``ratio`` = the other
commit's solve seconds / this code's; ``max_diff_m``: the largest difference of the setpoints
from the recording; the 1-minute load average.

Usage: ``python benchmarks/update_replay.py [--study FILE] [--commit C] [--rounds R]``
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from baseline import baseline_tree

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the Dask workers run
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, os.environ.get("GCS_BENCH_CODE", str(REPO)))


def record(study: Path, out: Path) -> dict:
    """Run the study's learning here, recording every update; the recording to ``out``."""
    import gcs.core.update as update
    from gcs.app.study_chunks import build_plan
    from gcs.core.study import chunk_plants, fly_plants
    from gcs.io.study import load_study

    log: list[tuple] = []
    ids: dict[int, int] = {}
    alive: list[object] = []  # keeps every update alive: no id is reused
    cls = update.InputUpdate
    init, fork, solve = cls.__init__, cls.fork, cls.solve

    def uid(obj: object) -> int:
        if id(obj) not in ids:
            alive.append(obj)
            ids[id(obj)] = len(ids)
        return ids[id(obj)]

    def rec_init(self, model, yd_m, weights, limits=None):
        init(self, model, yd_m, weights, limits)
        log.append(("init", uid(self), model, yd_m.copy(), weights, limits))

    def rec_fork(self):
        other = fork(self)
        log.append(("fork", uid(other), uid(self)))
        return other

    def rec_solve(self, d_hat_m, u_prev_m, robustness=None):
        res = solve(self, d_hat_m, u_prev_m, robustness)
        log.append(("solve", uid(self), d_hat_m.copy(), u_prev_m.copy(), robustness, res.u_m))
        return res

    cls.__init__, cls.fork, cls.solve = rec_init, rec_fork, rec_solve
    try:
        plan = build_plan(load_study(study))
        for setting in plan.settings:
            for level in range(len(plan.uncertainty.levels)):
                for chunk in range(plan.chunks):
                    fly_plants(plan, setting, level, chunk_plants(plan, chunk))
    finally:
        cls.__init__, cls.fork, cls.solve = init, fork, solve
    out.write_bytes(pickle.dumps(log))
    return {"solves": sum(e[0] == "solve" for e in log), "updates": len(ids)}


def replay(path: Path) -> dict:
    """Replay a recording with the code on ``sys.path``: CPU seconds by method."""
    import numpy as np

    import gcs
    from gcs.core.update import InputUpdate

    log = pickle.loads(path.read_bytes())
    updates: dict[int, InputUpdate] = {}
    build = 0.0
    by_method: dict[str, list[float]] = {}
    diff = 0.0
    for entry in log:
        if entry[0] == "init":
            cpu = time.process_time()
            updates[entry[1]] = InputUpdate(*entry[2:6])
            build += time.process_time() - cpu
        elif entry[0] == "fork":
            updates[entry[1]] = updates[entry[2]].fork()
        else:
            cpu = time.process_time()
            res = updates[entry[1]].solve(*entry[2:5])
            by_method.setdefault(res.method, []).append(time.process_time() - cpu)
            diff = max(diff, float(np.max(np.abs(res.u_m - entry[5]))))
    return {
        "code": str(Path(gcs.__file__).parents[1]),
        "build_cpu_s": build,
        "solve_cpu_s": sum(sum(v) for v in by_method.values()),
        "by_method": {k: [len(v), sum(v)] for k, v in sorted(by_method.items())},
        "max_diff_m": diff,
    }


def main() -> None:
    if len(sys.argv) == 3 and sys.argv[1] == "--replay":
        print(json.dumps(replay(Path(sys.argv[2]))))
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", type=Path, default=REPO / "docs/studies/antx-wdu.yaml")
    parser.add_argument("--commit", default="4a34af6")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    base = baseline_tree(args.commit)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "updates.pkl"
        print(json.dumps({"recorded": record(args.study, path)}), flush=True)
        runs: dict[str, list[dict]] = {"new": [], "baseline": []}
        for _ in range(args.rounds):
            for who, code in (("baseline", base), ("new", REPO)):
                env = dict(os.environ, GCS_BENCH_CODE=str(code))
                cmd = [sys.executable, __file__, "--replay", str(path)]
                text = subprocess.run(cmd, check=True, capture_output=True, text=True,
                                      env=env).stdout  # fmt: skip
                line = json.loads(text.strip().splitlines()[-1])
                if Path(line["code"]).resolve() != code.resolve():
                    raise RuntimeError(f"{who} ran {line['code']}, not {code}")
                runs[who].append(line)
    summary = {}
    for who, lines in runs.items():
        methods = {m for x in lines for m in x["by_method"]}
        summary[who] = {
            "solve_cpu_s": round(statistics.median(x["solve_cpu_s"] for x in lines), 3),
            "build_cpu_s": round(statistics.median(x["build_cpu_s"] for x in lines), 3),
            "by_method": {
                m: [
                    lines[-1]["by_method"].get(m, [0, 0.0])[0],
                    round(statistics.median(x["by_method"].get(m, [0, 0.0])[1] for x in lines), 3),
                ]
                for m in sorted(methods)
            },
            "max_diff_m": max(x["max_diff_m"] for x in lines),
        }
    print(json.dumps({
        "commit": args.commit, "rounds": args.rounds, "new": summary["new"],
        "baseline": summary["baseline"],
        "ratio": round(summary["baseline"]["solve_cpu_s"] / summary["new"]["solve_cpu_s"], 2),
        "load_1min": round(os.getloadavg()[0], 2),
    }))  # fmt: skip


if __name__ == "__main__":
    main()
