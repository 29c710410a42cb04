"""Why our e_pos,0 (0.91 m) is twice the paper's (0.422 m): the eight's timing, not the vehicle.

The paper gives its eight only as "vmax 2.1 m/s, amax 4 m/s^2, starting and ending in hover".
e_pos,0 is the mean over all N samples (eq. 10), so it also depends on how much of the trial is
hover and ramp, which the paper does not state. This script flies eq. (11) itself (the paper's
model of its own vehicle, validated on its flights) with the setpoints equal to the reference
(trial 0) on variants of ``trajectories/eight.yaml`` that keep vmax and amax, and prints e_pos,0.

Usage: .venv/bin/python benchmarks/eight_initial_error.py
Output: one JSON line per variant: the fields changed, duration [s], vmax [m/s], amax [m/s^2],
e_pos,0 [m].
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from gcs.core.metrics import epos
from gcs.core.model import DiscreteModel, simulate
from gcs.core.trajectory import EightShape, sample_eight
from gcs.io.config import load_profile, load_trajectory

ROOT = Path(__file__).resolve().parents[1]
VARIANTS: tuple[dict[str, float], ...] = (
    {},
    {"loops": 1},
    {"hover_s": 3.0},
    {"ramp_s": 3.0},
    {"loops": 1, "hover_s": 3.0, "ramp_s": 3.0},
)


def initial_error(shape: EightShape, model: DiscreteModel) -> dict[str, float]:
    """Duration, vmax, amax and e_pos,0 of ``model`` flying ``shape`` with U_0 = reference."""
    t_ilc_s = model.dt_s
    r = sample_eight(shape, t_ilc_s).pos_ned_m[:, :2]
    y = r[0] + simulate(model, r[:-1] - r[0])  # from hover at the start point
    v = np.diff(r, axis=0) / t_ilc_s
    a = np.diff(v, axis=0) / t_ilc_s
    return {
        "duration_s": round(len(r) * t_ilc_s, 2),
        "vmax_m_s": round(float(np.hypot(*v.T).max()), 2),
        "amax_m_s2": round(float(np.hypot(*a.T).max()), 2),
        "epos0_m": round(epos(r[1:], y), 3),
    }


def main() -> None:
    model = load_profile(ROOT / "profiles" / "antx.yaml").model_x  # eq. (11)
    shape = load_trajectory(ROOT / "trajectories" / "eight.yaml").shape
    for changed in VARIANTS:
        row = {"changed": changed, **initial_error(replace(shape, **changed), model)}
        print(json.dumps(row))


if __name__ == "__main__":
    main()
