"""The vehicle's model across flights: how well one linear model per axis, fitted to some
flights' trials, foresees other flights' trials, against the profile's model and the models the
learning used.

Printed, not asserted. For every learning run given (run directories, or directories searched
for them) with trial 0 flown more than once: trial 0 and its repeats (identical setpoints) are
the anchor, their mean ``y0``; each learned trial ``t`` gives the pair ``dy = y_t - y0`` on
``du = u_t - u0``, the repeatable disturbance cancelled (section 5 of docs/learning-floor.md).
A pair's noise is one flight's non-repeatable error and the anchor mean's:
``sqrt(1 + 1/n0)`` times one flight's (measured from the anchor's flights, RMS per axis).

The runs are split into two halves (alternately, in path order). Per axis and half:

- the model fitted to every pair of one half (the output-error fit of the refresh, the model's
  own order, the delay searched from 4 samples below the profile's to 2 above), and its RMS
  error on each pair of the other half (a flight it never saw), beside the profile's model's,
  the pair itself (no model) and the noise: where the error meets the noise, one linear model
  foresees the vehicle on this manoeuvre to within what no model can;
- models fitted to the first ``k`` pairs of one flight (k = 1, 2, 3: what a refresh after j = k
  has), once against the anchor and once from consecutive trials as the shipped refresh
  pairs them (the anchor's mean, then each learned trial with the one before), scored alike;
- the models the learning itself used (``model-JJJ.yaml``, or the profile's where no refresh
  stood), and each refresh decision in ``learn-JJJ.json`` (accepted, or taken back to the
  profile's model): how it changed the model's error on the other half's flights.

Then per run: each learned trial's e_pos in floors (the run's floor) beside the error on the
other half of the models that planned it.

With ``--learn-again SETTINGS`` (``name=value`` of ``learning.adaptive``, comma-separated, e.g.
``refresh_anchor=true,refresh_takeback=false``), every run is also learnt again trial by trial
by a ``gcs.Learner`` from its own profile with those settings, on the trials as flown, and the
models its steps would have planned each trial with are scored the same way, beside the run's
own (the same steps), with each step's foresight of the trial it plans (RMS per axis, ``F u +
d_hat`` at the setpoints flown).

With ``--write-profile PATH`` the model fitted to every pair of every run is written as a
profile for flying it: ``--base`` (default ``profiles/antx-adaptive.yaml``) with its ``model``
and ``model_y`` replaced.

Usage: ``python benchmarks/model_across_flights.py RUN_OR_DIR ... [--json OUT]
[--write-profile PATH [--base PROFILE]] [--learn-again SETTINGS]``
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from estimate_replay import find_runs
from takeback_replay import flown_trials, relearn

from gcs.core.metrics import epos
from gcs.core.model import DiscreteModel
from gcs.core.refresh import (
    fit_output_error,
    model_from_transfer_function,
    simulate_tf,
    transfer_function,
)
from gcs.io.rundir import RunDir

ROOT = Path(__file__).resolve().parents[1]
AXES = ("north", "east")
KS = (1, 2, 3)


@dataclass(frozen=True)
class Flight:
    """One run: setpoints and positions (T, N, 2) [m], the anchor's size, what it learned."""

    name: str
    u_m: np.ndarray
    y_m: np.ndarray
    n0: int
    floors: dict[int, float]  # learned trial -> e_pos / floor
    planned_by: dict[int, tuple[DiscreteModel, DiscreteModel]]  # trial -> models planning it
    decisions: list[tuple[int, int, str, float, DiscreteModel, DiscreteModel]]
    profile_models: tuple[DiscreteModel, DiscreteModel]
    # trial -> (models planning it, foresight RMS per axis [m], the run's own foresight [m]),
    # learnt again (--learn-again)
    again: dict[int, tuple[tuple[DiscreteModel, ...], list[float], list[float]]] | None = None


def learn_again(path: Path, changes: dict) -> dict:
    """The run learnt again with ``changes`` to its ``learning.adaptive``: per learned trial,
    the models that would have planned it and the step's foresight of it per axis [m]."""
    run = RunDir.open(path)
    rows = relearn(run, flown_trials(run), changes)
    return {row["predicts"]: (row["models"], row["errors_m"]) for row in rows}


def read_flight(path: Path) -> Flight | None:
    """The run at ``path``, or None without a repeated trial 0 and a learned trial after it."""
    run = RunDir.open(path)
    profile = run.profile()
    trials = flown_trials(run)
    if len(trials) < 3:
        return None
    u = np.array([t.u_m for t in trials])
    y = np.array([t.y_m for t in trials])
    same = np.max(np.abs(u - u[0]), axis=(1, 2)) <= 1e-9
    n0 = int(np.argmin(same)) if not np.all(same) else len(trials)
    if n0 < 2 or n0 == len(trials):
        return None
    floor = run.read_floor()
    ref = run.reference().pos_ned_m[1:, :2]
    records = run.learn_records()
    in_use = profile.models()
    planned_by, decisions = {}, []
    for j in range(n0 - 1, len(trials) - 1):
        record = records.get(j)
        if record is None:
            break
        after = run.read_model(j) if record["model_file"] is not None else in_use
        for a, axis in enumerate(record["decision"]["axes"]):
            refresh = axis.get("refresh")
            if not isinstance(refresh, dict) or not refresh.get("accepted"):
                continue
            kind = "taken back" if refresh["reason"].startswith("taken back") else "accepted"
            decisions.append((j, a, kind, float(refresh["moved"]), in_use[a], after[a]))
        in_use = after
        planned_by[j + 1] = in_use
    floors = {t: epos(ref, y[t]) / floor["epos_m"] for t in planned_by} if floor else {}
    return Flight(str(path), u, y, n0, floors, planned_by, decisions, profile.models())


def same_model(m1: DiscreteModel, m2: DiscreteModel) -> bool:
    """Whether two models have one transfer function and delay."""
    (b1, a1), (b2, a2) = transfer_function(m1), transfer_function(m2)
    return m1.delay_samples == m2.delay_samples and np.allclose(np.r_[b1, a1], np.r_[b2, a2])


def anchor_pairs(f: Flight) -> tuple[np.ndarray, np.ndarray]:
    """``du, dy`` (P, N, 2): each learned trial against the anchor's mean."""
    return f.u_m[f.n0 :] - f.u_m[0], f.y_m[f.n0 :] - f.y_m[: f.n0].mean(axis=0)


def consecutive_pairs(f: Flight) -> tuple[np.ndarray, np.ndarray]:
    """``du, dy`` (P, N, 2) as the shipped refresh pairs trials: the anchor's last flight, then
    each learned trial, each against the one before."""
    u, y = f.u_m[f.n0 - 1 :], f.y_m[f.n0 - 1 :]
    return np.diff(u, axis=0), np.diff(y, axis=0)


def pair_noise_m(f: Flight) -> np.ndarray:
    """RMS noise of one anchor pair per axis (2,) [m]."""
    y0 = f.y_m[: f.n0]
    v = (y0 - y0.mean(axis=0)) * np.sqrt(f.n0 / (f.n0 - 1))
    return np.sqrt(np.mean(v**2, axis=(0, 1)) * (1 + 1 / f.n0))


def fit(
    du: np.ndarray, dy: np.ndarray, start: DiscreteModel, iterations: int
) -> DiscreteModel | None:
    """The output-error model of ``start``'s order fitted to pairs ``du, dy`` (P, N) of one
    axis, the delay searched; None when the best fit is unstable."""
    b0, a0 = transfer_function(start)
    d0, best = start.delay_samples, None
    for d in range(max(0, d0 - 4), d0 + 3):
        b, a, loss = fit_output_error(
            b0[None], a0[None], d, du[None], dy[None], np.ones((1, *du.shape), bool),
            max_iter=iterations, rowwise=True,
        )  # fmt: skip
        if best is None or loss[0] < best[0]:
            best = (loss[0], b[0], a[0], d)
    _, b, a, d = best
    if np.max(np.abs(np.roots(np.r_[1.0, a]))) >= 0.999:
        return None
    return model_from_transfer_function(b, a, start.dt_s, d)


def errors_m(model: DiscreteModel | None, f: Flight, axis: int) -> np.ndarray:
    """RMS error of ``model``'s foresight of each anchor pair of ``f`` (P,) [m]."""
    du, dy = anchor_pairs(f)
    if model is None:
        return np.full(du.shape[0], np.inf)
    b, a = transfer_function(model)
    sim = simulate_tf(b[None], a[None], model.delay_samples, du[None, ..., axis], rowwise=True)
    return np.sqrt(np.mean((sim[0] - dy[..., axis]) ** 2, axis=1))


def held_out_m(model: DiscreteModel | None, others: list[Flight], axis: int) -> float:
    """Median over the flights of the median pair error: a model's error on other flights."""
    return float(np.median([np.median(errors_m(model, f, axis)) for f in others]))


def memo_held_out_m(
    model: DiscreteModel, others: list[Flight], axis: int, known: dict[int, float]
) -> float:
    """:func:`held_out_m`, each model object scored once (``known``: by ``id``)."""
    if id(model) not in known:
        known[id(model)] = held_out_m(model, others, axis)
    return known[id(model)]


def pooled(flights: list[Flight], axis: int, start: DiscreteModel) -> DiscreteModel | None:
    du = np.concatenate([anchor_pairs(f)[0][..., axis] for f in flights])
    dy = np.concatenate([anchor_pairs(f)[1][..., axis] for f in flights])
    return fit(du, dy, start, 200)


def describe(model: DiscreteModel | None) -> str:
    if model is None:
        return "unstable"
    b, a = transfer_function(model)
    radius = np.max(np.abs(np.roots(np.r_[1.0, a])))
    return (
        f"delay {model.delay_samples}, DC gain {b.sum() / (1 + a.sum()):.2f}, "
        f"pole radius {radius:.3f}"
    )


def quantiles(values: list[float]) -> str:
    """Median and 10 / 90 % of errors [m]; an unstable fit (inf) reads "unstable"."""
    with np.errstate(invalid="ignore"):  # inf - inf between two unstable fits
        q = np.percentile(np.asarray(values), [50, 10, 90])
    med, lo, hi = (f"{v:.3f}" if np.isfinite(v) else "unstable" for v in q)
    return f"{med} (10/90 % {lo}/{hi})"


def study(flights: list[Flight]) -> dict:
    halves = [flights[0::2], flights[1::2]]
    out: dict = {"runs": [f.name for f in flights], "axes": {}}
    held: dict[tuple[str, int], float] = {}  # (run, trial) planning models' error, per axis
    for axis, name in enumerate(AXES):
        start = flights[0].profile_models[axis]
        ax: dict = {"halves": [], "fits": {}, "used": {"profile": [], "refreshed": []},
                    "decisions": {}}  # fmt: skip
        for h, own in enumerate(halves):
            others = halves[1 - h]
            # a model's score by its identity: a run's models are shared by the trials they
            # planned and the decisions that made them
            known: dict[int, float] = {}
            model = pooled(own, axis, start)
            ax["halves"].append({
                "model": describe(model),
                "pooled_m": held_out_m(model, others, axis),
                "profile_m": held_out_m(start, others, axis),
                "pair_m": float(np.median([np.median(np.sqrt(np.mean(
                    anchor_pairs(f)[1][..., axis] ** 2, axis=1))) for f in others])),
                "noise_m": float(np.median([pair_noise_m(f)[axis] for f in others])),
            })  # fmt: skip
            for k in KS:
                for kind, pairs in (("anchor", anchor_pairs), ("consecutive", consecutive_pairs)):
                    scores = ax["fits"].setdefault(f"{kind} k={k}", [])
                    for f in own:
                        du, dy = pairs(f)
                        if du.shape[0] >= k:
                            m = fit(du[:k, :, axis], dy[:k, :, axis], start, 40)
                            scores.append(held_out_m(m, others, axis))
            for f in own:
                for t, models in f.planned_by.items():
                    m = models[axis]
                    score = memo_held_out_m(m, others, axis, known)
                    same = same_model(m, f.profile_models[axis])
                    ax["used"]["profile" if same else "refreshed"].append(score)
                    held[(f.name, t, axis)] = score
                for t, (models, foresight, own_foresight) in (f.again or {}).items():
                    if t in f.planned_by and t - f.n0 >= 1:  # the steps planning j >= 2
                        ax.setdefault("again", []).append(
                            (held[(f.name, t, axis)], held_out_m(models[axis], others, axis),
                             foresight[axis], own_foresight[axis])
                        )  # fmt: skip
                for _, a, kind, moved, before, after in f.decisions:
                    if a == axis:
                        change = memo_held_out_m(after, others, axis, known) - memo_held_out_m(
                            before, others, axis, known
                        )
                        ax["decisions"].setdefault(kind, []).append((change, moved))
        out["axes"][name] = ax
    out["trials"] = [
        {"run": f.name, "trial": t, "floors": f.floors.get(t),
         "held_out_m": [held[(f.name, t, a)] for a in (0, 1)]}
        for f in flights for t in f.planned_by
    ]  # fmt: skip
    return out


def report(result: dict) -> list[str]:
    lines = []
    for name, ax in result["axes"].items():
        lines.append(f"{name}: the model of one half scored on the other half's flights "
                     "(median RMS error of a pair [m])")  # fmt: skip
        for h, row in enumerate(ax["halves"]):
            lines.append(
                f"  half {h}: {row['model']}; error {row['pooled_m']:.3f}, the profile's "
                f"{row['profile_m']:.3f}, no model {row['pair_m']:.3f}, noise {row['noise_m']:.3f}"
            )
        for key, scores in ax["fits"].items():
            lines.append(f"  one flight's first pairs, {key}: {quantiles(scores)} ({len(scores)})")
        for key, scores in ax["used"].items():
            if scores:
                lines.append(f"  the learning's models, {key}: {quantiles(scores)} ({len(scores)})")
        for kind, rows in ax["decisions"].items():
            change = np.array([c for c, _ in rows])
            large = np.array([c for c, moved in rows if moved > 1.0])
            lines.append(
                f"  refresh {kind}: {len(rows)}, error on the other half's flights "
                f"{np.sum(change < 0)} lower / {np.sum(change > 0)} higher, median change "
                f"{1e3 * np.median(change):+.0f} mm; moves above 100 %: {np.sum(large < 0)} "
                f"lower of {large.size}"
            )
    for name, ax in result["axes"].items():
        if "again" in ax:
            own, again, fore, own_fore = (np.array(v) for v in zip(*ax["again"], strict=True))
            lines.append(
                f"{name}, the steps planning j >= 2 learnt again with {result['learn_again']} "
                f"({len(own)}): error on the other half {quantiles(list(again))} against the "
                f"run's own {quantiles(list(own))}, lower in {np.sum(again < own)}, higher in "
                f"{np.sum(again > own)}; foresight of the trial planned {quantiles(list(fore))} "
                f"against the run's own {quantiles(list(own_fore))}"
            )
    lines.append("per run: learned trial, e_pos [floors], its models' error on the other half "
                 "(north/east) [m]")  # fmt: skip
    by_run: dict[str, list[str]] = {}
    for row in result["trials"]:
        fl = "-" if row["floors"] is None else f"{row['floors']:.2f}"
        n, e = row["held_out_m"]
        by_run.setdefault(row["run"], []).append(f"{row['trial']}: {fl} ({n:.3f}/{e:.3f})")
    for run, cells in by_run.items():
        lines.append(f"  {Path(run).parent.name}/{Path(run).name}: " + ", ".join(cells))
    return lines


def write_profile(flights: list[Flight], path: Path, base: Path) -> None:
    """The profile ``base`` with the models fitted to every pair of every run."""
    data = yaml.safe_load(base.read_text())
    for axis, key in enumerate(("model", "model_y")):
        m = pooled(flights, axis, flights[0].profile_models[axis])
        if m is None:
            sys.exit(f"the {AXES[axis]} model fitted to every run is unstable; no profile written")
        data[key] = {"A": m.A.tolist(), "B": m.B.tolist(), "C": m.C.tolist(),
                     "D": [[0.0]], "dt_s": m.dt_s, "delay_samples": m.delay_samples}  # fmt: skip
        print(f"{AXES[axis]} model of every run: {describe(m)}")
    data["name"] = f"{data.get('name', 'profile')}-across-flights"
    data["description"] = f"The models fitted to the trials of {len(flights)} runs."
    path.write_text(yaml.safe_dump(data, sort_keys=False))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", help="run directories, or directories holding them")
    parser.add_argument("--json", type=Path, help="write the figures here")
    parser.add_argument(
        "--learn-again", help="learn every run again with these learning.adaptive settings"
    )
    parser.add_argument("--write-profile", type=Path, help="write the model of every run here")
    parser.add_argument(
        "--base", type=Path, default=ROOT / "profiles" / "antx-adaptive.yaml",
        help="the profile whose models --write-profile replaces",
    )  # fmt: skip
    args = parser.parse_args()
    changes = {}
    for item in (args.learn_again or "").split(","):
        if item:
            name, _, value = item.partition("=")
            changes[name.strip()] = yaml.safe_load(value)
    flights = []
    for path in find_runs(args.paths):
        try:
            flight = read_flight(path)
        except (OSError, ValueError) as exc:
            print(f"{path}: not read ({exc})", file=sys.stderr)
            continue
        if flight is not None and changes:
            new, own = learn_again(path, changes), learn_again(path, {})
            again = {t: (*new[t], own[t][1]) for t in new if t in own}
            flight = dataclasses.replace(flight, again=again)
        if flight is not None:
            flights.append(flight)
    if len(flights) < 4:
        sys.exit("fewer than four runs with trial 0 repeated and a learned trial")
    lengths = {f.u_m.shape[1] for f in flights}
    if len(lengths) > 1:
        sys.exit(f"runs of different trajectories (samples {sorted(lengths)}); give one kind")
    result = study(flights)
    result["learn_again"] = args.learn_again
    print(f"{len(flights)} runs")
    print("\n".join(report(result)))
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))
    if args.write_profile:
        write_profile(flights, args.write_profile, args.base)


if __name__ == "__main__":
    main()
