"""Benchmark of the ILC input update (gcs.core.update), both horizontal axes, and of the
learning step on three axes against two.

Prints one JSON line per case::

    {"n": N, "axes": 2, "constrained": bool, "seconds": median, "peak_mb": ..., ...}

``seconds`` is the median wall time of the 2-axis step (two ``next_input`` calls) over several
repeats, after one warm-up call. ``peak_mb`` is ``resource.getrusage(RUSAGE_SELF).ru_maxrss``
(Linux: KiB) of a fresh subprocess that runs only that case: it includes the interpreter and the
imported numpy/scipy/clarabel (``import_mb`` is the same figure taken just before the first
solve). Lines with ``"baseline": "dense_lifted"`` time the dense lifted formulation (N x N
``F``, normal equations or Clarabel on the dense QP) in the same run, with
``"ratio"`` = dense seconds / sparse seconds.

Model: eq. (11) of the paper, ``from_transfer_function([0.08, 1.94], [1, 1.752, 2.01], 0.25,
dt)``; N = 400 at dt = 0.05 s (20 s, the paper's t_ILC), N = 1500 at dt = 0.04 s (60 s),
N = 6000 at dt = 0.01 s (60 s at 100 Hz). Reference: an eight (north 2 m amplitude, east 1 m,
one lap per 20 s) with a minimum-jerk time warp so that it starts and ends at rest at the start
point. Disturbance: slowly varying offsets of a few decimetres (wind / ground effect).

Lines with ``"baseline": "per_call"`` time the whole learning step of a trial (both axes:
Algorithm 1's smoother and eq. (8)) through the public learner, two ways in the same run on the
same trials: ``per_call_s``, a new :class:`gcs.Learner` for every trial (everything built again
per call, as the learning step did before the learner existed) and ``learner_s``, one learner
kept across the trials (the QP's structure, its KKT factorisation, the Markov parameters and
the limits' rows built once); ``ratio`` = per_call_s / learner_s, medians over trials 2..8
(``first_step_s``: the kept learner's first step, which factorises). ``identical``: the two
ways gave the same setpoints, bit for bit. The trials: the vehicle is the model itself plus
the disturbance above and 5 mm of white noise.

Lines with ``"baseline": "two_axes"`` time the learning step of a trial through one kept
learner on three axes (north, east and down: altitude learned) against two (north and east),
each in a fresh subprocess of the same run, N = 6000 per axis: ``learner_s`` (median over
trials 2..8), ``first_step_s``, ``peak_mb`` (``ru_maxrss``, as above), and ``ratio`` = the
three-axis seconds / the two-axis seconds (``peak_ratio`` the same for memory). The down axis
has a vertical loop of its own (second order, 5.25 rad/s, damping 0.96, 0.15 s delay: the
mock's vertical loop as ``gcs identify --axis z`` sees it), a reference that climbs 0.5 m and
back, and a repeating vertical disturbance; constrained: the arena's floor and ceiling and
the same step and deviation limits.

Lines with ``"baseline": "code"`` time :meth:`gcs.Learner.step` over every step of a run
against the code of another commit (default ``e238ce6``, before the model refresh, the
smoother, the simulation and the update's KKT solves were moved to compiled code), each in
subprocesses of the same run, alternated (``--rounds`` of each): ``antx`` and
``antx-adaptive`` (``Learner.from_profile``) on the default eight (``trajectories/eight.yaml``,
N = 280, north and east), the vehicle the plants of ``tests/synthetic.py`` (10-20 % off the
profile's model: the adaptive learner refreshes it) plus a repeatable drift and 2 mm of white
noise, 8 trials; and the learner of the ``two_axes`` lines at N = 6000, free and constrained.
``median_s`` / ``max_s``: median and largest step (the refresh included), medians over the
rounds; ``ratio`` = baseline / this code; ``max_dev_m``: the largest difference of the learned
setpoints between the two codes over every step. The other commit is checked out with
``git worktree add --detach`` under the system's temporary directory (kept for later runs).

Lines with ``"baseline": "banded_rounds"`` time :meth:`gcs.Learner.step` of the ``antx`` and
``antx-adaptive`` runs above (the default eight, N = 280) with the active-set rounds of the
input update through the Schur complement of the structure's factorised KKT matrix (this
code) against the rounds that factorise the whole augmented KKT system (``_SCHUR_MAX_ROWS =
0``, the method before), in alternated subprocesses of one run (``--rounds R`` of each,
default 5): ``median_s`` / ``max_s`` the wall seconds of a step (per step the median over the
rounds, then the median and largest over the 8 steps), ``cpu_median_s`` the same in CPU
seconds of the process (less sensitive to the other jobs of a shared machine), ``ratio`` /
``cpu_ratio`` = banded / Schur; ``parts_ms``: median per step of ``InputUpdate.solve`` (every
axis; ``active_set`` and ``clarabel`` are parts of it), of the smoother and of the rest of the
step; ``rounds_per_step``: the equality-constrained solves of the active-set method per step
(Clarabel's polish included), ``ms_per_round`` the active-set wall time per round on the steps
without Clarabel; ``max_dev_m`` the largest difference of the learned setpoints between the
two methods, ``bitwise_repeatable`` whether every run of this code learned the same setpoints
bit for bit; ``load_avg_1min`` the machine's load when the line was printed.

Usage: ``python benchmarks/learn_step.py`` (all cases, each in a subprocess),
``python benchmarks/learn_step.py --code [COMMIT] [--rounds R]`` (the lines against another
commit only), ``python benchmarks/learn_step.py --rounds [R]`` (the ``banded_rounds`` lines
only), or
``python benchmarks/learn_step.py --case N constrained|free [sparse|dense|learner|axes2|axes3]``.
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from baseline import baseline_tree

REPO = Path(__file__).resolve().parents[1]
# the code under test: this tree, or another commit's checkout (the "code" lines)
sys.path.insert(0, os.environ.get("GCS_BENCH_CODE", str(REPO)))

from gcs import Box, Learner, LearnerSettings  # noqa: E402
from gcs.core.model import (  # noqa: E402
    from_transfer_function,
    lifted_matrix,
    relative_degree,
    simulate,
)
from gcs.core.update import (  # noqa: E402
    SetpointLimits,
    UpdateWeights,
    next_input,
    reference_for_inputs,
)

DT_S = {400: 0.05, 1500: 0.04, 6000: 0.01}
REPEATS = 7
DENSE_CASES = [(400, False), (1500, False), (400, True), (1500, True)]


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def scenario(n: int, constrained: bool):
    """Model, per-axis signals and limits of one case."""
    dt = DT_S[n]
    model = from_transfer_function([0.08, 1.94], [1, 1.752, 2.01], 0.25, dt)
    r = relative_degree(model)
    t = np.arange(1, n + 1) * dt
    tau = t / t[-1]
    laps = t[-1] / 20.0
    theta = 2 * np.pi * laps * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)
    yd = [2.0 * np.sin(theta), 1.0 * np.sin(2 * theta)]
    d_hat = [0.3 * np.sin(0.5 * t) ** 2, -0.2 * np.sin(0.4 * t + 0.5) ** 2]
    u_prev = [reference_for_inputs(y, r) for y in yd]
    limits = [None, None]
    if constrained:
        step = 2.5 * dt  # setpoint speed 2.5 m/s
        limits = [
            SetpointLimits(-2.1, 2.1, step, 0.8),
            SetpointLimits(-1.15, 1.15, step, 0.8),
        ]
    return model, yd, d_hat, u_prev, limits


def run_sparse(n: int, constrained: bool) -> dict:
    model, yd, d_hat, u_prev, limits = scenario(n, constrained)
    w = UpdateWeights()
    import_mb = _rss_mb()

    def step():
        return [next_input(model, yd[a], d_hat[a], u_prev[a], w, limits[a]) for a in range(2)]

    results = step()  # warm-up
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        step()
        times.append(time.perf_counter() - t0)
    return {
        "n": n,
        "axes": 2,
        "constrained": constrained,
        "seconds": round(statistics.median(times), 4),
        "peak_mb": round(_rss_mb(), 1),
        "import_mb": round(import_mb, 1),
        "methods": [res.method for res in results],
        "active": [res.active_constraints for res in results],
        "objective": [round(res.objective, 6) for res in results],
        "memory": "ru_maxrss",
    }


def _dense_axis(model, yd, d_hat, u_prev, w, limits):
    """Dense lifted baseline: F (N x N), normal equations, or Clarabel on the dense QP."""
    import clarabel
    import scipy.linalg
    import scipy.sparse as sp

    n = yd.size
    r = relative_degree(model)
    m = n - r + 1
    F = lifted_matrix(model, n)
    Fc = F[r - 1 :, :m]
    H = w.we * Fc.T @ Fc + (w.wdu + w.wu) * np.eye(m)
    g = w.we * Fc.T @ (yd - d_hat)[r - 1 :] + w.wdu * u_prev[:m]
    u = np.full(n, yd[-1])
    if limits is None:
        u[:m] = scipy.linalg.cho_solve(scipy.linalg.cho_factor(H), g)
        return u
    yd_u = reference_for_inputs(yd, r)[:m]
    lo = np.maximum(limits.u_min_m, yd_u - limits.max_deviation_m)
    hi = np.minimum(limits.u_max_m, yd_u + limits.max_deviation_m)
    eye = sp.eye(m, format="csc")
    D = (eye - sp.eye(m, k=-1, format="csc")).tocsc()
    tail = sp.csc_matrix(([-1.0], ([0], [m - 1])), shape=(1, m))
    s = limits.max_step_m
    A = sp.vstack([eye, -eye, D, -D, tail, -tail], format="csc")
    b = np.concatenate([hi, -lo, np.full(m, s), np.full(m, s), [s - yd[-1]], [s + yd[-1]]])
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-10
    P = sp.triu(sp.csc_matrix(2 * H), format="csc")
    sol = clarabel.DefaultSolver(
        P, -2 * g, A, b, [clarabel.NonnegativeConeT(b.size)], settings
    ).solve()
    u[:m] = np.asarray(sol.x)
    return u


def run_dense(n: int, constrained: bool) -> dict:
    model, yd, d_hat, u_prev, limits = scenario(n, constrained)
    w = UpdateWeights()
    import_mb = _rss_mb()

    def step():
        return [_dense_axis(model, yd[a], d_hat[a], u_prev[a], w, limits[a]) for a in range(2)]

    dense_u = step()
    repeats = 3 if n > 1000 else REPEATS
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        step()
        times.append(time.perf_counter() - t0)
    sparse_u = [next_input(model, yd[a], d_hat[a], u_prev[a], w, limits[a]).u_m for a in range(2)]
    diff = max(float(np.max(np.abs(a - b))) for a, b in zip(dense_u, sparse_u, strict=True))
    return {
        "baseline": "dense_lifted",
        "n": n,
        "axes": 2,
        "constrained": constrained,
        "seconds": round(statistics.median(times), 4),
        "peak_mb": round(_rss_mb(), 1),
        "import_mb": round(import_mb, 1),
        "max_abs_diff_vs_sparse_m": diff,
        "memory": "ru_maxrss",
    }


TRIALS = 8


def run_learner(n: int, constrained: bool) -> dict:
    """A new learner per trial against one learner kept across the trials (see above)."""
    model, yd, d_true, _, limits = scenario(n, constrained)
    ref = np.vstack([[0.0, 0.0], np.column_stack(yd)])  # at rest at the origin before a trial
    arena, step, dev = None, None, None
    if constrained:
        arena = Box((limits[0].u_min_m, limits[0].u_max_m), (limits[1].u_min_m, limits[1].u_max_m),
                    (-3.0, 0.0))  # fmt: skip
        step, dev = limits[0].max_step_m, limits[0].max_deviation_m
    settings = LearnerSettings(
        models=(model, model), arena=arena, max_step_m=step, max_deviation_m=dev
    )
    rng = np.random.default_rng(1)
    kept = Learner(settings, ref)
    u = ref[:-1].copy()
    per_call, learner, identical = [], [], True
    for _ in range(TRIALS):
        y = np.column_stack([simulate(model, u[:, a]) + d_true[a] for a in range(2)])
        y += 0.005 * rng.standard_normal(y.shape)
        t0 = time.perf_counter()
        fresh = Learner(settings, ref).step(u, y)
        per_call.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        u_next = kept.step(u, y)
        learner.append(time.perf_counter() - t0)
        identical = identical and np.array_equal(fresh, u_next)
        u = u_next
    per_call_s, learner_s = statistics.median(per_call[1:]), statistics.median(learner[1:])
    return {
        "baseline": "per_call",
        "n": n,
        "axes": 2,
        "constrained": constrained,
        "trials": TRIALS,
        "per_call_s": round(per_call_s, 5),
        "learner_s": round(learner_s, 5),
        "first_step_s": round(learner[0], 5),
        "ratio": round(per_call_s / learner_s, 2),
        "identical": bool(identical),
        "methods": list(kept.last.methods),
    }


AXES_N = 6000


def run_axes(n: int, constrained: bool, n_axes: int) -> dict:
    """One kept learner on ``n_axes`` (2: north and east; 3: with down) over the trials."""
    model, yd, d_true, _, limits = scenario(n, constrained)
    dt = DT_S[n]
    wn, zeta = 5.25, 0.96
    model_z = from_transfer_function([wn**2], [1.0, 2 * zeta * wn, wn**2], 0.15, dt)
    t = np.arange(1, n + 1) * dt
    tau = t / t[-1]
    yd = [*yd, -0.5 * np.sin(np.pi * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)) ** 2]
    d_true = [*d_true, 0.1 * np.sin(0.3 * t) ** 2]
    models = (model, model, model_z)[:n_axes]
    ref = np.vstack([np.zeros(n_axes), np.column_stack(yd[:n_axes])])
    arena, step, dev = None, None, None
    if constrained:
        arena = Box((limits[0].u_min_m, limits[0].u_max_m), (limits[1].u_min_m, limits[1].u_max_m),
                    (-1.0, 0.5))  # fmt: skip
        step, dev = limits[0].max_step_m, limits[0].max_deviation_m
    settings = LearnerSettings(
        models=models, arena=arena, max_step_m=step, max_deviation_m=dev,
        axes=(0, 1, 2)[:n_axes], max_vertical_step_m=step, max_vertical_deviation_m=dev,
    )  # fmt: skip
    import_mb = _rss_mb()
    rng = np.random.default_rng(1)
    kept = Learner(settings, ref)
    u = ref[:-1].copy()
    times = []
    for _ in range(TRIALS):
        y = np.column_stack([simulate(models[a], u[:, a]) + d_true[a] for a in range(n_axes)])
        y += 0.005 * rng.standard_normal(y.shape)
        t0 = time.perf_counter()
        u = kept.step(u, y)
        times.append(time.perf_counter() - t0)
    return {
        "baseline": "two_axes",
        "n": n,
        "axes": n_axes,
        "constrained": constrained,
        "trials": TRIALS,
        "learner_s": round(statistics.median(times[1:]), 5),
        "first_step_s": round(times[0], 5),
        "peak_mb": round(_rss_mb(), 1),
        "import_mb": round(import_mb, 1),
        "methods": list(kept.last.methods),
        "memory": "ru_maxrss",
    }


CODE_CASES = ("antx", "antx-adaptive", "6000-free", "6000-constrained")
BASELINE_COMMIT = "e238ce6"


def _eight_run(profile: str, out: Path) -> dict:
    """Every step of an 8-trial run of ``Learner.from_profile(profile)`` on the default eight."""
    from gcs.core.trajectory_sources import sample_reference
    from gcs.io.config import load_trajectory

    dt = 0.05
    ref = sample_reference(load_trajectory(REPO / "trajectories" / "eight.yaml").shape, dt)
    ref = ref.pos_ned_m[:, :2]
    plants = (
        from_transfer_function([0.09, 2.2], [1, 1.6, 2.3], 0.25, dt),
        from_transfer_function([0.07, 1.8], [1, 1.9, 1.85], 0.25, dt),
    )
    learner = Learner.from_profile(profile, ref)
    n = ref.shape[0] - 1
    t = np.arange(1, n + 1) * dt
    rng = np.random.default_rng(0)
    u = ref[:-1].copy()
    times, sequence = [], []
    for _ in range(TRIALS):
        y = np.column_stack(
            [ref[0, a] + simulate(plants[a], u[:, a] - ref[0, a]) + 0.05 * np.sin(0.7 * t) ** 2
             for a in range(2)]
        ) + rng.normal(0.0, 0.002, (n, 2))  # fmt: skip
        t0 = time.perf_counter()
        u = learner.step(u, y)
        times.append(time.perf_counter() - t0)
        sequence.append(u)
    np.save(out, np.array(sequence))
    return {"n": n, "steps_s": times, "methods": list(learner.last.methods)}


def _n6000_run(constrained: bool, out: Path) -> dict:
    """Every step of the ``two_axes`` learner (two axes, N = 6000)."""
    n = AXES_N
    model, yd, d_true, _, limits = scenario(n, constrained)
    ref = np.vstack([[0.0, 0.0], np.column_stack(yd)])
    arena, step, dev = None, None, None
    if constrained:
        arena = Box((limits[0].u_min_m, limits[0].u_max_m), (limits[1].u_min_m, limits[1].u_max_m),
                    (-3.0, 0.0))  # fmt: skip
        step, dev = limits[0].max_step_m, limits[0].max_deviation_m
    settings = LearnerSettings(
        models=(model, model), arena=arena, max_step_m=step, max_deviation_m=dev
    )
    rng = np.random.default_rng(1)
    learner = Learner(settings, ref)
    u = ref[:-1].copy()
    times, sequence = [], []
    for _ in range(TRIALS):
        y = np.column_stack([simulate(model, u[:, a]) + d_true[a] for a in range(2)])
        y += 0.005 * rng.standard_normal(y.shape)
        t0 = time.perf_counter()
        u = learner.step(u, y)
        times.append(time.perf_counter() - t0)
        sequence.append(u)
    np.save(out, np.array(sequence))
    return {"n": n, "steps_s": times, "methods": list(learner.last.methods)}


def run_code_case(case: str, out: Path) -> dict:
    """One case of the ``code`` lines with the code on ``sys.path``; setpoints to ``out``."""
    if case.startswith("6000-"):
        line = _n6000_run(case.endswith("constrained"), out)
    else:
        line = _eight_run(case, out)
    import gcs

    line |= {"case": case, "peak_mb": round(_rss_mb(), 1), "code": str(Path(gcs.__file__).parent)}
    return line


def run_code(commit: str, rounds: int) -> None:
    """The ``code`` lines: this tree against ``commit``, alternated, ``rounds`` of each."""
    base = baseline_tree(commit)
    with tempfile.TemporaryDirectory() as tmp:
        for case in CODE_CASES:
            runs: dict[str, list[dict]] = {"new": [], "baseline": []}
            for k in range(rounds):
                for who, code in (("baseline", base), ("new", REPO)):
                    out = Path(tmp) / f"{case}-{who}-{k}.npy"
                    env = dict(os.environ, GCS_BENCH_CODE=str(code))
                    cmd = [sys.executable, __file__, "--code-case", case, str(out)]
                    text = subprocess.run(cmd, check=True, capture_output=True, text=True,
                                          env=env).stdout  # fmt: skip
                    line = json.loads(text.strip().splitlines()[-1])
                    if Path(line["code"]).parent != code.resolve():
                        raise RuntimeError(f"{who} ran {line['code']}, not {code}")
                    runs[who].append(line | {"out": out})
            summary = {}
            for who, lines in runs.items():
                summary[who] = {
                    "median_s": statistics.median(statistics.median(x["steps_s"]) for x in lines),
                    "max_s": statistics.median(max(x["steps_s"]) for x in lines),
                    "peak_mb": max(x["peak_mb"] for x in lines),
                }
            dev = max(float(np.max(np.abs(np.load(a["out"]) - np.load(b["out"]))))
                      for a, b in zip(runs["new"], runs["baseline"], strict=True))  # fmt: skip
            new, old = summary["new"], summary["baseline"]
            print(json.dumps({
                "baseline": "code", "commit": commit, "case": case, "n": runs["new"][0]["n"],
                "axes": 2, "rounds": rounds, "trials": TRIALS,
                "median_s": round(new["median_s"], 5), "max_s": round(new["max_s"], 5),
                "baseline_median_s": round(old["median_s"], 5),
                "baseline_max_s": round(old["max_s"], 5),
                "ratio": round(old["median_s"] / new["median_s"], 2),
                "max_ratio": round(old["max_s"] / new["max_s"], 2),
                "peak_mb": new["peak_mb"], "baseline_peak_mb": old["peak_mb"],
                "max_dev_m": dev, "methods": runs["new"][-1]["methods"],
                "baseline_methods": runs["baseline"][-1]["methods"], "memory": "ru_maxrss",
            }), flush=True)  # fmt: skip


ROUNDS_CASES = ("antx", "antx-adaptive")


def _step_parts(profile: str, rounds_method: str, out: Path) -> dict:
    """Every step of :func:`_eight_run`'s run, with where each one spent its time.

    ``rounds_method``: ``"schur"`` (this code) or ``"banded"`` (``_SCHUR_MAX_ROWS = 0``: every
    active-set round factorises the whole augmented KKT system, the method before). The parts
    are wall seconds per step of ``InputUpdate.solve`` (eq. (8), every axis), of the
    active-set rounds and Clarabel within it, of the smoother (Algorithm 1) and of the rest
    (the trial's checks, the floor and records of the adaptive learner, the refresh); the
    rounds are the equality-constrained solves of the active-set method (Clarabel's polish
    included).
    """
    import gcs.core.learning as learning
    import gcs.core.update as update

    if rounds_method == "banded":
        update._SCHUR_MAX_ROWS = 0
    parts: dict[str, float] = {}
    counts = {"rounds": 0, "schur": 0}
    inside = [False]

    def timed(owner, name, label):
        inner = getattr(owner, name)

        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                parts[label] = parts.get(label, 0.0) + time.perf_counter() - t0

        setattr(owner, name, wrapper)

    def counted_active_set(inner):
        def wrapper(*args, **kwargs):
            inside[0] = True
            try:
                return inner(*args, **kwargs)
            finally:
                inside[0] = False

        return wrapper

    banded = update._BandedLU

    class CountingLU(banded):
        def __init__(self, K, stage):
            counts["rounds"] += inside[0]
            super().__init__(K, stage)

    schur_solve = update._Schur.solve

    def counting_schur(self, *args, **kwargs):
        found = schur_solve(self, *args, **kwargs)
        counts["rounds"] += found is not None
        counts["schur"] += found is not None
        return found

    update._BandedLU = CountingLU
    update._Schur.solve = counting_schur
    update._active_set = counted_active_set(update._active_set)
    timed(update.InputUpdate, "solve", "update_s")
    timed(update, "_active_set", "active_set_s")
    timed(update, "_solve_clarabel", "clarabel_s")
    timed(learning, "rts_smoother", "smoother_s")
    steps: list[dict] = []
    learner_step = Learner.step

    def step(self, u, y):
        parts.clear()
        counts["rounds"] = counts["schur"] = 0
        c0, t0 = time.process_time(), time.perf_counter()
        u_next = learner_step(self, u, y)
        total, cpu = time.perf_counter() - t0, time.process_time() - c0
        steps.append(parts | counts | {"step_s": total, "cpu_s": cpu})
        return u_next

    Learner.step = step
    line = _eight_run(profile, out)
    for part in steps:
        part["rest_s"] = part["step_s"] - part.get("update_s", 0.0) - part.get("smoother_s", 0.0)
    return line | {"parts": steps}


def run_rounds(rounds: int) -> None:
    """The ``banded_rounds`` lines: the active-set rounds through the Schur complement against
    the banded rounds, in alternated subprocesses of one run, ``rounds`` of each."""
    keys = ("step_s", "cpu_s", "update_s", "active_set_s", "clarabel_s", "smoother_s", "rest_s")
    with tempfile.TemporaryDirectory() as tmp:
        for case in ROUNDS_CASES:
            runs: dict[str, list[dict]] = {"banded": [], "schur": []}
            for k in range(rounds):
                for method in runs:
                    out = Path(tmp) / f"{case}-{method}-{k}.npy"
                    cmd = [sys.executable, __file__, "--rounds-case", case, method, str(out)]
                    text = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
                    runs[method].append(json.loads(text.strip().splitlines()[-1]) | {"out": out})
            summary = {}
            for method, lines in runs.items():
                # per step: the median over the rounds of the run; then over the steps
                steps = [[line["parts"][j] for line in lines] for j in range(TRIALS)]
                per_step = [{key: statistics.median(p.get(key, 0.0) for p in s) for key in keys}
                            | {"rounds": s[0]["rounds"], "schur": s[0]["schur"]}
                            for s in steps]  # fmt: skip
                active = [p for p in per_step if p["rounds"] > 0 and p["clarabel_s"] == 0.0]
                summary[method] = {
                    "median_s": statistics.median(p["step_s"] for p in per_step),
                    "max_s": max(p["step_s"] for p in per_step),
                    "cpu_median_s": statistics.median(p["cpu_s"] for p in per_step),
                    "median_parts_ms": {key[:-2]: round(1000 * statistics.median(
                        p[key] for p in per_step), 3) for key in keys[2:]},  # fmt: skip
                    "rounds_per_step": [p["rounds"] for p in per_step],
                    "schur_rounds": sum(p["schur"] for p in per_step),
                    "ms_per_round": round(1000 * sum(p["active_set_s"] for p in active)
                                          / max(1, sum(p["rounds"] for p in active)), 3),
                    "methods": lines[-1]["methods"],
                }  # fmt: skip
            dev = max(float(np.max(np.abs(np.load(a["out"]) - np.load(b["out"]))))
                      for a, b in zip(runs["schur"], runs["banded"], strict=True))  # fmt: skip
            same = all(np.array_equal(np.load(a["out"]), np.load(runs["schur"][0]["out"]))
                       for a in runs["schur"])  # fmt: skip
            new, old = summary["schur"], summary["banded"]
            print(json.dumps({
                "baseline": "banded_rounds", "case": case, "n": lines[0]["n"], "axes": 2,
                "rounds": rounds, "trials": TRIALS, "load_avg_1min": os.getloadavg()[0],
                "median_s": round(new["median_s"], 5), "max_s": round(new["max_s"], 5),
                "baseline_median_s": round(old["median_s"], 5),
                "baseline_max_s": round(old["max_s"], 5),
                "ratio": round(old["median_s"] / new["median_s"], 2),
                "cpu_median_s": round(new["cpu_median_s"], 5),
                "baseline_cpu_median_s": round(old["cpu_median_s"], 5),
                "cpu_ratio": round(old["cpu_median_s"] / new["cpu_median_s"], 2),
                "parts_ms": new["median_parts_ms"], "baseline_parts_ms": old["median_parts_ms"],
                "rounds_per_step": new["rounds_per_step"],
                "baseline_rounds_per_step": old["rounds_per_step"],
                "schur_rounds": new["schur_rounds"], "ms_per_round": new["ms_per_round"],
                "baseline_ms_per_round": old["ms_per_round"], "max_dev_m": dev,
                "bitwise_repeatable": bool(same), "methods": new["methods"],
            }), flush=True)  # fmt: skip


def _subprocess(n: int, constrained: bool, kind: str) -> dict:
    cmd = [sys.executable, __file__, "--case", str(n), "constrained" if constrained else "free"]
    out = subprocess.run(cmd + [kind], check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main() -> None:
    if len(sys.argv) == 4 and sys.argv[1] == "--code-case":
        print(json.dumps(run_code_case(sys.argv[2], Path(sys.argv[3]))))
        return
    if len(sys.argv) == 5 and sys.argv[1] == "--rounds-case":
        print(json.dumps(_step_parts(sys.argv[2], sys.argv[3], Path(sys.argv[4]))))
        return
    if len(sys.argv) >= 2 and sys.argv[1] == "--rounds":
        run_rounds(int(sys.argv[2]) if len(sys.argv) > 2 else 5)
        return
    if len(sys.argv) >= 2 and sys.argv[1] == "--code":
        args = sys.argv[2:]
        rounds = 3
        if "--rounds" in args:
            i = args.index("--rounds")
            rounds = int(args[i + 1])
            del args[i : i + 2]
        run_code(args[0] if args else BASELINE_COMMIT, rounds)
        return
    if len(sys.argv) >= 4 and sys.argv[1] == "--case":
        n, constrained = int(sys.argv[2]), sys.argv[3] == "constrained"
        kind = sys.argv[4] if len(sys.argv) > 4 else "sparse"
        if kind in ("axes2", "axes3"):
            print(json.dumps(run_axes(n, constrained, int(kind[-1]))))
            return
        run = {"dense": run_dense, "learner": run_learner}.get(kind, run_sparse)
        print(json.dumps(run(n, constrained)))
        return
    sparse_lines = {}
    for n in DT_S:
        for constrained in (False, True):
            line = _subprocess(n, constrained, "sparse")
            sparse_lines[(n, constrained)] = line
            print(json.dumps(line), flush=True)
    for n, constrained in DENSE_CASES:
        line = _subprocess(n, constrained, "dense")
        line["ratio"] = round(line["seconds"] / sparse_lines[(n, constrained)]["seconds"], 2)
        print(json.dumps(line), flush=True)
    for n in DT_S:
        for constrained in (False, True):
            print(json.dumps(_subprocess(n, constrained, "learner")), flush=True)
    for constrained in (False, True):
        two = _subprocess(AXES_N, constrained, "axes2")
        three = _subprocess(AXES_N, constrained, "axes3")
        three["ratio"] = round(three["learner_s"] / two["learner_s"], 2)
        three["peak_ratio"] = round(three["peak_mb"] / two["peak_mb"], 2)
        print(json.dumps(two), flush=True)
        print(json.dumps(three), flush=True)
    run_rounds(5)
    run_code(BASELINE_COMMIT, 3)


if __name__ == "__main__":
    main()
