"""One-step replay of recorded learning runs: how well other disturbance estimates would have
predicted each learned trial, against the estimate gcs made.

Printed, not asserted. For every learning run given (run directories, or directories searched
for them; runs of ``learning.adaptive`` with the data-driven noise model) and every learned
trial ``t`` whose step learned from at least one learned trial (``t >= repeats + 2``; a trial
flying another's setpoints again ends the run's replay): the trials ``0..t-1`` as the step saw
them, the models it ended with (``models_in_use``, after its refresh), their residuals
``z_i = Y_i - F U_i`` per axis, and then each candidate estimate ``d_hat`` of the disturbance.
Its prediction of trial ``t`` at the setpoints ``t`` flew, ``F U_t + d_hat``, is scored by
e_pos against what ``t`` measured. A better estimate of the repeatable error predicts closer.

The candidates (all from the public functions of ``gcs.core.noise_model``, the RTS smoother in
time after each as the shipped smoother path does):

- ``shipped``: the estimate the run made (``estimate_disturbance`` with the run's settings),
  checked against its ``estimate-JJJ.csv`` (``max |shipped - recorded|`` in the summary);
- ``newest``: the newest trial alone (Table I's choice in effect);
- ``last two``: the mean of the two newest;
- ``learned only``: the mean of the learned trials, trial 0 and its repeats left out (they
  carry the model's error at trial 0's setpoints);
- ``kappa >= K``: the shipped noise model with its model-error variance held at least ``K``
  (a prior that the model is ``sqrt(K)`` off), so that changed inputs weigh more;
- ``refit``: a model fitted to every pair of consecutive trials of different setpoints
  (``fit_output_error``, no cross-validation gate: the refresh's candidate always accepted),
  then the shipped estimate with it.
- ``no refresh in this step``: the models the step started from (its refresh undone), then
  the shipped estimate with them;
- ``the profile's models``: never refreshed.

Per candidate: its prediction error over the shipped one's, median, mean, the 10/90 %
quantiles and the share of steps where it predicted better. Then, for the shipped estimate, the
prediction error in units of what noise alone would leave (the run's floor times
``prediction_noise_ratio`` of its weights) and each learned trial's e_pos in floors, also per
trajectory with how hard its learned trials flew (the 99th percentile of the measured
acceleration).

Usage: ``python benchmarks/estimate_replay.py RUN_OR_DIR ... [--json OUT]``
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from gcs.app.learn import models_in_use
from gcs.core.floor import prediction_noise_ratio
from gcs.core.metrics import epos
from gcs.core.model import predicted_output, simulate
from gcs.core.noise_model import (
    IterationNoise,
    drift_scale,
    estimate_disturbance,
    fit_iteration_noise,
    fit_time_noise,
    iteration_filter,
    rts_smooth,
)
from gcs.core.refresh import fit_output_error, model_from_transfer_function, transfer_function
from gcs.io.rundir import RunDir

KAPPA_FLOORS = (0.01, 0.04, 0.16)
MOVED_M = 1e-9  # consecutive trials of different setpoints (as the refresh's pairs)


def find_runs(paths: list[str]) -> list[Path]:
    """Run directories among ``paths`` and below them (a ``floor.json`` beside a manifest)."""
    found: list[Path] = []
    for p in map(Path, paths):
        hits = [p] if (p / RunDir.FLOOR_FILE).exists() else sorted(p.rglob(RunDir.FLOOR_FILE))
        found += [h if h.is_dir() else h.parent for h in hits]
    return sorted({f.resolve() for f in found if (f / RunDir.MANIFEST_FILE).exists()})


def residuals(models, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``z`` (2, T, N) and the predicted changes ``F (U_i - U_(i-1))`` (2, T-1, N)."""
    z = np.stack([y[:, :, a] - simulate(models[a], u[:, :, a].T).T for a in (0, 1)])
    du = np.diff(u, axis=0)
    change = np.stack([simulate(models[a], du[:, :, a].T).T for a in (0, 1)])
    return z, change


def from_weights(z: np.ndarray, w: np.ndarray, smooth: bool) -> np.ndarray:
    """The weighted mean of the residuals (w: (2, T)), then the RTS smoother in time."""
    d = np.einsum("at,atn->an", w, z)
    if not smooth:
        return d
    tn = fit_time_noise(z)
    r_eff = np.maximum(tn.r_m2 * np.sum(w**2, axis=-1), 1e-12 * np.var(d, axis=-1) + 1e-30)
    return rts_smooth(d, tn.q_m2, r_eff)[0]


def refit(models, u: np.ndarray, y: np.ndarray) -> tuple:
    """Each axis's model fitted to every moved pair of consecutive trials (no gate)."""
    out = []
    for a in (0, 1):
        du, dy = np.diff(u[:, :, a], axis=0), np.diff(y[:, :, a], axis=0)
        moved = np.max(np.abs(du), axis=1) > MOVED_M
        if not moved.any():
            out.append(models[a])
            continue
        b0, a0 = transfer_function(models[a])
        d = models[a].delay_samples
        pairs = (du[moved][None], dy[moved][None])
        b, den, _ = fit_output_error(b0[None], a0[None], d, *pairs, np.ones(pairs[0].shape, bool))
        out.append(model_from_transfer_function(b[0], den[0], models[a].dt_s, d))
    return tuple(out)


def candidates(models, u, y, repeats: int, smooth: bool, offset: bool) -> tuple[dict, np.ndarray]:
    """name -> (models, d_hat (2, N)); the weights of the run's own estimate (2, T)."""
    z, change = residuals(models, u, y)
    m = drift_scale(change)
    shipped = estimate_disturbance(z, m, smooth, offset)
    out = {"shipped": (models, shipped.d_hat_m)}
    t = z.shape[1]
    for name, idx in (
        ("newest", [t - 1]),
        ("last two", [t - 2, t - 1]),
        ("learned only", list(range(repeats + 1, t))),
    ):
        w = np.zeros((2, t))
        w[:, idx] = 1.0 / len(idx)
        out[name] = (models, from_weights(z, w, smooth))
    noise = fit_iteration_noise(z, m, fit_time_noise(z).r_m2, offset)
    for k in KAPPA_FLOORS:
        held = IterationNoise(
            noise.q0_m2, np.maximum(noise.kappa, k), noise.r_m2, noise.loglik, noise.identified
        )
        out[f"kappa >= {k}"] = (
            models,
            from_weights(z, iteration_filter(z, m, held).weights, smooth),
        )
    fitted = refit(models, u, y)
    z2, change2 = residuals(fitted, u, y)
    out["refit"] = (fitted, estimate_disturbance(z2, drift_scale(change2), smooth, offset).d_hat_m)
    return out, shipped.weights


def replay_run(path: Path) -> list[dict]:
    """One row per replayed step of the run."""
    run = RunDir.open(path)
    profile = run.profile()
    adaptive = profile.learning.adaptive
    if adaptive is None or adaptive.noise != "data":
        return []
    repeats = profile.learning.repeats
    smooth = run.algorithm == "smoother"
    done = set(run.complete_trials())
    ref = run.reference().pos_ned_m
    start = ref[0, :2]
    floor_m = json.loads(run.floor_path.read_text())["epos_m"]
    trials, rows = {}, []
    t = repeats + 2
    while t in done and run.again_of(t) is None and run.estimate_path(t - 1).exists():
        for k in range(t + 1):
            if k not in trials:
                rec = run.measured_trial(k, profile.mocap.measurement)
                trials[k] = (rec.sp_ned_m[:-1, :2] - start, rec.pos_ned_m[1:, :2] - start)
        u = np.stack([trials[k][0] for k in range(t)])
        y = np.stack([trials[k][1] for k in range(t)])
        models = models_in_use(run, profile, t)[0]
        cands, weights = candidates(models, u, y, repeats, smooth, adaptive.drift_offset)
        before = models_in_use(run, profile, t - 1)[0] if t - 1 > repeats else profile.models()
        z0, change0 = residuals(before, u, y)
        d0 = estimate_disturbance(z0, drift_scale(change0), smooth, adaptive.drift_offset)
        cands["no refresh in this step"] = (before, d0.d_hat_m)
        first = profile.models()
        z1, change1 = residuals(first, u, y)
        d1 = estimate_disturbance(z1, drift_scale(change1), smooth, adaptive.drift_offset)
        cands["the profile's models"] = (first, d1.d_hat_m)
        u_t, y_t = trials[t]
        recorded = run.read_estimate(t - 1)[0][:, :2].T
        errors = {}
        for name, (mods, d_hat) in cands.items():
            y_hat = np.column_stack(
                [predicted_output(mods[a], u_t[:, a], d_hat[a]) for a in (0, 1)]
            )
            errors[name] = epos(y_hat, y_t)
        noise_ratio = float(np.mean([prediction_noise_ratio(w) for w in weights]))
        rows.append({
            "run": str(path),
            "trial": t,
            "recorded_diff_m": float(np.max(np.abs(cands["shipped"][1] - recorded))),
            "errors_m": errors,
            "floor_m": floor_m,
            "noise_ratio": noise_ratio,
            "trial_epos_m": epos(ref[1:, :2] - start, y_t),
            "trial_acc_p99_m_s2": peak_acceleration(y_t, profile.t_ilc_s),
            "trajectory": trajectory_name(run.manifest["trajectory"]),
        })  # fmt: skip
        t += 1
    return rows


def trajectory_name(trajectory: dict) -> str:
    """The trajectory's name, with its loop's period when it has one."""
    period = trajectory.get("period_s")
    return trajectory["name"] + ("" if period is None else f" ({period:g} s loop)")


def peak_acceleration(pos_m: np.ndarray, dt_s: float) -> float:
    """99th percentile of the horizontal acceleration of measured positions (N, 2) [m/s^2],
    the velocity first averaged over 5 samples (the measurement's noise differentiated twice
    would swamp it)."""
    vel = np.diff(pos_m, axis=0) / dt_s
    box = np.ones(5) / 5
    vel = np.column_stack([np.convolve(vel[:, i], box, "same") for i in range(2)])
    return float(np.percentile(np.linalg.norm(np.diff(vel, axis=0), axis=1) / dt_s, 99))


def summary(rows: list[dict]) -> str:
    names = list(rows[0]["errors_m"])
    shipped = np.array([r["errors_m"]["shipped"] for r in rows])
    lines = [
        f"{len({r['run'] for r in rows})} runs, {len(rows)} steps; max |shipped - recorded| "
        f"{max(r['recorded_diff_m'] for r in rows):.1e} m; the shipped estimate's prediction "
        f"error: median {1000 * np.median(shipped):.0f} mm",
        "",
        "| candidate | error / shipped: median | mean | 10 % | 90 % | predicts better |",
        "|---|---|---|---|---|---|",
    ]
    for name in names[1:]:
        ratio = np.array([r["errors_m"][name] for r in rows]) / shipped
        q10, q50, q90 = np.percentile(ratio, [10, 50, 90])
        lines.append(
            f"| {name} | {q50:.3f} | {ratio.mean():.3f} | {q10:.3f} | {q90:.3f} | "
            f"{np.mean(ratio < 1):.0%} |"
        )
    excess = shipped / np.array([r["floor_m"] * r["noise_ratio"] for r in rows])
    floors = np.array([r["trial_epos_m"] / r["floor_m"] for r in rows])
    ratio = np.array([r["noise_ratio"] for r in rows])
    lines += [
        "",
        "quantiles 10/25/50/75/90 %:",
        f"- shipped prediction error / (floor x noise ratio): "
        f"{', '.join(f'{v:.2f}' for v in np.percentile(excess, [10, 25, 50, 75, 90]))}",
        f"- noise ratio sqrt(1 + sum w^2): "
        f"{', '.join(f'{v:.2f}' for v in np.percentile(ratio, [10, 25, 50, 75, 90]))}",
        f"- learned trial e_pos / floor: "
        f"{', '.join(f'{v:.2f}' for v in np.percentile(floors, [10, 25, 50, 75, 90]))}",
        "",
        "by trajectory:",
        "",
        "| trajectory | steps | acceleration p99 [m/s^2]: median | prediction error / noise's "
        "share: median | trial e_pos / floor: median |",
        "|---|---|---|---|---|",
    ]
    acc = np.array([r["trial_acc_p99_m_s2"] for r in rows])
    for name in sorted({r["trajectory"] for r in rows}):
        sel = np.array([r["trajectory"] == name for r in rows])
        lines.append(
            f"| {name} | {sel.sum()} | {np.median(acc[sel]):.2f} | {np.median(excess[sel]):.2f} "
            f"| {np.median(floors[sel]):.2f} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", help="run directories, or directories holding them")
    parser.add_argument("--json", type=Path, help="write every step's row here")
    args = parser.parse_args()
    rows = []
    for path in find_runs(args.paths):
        try:
            rows += replay_run(path)
        except (OSError, ValueError) as exc:
            print(f"{path}: not replayed ({exc})", file=sys.stderr)
    if not rows:
        sys.exit("no learned trial to replay (runs of learning.adaptive, t >= repeats + 2)")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    print(summary(rows))


if __name__ == "__main__":
    main()
