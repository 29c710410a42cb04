"""Learning at the floor when the non-repeatable error is correlated in time (a vehicle's wander).

A vehicle in a lab wanders by decimetres in hover, slowly: its non-repeatable error is
correlated over seconds, not white as the Monte Carlo studies draw it. This benchmark flies
the same synthetic vehicle with both kinds, through the public learner (:class:`gcs.Learner`),
the paper's profile (``antx``) and the adaptive one (``antx-adaptive``), and prints each run's
e_pos in floors per trial (trials 1..repeats of ``antx-adaptive`` repeat trial 0), then, per
profile and correlation, the median and largest e_pos in floors over the iterations j >= 2 of
every seed, and the adaptive learner's decisions, so that what time correlation
does to learning at the floor can be read off.

The vehicle: ``tests/synthetic.py``'s plants (10-20 % off the profile's eq. (11)), the default
eight (N = 280 at 0.05 s, north and east), a repeatable disturbance of 5 cm
(``0.05 sin(0.7 t + axis)^2``) and, per axis and flight, a non-repeatable error of standard
deviation ``--sigma`` [m]: white noise averaged over ``corr`` seconds (a moving average,
rescaled to keep the standard deviation; ``corr`` = 0.05 s is white at this grid). Each run is
seeded by its index: every run is reproducible.

The floor of a line is the non-repeatable error's own e_pos, ``sigma sqrt(pi / 2)`` (the
expected mean distance of a 2-D Gaussian error with that standard deviation per axis), the
same for both profiles and every correlation; ``est`` is the floor the adaptive learner
estimated from trial 0 and its repeats, in the same units. After ``|``: per learning step,
the refresh's accepted model moves [%] north/east (``-`` kept, ``B`` taken back), ``R`` when
the safeguard fell back.

``--vary FIELD=V1,V2`` flies the adaptive profile once per value of its
``learning.adaptive.FIELD`` (YAML scalars: ``refresh_takeback=false,true``,
``refresh_min_gain_z=0,1.645``, ``refresh_noise=white,measured``); given several times, once
per combination. Every variant flies the same seeds, so the same wander. The summary adds, per
variant, the refresh's accepted moves and those taken back, the steps the minmax bound cut,
the refreshes not adopted (``refresh_holdout``) and the model's error after the last refresh,
``max |F / F_true - 1|`` over the learning band of the true plant (the quantity that decides
convergence), largest over the two axes.

``--latency L`` [s] delays what the learner measures by ``L`` (rounded to samples): a lab's
motion-to-frame latency that the model does not hold (the refresh may find it: it searches the
model's delay within +-2 samples).

``--plants off35`` flies plants 35 % off the profile's model instead (``max |F_model / F_true -
1|`` over the learning band: 0.35 north, 0.35 east, against 0.22 and 0.18 for the tests'
plants), where the refresh has a model to correct.

Usage::

    .venv/bin/python benchmarks/floor_correlated_noise.py [--sigma 0.1] [--corr 0.05,0.75,2.0]
        [--seeds 4] [--trials 16] [--plants tests] [--latency 0.05]
        [--vary refresh_takeback=false,true ...] [--json out.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from synthetic import true_plants  # noqa: E402

from gcs import Learner  # noqa: E402
from gcs.core.learning import AdaptiveSettings  # noqa: E402
from gcs.core.model import from_transfer_function, simulate  # noqa: E402
from gcs.core.refresh import model_change, transfer_function  # noqa: E402
from gcs.core.trajectory_sources import sample_reference  # noqa: E402
from gcs.io.config import load_trajectory  # noqa: E402

DT_S = 0.05


def wander(rng: np.random.Generator, n: int, sigma_m: float, corr_s: float) -> np.ndarray:
    """White noise averaged over ``corr_s`` [s], standard deviation ``sigma_m`` [m], shape (n,)."""
    w = max(1, int(round(corr_s / DT_S)))
    x = np.convolve(rng.standard_normal(n + 4 * w), np.ones(w), mode="same")[2 * w : 2 * w + n]
    return sigma_m * x / np.sqrt(w)


#: Plants 35 % off eq. (11) over the learning band (north faster and less damped, east slower).
OFF35 = (
    from_transfer_function([0.1, 2.4], [1.0, 1.5, 2.5], 0.25, DT_S),
    from_transfer_function([0.07, 1.75], [1.0, 2.1, 1.75], 0.25, DT_S),
)


def model_error(model, plant, band_gain2: float) -> float:
    """``max |F_model / F_plant - 1|`` where ``|F_plant|^2 >= band_gain2``."""
    bp, ap = transfer_function(plant)
    bm, am = transfer_function(model)
    return float(
        model_change(bp[None], ap[None], bm[None], am[None], plant.delay_samples, DT_S,
                     band_gain2, model.delay_samples)[0]
    )  # fmt: skip


def run(
    profile: str,
    sigma_m: float,
    corr_s: float,
    seed: int,
    trials: int,
    plants: str = "tests",
    latency_s: float = 0.0,
    fields: dict | None = None,
) -> dict:
    """One run of ``trials`` flights; e_pos per trial [m] and the learner's decisions.
    ``fields`` set fields of the adaptive profile's ``learning.adaptive``."""
    ref = sample_reference(load_trajectory(ROOT / "trajectories" / "eight.yaml").shape, DT_S)
    ref = ref.pos_ned_m[:, :2]
    n = ref.shape[0] - 1
    t_s = np.arange(1, n + 1) * DT_S
    plants = true_plants() if plants == "tests" else OFF35
    rng = np.random.default_rng(seed)
    learner = Learner.from_profile(profile, ref)
    if fields and learner.adaptive is not None:
        learner.adaptive = dataclasses.replace(learner.adaptive, **fields)
    u = ref[:-1].copy()
    lag = int(round(latency_s / DT_S))
    epos, steps = [], []
    for _ in range(trials):
        y = np.column_stack(
            [ref[0, a] + simulate(plants[a], np.r_[np.zeros(lag), u[: n - lag, a] - ref[0, a]])
             + 0.05 * np.sin(0.7 * t_s + a) ** 2 + wander(rng, n, sigma_m, corr_s)
             for a in range(2)]
        )  # fmt: skip
        epos.append(float(np.mean(np.hypot(*(y - ref[1:]).T))))
        u = learner.step(u, y)
        if learner.decisions is not None:
            rec = learner.decisions.as_dict()
            moved = [
                round(100 * ax["refresh"]["moved"]) if ax["refresh"]["accepted"] else None
                for ax in rec["axes"]
            ]
            back = [
                bool(ax["refresh"]) and ax["refresh"]["reason"].startswith("taken back")
                for ax in rec["axes"]
            ]
            steps.append(
                {"moved_pct": moved, "taken_back": back, "safeguard": rec["safeguard"]["action"],
                 "minmax_step": [ax["minmax_step"] for ax in rec["axes"]],
                 "not_adopted": [bool(ax["refresh"]) and "not adopted" in ax["refresh"]["reason"]
                                 for ax in rec["axes"]]}
            )  # fmt: skip
    floor = learner.floor
    w = learner.settings.weights
    errors = [model_error(learner.models[a], plants[a], w.wdu / w.we) for a in range(2)]
    return {
        "profile": label(profile, fields or {}),
        "model_error": errors,
        "sigma_m": sigma_m,
        "corr_s": corr_s,
        "latency_s": lag * DT_S,
        "seed": seed,
        "floor_m": sigma_m * float(np.sqrt(np.pi / 2)),
        "floor_estimate_m": floor.epos_m if floor is not None else None,
        "repeats": learner.repeats,
        "epos_m": epos,
        "steps": steps,
    }


def label(profile: str, fields: dict) -> str:
    """A variant's name: the profile, then the fields it sets."""
    return "/".join([profile] + [f"{k}={yaml.safe_dump(v).split()[0]}" for k, v in fields.items()])


def line(r: dict) -> str:
    f = r["floor_m"]
    est = f"{r['floor_estimate_m'] / f:.2f}" if r["floor_estimate_m"] else "-"
    moves = " ".join(
        "/".join(
            "-" if m is None else ("B" if b else str(m))
            for m, b in zip(s["moved_pct"], s.get("taken_back", (False, False)), strict=True)
        )
        + ("R" if s["safeguard"] == "revert" else "")
        for s in r["steps"]
    )
    floors = " ".join(f"{e / f:.2f}" for e in r["epos_m"])
    head = f"{r['profile']:22s} corr {r['corr_s']:4.2f} s seed {r['seed']} est {est}"
    return f"{head} | {floors} | {moves}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sigma", type=float, default=0.1, help="non-repeatable std per axis [m]")
    parser.add_argument("--corr", default="0.05,0.75,2.0", help="correlation times [s]")
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--trials", type=int, default=16)
    parser.add_argument("--plants", choices=("tests", "off35"), default="tests")
    parser.add_argument("--latency", type=float, default=0.0, help="measurement latency [s]")
    parser.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="FIELD=V1,V2",
        help="fly the adaptive profile once per value of learning.adaptive.FIELD; "
        "several: once per combination",
    )
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    known = {f.name for f in dataclasses.fields(AdaptiveSettings)}
    axes = []
    for spec in args.vary:
        name, _, values = spec.partition("=")
        if name not in known or not values:
            parser.error(f"--vary {spec}: not FIELD=V1,V2 with FIELD one of learning.adaptive's")
        axes.append([(name, yaml.safe_load(v)) for v in values.split(",")])
    variants = [("antx", {})] + [("antx-adaptive", dict(c)) for c in itertools.product(*axes)]
    labels = [label(*v) for v in variants]
    runs = []
    t0 = time.monotonic()
    for corr in (float(c) for c in args.corr.split(",")):
        for profile, fields in variants:
            for seed in range(args.seeds):
                runs.append(
                    run(profile, args.sigma, corr, seed, args.trials, args.plants, args.latency,
                        fields)
                )  # fmt: skip
                print(line(runs[-1]), flush=True)
    summary = []
    for corr in sorted({r["corr_s"] for r in runs}):
        for profile in labels:
            rs = [r for r in runs if r["corr_s"] == corr and r["profile"] == profile]
            # j >= 2: the iteration counts learning updates (a repeat is a flight of j = 0)
            late = [e / r["floor_m"] for r in rs for e in r["epos_m"][2 + r["repeats"] :]]
            summary.append(
                {
                    "profile": profile,
                    "corr_s": corr,
                    "median_floors_j3_on": float(np.median(late)),
                    "max_floors_j3_on": float(np.max(late)),
                }  # fmt: skip
            )
            extra = ""
            if profile != "antx":
                moves = [m for r in rs for st in r["steps"] for m in st["moved_pct"] if m]
                err = [100 * max(r["model_error"]) for r in rs]
                backs = sum(b for r in rs for st in r["steps"] for b in st["taken_back"])
                cut = [f for r in rs for st in r["steps"] for f in st["minmax_step"] if f < 1]
                held = sum(b for r in rs for st in r["steps"] for b in st["not_adopted"])
                extra = (
                    f"; moves accepted {len(moves)}, largest {max(moves, default=0)} %, "
                    f"taken back {backs}; steps cut {len(cut)} (median "
                    f"{np.median(cut) if cut else 1:.2f}); not adopted {held}; "
                    f"model error at the end {' '.join(f'{e:.0f}' for e in err)} %"
                )
            print(
                f"{profile:22s} corr {corr:4.2f} s: j >= 2, median "
                f"{summary[-1]['median_floors_j3_on']:.2f} floors, largest "
                f"{summary[-1]['max_floors_j3_on']:.2f} ({len(rs)} runs){extra}"
            )
    print(f"{time.monotonic() - t0:.0f} s")
    if args.json:
        args.json.write_text(json.dumps({"runs": runs, "summary": summary}, indent=1))


if __name__ == "__main__":
    main()
