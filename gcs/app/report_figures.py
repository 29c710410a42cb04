"""The report's figures: the paper's Fig. 2, 4 and 5 for both horizontal axes, and what ILC
changes (the setpoints against the reference and the limits, the error over time, the learned
disturbance with its ±2σ band). Every figure names its run (id, profile, trajectory, seed,
gcs version).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from gcs.app.figures import save_figure
from gcs.app.report import (
    RunFacts,
    RunLearning,
    TrialLearning,
    choose_iterations,
    is_three_d,
    run_facts,
    run_learning,
    run_metrics,
)
from gcs.core.metrics import IterationMetrics
from gcs.core.model import relative_degree
from gcs.errors import ProfileError, RunLogError
from gcs.io.rundir import RunDir

__all__ = ["FIGURES", "CAPTIONS", "report_figures", "write_plots", "run_label"]


def run_label(facts: RunFacts) -> str:
    """The line every figure carries: which run, flown with what.

    Returns: two lines: the run id and algorithm, then profile, trajectory, seed and gcs version.
    """
    return (
        f"{facts.run_id} ({facts.algorithm})\nprofile {facts.profile} · trajectory "
        f"{facts.trajectory} · {facts.seed_text()} · gcs {facts.gcs_version}"
    )


AXES = (("north", 0), ("east", 1))


FIGURES = ("xy", "position", "setpoints", "error", "epos", "disturbance", "altitude", "views")


def _colors(iterations: list[int]) -> dict[int, Any]:
    import matplotlib

    cmap = matplotlib.colormaps["viridis"]
    n = max(len(iterations) - 1, 1)
    return {j: cmap(0.85 * i / n) for i, j in enumerate(iterations)}


def _fig_xy(
    plt: Any, ref: Any, records: dict, iterations: list[int], names: dict, label: str
) -> Any:
    colors = _colors(iterations)
    fig, ax = plt.subplots(figsize=(5.6, 6.4))
    fig.suptitle(label, fontsize=8, color="0.3")
    north, east = ref.pos_ned_m[:, 0], ref.pos_ned_m[:, 1]
    ax.plot(east, north, "k--", lw=1.6, label="reference")
    ax.plot(east[0], north[0], "o", ms=9, mfc="white", mec="k", mew=1.6, zorder=5, label="start")
    # arrows along the reference at shares of its length, one per part of the path (an eight
    # flown twice passes each place twice: a second arrow there would say nothing new)
    length = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(north), np.diff(east)))])
    size = max(np.ptp(north), np.ptp(east), 1e-9)
    placed: list[int] = []
    for share in np.arange(1, 16) / 16:
        k = min(int(np.searchsorted(length, share * length[-1])), len(north) - 3)
        apart = all(np.hypot(north[k] - north[i], east[k] - east[i]) > size / 4 for i in placed)
        moving = np.hypot(north[k + 2] - north[k], east[k + 2] - east[k]) > 1e-6
        if apart and moving and len(placed) < 4:
            placed.append(k)
            ax.annotate(
                "", xy=(east[k + 2], north[k + 2]), xytext=(east[k], north[k]), zorder=5,
                arrowprops={"arrowstyle": "-|>", "color": "k", "lw": 1.4, "mutation_scale": 16},
            )  # fmt: skip
    ax.plot([], [], marker=r"$\rightarrow$", ls="none", color="k", ms=12,
            label="direction of flight")  # fmt: skip
    for j in iterations:
        p = records[j].pos_ned_m
        ax.plot(p[:, 1], p[:, 0], lw=1.1, color=colors[j], label=names[j])
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="center left")
    ax.set_title("Horizontal path per iteration (paper Fig. 4)")
    return fig


def _two_axes(plt: Any, title: str, label: str) -> tuple[Any, Any]:
    fig, axs = plt.subplots(2, 1, figsize=(9, 6.6), sharex=True)
    fig.suptitle(f"{title}\n{label}", fontsize=10)
    axs[1].set_xlabel("t [s]")
    for ax in axs:
        ax.grid(True, alpha=0.3)
    return fig, axs


def _fig_position(
    plt: Any, ref: Any, records: dict, iterations: list[int], names: dict, label: str
) -> Any:
    colors = _colors(iterations)
    fig, axs = _two_axes(plt, "Position per iteration (paper Fig. 5, both axes)", label)
    for ax, (name, c) in zip(axs, AXES, strict=True):
        ax.plot(ref.t_s, ref.pos_ned_m[:, c], "k--", lw=1.6, label="reference")
        for j in iterations:
            r = records[j]
            ax.plot(r.t_s, r.pos_ned_m[:, c], lw=1.1, color=colors[j], label=names[j])
        ax.set_ylabel(f"{name} [m]")
    axs[0].legend(fontsize=8, ncol=len(iterations) + 1, loc="lower left")  # the hover: empty
    return fig


def _fig_altitude(
    plt: Any, ref: Any, records: dict, iterations: list[int], names: dict, label: str
) -> Any:
    """Altitude (-down) per iteration over the reference, and its error, against time."""
    colors = _colors(iterations)
    fig, axs = _two_axes(plt, "Altitude per iteration", label)
    axs[0].plot(ref.t_s, -ref.pos_ned_m[:, 2], "k--", lw=1.6, label="reference")
    for j in iterations:
        r = records[j]
        axs[0].plot(r.t_s, -r.pos_ned_m[:, 2], lw=1.1, color=colors[j], label=names[j])
        err = -(r.pos_ned_m[:, 2] - ref.pos_ned_m[:, 2])
        axs[1].plot(r.t_s, err, lw=1.0, color=colors[j], label=names[j])
    axs[0].set_ylabel("altitude -down [m]")
    axs[1].set_ylabel("altitude error [m]")
    axs[0].legend(fontsize=8, ncol=len(iterations) + 1, loc="lower left")
    return fig


def _fig_views(
    plt: Any, ref: Any, records: dict, iterations: list[int], names: dict, label: str
) -> Any:
    """The path in three views: from above (east, north), from the side (north, altitude) and
    from the front (east, altitude)."""
    colors = _colors(iterations)
    fig, axs = plt.subplots(1, 3, figsize=(13, 4.6))
    fig.suptitle(f"Path per iteration in three views\n{label}", fontsize=10)
    views = (("top", 1, 0, "east [m]", "north [m]"), ("side", 0, 2, "north [m]", "altitude [m]"),
             ("front", 1, 2, "east [m]", "altitude [m]"))  # fmt: skip
    for ax, (title, h, v, xlabel, ylabel) in zip(axs, views, strict=True):
        sign = -1.0 if v == 2 else 1.0  # altitude up
        p = ref.pos_ned_m
        ax.plot(p[:, h], sign * p[:, v], "k--", lw=1.6, label="reference")
        ax.plot(p[0, h], sign * p[0, v], "o", ms=8, mfc="white", mec="k", zorder=5, label="start")
        for j in iterations:
            q = records[j].pos_ned_m
            ax.plot(q[:, h], sign * q[:, v], lw=1.0, color=colors[j], label=names[j])
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
    axs[0].legend(fontsize=8, loc="center left")
    return fig


def _fig_setpoints(
    plt: Any, run: RunDir, ref: Any, records: dict, iterations: list[int], names: dict, label: str
) -> Any:
    profile = run.profile()
    colors = _colors(iterations)
    fig, axs = _two_axes(
        plt, "Setpoints flown per iteration, against the reference and limits", label
    )
    t_u = ref.t_s[:-1]
    limits = profile.arena.bounds()
    models = profile.models()
    dev = profile.learning.max_deviation_m if run.kind == "learning" else None
    for ax, (name, c) in zip(axs, AXES, strict=True):
        ax.plot(ref.t_s, ref.pos_ned_m[:, c], "k--", lw=1.6, label="reference", zorder=3)
        if dev is not None:
            r = relative_degree(models[c])
            yd = ref.pos_ned_m[:, c]
            aligned = np.concatenate([yd[r:], np.full(r - 1, yd[-1])])
            ax.fill_between(
                t_u, aligned - dev, aligned + dev, color="0.85", lw=0,
                label=f"max_deviation_m ±{dev:g} m (about yd(k+{r}))",
            )  # fmt: skip
        for j in iterations:
            sp = records[j].sp_ned_m[:-1, c]
            ax.step(t_u, sp, where="post", lw=1.0, color=colors[j], label=f"u, {names[j]}")
        for edge in limits[c]:
            ax.axhline(edge, color="C3", lw=1.2, ls=":")
        ax.plot([], [], color="C3", lw=1.2, ls=":", label="arena")
        ax.set_ylabel(f"{name} setpoint [m]")
        ax.set_ylim(limits[c][0] - 0.3, limits[c][1] + 0.3)
    # below the figure: the band and the arena leave no empty corner inside
    handles, labels = axs[0].get_legend_handles_labels()
    axs[1].legend(handles, labels, fontsize=8, ncol=4, loc="upper center",
                  bbox_to_anchor=(0.5, -0.2))  # fmt: skip
    return fig


def _fig_error(
    plt: Any, ref: Any, records: dict, iterations: list[int], names: dict, label: str
) -> Any:
    colors = _colors(iterations)
    fig, axs = _two_axes(plt, "Tracking error per iteration (position - reference)", label)
    for ax, (name, c) in zip(axs, AXES, strict=True):
        for j in iterations:
            r = records[j]
            ax.plot(r.t_s, r.pos_ned_m[:, c] - ref.pos_ned_m[:, c], lw=1.0, color=colors[j],
                    label=names[j])  # fmt: skip
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_ylabel(f"{name} error [m]")
    axs[0].legend(fontsize=8, ncol=len(iterations), loc="lower left")
    return fig


def _fig_epos(
    plt: Any,
    rows: list[IterationMetrics],
    algorithm: str,
    label: str,
    learning: RunLearning | None = None,
) -> Any:
    from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter

    e0 = rows[0].epos_m
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    fig.suptitle(label, fontsize=8, color="0.3")
    js = [r.iteration for r in rows]  # trial numbers
    ax.semilogy(js, [r.epos_m for r in rows], "o-", color="C0", label="e_pos")
    for r in rows:
        ax.annotate(f"{r.epos_pct:.1f} %", (r.iteration, r.epos_m), textcoords="offset points",
                    xytext=(7, 3), ha="left", fontsize=8)  # fmt: skip
    low = min(r.epos_m for r in rows)
    floor = learning.floor if learning is not None else None
    if floor is not None:
        # the band a trial at the floor falls in (z <= floor_z), and the floor itself
        top = floor.epos_m + learning.floor_z * float(
            np.hypot(floor.scatter_m, floor.floor_scatter_m)
        )
        ax.axhspan(
            max(floor.epos_m - floor.scatter_m, floor.epos_m / 3),
            top,
            color="C2",
            alpha=0.15,
            lw=0,
            label=f"at the floor (z <= {learning.floor_z:g})",
        )
        ax.axhline(floor.epos_m, color="C2", lw=1.2,
                   label=f"floor {1e3 * floor.epos_m:.1f} mm (repeat)")  # fmt: skip
        low = min(low, floor.epos_m - floor.scatter_m)
    labels = [str(j) for j in js]
    if learning is not None and learning.history:
        trials = [learning.trials[t] for t in js]
        labels = [f"{t.iteration}{'r' if t.repeat_of is not None else ''}" for t in trials]
        conv = [t.trial for t in trials if t.verdict is not None and t.verdict.converged]
        if conv:
            e = {r.iteration: r.epos_m for r in rows}
            ax.plot(conv, [e[t] for t in conv], "s", mfc="none", mec="C3", ms=10,
                    label="converged")  # fmt: skip
        ax.set_xlabel("iteration j (r: a repeat of j = 0, which measures the floor)")
    else:
        ax.set_xlabel("iteration j")
    ax.set_ylabel("e_pos,j [m]")
    ax.set_xticks(js, labels)
    ax.set_xlim(min(js) - 0.4, max(js) + 0.4)
    ax.set_ylim(max(low, 1e-6) / 1.6, e0 * 1.6)
    # plain numbers on both log axes: 1-2-5 steps read better than powers of ten
    steps = [m * 10.0**e for e in range(-4, 3) for m in (1, 2, 5)]
    ax.yaxis.set_major_locator(FixedLocator(steps))
    ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="major", alpha=0.3)
    right = ax.secondary_yaxis("right", functions=(lambda m: 100 * m / e0, lambda p: p * e0 / 100))
    right.yaxis.set_major_locator(FixedLocator(steps))
    right.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    right.yaxis.set_minor_formatter(NullFormatter())
    right.set_ylabel("e_pos,j / e_pos,0 [%]")
    if floor is not None:
        ax.legend(fontsize=8, loc="upper right")
    ax.set_title(f"Average position error per iteration ({algorithm}; paper Fig. 2)")
    return fig


def _fig_disturbance(plt: Any, run: RunDir, iterations: list[int], label: str) -> Any | None:
    estimates = {}
    for j in iterations:
        if run.estimate_path(j).exists():
            estimates[j] = run.read_estimate(j)
    if not estimates:
        return None
    colors = _colors(list(estimates))
    fig, axs = _two_axes(
        plt, "Learned repetitive disturbance D (learning coordinates), ±2σ shaded", label
    )
    t = np.arange(1, run.n_samples + 1) * run.t_ilc_s
    # the band is often millimetres on a scale of decimetres: its size is said in the legend
    two_sigma = 2 * np.sqrt(np.maximum(np.concatenate([p for _, p in estimates.values()]), 0.0))
    band = f"±2σ (median {1e3 * float(np.median(two_sigma)):.2g} mm)"
    for ax, (name, c) in zip(axs, AXES, strict=True):
        for i, (j, (d, p)) in enumerate(estimates.items()):
            ax.plot(t, d[:, c], lw=1.0, color=colors[j], label=f"from trial {j}")
            sigma = np.sqrt(np.maximum(p[:, c], 0.0))  # the estimate's variance per sample
            ax.fill_between(t, d[:, c] - 2 * sigma, d[:, c] + 2 * sigma, color=colors[j],
                            alpha=0.25, lw=0, label=band if i == 0 else None)  # fmt: skip
        ax.set_ylabel(f"d {name} [m]")
    axs[0].legend(fontsize=8, ncol=len(estimates) + 1, loc="lower left")
    return fig


def _trial_name(t: TrialLearning) -> str:
    """A trial's label in the figures of a run with repeats: its number and its j."""
    return f"trial {t.trial}, j = {t.iteration}" + (" (repeat)" if t.repeat_of is not None else "")


def report_figures(
    run: RunDir, iterations: list[int], progress: Callable[[int, int], None] | None = None
) -> dict[str, Any]:
    """The report's figures, by name (matplotlib figures; the caller saves and closes them).

    ``xy``: horizontal path per iteration over the reference (paper Fig. 4), its start and
    arrows in the direction of flight; ``position``: north and east against time per
    iteration (Fig. 5, both axes); ``setpoints``: the setpoints flown per iteration against
    the reference, the ``max_deviation_m`` band and the arena; ``error``: position minus
    reference against time per iteration; ``epos``: e_pos,j per iteration, log scale, with
    its percentage of e_pos,0 (Fig. 2), and with a floor the band of e_pos a trial at the
    floor falls in; ``disturbance``: the learned D per iteration with its ±2σ band from the
    estimate's variance (only where estimates exist); in a 3-D run
    (:func:`gcs.app.report.is_three_d`) ``altitude``: altitude and its error against time per
    iteration, and ``views``: the path from above, the side and the front. Every figure
    carries the run's id, profile, trajectory, seed and gcs version (:func:`run_label`). In a
    run with repeats the trials are labelled with their number and their iteration j.

    ``run``: the run directory (trial 0 complete; see :func:`run_metrics`). ``progress``: told
    ``(done, total)`` figures as they are drawn (:func:`gcs.app.progress.track`).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = run_metrics(run)
    ref = run.reference()
    try:
        measurement = run.profile().mocap.measurement
    except ProfileError as exc:
        raise RunLogError(f"{run.manifest_path}: {exc}") from None
    records = {j: run.measured_trial(j, measurement) for j in iterations}  # what learning saw
    learning = run_learning(run) if run.kind == "learning" else None
    names = {j: f"j = {j}" for j in iterations}
    if learning is not None and learning.history:
        names = {j: _trial_name(learning.trials[j]) for j in iterations}
    label = run_label(run_facts(run))
    draw: dict[str, Callable[[], Any]] = {
        "xy": lambda: _fig_xy(plt, ref, records, iterations, names, label),
        "position": lambda: _fig_position(plt, ref, records, iterations, names, label),
        "setpoints": lambda: _fig_setpoints(plt, run, ref, records, iterations, names, label),
        "error": lambda: _fig_error(plt, ref, records, iterations, names, label),
        "epos": lambda: _fig_epos(plt, rows, run.algorithm, label, learning),
        "disturbance": lambda: _fig_disturbance(plt, run, iterations, label),
    }
    if run.kind == "learning" and is_three_d(run):
        draw["altitude"] = lambda: _fig_altitude(plt, ref, records, iterations, names, label)
        draw["views"] = lambda: _fig_views(plt, ref, records, iterations, names, label)
    figures = {}
    for done, (name, figure) in enumerate(draw.items(), start=1):
        fig = figure()
        if fig is not None:  # no disturbance figure where no estimate exists
            figures[name] = fig
        if progress is not None:
            progress(done, len(draw))
    return figures


def write_plots(
    run: RunDir,
    out_dir: Path,
    iterations: list[int] | None = None,
    progress: Callable[[int, int], None] | None = None,
    figure_format: str = "png",
) -> list[Path]:
    """Write the report's figures as files ``<name>.<format>`` (see :func:`report_figures`).

    ``out_dir``: where to write (created if missing). ``iterations``: trials to draw (default: 0, 1,
    2 and the last). ``progress``: told ``(done, total)`` figures as they are drawn.
    ``figure_format``: ``png``, ``svg`` or ``pdf``.
    """
    chosen = choose_iterations(run, iterations)
    figures = report_figures(run, chosen, progress)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return [save_figure(fig, out_dir / f"{name}.{figure_format}") for name, fig in figures.items()]


CAPTIONS = {
    "xy": "Horizontal path of each iteration over the reference (dashed), from the start "
    "(circle) in the direction of the arrows.",
    "position": "North and east position against time: reference (dashed) and iterations.",
    "setpoints": "Setpoints flown (what ILC changes) against the reference, the "
    "max_deviation_m band the update keeps to, and the arena (dotted).",
    "error": "Position minus reference against time, per iteration and axis.",
    "epos": "e_pos,j (eq. 10) per iteration; right axis in % of e_pos,0. With a repeat of "
    "trial 0: the floor (one flight's non-repeatable error) and the band a trial at the floor "
    "falls in.",
    "disturbance": "Repetitive disturbance D estimated from each trial, per axis, with its "
    "±2σ band (the estimate's own variance).",
    "altitude": "Altitude (-down) of each iteration over the reference (dashed), and its "
    "error, against time (3-D runs).",
    "views": "The path of each iteration in three views: from above, the side and the front "
    "(3-D runs).",
}
