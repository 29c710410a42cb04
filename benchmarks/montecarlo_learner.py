"""Why ``gcs montecarlo`` does not run its plants through :class:`gcs.Learner` one by one.

The study's learning is the learner's operation (Algorithm 1 or K-ILC, then eq. (8) without
limits), but it runs it for every plant and noise realisation at once: the update is one dense
operator applied to a (N, plants x repeats) matrix, the smoother one batched pass. This script
times, in the same run, one uncertainty level of the default study (100 plants x 10 repeats x
30 iterations, N = 200) batched, and the same plants through one learner per plant and
repeat (a one-axis learner: the nominal model, Table I, no limits), on the first
``--plants`` plants x ``--repeats`` repeats, extrapolated to the level; and checks that the
two agree on those plants (e_j norms, relative 1e-6).

Prints one JSON line: ``{"algorithm", "level", "batched_s", "learner_s_per_run",
"learner_s_extrapolated", "ratio", "max_rel_diff"}`` per algorithm.

Usage: ``python benchmarks/montecarlo_learner.py [--plants 3] [--repeats 2]``
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gcs import Learner, LearnerSettings  # noqa: E402
from gcs.core import montecarlo as mc  # noqa: E402
from gcs.core.model import from_transfer_function, simulate  # noqa: E402
from gcs.core.update import UpdateWeights  # noqa: E402

LEVEL = 0.1


def _msd(wn: float, zeta: float, dt: float):
    return from_transfer_function([wn * wn], [1.0, 2.0 * zeta * wn, wn * wn], 0.0, dt)


def learner_norms(
    s: mc.MontecarloSettings, algorithm: str, plants: int, repeats: int
) -> np.ndarray:
    """e_j norms of the first plants x repeats, one learner each, the study's noise stream."""
    n, dt = s.n_samples, s.t_ilc_s
    sample = mc.sample_plants(s, LEVEL)
    t_out = dt * np.arange(1, n + 1)
    yd = s.reference_amp_m * np.sin(s.reference_omega_rad_s * t_out)
    d = s.disturbance_amp_m * np.sin(s.disturbance_omega_rad_s * t_out) ** 2
    u0 = s.reference_amp_m * np.sin(s.reference_omega_rad_s * dt * np.arange(n))
    settings = LearnerSettings(
        models=(_msd(s.wn_rad_s, s.zeta, dt),), algorithm=algorithm, axes=(0,),
        weights=UpdateWeights(s.we, s.wdu, s.wu), smoother=s.smoother, kilc=s.kilc,
    )  # fmt: skip
    ref = np.concatenate([[0.0], yd])[:, None]
    rng = mc._rng(s, LEVEL, 1)
    p_all, r_all = sample.wn_rad_s.size, s.repeats
    noise = [rng.standard_normal((p_all * r_all, n)) for _ in range(s.iterations + 1)]
    norms = np.zeros((plants, repeats, s.iterations + 1))
    for i in range(plants):
        plant = _msd(float(sample.wn_rad_s[i]), float(sample.zeta[i]), dt)
        for k in range(repeats):
            learner = Learner(settings, ref)
            u = u0[:, None].copy()
            for j in range(s.iterations + 1):
                y_true = simulate(plant, u[:, 0]) + d
                y = y_true + s.noise_std * noise[j][i * r_all + k]
                norms[i, k, j] = np.linalg.norm(yd - y_true)
                u = learner.step(u, y[:, None])
    return norms


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plants", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    s = mc.MontecarloSettings(levels=(LEVEL,))
    for algorithm in mc.ALGORITHMS:
        t0 = time.perf_counter()
        batched = mc.error_norms(s, LEVEL, algorithm)
        batched_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        mine = learner_norms(s, algorithm, args.plants, args.repeats)
        per_run = (time.perf_counter() - t0) / (args.plants * args.repeats)
        extrapolated = per_run * s.plants * s.repeats
        ref = batched[: args.plants, : args.repeats]
        line = {
            "algorithm": algorithm,
            "level": LEVEL,
            "batched_s": round(batched_s, 3),
            "learner_s_per_run": round(per_run, 3),
            "learner_s_extrapolated": round(extrapolated, 1),
            "ratio": round(extrapolated / batched_s, 1),
            "max_rel_diff": float(np.max(np.abs(mine - ref) / np.abs(ref))),
        }
        print(json.dumps(line), flush=True)


if __name__ == "__main__":
    main()
