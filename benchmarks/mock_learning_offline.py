"""Learning against the mock drone's physics offline (no network), to explain the floor.

Flies the default eight through ``gcs.mock.physics.QuadPhysics`` directly: setpoint k is
commanded at k t_ilc, the measured position sampled at k t_ilc, the learning step is the one
``gcs fly`` runs. Varies the mock's non-repeatable parts (gusts, mocap noise), then, without
them, takes away its repeatable nonlinear parts (the position-dependent field, the quadratic
drag) one after the other; ``learning_model_mismatch.py`` goes on from there with exact linear
loops. Prints, per case, e_pos,j / e_pos,0 for j = 0..7 and the repeatability of the vehicle:
the RMS difference between two flights of identical setpoints with different gust seeds.

Usage: .venv/bin/python benchmarks/mock_learning_offline.py
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from gcs.api import Learner, learner_settings
from gcs.core.trajectory import sample_eight
from gcs.io.config import Profile, load_profile, load_trajectory
from gcs.mock.config import MockConfig, load_mock_config
from gcs.mock.physics import QuadPhysics, Target

ROOT = Path(__file__).resolve().parents[1]


def fly(
    cfg: MockConfig, sp: np.ndarray, start: np.ndarray, t_ilc_s: float, seed: int
) -> np.ndarray:
    """Positions y(0..N) for setpoints u(0..N-1), the vehicle settled at ``start`` first."""
    sim = QuadPhysics(cfg, seed=seed, pos_ned_m=tuple(start))
    sim.t_s = -5.0
    sim.command(-5.0, Target(tuple(start)))
    sim.advance_to(0.0)
    n = len(sp)
    pos = np.zeros((n + 1, 3))
    for k in range(n + 1):
        sim.advance_to(k * t_ilc_s)
        pos[k] = sim.measure()[0]
        if k < n:
            sim.command(k * t_ilc_s, Target(tuple(sp[k])))
    return pos


def learn(
    cfg: MockConfig,
    algorithm: str,
    trials: int = 8,
    profile: Profile | None = None,
    seed: int = 100,
) -> list[float]:
    """e_pos,j [m] for j = 0 .. trials - 1; trial j flown with gust seed ``seed + j``."""
    profile = profile or load_profile(ROOT / "profiles" / "antx.yaml")
    ref = sample_eight(load_trajectory(ROOT / "trajectories" / "eight.yaml").shape, profile.t_ilc_s)
    learner = Learner(learner_settings(profile, algorithm), ref.pos_ned_m[:, :2])
    sp = ref.pos_ned_m[:-1].copy()
    out = []
    for j in range(trials):
        pos = fly(cfg, sp, ref.pos_ned_m[0], profile.t_ilc_s, seed=seed + j)
        err = np.hypot(*(pos[1:, :2] - ref.pos_ned_m[1:, :2]).T).mean()
        out.append(float(err))
        u_ne = learner.step(sp[:, :2], pos[1:, :2])
        sp = np.column_stack([u_ne, ref.pos_ned_m[:-1, 2]])
    return out


def repeatability_m(cfg: MockConfig) -> float:
    profile = load_profile(ROOT / "profiles" / "antx.yaml")
    ref = sample_eight(load_trajectory(ROOT / "trajectories" / "eight.yaml").shape, profile.t_ilc_s)
    a = fly(cfg, ref.pos_ned_m[:-1], ref.pos_ned_m[0], profile.t_ilc_s, seed=1)
    b = fly(cfg, ref.pos_ned_m[:-1], ref.pos_ned_m[0], profile.t_ilc_s, seed=2)
    return float(np.sqrt(np.mean(np.sum((a[:, :2] - b[:, :2]) ** 2, axis=1))))


def main() -> None:
    base = load_mock_config(ROOT / "profiles" / "mock.yaml")
    quiet = replace(
        base,
        disturbance=replace(base.disturbance, gust_sigma_m_s2=0.0),
        noise=replace(base.noise, pos_sigma_m=0.0, vel_sigma_m_s=0.0),
    )
    no_field = replace(quiet, disturbance=replace(quiet.disturbance, field_amplitude_m_s2=0.0))
    cases = {
        "mock defaults": base,
        "no gusts": replace(base, disturbance=replace(base.disturbance, gust_sigma_m_s2=0.0)),
        "half gusts": replace(
            base,
            disturbance=replace(
                base.disturbance, gust_sigma_m_s2=0.5 * base.disturbance.gust_sigma_m_s2
            ),
        ),
        "no gusts, no noise": quiet,
        # what the repeatable nonlinear parts cost: the field, then the quadratic drag too
        "no gusts, no noise, no field": no_field,
        "no gusts, no noise, no field, no quadratic drag": replace(
            no_field, physics=replace(no_field.physics, drag_quad_1_m=0.0)
        ),
    }
    for name, cfg in cases.items():
        for algorithm in ("smoother", "kilc"):
            e = learn(cfg, algorithm)
            row = {
                "case": name,
                "algorithm": algorithm,
                "repeatability_rms_m": round(repeatability_m(cfg), 4),
                "epos0_m": round(e[0], 4),
                "epos_pct": [round(100 * x / e[0], 2) for x in e],
            }
            print(json.dumps(row))


if __name__ == "__main__":
    main()
