"""Replay a recorded run directory through the learner: the same setpoints, computed again.

Reads a run directory that ``gcs fly`` (or ``gcs learn``) wrote, gives its trials one by one
to a learner made from the run's own profile and reference, and compares each learned
sequence with the setpoints the run recorded for the next trial. The run directory stores
setpoints with 9 significant digits, so the learned values are compared at that precision:
the largest difference is printed (and returned); on a run learnt by the paper's smoother or
with the profile's ``learning.adaptive`` options it is below 1e-9 m.

(K-ILC runs: ``gcs learn`` resumes the filter from the state it wrote after each trial, at the
file's precision, where this script carries it in memory; the two can differ in the file's
last digit, 1e-9 m.)

Run: ``python examples/replay_run.py RUN_DIR``
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from gcs import Learner
from gcs.io.runlog import RunDir


def replay(path: Path) -> float:
    """Largest difference [m] between the learned and the recorded setpoints of every trial."""
    run = RunDir.open(path)
    learner = Learner.from_profile(run.profile(), run.reference(), run.algorithm)
    worst = 0.0
    for j in run.complete_trials():
        trial = run.read_trial(j).measured("mocap")  # the mocap where the trial has it
        u_next = learner.step(trial.sp_ned_m[:-1, :2], trial.pos_ned_m[1:, :2])
        if not (run.path / f"setpoints-{j + 1:03d}.csv").exists():
            break  # the newest trial was not learnt from yet
        recorded = run.read_setpoints(j + 1)[:, :2]
        as_stored = np.array([[float(f"{v:.9g}") for v in row] for row in u_next])
        diff = float(np.max(np.abs(as_stored - recorded)))
        print(f"trial {j} -> {j + 1}: largest difference {diff:.2e} m")
        worst = max(worst, diff)
    return worst


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python examples/replay_run.py RUN_DIR")
    print(f"largest difference over the run: {replay(Path(sys.argv[1])):.2e} m")
