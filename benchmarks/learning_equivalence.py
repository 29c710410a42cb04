"""Learned setpoints of every learning regression case, this code against another commit.

Runs ``tests/learning_cases.py``'s cases (the record ``tests/data/learning-regression.npz``)
twice, each in a subprocess: with this tree's ``gcs`` and with a checkout of another commit
(default ``e238ce6``; ``git worktree add --detach`` under the temporary directory, as
``benchmarks/learn_step.py --code`` makes it), and captures every learned setpoint sequence
at full precision (the run directory stores 9 significant digits). Prints one line per case:
the largest absolute [m] and relative difference over its learned sequences.

Usage: ``python benchmarks/learning_equivalence.py [COMMIT]``
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def capture(code: Path, out: Path) -> None:
    """In this process: the cases with ``code``'s gcs, every learned sequence to ``out``."""
    sys.path[:0] = [str(code), str(code / "tests")]
    import learning_cases

    from gcs.io import rundir

    got: dict[str, np.ndarray] = {}
    original = rundir.RunDir._setpoints_text

    def recording(self, j: int, sp: np.ndarray) -> str:
        got[f"{self.path.parent.name}:{self.path.name}/{j:03d}"] = np.array(sp, dtype=float)
        return original(self, j, sp)

    rundir.RunDir._setpoints_text = recording
    learning_cases.learned()
    np.savez(out, **{k: v for k, v in got.items() if ".tmp" not in k})


def main() -> None:
    if len(sys.argv) == 4 and sys.argv[1] == "--capture":
        capture(Path(sys.argv[2]), Path(sys.argv[3]))
        return
    sys.path.insert(0, str(REPO / "benchmarks"))
    from learn_step import BASELINE_COMMIT, _baseline_tree

    commit = sys.argv[1] if len(sys.argv) > 1 else BASELINE_COMMIT
    base = _baseline_tree(commit)
    with tempfile.TemporaryDirectory() as tmp:
        files = {}
        for who, code in (("baseline", base), ("new", REPO)):
            files[who] = Path(tmp) / f"{who}.npz"
            cmd = [sys.executable, __file__, "--capture", str(code), str(files[who])]
            subprocess.run(cmd, check=True, capture_output=True)
        old, new = np.load(files["baseline"]), np.load(files["new"])
        cases: dict[str, list[float]] = {}
        for key in sorted(old.files):
            case = key.split(":")[0]
            worst = cases.setdefault(case, [0.0, 0.0])
            a, b = old[key], new[key]
            diff = float(np.max(np.abs(a - b)))
            worst[0] = max(worst[0], diff)
            worst[1] = max(worst[1], diff / max(float(np.max(np.abs(a))), 1e-300))
        for case, (absolute, relative) in cases.items():
            print(json.dumps({"case": case, "commit": commit, "max_abs_m": absolute,
                              "max_rel": relative}))  # fmt: skip
        if sorted(old.files) != sorted(new.files):
            print(json.dumps({"differing_sequences": sorted(set(old.files) ^ set(new.files))}))


if __name__ == "__main__":
    main()
