"""The paper's method (Table I) against the data-driven options, offline on the mock's physics.

Flies the default eight through ``gcs.mock.physics.QuadPhysics`` directly (no network), as
``mock_learning_offline.py`` does: setpoint k commanded at k t_ilc, the reported position
sampled at k t_ilc, the vehicle hovering 5 s at the start point before each trial. Per seed:

* trial 0 (setpoints = the reference) is flown twice with different gust seeds: the two
  flights give the measured single-flight floor (``gcs.core.floor.floor_from_flights``);
* the paper's method (``--baseline-profile``, ``learning_step`` on the newest trial) and the
  new options (``--profile``'s ``learning.adaptive``, ``plan_next_trial`` on every trial,
  the repeat included) learn from that same trial 0; trial j of both is flown with the same
  gust seed (common random numbers), ``1000 seed + j + 1``; the repeat with ``1000 seed + 1``.

Prints per seed e_pos,j / e_pos,0 [%] for both, the floor [% of e_pos,0], median(j = 3..5) /
floor, the RMS and largest setpoint deviation from the reference per trial, and the decisions
of the new options (noise weights, refresh, safeguard, floor verdicts); then a summary.
Nothing is asserted: the figures go to the report as they come out.

Usage:
    .venv/bin/python benchmarks/mock_learning_adaptive.py [--seeds 0,1,2,3] [--trials 8]
        [--mock-config profiles/mock.yaml] [--gusts-off] [--profile profiles/antx-adaptive.yaml]
        [--baseline-profile profiles/antx.yaml] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from mock_learning_offline import fly  # the same flight: setpoint k at k t_ilc, 5 s hover first

from gcs.api import Learner, learner_settings
from gcs.core.floor import floor_from_flights
from gcs.core.learning import AdaptiveSettings
from gcs.core.metrics import epos
from gcs.core.trajectory import sample_eight
from gcs.io.config import Profile, load_profile, load_trajectory
from gcs.mock.config import MockConfig, load_mock_config

ROOT = Path(__file__).resolve().parents[1]


def flight_seed(seed: int, trial: int) -> int:
    """Gust seed of trial ``trial`` (-1: the repeat of trial 0)."""
    return 1000 * seed + (1 if trial < 0 else (0 if trial == 0 else trial + 1))


def run_seed(cfg: MockConfig, profile: Profile, baseline: Profile, seed: int, trials: int) -> dict:
    ref = sample_eight(load_trajectory(ROOT / "trajectories" / "eight.yaml").shape, profile.t_ilc_s)
    r3 = ref.pos_ned_m
    r2 = r3[:, :2]
    dt = profile.t_ilc_s
    u0 = r3[:-1].copy()
    y0 = fly(cfg, u0, r3[0], dt, flight_seed(seed, 0))
    y0b = fly(cfg, u0, r3[0], dt, flight_seed(seed, -1))
    floor = floor_from_flights(np.array([y0[1:, :2], y0b[1:, :2]]))

    # the paper's method: the newest trial
    learner = Learner(learner_settings(baseline), r2)
    sp, e_paper, sp_paper = u0.copy(), [], []
    pos = y0
    for j in range(trials):
        if j > 0:
            pos = fly(cfg, sp, r3[0], dt, flight_seed(seed, j))
        e_paper.append(epos(r2[1:], pos[1:, :2]))
        sp_paper.append(sp[:, :2] - r2[:-1])
        sp = np.column_stack([learner.step(sp[:, :2], pos[1:, :2]), r3[:-1, 2]])

    # the new options: every trial so far, the repeat of trial 0 included
    ad: AdaptiveSettings = profile.learning.adaptive
    learner = Learner(learner_settings(profile), r2, ad, repeats=1)
    learner.step(u0[:, :2], y0[1:, :2])  # trial 0; the next flight is its repeat
    last_sp, last_pos = u0[:, :2], y0b
    e_new, sp_new, decisions = [epos(r2[1:], y0[1:, :2])], [u0[:, :2] - r2[:-1]], []
    seconds = []
    for j in range(1, trials):
        t0 = time.perf_counter()
        u_ne = learner.step(last_sp, last_pos[1:, :2])
        seconds.append(time.perf_counter() - t0)
        decisions.append(_decisions(learner.decisions.as_dict()))
        sp = np.column_stack([u_ne, r3[:-1, 2]])
        pos = fly(cfg, sp, r3[0], dt, flight_seed(seed, j))
        e_new.append(epos(r2[1:], pos[1:, :2]))
        sp_new.append(sp[:, :2] - r2[:-1])
        last_sp, last_pos = sp[:, :2], pos
    learner.step(last_sp, last_pos[1:, :2])
    verdicts = learner.decisions.as_dict()["verdicts"]
    return {
        "seed": seed,
        "epos0_m": e_paper[0],
        "floor": floor.as_dict(),
        "paper_pct": [100 * e / e_paper[0] for e in e_paper],
        "new_pct": [100 * e / e_new[0] for e in e_new],
        "paper_med35_over_floor": float(np.median(e_paper[3:6]) / floor.epos_m),
        "new_med35_over_floor": float(np.median(e_new[3:6]) / floor.epos_m),
        "new_max_from2_over_floor": float(np.max(e_new[2:]) / floor.epos_m),
        "paper_sp_rms_m": [_rms(s) for s in sp_paper],
        "new_sp_rms_m": [_rms(s) for s in sp_new],
        "paper_sp_max_m": [float(np.max(np.abs(s))) for s in sp_paper],
        "new_sp_max_m": [float(np.max(np.abs(s))) for s in sp_new],
        "decisions": decisions,
        "verdicts_new": [
            (v["trial"], round(v["ratio"], 2), v["at_floor"], v["converged"]) for v in verdicts
        ],
        "plan_seconds_median": float(np.median(seconds)) if seconds else float("nan"),
    }


def _rms(dev: np.ndarray) -> float:
    """RMS of the horizontal setpoint deviation from the reference [m]."""
    return float(np.sqrt(np.mean(np.sum(dev**2, axis=1))))


def _decisions(rec: dict) -> dict:
    out = {"safeguard": rec["safeguard"] and rec["safeguard"]["action"]}
    for ax in rec["axes"]:
        noise, refresh = ax["noise"], ax["refresh"]
        out[ax["axis"]] = {
            "w_last": round(noise["weights"][-1], 2) if noise["weights"] else None,
            "r_mm": round(1e3 * np.sqrt(noise["r_m2"]), 1)
            if noise["r_m2"] == noise["r_m2"]
            else None,
            "kappa": noise["kappa"],
            "refresh": None
            if refresh is None
            else (refresh["accepted"], round(refresh["moved"], 3), refresh["reason"][:8]),
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2,3")
    parser.add_argument("--trials", type=int, default=8)
    parser.add_argument("--mock-config", type=Path, default=ROOT / "profiles" / "mock.yaml")
    parser.add_argument("--gusts-off", action="store_true")
    parser.add_argument("--profile", type=Path, default=ROOT / "profiles" / "antx-adaptive.yaml")
    parser.add_argument("--baseline-profile", type=Path, default=ROOT / "profiles" / "antx.yaml")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--verbose", action="store_true", help="print every decision")
    args = parser.parse_args()
    cfg = load_mock_config(args.mock_config)
    if args.gusts_off:
        cfg = replace(cfg, disturbance=replace(cfg.disturbance, gust_sigma_m_s2=0.0))
    profile, baseline = load_profile(args.profile), load_profile(args.baseline_profile)
    rows = []
    for seed in (int(s) for s in args.seeds.split(",")):
        row = run_seed(cfg, profile, baseline, seed, args.trials)
        rows.append(row)
        _print_seed(row, args.verbose)
    _print_summary(rows)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")


def _print_seed(row: dict, verbose: bool) -> None:
    f = row["floor"]
    e0 = row["epos0_m"]
    print(
        f"seed {row['seed']}: e_pos,0 {e0:.3f} m, floor {1e3 * f['epos_m']:.1f} mm "
        f"({100 * f['epos_m'] / e0:.2f} %), scatter {1e3 * f['scatter_m']:.1f} mm, "
        f"RMS {1e3 * f['rms_m']:.1f} mm; plan {row['plan_seconds_median']:.2f} s"
    )
    print("   j  paper %  new %   sp RMS paper/new [m]  sp max paper/new [m]")
    for j, (a, b) in enumerate(zip(row["paper_pct"], row["new_pct"], strict=True)):
        print(
            f"  {j:2d} {a:7.2f} {b:7.2f}   {row['paper_sp_rms_m'][j]:6.3f} / "
            f"{row['new_sp_rms_m'][j]:6.3f}       {row['paper_sp_max_m'][j]:6.3f} / "
            f"{row['new_sp_max_m'][j]:6.3f}"
        )
    print(
        f"  median(j=3..5)/floor: paper {row['paper_med35_over_floor']:.2f}, "
        f"new {row['new_med35_over_floor']:.2f}; new max(j>=2)/floor "
        f"{row['new_max_from2_over_floor']:.2f}"
    )
    print(f"  verdicts (new): {row['verdicts_new']}")
    if verbose:
        for j, d in enumerate(row["decisions"], start=1):
            print(f"  plan for trial {j}: {d}")


def _print_summary(rows: list[dict]) -> None:
    paper = [r["paper_med35_over_floor"] for r in rows]
    new = [r["new_med35_over_floor"] for r in rows]
    print(
        "summary median(j=3..5)/floor per seed: paper "
        + " ".join(f"{x:.2f}" for x in paper)
        + " | new "
        + " ".join(f"{x:.2f}" for x in new)
    )
    j3 = [(r["paper_pct"][3], r["new_pct"][3]) for r in rows if len(r["paper_pct"]) > 3]
    print("j = 3 [% of e_pos,0] paper / new: " + ", ".join(f"{a:.2f} / {b:.2f}" for a, b in j3))


if __name__ == "__main__":
    main()
