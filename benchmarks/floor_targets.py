"""How often a trial with nothing repeatable left meets the floor-ratio targets (mock or recorded).

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

Or, with ``--run DIR`` (once per run), the flights of identical setpoints a run recorded
(trial 0 and its repeats: ``learning.adaptive.repeats``), e.g. on real firmware in a lab
(``benchmarks/lab_floor_px4.py --profiles antx-adaptive+learning.adaptive.repeats=5 --iter
6``): each run's flights give their ``delta_i`` from their own mean, and the runs must be of
one point (the same noise; ``--within-run`` draws the trials from the floor's own run, as in
one flight session). Then the floor is drawn from ``--floor-flights`` flights of one
run, the trials from the others, and the targets are also those of the lab-floor test (two
trials, each within 2 floors of a floor from three flights) and of its goal (five trials, each
within 1.5 floors and their median within 1.25). ``--weights recorded`` gives each trial
j = 2..6 the estimate's trial weights the runs (or ``--weights-run`` ones) recorded for it:
a learner whose model foresaw everything, estimating as those runs did; ``--point-floor``
judges every trial against the point's floor (the median of the runs' floors) instead.

Nothing is asserted; the figures go to docs/results.md as they come out.

    .venv/bin/python benchmarks/floor_targets.py                        # indoor, the reference
    .venv/bin/python benchmarks/floor_targets.py --mock-config profiles/mock-gps.yaml
    .venv/bin/python benchmarks/floor_targets.py --setpoints logs/p5-live/x/setpoints-008.csv
    .venv/bin/python benchmarks/floor_targets.py --run RUN_A --run RUN_B --floor-flights 3
    .venv/bin/python benchmarks/floor_targets.py --run RUN_A --run RUN_B --floor-flights 4 \
        --weights recorded --weights-run RUN_A
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from mock_learning_offline import fly  # setpoint k at k t_ilc, 5 s settled at the start first

from gcs.core.floor import floor_flights, floor_from_flights
from gcs.core.metrics import epos
from gcs.core.trajectory import sample_eight
from gcs.io.config import load_trajectory
from gcs.io.rundir import RunDir
from gcs.mock.config import load_mock_config

ROOT = Path(__file__).resolve().parents[1]
T_ILC_S = 0.05


def _setpoints(path: Path | None, ref: np.ndarray) -> np.ndarray:
    if path is None:
        return ref[:-1].copy()
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    return table[:, 2:5]


def recorded_groups(runs: list[Path]) -> tuple[np.ndarray, list[np.ndarray]]:
    """The reference (N+1, 3) and, per run, its flights of trial 0's setpoints (K, N, 2) [m]."""
    groups, ref = [], None
    for path in runs:
        run = RunDir.open(path)
        ref = run.reference().pos_ned_m
        measurement = run.profile().mocap.measurement  # as gcs report measures it
        records = [run.measured_trial(t, measurement) for t in run.complete_trials()]
        group = floor_flights(np.array([r.sp_ned_m[:-1, :2] for r in records]))
        groups.append(np.array([records[i].pos_ned_m[1:, :2] for i in group]))
    assert ref is not None
    return ref, groups


def recorded_weights(runs: list[Path], iterations: range = range(2, 7)) -> list[np.ndarray]:
    """Per learned trial ``j`` in ``iterations``, the trial weights its estimate had in the runs
    (the learn record that made trial ``j``'s setpoints, each axis): their median over runs and
    axes, of the length most of them have (trial 0 and its repeats first, oldest first)."""
    found: dict[int, list[list[float]]] = {j: [] for j in iterations}
    for path in runs:
        for record in RunDir.open(path).learn_records().values():
            j = record["next_iteration"]
            if j in found:
                found[j] += [axis["noise"]["weights"] for axis in record["decision"]["axes"]]
    out = []
    for j in iterations:
        if not found[j]:
            raise SystemExit(f"no learn record made a trial j = {j} in these runs")
        lengths = [len(w) for w in found[j]]
        common = max(set(lengths), key=lengths.count)
        out.append(np.median([w for w in found[j] if len(w) == common], axis=0))
    return out


def flight_deltas(ys: np.ndarray) -> np.ndarray:
    """Each of ``K`` flights' non-repeatable part, ``sqrt(K / (K - 1)) (Y_i - mean Y)``
    (K, N, 2) [m] (docs/learning-floor.md, section 1)."""
    k = ys.shape[0]
    return np.sqrt(k / (k - 1)) * (ys - ys.mean(axis=0))


def targets(
    groups: list[np.ndarray],
    floor_flights_n: int,
    draws: int,
    weights: list[np.ndarray] | None = None,
    within: bool = False,
    seed: int = 0,
    point_floor_m: float | None = None,
) -> dict[str, float | None | list[float]]:
    """The chance that trials with nothing repeatable left meet each target, against a floor
    from ``floor_flights_n`` flights of one group and up to six trials from the other flights
    (``within``: of the same group only, as in one flight session; a target that needs more
    trials than there are is None).

    ``weights``: a learner whose model is right but whose estimate is the weighted mean of
    earlier flights (their non-repeatable parts, drawn from the other flights too): trial
    ``i``'s error is its flight's ``delta`` minus the mean weighted by ``weights[i]`` (of any
    other flights, the floor's too, as learning weighs trial 0 and its repeats), and there
    are as many trials as weight vectors (at most six); None: a perfect estimate.

    ``point_floor_m``: judge every draw against this floor [m] (e.g. the point's, the median
    of the groups' floors) instead of the drawn group's; the trials still come from flights
    other than those ``floor_flights_n`` drawn.
    """
    # (group, flight, one flight's non-repeatable part (N, 2))
    deltas = [(g, i, d) for g, ys in enumerate(groups) for i, d in enumerate(flight_deltas(ys))]
    by_key = {(h, i): d for (h, i, d) in deltas}
    ws = [np.zeros(0)] * 6 if weights is None else [np.asarray(w, float) for w in weights[:6]]
    rng = np.random.default_rng(seed)
    need = {"median3_within_1_15": 3, "max6_within_1_3": 6, "max2_within_2": 2, "goal5": 5}
    hits = dict.fromkeys(need, 0)
    ratios, counts, every = [], [], []
    for _ in range(draws):
        g = int(rng.integers(len(groups)))
        chosen = rng.permutation(groups[g].shape[0])[:floor_flights_n]
        floor = (
            floor_from_flights(groups[g][chosen]).epos_m if point_floor_m is None else point_floor_m
        )
        pool = [(h, i) for (h, i, _) in deltas if h == g or not within]
        rest = [k for k, (h, i) in enumerate(pool) if not (h == g and i in chosen)]
        if len(rest) < 2 or len(pool) < 1 + max(w.size for w in ws):
            raise SystemExit(f"{len(pool)} flights, {len(rest)} beside the floor's: too few")
        trials = []
        flights = rng.permutation(rest)[: len(ws)]  # distinct flights, one per trial
        for own, w in zip(flights, ws[: flights.size], strict=True):
            # the estimate's flights: any others, the floor's too (learning weighs trial 0
            # and its repeats as well; successive estimates share flights)
            others = [k for k in rng.permutation(len(pool)) if k != own][: w.size]
            mean = np.tensordot(w, np.array([by_key[pool[k]] for k in others]), axes=1)
            err = by_key[pool[own]] - mean
            trials.append(np.hypot(err[:, 0], err[:, 1]).mean() / floor)
        t = np.array(trials)
        counts.append(t.size)
        hits["median3_within_1_15"] += t.size >= 3 and np.median(t[:3]) <= 1.15
        hits["max6_within_1_3"] += t.size >= 6 and t.max() <= 1.3
        hits["max2_within_2"] += t[:2].max() <= 2.0
        hits["goal5"] += t.size >= 5 and t[:5].max() <= 1.5 and np.median(t[:5]) <= 1.25
        ratios.append(t[0])
        every.extend(t)
    out: dict[str, float | None | list[float]] = {
        k: (v / draws if min(counts) >= need[k] else None) for k, v in hits.items()
    }
    out["ratio_quantiles"] = [float(q) for q in np.quantile(ratios, [0.05, 0.5, 0.95])]
    out["share_above_1_5"] = float(np.mean(np.array(every) > 1.5))  # of all drawn trials
    return out


def _pct(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.0f} %"


def main_recorded(args: argparse.Namespace) -> None:
    """The targets of recorded flights (``--run``)."""
    _, groups = recorded_groups(args.run)
    if args.weights is None:
        weights = None
    elif args.weights == "recorded":
        weights = recorded_weights(args.weights_run or args.run)
        print(
            "the runs' trial weights, j = 2..6: "
            + "; ".join(",".join(f"{x:.2f}" for x in w) for w in weights)
        )
    else:
        weights = [np.array([float(x) for x in args.weights.split(",")])] * 6
    floors = [floor_from_flights(ys).epos_m for ys in groups]
    point_floor = float(np.median(floors)) if args.point_floor else None
    found = targets(
        groups, args.floor_flights, args.draws, weights, args.within_run, 0, point_floor
    )
    per_flight = [float(np.hypot(*d.T).mean()) for ys in groups for d in flight_deltas(ys)]
    out = {
        "runs": [str(r) for r in args.run], "flights": [len(ys) for ys in groups],
        "floor_m": floors, "perfect_trial_epos_mean_m": float(np.mean(per_flight)),
        "perfect_trial_epos_sd_m": float(np.std(per_flight, ddof=1)),
        "floor_flights": args.floor_flights, "weights": args.weights,
        "within_run": args.within_run, "point_floor_m": point_floor, **found,
    }  # fmt: skip
    f = float(np.mean(floors))
    print(
        f"{sum(out['flights'])} flights of identical setpoints in {len(groups)} runs: floors "
        + ", ".join(f"{1e3 * x:.1f}" for x in floors)
        + f" mm; a perfect trial's e_pos {1e3 * out['perfect_trial_epos_mean_m']:.1f} ± "
        f"{1e3 * out['perfect_trial_epos_sd_m']:.1f} mm "
        f"({100 * out['perfect_trial_epos_sd_m'] / f:.0f} % of the floor)\n"
        f"  {'perfect trials' if weights is None else 'trials, estimate weights ' + args.weights}"
        + (
            f" against the point's floor ({1e3 * point_floor:.1f} mm, the median of the runs')"
            if point_floor is not None
            else f" against a floor from {args.floor_flights} flights"
        )
        + ": e/floor 5-50-95 % "
        + " / ".join(f"{q:.2f}" for q in found["ratio_quantiles"])
        + f"; two within 2 floors (the lab-floor test): {_pct(found['max2_within_2'])}; "
        f"five within 1.5, median within 1.25 (its goal): {_pct(found['goal5'])}; "
        f"trials above 1.5: {_pct(found['share_above_1_5'])}; "
        f"median of 3 within 1.15: {_pct(found['median3_within_1_15'])}; none of 6 "
        f"above 1.3: {_pct(found['max6_within_1_3'])}"
        + (" (floor and trials of one run)" if args.within_run else "")
        + "\n"
    )
    if args.json is not None:
        args.json.write_text(json.dumps(out, indent=1) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mock-config", type=Path, default=None)
    parser.add_argument("--setpoints", type=Path, default=None, help="default: the reference")
    parser.add_argument("--flights", type=int, default=24)
    parser.add_argument("--seed", type=int, default=5000, help="gust seeds seed, seed + 1, ..")
    parser.add_argument("--draws", type=int, default=4000)
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument(
        "--run", type=Path, action="append", default=[], help="a recorded run (repeatable)"
    )
    parser.add_argument(
        "--floor-flights", type=int, default=3, help="flights of the floor (--run): 3 as shipped"
    )
    parser.add_argument(
        "--weights",
        default=None,
        help="--run: trials of a right model with an estimate of these trial weights (w1,w2,..;"
        " 'recorded': those the runs' estimates had at j = 2..6, one vector per trial)",
    )
    parser.add_argument(
        "--weights-run",
        type=Path,
        action="append",
        default=[],
        help="--weights recorded: the runs whose weights to take (repeatable; default --run)",
    )
    parser.add_argument(
        "--point-floor",
        action="store_true",
        help="--run: judge every trial against the point's floor (the median of the runs')",
    )
    parser.add_argument(
        "--within-run",
        action="store_true",
        help="--run: the trials from the floor's own run only (one flight session)",
    )
    args = parser.parse_args()
    if args.run:
        main_recorded(args)
        return
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
