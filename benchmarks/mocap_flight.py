"""Motion capture in flight: setpoint jitter with and without forwarding, the estimate's lag
behind the mocap, and learning on the indoor mock measured by mocap or by the estimate.

Everything flies the mock drone through ``gcs fly`` (real MAVSDK, real NatNet from the mock's
arena, the ``motioncapture`` library), under the live lock:

- **jitter**: the default mock (its own estimate, so it flies without vision) with its arena
  streaming at 120 Hz and the EKF2 parameters of an indoor PX4 (so that forwarding passes the
  pre-flight checks; the mock counts the vision and navigates on its own estimate); one trial
  of ``eight-short`` with ``mocap.forward: false``, then one
  with ``true``, alternated ``--pairs`` times. Per flight: the setpoint inter-arrival times the
  mock recorded on its own clock within the trial, their deviation from 1/60 s (median, 99th
  percentile), and the largest send delay gcs saw. The ratio with/without is of medians
  measured in the same run.
- **learning** and **lag**: the indoor mock (``profiles/mock-mocap.yaml``, vision only, fed by
  what gcs forwards) flies ``--iter`` trials learning on the mocap, then again learning on the
  estimate (same seed); per trial e_pos by the mocap and by the estimate, and the estimate's
  lag behind the mocap (``mocap_lag_s`` of each trial).

Usage: ``flock /tmp/gcs-live.lock .venv/bin/python benchmarks/mocap_flight.py [--pairs 2]
[--iter 6] [--figures docs/img]``. Prints JSON; with ``--figures`` writes mocap-jitter.png,
mocap-lag.png and mocap-learning.png there.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from synthetic import CI_FLIGHT  # noqa: E402

from gcs.core.trials import trial_errors  # noqa: E402
from gcs.errors import RunLogError  # noqa: E402
from gcs.io.runlog import RunDir  # noqa: E402
from gcs.mock.mocap.arena import ArenaOptions  # noqa: E402
from gcs.mock.process import MockProcess  # noqa: E402

STREAM_HZ = 60.0


def profile(tmp: Path, name: str, **mocap: object) -> Path:
    data = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    data["flight"] = dict(data.get("flight") or {}, **CI_FLIGHT)
    data["mocap"] = mocap
    path = tmp / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def gcs(*args: object) -> str:
    proc = subprocess.run(
        [sys.executable, "-m", "gcs", *map(str, args)],
        cwd=ROOT, capture_output=True, text=True, timeout=900,
        env={**os.environ, "COLUMNS": "200"},
    )  # fmt: skip
    if proc.returncode != 0:
        raise SystemExit(f"gcs {' '.join(map(str, args))} failed:\n{proc.stdout}{proc.stderr}")
    return proc.stdout


INDOOR_PARAMS = {"ekf2_gps_ctrl": 0, "ekf2_ev_ctrl": 11, "ekf2_hgt_ref": 3, "ekf2_ev_delay_ms": 5.0}


def jitter_flight(tmp: Path, forward: bool, seed: int) -> dict:
    run_path = tmp / f"jitter-{'on' if forward else 'off'}-{seed}"
    stats = tmp / f"stats-{run_path.name}.json"
    config = tmp / "mock-own-estimate.yaml"
    config.write_text(yaml.safe_dump({"px4": INDOOR_PARAMS}))
    arena = ArenaOptions(seed=seed)
    with MockProcess(config_path=config, seed=seed, stats_path=stats, arena=arena) as mock:
        gcs(
            "fly", "--connect", mock.url, "--mocap", mock.mocap_url, "--iter", 1,
            "--trajectory", "eight-short", "--run", run_path,
            "--profile", profile(tmp, run_path.name, forward=forward),
        )  # fmt: skip
    run = RunDir.open(run_path)
    extra = run.read_status(0).extra
    t0 = extra["t0_vehicle_s"]
    t = np.array(json.loads(stats.read_text())["setpoints"]["t_rx_vehicle_s"])
    t = t[(t >= t0) & (t <= t0 + run.n_samples * run.t_ilc_s)]
    dev_ms = np.abs(np.diff(t) - 1.0 / STREAM_HZ) * 1e3
    session = json.loads((run_path / "session-001.json").read_text())["mocap"]
    return {
        "forward": forward,
        "seed": seed,
        "arrivals": int(t.size),
        "dev_p50_ms": float(np.median(dev_ms)),
        "dev_p99_ms": float(np.percentile(dev_ms, 99)),
        "max_send_late_ms": 1e3 * extra["max_send_late_s"],
        "forwarded": session["forwarded"],
        "intervals_ms": (np.diff(t) * 1e3).tolist(),
    }


def learning_flight(tmp: Path, measurement: str, iterations: int) -> dict:
    run_path = tmp / f"learn-{measurement}"
    gcs(
        "fly", "--mock", "--mocap", "mock", "--iter", iterations, "--trajectory", "eight-short",
        "--run", run_path, "--profile", profile(tmp, run_path.name, measurement=measurement),
    )  # fmt: skip
    run = RunDir.open(run_path)
    rows = []
    for j in run.complete_trials():
        record = run.read_trial(j)
        try:
            by_mocap = trial_errors(record.measured("mocap"))[0]
        except RunLogError:  # a grid point without mocap (said in the output)
            by_mocap = None
        rows.append(
            {
                "j": j,
                "epos_mocap_m": by_mocap,
                "epos_estimate_m": trial_errors(record)[0],
                "lag_s": run.read_status(j).extra.get("mocap_lag_s"),
            }
        )
    return {"measurement": measurement, "trials": rows}


def figures(out: Path, jitter: list[dict], learning: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    for i, r in enumerate(jitter):
        color = "tab:orange" if r["forward"] else "tab:blue"
        ax.bar(i - 0.2, r["dev_p50_ms"], 0.4, color=color, alpha=0.9)
        ax.bar(i + 0.2, r["dev_p99_ms"], 0.4, color=color, alpha=0.45)
    ax.set_xticks(
        range(len(jitter)),
        [f"{'on' if r['forward'] else 'off'} (seed {r['seed']})" for r in jitter],
    )
    ax.set_xlabel("forwarding (solid: median, light: 99th percentile)")
    ax.set_ylabel("|inter-arrival - 1/60 s| [ms]")
    fig.tight_layout()
    fig.savefig(out / "mocap-jitter.png", dpi=110)
    fig, ax = plt.subplots(figsize=(6.4, 3.2))
    for run, marker in zip(learning, ("o", "s"), strict=True):
        lag = [1e3 * t["lag_s"] for t in run["trials"] if t["lag_s"] is not None]
        ax.plot(range(len(lag)), lag, marker, label=f"learning on {run['measurement']}")
    ax.set_xlabel("trial j")
    ax.set_ylabel("estimate behind mocap [ms]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "mocap-lag.png", dpi=110)
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for run, color in zip(learning, ("tab:orange", "tab:blue"), strict=True):
        trials = run["trials"]
        j = [t["j"] for t in trials]
        m = run["measurement"]
        by_mocap = [
            np.nan if t["epos_mocap_m"] is None else t["epos_mocap_m"] for t in run["trials"]
        ]
        ax.plot(j, by_mocap, "-o", color=color,
                label=f"learning on {m}: e_pos by mocap")  # fmt: skip
        ax.plot(j, [t["epos_estimate_m"] for t in run["trials"]], "--x", color=color,
                label=f"learning on {m}: e_pos by estimate")  # fmt: skip
    ax.set_xlabel("trial j")
    ax.set_ylabel("e_pos [m]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "mocap-learning.png", dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=2)
    parser.add_argument("--iter", type=int, default=6)
    parser.add_argument("--figures", type=Path)
    parser.add_argument(
        "--jitter-from", type=Path, help="take the jitter flights' JSON lines from this log"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="gcs-mocap-bench-") as tmp_name:
        tmp = Path(tmp_name)
        jitter = []
        if args.jitter_from is not None:
            jitter = [
                json.loads(line)
                for line in args.jitter_from.read_text().splitlines()
                if line.startswith('{"forward"')
            ]
        for seed in range(args.pairs if not jitter else 0):
            for forward in (False, True):
                jitter.append(jitter_flight(tmp, forward, seed))
                r = jitter[-1]
                print(json.dumps({k: v for k, v in r.items() if k != "intervals_ms"}), flush=True)
        learning = [learning_flight(tmp, m, args.iter) for m in ("mocap", "estimate")]
    off = [r["dev_p50_ms"] for r in jitter if not r["forward"]]
    on = [r["dev_p50_ms"] for r in jitter if r["forward"]]
    p99_off = [r["dev_p99_ms"] for r in jitter if not r["forward"]]
    p99_on = [r["dev_p99_ms"] for r in jitter if r["forward"]]
    lags = [t["lag_s"] for run in learning for t in run["trials"] if t["lag_s"] is not None]
    summary = {
        "jitter_dev_p50_ms_off": float(np.median(off)),
        "jitter_dev_p50_ms_on": float(np.median(on)),
        "jitter_ratio_on_off": float(np.median(on) / np.median(off)),
        "jitter_dev_p99_ms_off": float(np.median(p99_off)),
        "jitter_dev_p99_ms_on": float(np.median(p99_on)),
        "lag_ms_median": 1e3 * float(np.median(lags)) if lags else None,
        "lag_ms_range": [1e3 * min(lags), 1e3 * max(lags)] if lags else None,
        "learning": learning,
    }  # fmt: skip
    print(json.dumps(summary, indent=1))
    if args.figures is not None:
        figures(args.figures, jitter, learning)


if __name__ == "__main__":
    main()
