"""How often a trial with nothing repeatable left meets the floor-ratio targets (offline, mock).

Flies one setpoint sequence ``--flights`` times through ``gcs.mock.physics.QuadPhysics`` (no
network; each flight with its own gust seed, the vehicle settled at the start first, as
``mock_learning_offline.py``). Flights of identical setpoints differ only by their
non-repeatable parts, so with K flights ``delta_i = sqrt(K / (K - 1)) (Y_i - mean Y)`` is
distributed exactly as one flight's non-repeatable error (docs/learning-floor.md, section 1),
and ``e_pos(delta_i)`` as the e_pos of a trial whose repeatable error is zero: the best any
learning can do. Against that:

* the scatter of such a trial's e_pos, and of the floor measured from one pair of flights
  (what ``gcs fly`` does with one repeat of trial 0);
* the chance that such perfect trials meet the floor-ratio targets when compared with a
  floor measured from one pair: median of three within 1.15 floors, and none of six above
  1.3 floors (random draws of disjoint flights);
* the e_pos of the sequence itself (mean over the flights) against the floor, and its
  repeatable part (the e_pos of the mean flight), e.g. for the setpoints a live run learned
  (``--setpoints run/setpoints-008.csv``).

Nothing is asserted; the figures go to docs/results.md as they come out.

    .venv/bin/python benchmarks/floor_targets.py                        # indoor, the reference
    .venv/bin/python benchmarks/floor_targets.py --mock-config profiles/mock-gps.yaml
    .venv/bin/python benchmarks/floor_targets.py --setpoints logs/p5-live/x/setpoints-008.csv
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from mock_learning_offline import fly  # setpoint k at k t_ilc, 5 s settled at the start first

from gcs.core.floor import floor_from_flights
from gcs.core.metrics import epos
from gcs.core.trajectory import sample_eight
from gcs.io.config import load_trajectory
from gcs.mock.config import load_mock_config

ROOT = Path(__file__).resolve().parents[1]
T_ILC_S = 0.05


def _setpoints(path: Path | None, ref: np.ndarray) -> np.ndarray:
    if path is None:
        return ref[:-1].copy()
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    return table[:, 2:5]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mock-config", type=Path, default=None)
    parser.add_argument("--setpoints", type=Path, default=None, help="default: the reference")
    parser.add_argument("--flights", type=int, default=24)
    parser.add_argument("--seed", type=int, default=5000, help="gust seeds seed, seed + 1, ..")
    parser.add_argument("--draws", type=int, default=4000)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    cfg = load_mock_config(args.mock_config)
    ref = sample_eight(load_trajectory(ROOT / "trajectories" / "eight.yaml").shape, T_ILC_S)
    r = ref.pos_ned_m
    sp = _setpoints(args.setpoints, r)
    k = args.flights
    ys = np.array([fly(cfg, sp, r[0], T_ILC_S, args.seed + i)[1:, :2] for i in range(k)])
    e_flown = np.array([epos(r[1:, :2], y) for y in ys])
    # the repeatable part: the mean flight's e_pos (its non-repeatable share shrinks as 1/sqrt(K))
    e_repeatable = epos(r[1:, :2], ys.mean(axis=0))
    delta = np.sqrt(k / (k - 1)) * (ys - ys.mean(axis=0))
    e_perfect = np.hypot(delta[..., 0], delta[..., 1]).mean(axis=1)  # e_pos of v alone
    floor_all = floor_from_flights(ys)
    pairs = [floor_from_flights(ys[[2 * i, 2 * i + 1]]) for i in range(k // 2)]
    pair_epos = np.array([f.epos_m for f in pairs])
    pair_scatter = np.array([f.scatter_m for f in pairs])
    rng = np.random.default_rng(0)
    med_ok, max_ok, ratios = 0, 0, []
    for _ in range(args.draws):
        pick = rng.permutation(k)
        floor = floor_from_flights(ys[pick[:2]]).epos_m
        three, six = e_perfect[pick[2:5]], e_perfect[pick[2:8]]
        med_ok += np.median(three) / floor <= 1.15
        max_ok += np.max(six) / floor <= 1.3
        ratios.append(e_perfect[pick[2]] / floor)
    out = {
        "mock_config": str(args.mock_config), "setpoints": str(args.setpoints), "flights": k,
        "floor_m": floor_all.epos_m, "floor_scatter_within_trial_m": floor_all.scatter_m,
        "perfect_trial_epos_mean_m": float(e_perfect.mean()),
        "perfect_trial_epos_sd_m": float(e_perfect.std(ddof=1)),
        "pair_floor_sd_m": float(pair_epos.std(ddof=1)),
        "pair_scatter_median_m": float(np.median(pair_scatter)),
        "flown_epos_mean_m": float(e_flown.mean()), "flown_epos_sd_m": float(e_flown.std(ddof=1)),
        "repeatable_epos_m": float(e_repeatable),
        "p_median3_within_1_15": med_ok / args.draws, "p_max6_within_1_3": max_ok / args.draws,
        "ratio_quantiles": [float(q) for q in np.quantile(ratios, [0.05, 0.5, 0.95])],
    }  # fmt: skip
    f = out["floor_m"]
    print(
        f"{k} flights of {args.setpoints or 'the reference'} on "
        f"{args.mock_config or 'the default mock'}:\n"
        f"  floor (all flights) {1e3 * f:.1f} mm; a perfect trial's e_pos "
        f"{1e3 * out['perfect_trial_epos_mean_m']:.1f} ± {1e3 * out['perfect_trial_epos_sd_m']:.1f}"
        f" mm ({100 * out['perfect_trial_epos_sd_m'] / f:.0f} %); the within-trial scatter "
        f"estimate {1e3 * out['floor_scatter_within_trial_m']:.1f} mm (one pair: median "
        f"{1e3 * out['pair_scatter_median_m']:.1f} mm)\n"
        f"  the floor from one pair scatters by {1e3 * out['pair_floor_sd_m']:.1f} mm "
        f"({100 * out['pair_floor_sd_m'] / f:.0f} %)\n"
        f"  the sequence flown: e_pos {1e3 * out['flown_epos_mean_m']:.1f} ± "
        f"{1e3 * out['flown_epos_sd_m']:.1f} mm = {out['flown_epos_mean_m'] / f:.2f} floors; "
        f"its repeatable part (the mean flight's e_pos) {1e3 * e_repeatable:.1f} mm\n"
        f"  perfect trials against a floor from one pair: e/floor 5-50-95 % "
        + " / ".join(f"{q:.2f}" for q in out["ratio_quantiles"])
        + f"; median of 3 within 1.15: {100 * out['p_median3_within_1_15']:.0f} %; "
        f"none of 6 above 1.3: {100 * out['p_max6_within_1_3']:.0f} %"
    )
    if args.json is not None:
        args.json.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
