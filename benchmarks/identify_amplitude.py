"""Why the identification amplitude matters on the mock drone, offline (no network).

The mock's closed loop depends on the amplitude (quadratic drag, the position-dependent field),
so a model identified from a small excitation around hover describes a different loop from the
one that flies the eight. For each PRBS level this script

1. flies the two identification experiments of ``profiles/antx.yaml`` through
   ``gcs.mock.physics.QuadPhysics`` (default mock: field, gusts, noise), the level replaced;
2. identifies both axes with ``gcs.core.pbsid.identify`` (the settings ``gcs identify`` uses);
3. prints the model's frequency response at the eight's frequency on that axis (north: loop
   frequency, east: twice it) next to the mock's, measured by flying the eight at full size
   and at 5 % of it (gusts and noise off, sine fit over the steady loops);
4. learns the default eight with that model (smoother, Table I) as ``gcs fly`` does and prints
   e_pos,j / e_pos,0 for j = 1..3, gusts off and with three gust seeds; eq. (11) likewise.

Usage: .venv/bin/python benchmarks/identify_amplitude.py [--id-seed S] [LEVEL_M ...]
Output: one JSON line per row.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from mock_learning_offline import fly, learn

from gcs.app.identify_plan import plan_experiments
from gcs.core.model import frequency_response
from gcs.core.pbsid import identify, natural_frequency_damping, simulate_free, vaf
from gcs.core.trajectory import sample_eight
from gcs.errors import ModelError
from gcs.io.config import Profile, load_profile, load_trajectory
from gcs.mock.config import MockConfig, load_mock_config

ROOT = Path(__file__).resolve().parents[1]
PROFILE = load_profile(ROOT / "profiles" / "antx.yaml")
SHAPE = load_trajectory(ROOT / "trajectories" / "eight.yaml").shape
MOCK = load_mock_config(ROOT / "profiles" / "mock.yaml")
QUIET = replace(
    MOCK,
    disturbance=replace(MOCK.disturbance, gust_sigma_m_s2=0.0),
    noise=replace(MOCK.noise, pos_sigma_m=0.0, vel_sigma_m_s=0.0),
)
#: The eight's frequency on each axis [rad/s]: north at the loop frequency, east at twice it.
W_RAD_S = (2 * np.pi / SHAPE.period_s, 4 * np.pi / SHAPE.period_s)


def eight_response(cfg: MockConfig, scale: float, axis: int) -> complex:
    """Mock's output/input phasor on ``axis`` flying the eight scaled by ``scale``."""
    shape = replace(
        SHAPE,
        amplitude_north_m=scale * SHAPE.amplitude_north_m,
        amplitude_east_m=scale * SHAPE.amplitude_east_m,
    )
    ref = sample_eight(shape, PROFILE.t_ilc_s)
    pos = fly(cfg, ref.pos_ned_m[:-1], ref.pos_ned_m[0], PROFILE.t_ilc_s, seed=1)
    t = np.arange(ref.pos_ned_m.shape[0]) * PROFILE.t_ilc_s
    steady = (t > shape.hover_s + shape.ramp_s + 1.0) & (t < t[-1] - shape.hover_s - 2.0)
    w = W_RAD_S[axis]
    basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])[steady]
    cu = np.linalg.lstsq(basis, ref.pos_ned_m[steady, axis], rcond=None)[0]
    cy = np.linalg.lstsq(basis, pos[steady, axis], rcond=None)[0]
    return complex(cy[0], cy[1]) / complex(cu[0], cu[1])


def learn_pct(profile: Profile, cfg: MockConfig, seed: int) -> list[float]:
    """e_pos,j / e_pos,0 [%] for j = 1..3 (smoother)."""
    e = learn(cfg, "smoother", trials=4, profile=profile, seed=seed)
    return [round(100 * x / e[0], 2) for x in e[1:]]


def identified_profile(level_m: float, id_seed: int) -> tuple[Profile, list[dict]]:
    settings = replace(PROFILE.identification, amplitude_m=level_m)
    exps = plan_experiments(settings, PROFILE.t_ilc_s, "both", PROFILE.arena)
    flown = [
        fly(MOCK, sp, exps.center_ned_m, PROFILE.t_ilc_s, seed=id_seed + e)[:-1]
        for e, sp in enumerate(exps.setpoints_ned_m)
    ]
    models, rows = [], []
    for axis in (0, 1):
        c = exps.center_ned_m[axis]
        u0, u1 = (sp[:, axis] - c for sp in exps.setpoints_ned_m)
        y0, y1 = (pos[:, axis] - c for pos in flown)
        res = identify(
            [(u0, y0)], PROFILE.t_ilc_s, past=settings.past, future=settings.future,
            order=settings.order, max_delay=settings.max_delay,
        )  # fmt: skip
        try:
            wn, zeta = natural_frequency_damping(res.model)
        except ModelError:  # a first-order model has no pole pair
            wn = zeta = float("nan")
        h = frequency_response(res.model, np.array([W_RAD_S[axis]]))[0]
        rows.append(
            {
                "order": res.order,
                "delay_samples": res.delay_samples,
                "wn_rad_s": round(wn, 3),
                "zeta": round(zeta, 3),
                "vaf_pct": round(vaf(y1, simulate_free(res.model, u1)), 1),
                **phasor(h),
            }
        )
        models.append(res.model)
    return replace(PROFILE, model_x=models[0], model_y=models[1]), rows


def phasor(h: complex) -> dict:
    return {"gain": round(abs(h), 3), "phase_deg": round(float(np.degrees(np.angle(h))), 1)}


def learning_row(profile: Profile) -> dict:
    return {
        "no_gusts_pct": learn_pct(profile, QUIET, 200),
        "gust_seeds_pct": [learn_pct(profile, MOCK, 300 + 10 * k) for k in range(3)],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("levels_m", nargs="*", type=float, default=[0.3, 0.6, 0.9, 1.2])
    parser.add_argument("--id-seed", type=int, default=1, help="gust seed of the experiments")
    args = parser.parse_args()
    for axis in (0, 1):
        for scale in (1.0, 0.05):
            row = {"mock": "eight", "axis": "xy"[axis], "scale": scale}
            print(json.dumps(row | phasor(eight_response(QUIET, scale, axis))))
    for axis in (0, 1):
        h = frequency_response(PROFILE.models()[axis], np.array([W_RAD_S[axis]]))[0]
        print(json.dumps({"model": "eq. (11)", "axis": "xy"[axis]} | phasor(h)))
    print(json.dumps({"model": "eq. (11)", "learning": learning_row(PROFILE)}))
    for level in args.levels_m:
        profile, rows = identified_profile(level, args.id_seed)
        for axis, row in enumerate(rows):
            print(json.dumps({"model": f"PRBS {level:g} m", "axis": "xy"[axis]} | row))
        print(json.dumps({"model": f"PRBS {level:g} m", "learning": learning_row(profile)}))


if __name__ == "__main__":
    main()
