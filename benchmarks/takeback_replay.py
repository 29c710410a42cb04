"""Recorded learning runs learnt again with and without the take-back of a refreshed model
(``learning.adaptive.refresh_takeback``), or another of the refresh's options on and off
(``--option``; ``refresh_min_gain_z`` 0 and 1.645): what each would have predicted of the
trials flown.

Printed, not asserted. For every learning run given (run directories, or directories searched
for them; runs of ``learning.adaptive`` with the data-driven noise model and the refresh), the
trials as flown (up to the first that flies another's setpoints again) are learnt again by a
``gcs.Learner`` from the profile, trial by trial, once with ``refresh_takeback`` (or
``--option``) off and once on (everything else as the run's profile). After each step, its
models and estimate predict the next trial at the setpoints it flew (``F u + d_hat``, the step's
own plan), per axis, and are scored by the RMS error against what the trial measured.

The trials were flown with the setpoints of the run's own learning, so this compares the two
learnings' foresight on the same flights, not the trials they would have flown. With the option
off the replay is the run's learning when the run had it off: its estimates are checked
against the run's ``estimate-JJJ.csv`` (``max |replay - recorded|`` in the summary).

Per run: each judgement (trial, axis, z; ``back`` where the profile's model was taken back) and
the prediction errors of every step where the two learnings differ. Then over all runs: the
judgements, the take-backs, and for the steps that differ the ratio on / off of the prediction
errors.

Usage: ``python benchmarks/takeback_replay.py RUN_OR_DIR ... [--option refresh_pool_repeats]
[--json OUT]``
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
from estimate_replay import find_runs  # the same runs as the estimates' replay

from gcs.api import Learner, learner_settings
from gcs.core.learner import Trial
from gcs.core.learning import TAKEBACK_Z
from gcs.core.model import predicted_output
from gcs.io.rundir import RunDir

AXES = ("north", "east")


def flown_trials(run: RunDir) -> list[Trial]:
    """The complete trials in order, north and east, until one flies another's setpoints."""
    measurement = run.profile().mocap.measurement
    done, trials = set(run.complete_trials()), []
    while len(trials) in done and run.again_of(len(trials)) is None:
        rec = run.measured_trial(len(trials), measurement)
        trials.append(Trial(rec.sp_ned_m[:-1, :2], rec.pos_ned_m[1:, :2]))
    return trials


def learn_again(run: RunDir, trials: list[Trial], option: str, on: bool) -> list[dict]:
    """:func:`relearn` with ``option`` of the run's ``learning.adaptive`` set to ``on``
    (``refresh_min_gain_z``: 1.645 and 0)."""
    value = (TAKEBACK_Z if on else 0.0) if option == "refresh_min_gain_z" else on
    return relearn(run, trials, {option: value})


def relearn(run: RunDir, trials: list[Trial], changes: dict) -> list[dict]:
    """One row per learning step that plans a flown trial, with ``changes`` to the run's
    ``learning.adaptive``: its judgements, the models it planned the trial with and the RMS
    error of its prediction of that trial per axis [m]."""
    profile = run.profile()
    adaptive = dataclasses.replace(profile.learning.adaptive, **changes)
    ref = run.reference().pos_ned_m[:, :2]
    learner = Learner(
        learner_settings(profile, run.algorithm), ref, adaptive, profile.learning.repeats
    )
    start, rows = ref[0], []
    for t, trial in enumerate(trials[:-1]):
        learner.step(trial.u_m, trial.y_m)
        step = learner.last
        if step is None or step.record is None:
            continue  # a repeat of trial 0
        nxt = trials[t + 1]
        errors = [
            float(
                np.sqrt(
                    np.mean(
                        (
                            predicted_output(
                                step.models[a], nxt.u_m[:, a] - start[a], step.d_hat_m[:, a]
                            )
                            - (nxt.y_m[:, a] - start[a])
                        )
                        ** 2
                    )
                )
            )  # fmt: skip
            for a in (0, 1)
        ]
        judged = [
            (ax.refresh.takeback_z, ax.refresh.reason.startswith("taken back"))
            if ax.refresh is not None
            else (float("nan"), False)
            for ax in step.record.axes
        ]
        rows.append({"trial": t, "predicts": t + 1, "errors_m": errors, "judged": judged,
                     "d_hat_m": step.d_hat_m, "models": tuple(step.models)})  # fmt: skip
    return rows


def replay_run(path: Path, option: str = "refresh_takeback") -> dict | None:
    """Both learnings of one run, ``option`` off and on, or None when it is not a run of the
    data-driven refresh."""
    run = RunDir.open(path)
    adaptive = run.profile().learning.adaptive
    if adaptive is None or adaptive.noise != "data" or not adaptive.refresh:
        return None
    trials = flown_trials(run)
    off, on = learn_again(run, trials, option, False), learn_again(run, trials, option, True)
    diff = 0.0
    if not getattr(adaptive, option):
        for row in off:
            if run.estimate_path(row["trial"]).exists():
                recorded = run.read_estimate(row["trial"])[0][:, :2]
                diff = max(diff, float(np.max(np.abs(row["d_hat_m"] - recorded))))
    for row in off + on:
        del row["d_hat_m"], row["models"]
    return {"run": str(path), "trials": len(trials), "off": off, "on": on, "recorded_diff_m": diff}


def run_lines(result: dict) -> list[str]:
    """One line per judgement and per step whose prediction differs."""
    lines = [f"{result['run']}: {result['trials']} trials"]
    for off, on in zip(result["off"], result["on"], strict=True):
        for a, (z, back) in enumerate(on["judged"]):
            if np.isfinite(z):
                verdict = "back" if back else "kept"
                lines.append(f"  after trial {on['trial']}: {AXES[a]} z = {z:+.2f} ({verdict})")
        if off["errors_m"] != on["errors_m"]:
            pairs = ", ".join(
                f"{AXES[a]} {1e3 * off['errors_m'][a]:.0f} -> {1e3 * on['errors_m'][a]:.0f} mm"
                for a in (0, 1)
            )
            lines.append(f"  trial {on['predicts']} predicted: {pairs}")
    return lines


def summary(results: list[dict], option: str = "refresh_takeback") -> list[str]:
    """Judgements, take-backs, and the ratio on / off where the predictions differ."""
    z = [j[0] for r in results for row in r["on"] for j in row["judged"] if np.isfinite(j[0])]
    backs = sum(j[1] for r in results for row in r["on"] for j in row["judged"])
    ratios = [
        on["errors_m"][a] / off["errors_m"][a]
        for r in results
        for off, on in zip(r["off"], r["on"], strict=True)
        for a in (0, 1)
        if on["errors_m"][a] != off["errors_m"][a]
    ]
    lines = [
        f"{len(results)} runs; max |replay with {option} off - recorded estimate| "
        f"{max(r['recorded_diff_m'] for r in results):.1e} m",
        f"judgements {len(z)}: z quantiles 10/50/90 % "
        + ", ".join(f"{v:+.2f}" for v in np.percentile(z, [10, 50, 90]))
        if z
        else "judgements 0",
        f"taken back (z > {TAKEBACK_Z:.3f}): {backs}",
    ]
    if ratios:
        lines.append(
            f"predictions that differ: {len(ratios)}; error with / without {option}: "
            + ", ".join(f"{v:.2f}" for v in ratios)
        )
        lines.append(
            f"ratio median {np.median(ratios):.2f}, 10/90 % "
            + ", ".join(f"{v:.2f}" for v in np.percentile(ratios, [10, 90]))
            + f"; better with it in {sum(v < 1 for v in ratios)} of {len(ratios)}"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", help="run directories, or directories holding them")
    parser.add_argument(
        "--option",
        default="refresh_takeback",
        choices=("refresh_takeback", "refresh_minmax_step", "refresh_holdout",
                 "refresh_pool_repeats", "refresh_anchor", "refresh_min_gain_z"),
        help="the learning.adaptive option learnt again off and on (refresh_min_gain_z: 0 "
        "and 1.645)",
    )  # fmt: skip
    parser.add_argument("--json", type=Path, help="write every run's rows here")
    args = parser.parse_args()
    results = []
    for path in find_runs(args.paths):
        try:
            result = replay_run(path, args.option)
        except (OSError, ValueError) as exc:
            print(f"{path}: not replayed ({exc})", file=sys.stderr)
            continue
        if result is not None:
            results.append(result)
            print("\n".join(run_lines(result)), flush=True)
    if not results:
        sys.exit("no learning run with the data-driven refresh to replay")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    print()
    print("\n".join(summary(results, args.option)))


if __name__ == "__main__":
    main()
