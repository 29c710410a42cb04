"""Learning on at the floor, against holding or halving the steps there (offline, mock).

Two policies one might expect to keep learning at its floor, each against the learner as
shipped (which takes the whole update after every trial):

* ``hold``: once the newest learned trial's verdict is "converged" (it and the learned trial
  before it at the floor, their mean within one scatter of it:
  ``gcs.core.floor.floor_verdicts``), stop updating and fly that trial's setpoints again for as
  long as each such flight stays at the floor; learn again from the first that does not.
  Nothing moves while it holds, so no step can chase the estimate's noise or a model's miss.
* ``half``: once any trial has been called converged, take half of each update from the newest
  setpoints (a learning gain of 0.5 at the floor).

All fly the packaged eight through ``gcs.mock.physics.QuadPhysics`` directly (no network, as
``mock_learning_offline.py``: setpoint k commanded at k t_ilc, the vehicle settled 5 s at the
start first), with ``--profile`` (``learning.adaptive``, its ``repeats``): trial 0 and its
repeats, then ``--trials`` learned trials; flight ``i`` of a seed has the gust seed
``1000 seed + i`` in each (common random numbers, so they agree until a policy first acts).
Trials are given in floors of the learner's floor (from trial 0's flights). Printed per seed
and summed up (j = 2..6 as the lab benchmark's goal counts them, j = 2..end, the last four);
nothing is asserted.

    .venv/bin/python benchmarks/hold_at_floor.py [--seeds 0,1,2,3,4,5,6,7] [--trials 10]
        [--policies hold,half]
        [--mock-config profiles/mock.yaml] [--profile profiles/antx-adaptive.yaml] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from mock_learning_offline import fly  # setpoint k at k t_ilc, 5 s settled at the start first

from gcs.api import Learner, learner_settings
from gcs.core.floor import first_flights
from gcs.core.metrics import epos
from gcs.core.trajectory import sample_eight
from gcs.io.config import Profile, load_profile, load_trajectory
from gcs.mock.config import MockConfig, load_mock_config

ROOT = Path(__file__).resolve().parents[1]


def held_setpoints(learner: Learner) -> np.ndarray | None:
    """The converged learned trial's setpoints while every flight of them is at the floor,
    else None (learn on). From the learner's newest decisions."""
    record = learner.decisions
    if record is None or not record.verdicts:
        return None
    first = first_flights(np.array([t.u_m for t in learner.history]))
    learned = [j for j, f in enumerate(first) if f == j and j > learner.repeats]
    if not learned or not record.verdicts[learned[-1]].converged:
        return None
    newest = learned[-1]
    flights = [k for k, f in enumerate(first) if f == newest]
    if all(record.verdicts[k].at_floor for k in flights):
        return learner.history[newest].u_m.copy()
    return None


def converged_once(learner: Learner) -> bool:
    """Whether any trial so far has been called converged (the learner's newest decisions)."""
    record = learner.decisions
    return record is not None and any(v.converged for v in record.verdicts)


def run_seed(cfg: MockConfig, profile: Profile, seed: int, trials: int, policy: str) -> dict:
    """One seed's flights under ``policy`` (``"learn on"``, ``"hold"``, ``"half"``): e_pos of
    the learned trials in floors, and which the policy changed."""
    ref = sample_eight(load_trajectory(ROOT / "trajectories" / "eight.yaml").shape, profile.t_ilc_s)
    r3 = ref.pos_ned_m
    repeats = profile.learning.repeats
    learner = Learner(learner_settings(profile), r3[:, :2], profile.learning.adaptive, repeats)
    sp, e, acted_at = r3[:-1].copy(), [], [False]
    for i in range(repeats + 1 + trials):
        pos = fly(cfg, sp, r3[0], profile.t_ilc_s, 1000 * seed + i)
        e.append(epos(r3[1:, :2], pos[1:, :2]))
        u = learner.step(sp[:, :2], pos[1:, :2])
        acted = False
        if policy == "hold" and (again := held_setpoints(learner)) is not None:
            u, acted = again, True
        elif policy == "half" and i > repeats and converged_once(learner):
            u, acted = sp[:, :2] + 0.5 * (u - sp[:, :2]), True
        acted_at.append(acted)
        sp = np.column_stack([u, r3[:-1, 2]])
    assert learner.floor is not None
    floor = learner.floor.epos_m
    return {
        "seed": seed,
        "policy": policy,
        "floor_m": floor,
        "floors": [x / floor for x in e[repeats + 1 :]],
        "acted": acted_at[repeats + 1 : -1],
    }


def summary(rows: list[dict]) -> str:
    """One line: j = 2..6, j = 2..end and the last four, in floors."""
    f = np.array([r["floors"] for r in rows])
    goal = sum(1 for x in f[:, 1:6] if x.max() <= 1.5 and np.median(x) <= 1.25)
    return (
        f"j = 2..6 median {np.median(f[:, 1:6]):.2f}, largest {f[:, 1:6].max():.2f}, "
        f"above 1.5 {(f[:, 1:6] > 1.5).sum()}/{f[:, 1:6].size}, goal met {goal}/{len(rows)}; "
        f"j = 2..{f.shape[1]} median {np.median(f[:, 1:]):.2f}, above 1.5 "
        f"{(f[:, 1:] > 1.5).sum()}/{f[:, 1:].size}; the last four: median "
        f"{np.median(f[:, -4:]):.2f}; set by the policy {sum(sum(r['acted']) for r in rows)}"
    )


def main() -> None:
    """Fly every seed both ways and print."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="0,1,2,3,4,5,6,7")
    ap.add_argument("--trials", type=int, default=10, help="learned trials after trial 0's")
    ap.add_argument("--mock-config", type=Path, default=ROOT / "profiles" / "mock.yaml")
    ap.add_argument("--profile", type=Path, default=ROOT / "profiles" / "antx-adaptive.yaml")
    ap.add_argument("--policies", default="hold,half", help="against learning on")
    ap.add_argument("--json", type=Path, help="write every row here")
    args = ap.parse_args()
    cfg, profile = load_mock_config(args.mock_config), load_profile(args.profile)
    policies = ["learn on", *(p for p in args.policies.split(",") if p)]
    rows = []
    for seed in (int(s) for s in args.seeds.split(",")):
        for policy in policies:
            row = run_seed(cfg, profile, seed, args.trials, policy)
            rows.append(row)
            marks = ["*" if h else "" for h in row["acted"]]
            cells = " ".join(f"{x:.2f}{m}" for x, m in zip(row["floors"], marks, strict=True))
            print(f"seed {seed} {policy:8s} floor {1000 * row['floor_m']:.1f} mm  j = 1..: {cells}")
    print("(* the policy set these setpoints: held, or half the update)")
    for policy in policies:
        print(f"{policy}: {summary([r for r in rows if r['policy'] == policy])}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
