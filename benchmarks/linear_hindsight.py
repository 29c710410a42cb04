"""How well any linear time-invariant model of a flight could have predicted its learned trials,
in hindsight: a bound on what a better model could do for the learning step.

Printed, not asserted. For every learning run given (run directories, or directories searched
for them) with trial 0 repeated: the measured positions of trial 0 and its repeats (identical
setpoints) give the repeatable response ``y0`` (their mean) and how far one flight of it
scatters about that mean (``scatter``: RMS over the trial of the horizontal distance,
corrected for the mean's own share, ``sqrt(n / (n - 1))``). Then, for each learned trial
``t``, an FIR model of ``--taps`` taps per input, both horizontal axes coupled (north and east
setpoint changes drive each output), is fitted by ridge least squares (``--ridge``) to every
other learned trial of the flight, its output change ``y_i - y0`` on its setpoint change
``u_i - u0``: the later trials included, which no learning step has. Its prediction of ``t``
misses by ``miss`` (RMS horizontal distance). Noise alone gives about ``scatter`` (trial
``t``'s own) and a little more (the mean ``y0``'s, the fit's); a ``miss`` well above it says
that no model of that class, however identified, foresaw the trial: the vehicle flew it
otherwise than its other trials.

Per trial: e_pos in floors (the run's floor), ``miss``, ``scatter``, their ratio. Usage:

    .venv/bin/python benchmarks/linear_hindsight.py RUN_OR_DIR ... [--taps 30] [--ridge 1.0]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from estimate_replay import find_runs
from scipy.linalg import toeplitz

from gcs.core.metrics import epos
from gcs.io.rundir import RunDir


def lagged(du: np.ndarray, taps: int) -> np.ndarray:
    """The regressors of a coupled FIR: ``du`` (N, 2) delayed by 0..taps-1 samples, (N, 2 taps)."""
    zeros = np.zeros(taps)
    return np.hstack([toeplitz(du[:, a], zeros) for a in range(du.shape[1])])


def hindsight_misses(
    u0: np.ndarray, y0: np.ndarray, learned: dict[int, tuple[np.ndarray, np.ndarray]],
    taps: int, ridge: float,
) -> dict[int, float]:  # fmt: skip
    """Leave-one-out misses [m] of the coupled FIR on the learned trials.

    Parameters
    ----------
    u0, y0 : ndarray, shape (N, 2)
        Trial 0's setpoints and the mean measured position of its flights [m, north/east].
    learned : dict
        Trial number -> (setpoints, measured position), each (N, 2) [m].
    taps : int
        FIR length per input [samples].
    ridge : float
        Ridge weight on the taps.

    Returns
    -------
    dict
        Trial number -> RMS horizontal distance of the prediction from the measurement [m].
    """
    out = {}
    for t in learned:
        others = [i for i in learned if i != t]
        if not others:
            continue
        x = np.vstack([lagged(learned[i][0] - u0, taps) for i in others])
        y = np.vstack([learned[i][1] - y0 for i in others])
        h = np.linalg.solve(x.T @ x + ridge * np.eye(x.shape[1]), x.T @ y)  # (2 taps, 2)
        pred = y0 + lagged(learned[t][0] - u0, taps) @ h
        out[t] = float(np.sqrt(np.mean(np.sum((learned[t][1] - pred) ** 2, axis=1))))
    return out


def run_rows(path: Path, taps: int, ridge: float) -> list[dict]:
    """One row per learned trial of the run (none when trial 0 was not repeated)."""
    run = RunDir.open(path)
    profile = run.profile()
    repeats = profile.learning.repeats
    done = run.complete_trials()
    if repeats < 1 or any(k not in done for k in range(repeats + 1)):
        return []
    ref = run.reference().pos_ned_m[1:, :2]
    floor_m = json.loads(run.floor_path.read_text())["epos_m"]

    def trial(k: int) -> tuple[np.ndarray, np.ndarray]:
        rec = run.measured_trial(k, profile.mocap.measurement)
        return rec.sp_ned_m[:-1, :2], rec.pos_ned_m[1:, :2]

    first = [trial(k) for k in range(repeats + 1)]
    u0 = first[0][0]
    y0 = np.mean([y for _, y in first], axis=0)
    n = len(first)
    scatter = float(
        np.sqrt(np.mean([np.mean(np.sum((y - y0) ** 2, axis=1)) for _, y in first]) * n / (n - 1))
    )
    learned = {}
    for k in sorted(done):
        if k > repeats and run.again_of(k) is None:
            learned[k] = trial(k)
    misses = hindsight_misses(u0, y0, learned, taps, ridge)
    return [
        {
            "run": str(path),
            "trial": t,
            "floors": epos(ref, learned[t][1]) / floor_m,
            "miss_m": miss,
            "scatter_m": scatter,
        }
        for t, miss in misses.items()
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", help="run directories, or directories holding them")
    parser.add_argument("--taps", type=int, default=30, help="FIR length per input [samples]")
    parser.add_argument("--ridge", type=float, default=1.0, help="ridge weight on the taps")
    args = parser.parse_args()
    rows = []
    for path in find_runs(args.paths):
        try:
            rows += run_rows(path, args.taps, args.ridge)
        except (OSError, ValueError) as exc:
            print(f"{path}: not read ({exc})", file=sys.stderr)
    if not rows:
        sys.exit("no learned trial after a repeated trial 0 in the runs given")
    print(f"coupled FIR, {args.taps} taps per input, ridge {args.ridge:g}, leave one trial out")
    print("| run | trial | e_pos [floors] | miss [m] | repeat scatter [m] | miss / scatter |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {Path(r['run']).name} | {r['trial']} | {r['floors']:.2f} | {r['miss_m']:.3f} "
            f"| {r['scatter_m']:.3f} | {r['miss_m'] / r['scatter_m']:.2f} |"
        )


if __name__ == "__main__":
    main()
