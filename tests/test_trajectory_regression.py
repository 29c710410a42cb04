"""The shipped eights sample as recorded, and as the formula computed one sample at a time says.

``tests/data/eight-samples.npz`` holds ``sample_eight``'s times, positions, velocities and
accelerations of the shipped eights. They agree within relative 1e-12 of each array's largest
value on any machine (docs/results.md, "Reproducibility"): numpy's vectorised ``sin``/``cos``
take another code path on each SIMD level (last bits differ), a handful of operations follow. The
same formula evaluated sample by sample with Python's ``math`` pins what the record holds to
the eight of the paper's tables, independently of numpy. ``python
tests/test_trajectory_regression.py`` writes the record again.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from records import assert_scaled

from gcs.core.trajectory import EightShape, Reference, sample_eight
from gcs.io.config import load_trajectory

ROOT = Path(__file__).resolve().parents[1]
RECORD = ROOT / "tests" / "data" / "eight-samples.npz"
CASES = [("eight", 0.05), ("eight", 0.02), ("eight-short", 0.05), ("eight-short", 0.02)]
FIELDS = ("t_s", "pos_ned_m", "vel_ned_m_s", "acc_ned_m_s2")
RTOL = 1e-12  # of each array's largest magnitude, across machines
RTOL_SCALAR = 1e-13  # the same, against the sample-by-sample formula


def sampled(name: str, t_ilc_s: float) -> Reference:
    return sample_eight(load_trajectory(ROOT / "trajectories" / f"{name}.yaml").shape, t_ilc_s)


def eight_by_hand(shape: EightShape, t_s: float) -> tuple[float, ...]:
    """Position, velocity and acceleration (north, east) of the eight at ``t_s``, with ``math``."""
    w, T, hover = 2.0 * math.pi / shape.period_s, shape.ramp_s, shape.hover_s
    cruise = shape.loops * shape.period_s - T
    tm, t_end = t_s - hover, 2.0 * T + cruise

    def ramp(tau: float) -> tuple[float, float, float]:
        # integral of the quintic smooth-step, the smooth-step, its derivative
        integral = T * (2.5 * tau**4 - 3.0 * tau**5 + tau**6)
        step = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
        return integral, step, 30.0 * tau**2 * (1.0 - tau) ** 2 / T

    if tm <= 0.0:
        s, sd, sdd = 0.0, 0.0, 0.0
    elif tm < T:
        i, d, dd = ramp(tm / T)
        s, sd, sdd = w * i, w * d, w * dd
    elif tm <= T + cruise:
        s, sd, sdd = w * (T / 2.0 + (tm - T)), w, 0.0
    elif tm < t_end:
        i, d, dd = ramp((t_end - tm) / T)
        s, sd, sdd = w * (T + cruise) - w * i, w * d, -w * dd
    else:
        s, sd, sdd = w * (T + cruise), 0.0, 0.0
    a, b = shape.amplitude_north_m, shape.amplitude_east_m
    north_m, east_m = shape.center_ned_m[0], shape.center_ned_m[1]
    return (
        north_m + a * math.sin(s), east_m + 0.5 * b * math.sin(2.0 * s),
        a * math.cos(s) * sd, b * math.cos(2.0 * s) * sd,
        a * (math.cos(s) * sdd - math.sin(s) * sd**2),
        b * (math.cos(2.0 * s) * sdd - 2.0 * math.sin(2.0 * s) * sd**2),
    )  # fmt: skip


@pytest.mark.parametrize(("name", "t_ilc_s"), CASES)
def test_shipped_eight_samples_are_those_recorded(name: str, t_ilc_s: float) -> None:
    ref = sampled(name, t_ilc_s)
    with np.load(RECORD) as record:
        for field in FIELDS:
            key = f"{name}@{t_ilc_s:g}/{field}"
            assert_scaled(getattr(ref, field), record[key], RTOL, key)


@pytest.mark.parametrize(("name", "t_ilc_s"), CASES)
def test_the_record_is_the_formula_computed_sample_by_sample(name: str, t_ilc_s: float) -> None:
    shape = load_trajectory(ROOT / "trajectories" / f"{name}.yaml").shape
    with np.load(RECORD) as record:
        t = record[f"{name}@{t_ilc_s:g}/t_s"]
        np.testing.assert_array_equal(t, np.arange(len(t)) * t_ilc_s)  # exact: k * dt
        assert t[-1] >= shape.duration_s - 1e-9 > t[-2]
        by_hand = np.array([eight_by_hand(shape, float(tk)) for tk in t])
        columns = {"pos_ned_m": [0, 1], "vel_ned_m_s": [2, 3], "acc_ned_m_s2": [4, 5]}
        for field, cols in columns.items():
            key = f"{name}@{t_ilc_s:g}/{field}"
            assert_scaled(record[key][:, :2], by_hand[:, cols], RTOL_SCALAR, key)
        centre = np.asarray(shape.center_ned_m)
        np.testing.assert_array_equal(record[f"{name}@{t_ilc_s:g}/pos_ned_m"][:, 2], centre[2])
        for field in ("vel_ned_m_s", "acc_ned_m_s2"):
            assert not record[f"{name}@{t_ilc_s:g}/{field}"][:, 2].any()


def main() -> None:
    arrays = {}
    for name, t_ilc_s in CASES:
        ref = sampled(name, t_ilc_s)
        arrays |= {f"{name}@{t_ilc_s:g}/{field}": getattr(ref, field) for field in FIELDS}
    np.savez_compressed(RECORD, **arrays)
    print(f"{RECORD}: {len(arrays)} arrays, {RECORD.stat().st_size} bytes")


if __name__ == "__main__":
    main()
