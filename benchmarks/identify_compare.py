"""Compare gcs's PBSID-opt with SIPPY's N4SID, MOESP and PARSIM-K on synthetic data.

SIPPY (``sippy_unipi``, LGPL-3.0) is a benchmark-only dependency, never a runtime one.
Install it in a separate environment::

    python3 -m venv /tmp/bench-venv
    /tmp/bench-venv/bin/pip install sippy_unipi numpy scipy
    /tmp/bench-venv/bin/pip install -e . --no-deps      # from the checkout
    /tmp/bench-venv/bin/python benchmarks/identify_compare.py

Without SIPPY the script says so and exits 0. Every case is seeded; the plants are the
paper's eq. (11) and a lightly damped second-order plant, both with input delay. SIPPY's
subspace methods have no delay handling, so they are given the *true* delay (the data are
shifted by it) and the true order 2 -- an advantage PBSID does not get (it estimates both).
Output: a table, then one JSON line per (case, method).
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import time
from dataclasses import dataclass

import numpy as np

from gcs.core.excitation import multisine, prbs
from gcs.core.model import DiscreteModel, from_state_space, from_transfer_function
from gcs.core.pbsid import continuous_poles, identify, simulate_free, vaf

DT = 0.05
PAPER = from_transfer_function([0.08, 1.94], [1, 1.752, 2.01], 0.25, DT)
LIGHT = from_transfer_function([6.25], [1, 1.5, 6.25], 0.10, DT)


@dataclass(frozen=True)
class Case:
    name: str
    plant: DiscreteModel
    closed_loop: bool
    noise_m: float  # measurement noise std [m] (fed back in closed loop)
    dist: float  # input disturbance std [m] (enters the loop)
    ref_amp_m: float  # excitation amplitude [m]
    kp: float = 0.0
    ki: float = 0.0


CASES = [
    Case("paper/open-loop", PAPER, False, 0.01, 0.0, 0.5),
    Case("light/open-loop", LIGHT, False, 0.01, 0.0, 0.5),
    Case("paper/closed-loop", PAPER, True, 0.01, 0.05, 0.5, 0.6, 0.4),
    Case("light/closed-loop", LIGHT, True, 0.01, 0.05, 0.5, 0.3, 0.5),
    Case("paper/closed-loop, strong noise feedback", PAPER, True, 0.03, 0.3, 0.1, 1.0, 0.6),
    Case("light/closed-loop, strong noise feedback", LIGHT, True, 0.03, 0.3, 0.1, 0.6, 0.8),
]


def run(case: Case, r: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (u, y_measured, y_clean). Open loop: u = r. Closed loop: PI on the measurement."""
    rng = np.random.default_rng(seed)
    v = case.noise_m * rng.standard_normal(r.size)
    w = case.dist * rng.standard_normal(r.size)
    p = case.plant
    x = np.zeros(p.order)
    d = p.delay_samples
    u = np.zeros(r.size)
    y = np.zeros(r.size)
    integral = 0.0
    for k in range(r.size):
        y[k] = p.C[0] @ x
        if case.closed_loop:
            err = r[k] - (y[k] + v[k])
            integral += case.ki * DT * err
            u[k] = case.kp * err + integral
        else:
            u[k] = r[k]
        x = p.A @ x + p.B[:, 0] * ((u[k - d] if k >= d else 0.0) + w[k])
    return u, y + v, y


def pole_error_pct(model: DiscreteModel, truth: DiscreteModel) -> float:
    got = continuous_poles(model)
    return 100 * max(float(np.min(np.abs(got - s)) / abs(s)) for s in continuous_poles(truth))


def sippy_model(method: str, u: np.ndarray, y: np.ndarray, delay: int) -> DiscreteModel:
    from sippy_unipi import system_identification

    us, ys = u[: u.size - delay], y[delay:]
    with contextlib.redirect_stdout(io.StringIO()):
        m = system_identification(
            ys, us, method, SS_fixed_order=2, SS_f=10, SS_p=20, SS_D_required=False, tsample=DT
        )
    D = np.zeros((1, 1))  # SIPPY's D is zero when SS_D_required=False
    return from_state_space(np.asarray(m.A), np.asarray(m.B), np.asarray(m.C), D, DT, delay)


def main() -> int:
    try:
        import sippy_unipi  # noqa: F401
    except ImportError:
        print(
            "sippy_unipi is not importable: install it in a separate venv (see the module "
            "docstring) to run this comparison; nothing to compare."
        )
        return 0
    rows = []
    for i, case in enumerate(CASES):
        r = prbs(4000, DT, case.ref_amp_m, 2.0, seed=100 + i)
        u, y, _ = run(case, r, seed=200 + i)
        rv = multisine(2000, DT, 0.5, 0.02, 0.5, seed=300 + i)
        # validation: same loop, same noise, independent realisation
        uv, yv, yv_clean = run(case, rv, seed=400 + i)
        ceiling = vaf(yv, simulate_free(case.plant, uv))
        models: dict[str, tuple[DiscreteModel | None, float, str]] = {}
        t0 = time.perf_counter()
        res = identify([(u, y)], DT)
        models["PBSID-opt (gcs)"] = (res.model, time.perf_counter() - t0, "")
        t0 = time.perf_counter()
        res = identify([(u, y)], DT, delay_samples=case.plant.delay_samples)
        models["PBSID-opt, d given"] = (res.model, time.perf_counter() - t0, "")
        for method in ("N4SID", "MOESP", "PARSIM-K"):
            t0 = time.perf_counter()
            try:
                m = sippy_model(method, u, y, case.plant.delay_samples)
                models[f"{method} (sippy)"] = (m, time.perf_counter() - t0, "")
            except Exception as exc:  # noqa: BLE001 - report any failure of the third party
                models[f"{method} (sippy)"] = (None, time.perf_counter() - t0, repr(exc)[:80])
        for method, (m, secs, err) in models.items():
            row = {
                "case": case.name,
                "method": method,
                "closed_loop": case.closed_loop,
                "delay_true": case.plant.delay_samples,
                "delay_est": m.delay_samples if m is not None else None,
                "pole_error_pct": round(pole_error_pct(m, case.plant), 2) if m else None,
                "vaf_val_pct": round(vaf(yv, simulate_free(m, uv)), 2) if m else None,
                "vaf_val_clean_pct": round(vaf(yv_clean, simulate_free(m, uv)), 2) if m else None,
                "vaf_true_model_pct": round(ceiling, 2),
                "seconds": round(secs, 3),
                "error": err,
            }
            rows.append(row)
    head = (
        f"{'case':42s} {'method':18s} {'delay':>7s} {'pole err %':>10s} {'VAF val %':>9s} "
        f"{'VAF clean %':>11s} {'VAF truth %':>11s}"
    )
    print(head)
    print("-" * len(head))
    for row in rows:
        if row["error"]:
            print(f"{row['case']:42s} {row['method']:18s} failed: {row['error']}")
            continue
        print(
            f"{row['case']:42s} {row['method']:18s} {row['delay_est']:>3d}/{row['delay_true']:<3d} "
            f"{row['pole_error_pct']:10.2f} {row['vaf_val_pct']:9.2f} "
            f"{row['vaf_val_clean_pct']:11.2f} {row['vaf_true_model_pct']:11.2f}"
        )
    print()
    for row in rows:
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
