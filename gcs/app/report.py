"""Reports of a run: the Table IV rows (rich table, JSON), figures, and one HTML file.

Percentages are always relative to trial 0 (a run whose trial 0 is missing or incomplete, or
whose e_pos,0 is zero, has no percentages and is refused); trials that are missing or
incomplete are listed, never silently left out. The figures follow the paper's (Fig. 2, 4
and 5) for both horizontal axes, and add what ILC changes: the setpoints against the
reference and the limits, the error over time, and the learned disturbance.
"""

from __future__ import annotations

import base64
import html
import io
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from rich.markup import escape
from rich.table import Table

from gcs.app.learn import run_measurement, trial_errors
from gcs.core.metrics import IterationMetrics, iteration_table
from gcs.core.model import relative_degree
from gcs.errors import ProfileError, RunLogError
from gcs.io.runlog import RunDir, TrialRecord, atomic_write_text

__all__ = [
    "TrialEntry",
    "trial_overview",
    "trial_notes",
    "aborted_attempts",
    "run_metrics",
    "trial_clock_rates",
    "session_lines",
    "mocap_lines",
    "metrics_table",
    "metrics_json",
    "parse_iterations",
    "choose_iterations",
    "report_figures",
    "write_plots",
    "write_html",
    "complete_records",
    "figure_png",
    "save_figure",
]

AXES = (("north", 0), ("east", 1))
FIGURES = ("xy", "position", "setpoints", "error", "epos", "disturbance")


@dataclass(frozen=True)
class TrialEntry:
    """What the run directory says about one trial index.

    Parameters
    ----------
    trial : int
        Trial index j.
    status : str
        ``"complete"``, ``"incomplete"`` or ``"missing"`` (no sidecar although a later trial
        has one).
    reason : str or None
        Why an incomplete trial stopped (or what is missing).
    """

    trial: int
    status: str
    reason: str | None = None


def trial_overview(run: RunDir) -> list[TrialEntry]:
    """Every trial index from 0 to the newest on disk, with its status.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    list of TrialEntry
        By index; a gap is ``"missing"``, a CSV without its sidecar ``"incomplete"``.
    """
    statuses = {s.trial: s for s in run.statuses()}
    csv_only = {
        int(p.stem.split("-")[1])
        for p in run.path.glob("trial-[0-9][0-9][0-9].csv")
        if int(p.stem.split("-")[1]) not in statuses
    }
    last = max([*statuses, *csv_only], default=-1)
    out = []
    for j in range(last + 1):
        if j in statuses:
            s = statuses[j]
            out.append(TrialEntry(j, "complete" if s.complete else "incomplete", s.reason))
        elif j in csv_only:
            out.append(TrialEntry(j, "incomplete", f"trial-{j:03d}.csv without its .json"))
        else:
            out.append(TrialEntry(j, "missing", f"no trial-{j:03d}.json"))
    return out


def trial_notes(entries: list[TrialEntry], aborted: dict[int, int] | None = None) -> list[str]:
    """One line per trial that is not in the table (missing or incomplete), and per trial
    flown again after an incomplete attempt.

    Parameters
    ----------
    entries : list of TrialEntry
        From :func:`trial_overview`.
    aborted : dict of int to int, optional
        Incomplete attempts kept in ``aborted/``, by trial (:func:`aborted_attempts`).

    Returns
    -------
    list of str
    """
    out = []
    for e in entries:
        if e.status != "complete":
            reason = f" ({e.reason})" if e.reason else ""
            out.append(f"trial {e.trial}: {e.status}{reason}, not in the table")
    for j, n in sorted((aborted or {}).items()):
        attempts = "attempt" if n == 1 else "attempts"
        out.append(f"trial {j}: {n} earlier incomplete {attempts} kept in aborted/")
    return out


def aborted_attempts(run: RunDir) -> dict[int, int]:
    """Incomplete attempts of each trial that was flown again, kept in ``aborted/``.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    dict of int to int
        Number of attempts by trial index.
    """
    counts: dict[int, int] = {}
    for p in (run.path / "aborted").glob("trial-[0-9][0-9][0-9]-attempt-*.json"):
        j = int(p.name.split("-")[1])
        counts[j] = counts.get(j, 0) + 1
    return counts


def complete_records(run: RunDir, measurement: str | None = None) -> dict[int, TrialRecord]:
    """Every complete trial of ``run``, by index, measured as asked.

    Parameters
    ----------
    run : RunDir
        The run directory.
    measurement : str or None
        ``"mocap"`` or ``"estimate"`` (:meth:`TrialRecord.measured`); None: the run's own
        (``mocap.measurement`` of its profile, default mocap where a trial has it).

    Returns
    -------
    dict of int to TrialRecord
    """
    measurement = measurement or run_measurement(run.profile())
    out = {}
    for j in run.complete_trials():
        try:
            out[j] = run.read_trial(j).measured(measurement)
        except RunLogError as exc:
            raise RunLogError(f"{run.path}/trial-{j:03d}.csv: {exc}") from None
    return out


def mocap_lines(run: RunDir) -> list[str]:
    """With motion capture: e_pos by the mocap and by the estimate per trial, and the lag.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    list of str
        Empty when no complete trial has mocap columns.
    """
    lines = []
    for j in run.complete_trials():
        record = run.read_trial(j)
        if record.mocap_ned_m is None:
            continue
        e_est, _ = trial_errors(record)
        try:
            e_moc = f"{trial_errors(record.measured('mocap'))[0]:.4f} m"
        except RunLogError:
            e_moc = "n/a (mocap gaps)"
        lag = _num((run.read_status(j).extra or {}).get("mocap_lag_s"))
        if not np.isfinite(lag):
            lag_text = "the estimate's lag behind the mocap not measurable"
        elif lag >= 0:
            lag_text = f"the estimate lags the mocap by {lag * 1e3:.0f} ms"
        else:
            lag_text = f"the estimate leads the mocap by {-lag * 1e3:.0f} ms"
        lines.append(
            f"trial {j}: e_pos by mocap {e_moc}, by the estimate {e_est:.4f} m; {lag_text}"
        )
    if lines:
        lines.insert(0, f"measurement: {run_measurement(run.profile())} (mocap.measurement)")
    return lines


def run_metrics(run: RunDir, measurement: str | None = None) -> list[IterationMetrics]:
    """Table IV rows of the complete trials of ``run`` (computed from the CSV files).

    Percentages are relative to trial 0, and the change column compares consecutive trials
    only (``-`` after a gap).

    Parameters
    ----------
    run : RunDir
        The run directory.
    measurement : str or None
        ``"mocap"`` or ``"estimate"``; None: the run's own.

    Returns
    -------
    list of IterationMetrics

    Raises
    ------
    RunLogError
        No complete trial 0 (missing or incomplete), or e_pos,0 = 0.
    """
    records = complete_records(run, measurement)
    if 0 not in records:
        what = "incomplete" if (run.path / "trial-000.json").exists() else "missing"
        raise RunLogError(
            f"{run.path}: trial 0 is {what}; e_pos,j / e_pos,0 needs it (complete trials: "
            f"{', '.join(map(str, records)) or 'none'})"
        )
    errors = {j: trial_errors(r) for j, r in records.items()}
    if not errors[0][0] > 0:
        raise RunLogError(
            f"{run.path}/trial-000.csv: e_pos,0 = 0 (the positions equal the reference); "
            "no percentages relative to it"
        )
    order = sorted(errors)
    rows = iteration_table([errors[j][0] for j in order], [errors[j][1] for j in order], order)
    return [
        r if i == 0 or order[i] - order[i - 1] == 1 else replace(r, delta_pct=None)
        for i, r in enumerate(rows)
    ]


def trial_clock_rates(run: RunDir) -> dict[int, float | None]:
    """The vehicle-time / wall-time rate each trial was flown at, from the sidecars.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    dict of int to float or None
        By trial index; None where it was not recorded (runs flown before it was).
    """
    rates: dict[int, float | None] = {}
    for status in run.statuses():
        rate = (status.extra or {}).get("vehicle_time_rate")
        ok = isinstance(rate, int | float) and not isinstance(rate, bool)
        rates[status.trial] = float(rate) if ok else None
    return rates


def _num(value: Any) -> float:
    return (
        float(value) if isinstance(value, int | float) and not isinstance(value, bool) else np.nan
    )


def session_lines(run: RunDir) -> list[str]:
    """One line per flight session: trials, navigation source, hover and settle tolerances.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    list of str
    """
    lines = []
    for s in run.sessions():
        nav = s.get("navigation")
        nav = nav.get("source", "unknown") if isinstance(nav, dict) else "unknown"
        line = f"session {s.get('session')} (from trial {s.get('first_trial')}): navigation {nav}"
        hovers = s.get("hovers")
        if isinstance(hovers, list) and hovers and isinstance(hovers[0], dict):
            stats = hovers[0].get("stats")
            stats = stats if isinstance(stats, dict) else {}
            line += (
                f"; hover {_num(stats.get('offset_m')):.2f} m off, at most "
                f"{_num(stats.get('distance_max_m')):.2f} m, "
                f"{100 * _num(stats.get('noise_m')):.1f} cm fast noise"
            )
        tolerance = s.get("tolerance_m")
        if tolerance is not None:
            line += f"; settle tolerance {_num(tolerance):.2f} m"
        lines.append(line)
    return lines


def metrics_table(
    rows: list[IterationMetrics],
    title: str = "",
    rates: dict[int, float | None] | None = None,
) -> Table:
    """A rich table with one row per trial (the columns of the paper's Table IV).

    Parameters
    ----------
    rows : list of IterationMetrics
        The rows.
    title : str
        Table title.
    rates : dict of int to float or None, optional
        Vehicle-time rate per trial (:func:`trial_clock_rates`): adds a column when one is
        known.

    Returns
    -------
    rich.table.Table
    """
    table = Table(title=title or None)
    headers = ["j", "e_pos [m]", "e_pos/e_pos0 [%]", "|Δe_pos|/prev [%]", "max err [m]"]
    if rates is not None and all(rate is None for rate in rates.values()):
        rates = None  # a run flown before rates were recorded
    if rates is not None:
        headers.append("clock [x]")
    for header in headers:
        # headers may wrap in a narrow terminal; the numbers never do
        table.add_column(
            escape(header), justify="right", min_width=len(header) if header == "j" else 6
        )
    for cells in _table_cells(rows, rates):
        table.add_row(*cells)
    return table


def _table_cells(
    rows: list[IterationMetrics], rates: dict[int, float | None] | None
) -> list[list[str]]:
    out = []
    for r in rows:
        delta = "-" if r.delta_pct is None else f"{r.delta_pct:.2f}"
        cells = [
            str(r.iteration), f"{r.epos_m:.4f}", f"{r.epos_pct:.2f}", delta, f"{r.max_err_m:.4f}"
        ]  # fmt: skip
        if rates is not None:
            rate = rates.get(r.iteration)
            cells.append("-" if rate is None else f"{rate:.3f}")
        out.append(cells)
    return out


def metrics_json(
    rows: list[IterationMetrics],
    rates: dict[int, float | None] | None = None,
    entries: list[TrialEntry] | None = None,
) -> list[dict]:
    """One JSON object per trial: iteration, status, epos_m, epos_pct, delta_pct, max_err_m.

    Parameters
    ----------
    rows : list of IterationMetrics
        The rows of the complete trials.
    rates : dict of int to float or None, optional
        Vehicle-time rate per trial: adds the key ``vehicle_time_rate`` (null if unknown).
    entries : list of TrialEntry, optional
        Every trial (:func:`trial_overview`): missing and incomplete trials are listed too,
        with ``status``, ``reason`` and null metrics.

    Returns
    -------
    list of dict
        By trial index.
    """
    by_trial = {r.iteration: {**asdict(r), "status": "complete", "reason": None} for r in rows}
    for e in entries or []:
        if e.status != "complete":
            empty = dict.fromkeys(("epos_m", "epos_pct", "delta_pct", "max_err_m"))
            by_trial[e.trial] = {"iteration": e.trial, **empty, "status": e.status,
                                 "reason": e.reason}  # fmt: skip
    out = [by_trial[j] for j in sorted(by_trial)]
    if rates is not None:
        for row in out:
            row["vehicle_time_rate"] = rates.get(row["iteration"])
    return out


def parse_iterations(text: str) -> list[int]:
    """``"0,2,5"`` as ``[0, 2, 5]`` (sorted, unique); refused with the option's name.

    Parameters
    ----------
    text : str
        Comma-separated trial indices.

    Returns
    -------
    list of int
    """
    try:
        values = sorted({int(v) for v in text.split(",") if v.strip()})
    except ValueError:
        raise RunLogError(
            f"--iterations {text}: not a list of trial numbers (e.g. 0,2,5)"
        ) from None
    if not values or values[0] < 0:
        raise RunLogError(f"--iterations {text}: give trial numbers >= 0 (e.g. 0,2,5)")
    return values


def choose_iterations(run: RunDir, wanted: list[int] | None) -> list[int]:
    """The trials to draw: ``wanted`` (each must be complete), or 0, 1, 2 and the last.

    Parameters
    ----------
    run : RunDir
        The run directory.
    wanted : list of int or None
        From ``--iterations``.

    Returns
    -------
    list of int
    """
    done = run.complete_trials()
    if wanted is None:
        return sorted({j for j in (0, 1, 2, max(done, default=0)) if j in done})
    bad = [j for j in wanted if j not in done]
    if bad:
        raise RunLogError(
            f"--iterations: trial {bad[0]} is not a complete trial of {run.path} "
            f"(complete: {', '.join(map(str, done)) or 'none'})"
        )
    return wanted


# ------------------------------------------------------------------------------- figures


def _colors(iterations: list[int]) -> dict[int, Any]:
    import matplotlib

    cmap = matplotlib.colormaps["viridis"]
    n = max(len(iterations) - 1, 1)
    return {j: cmap(0.85 * i / n) for i, j in enumerate(iterations)}


def _fig_xy(plt: Any, ref: Any, records: dict, iterations: list[int]) -> Any:
    colors = _colors(iterations)
    fig, ax = plt.subplots(figsize=(5.6, 6.0))
    ax.plot(ref.pos_ned_m[:, 1], ref.pos_ned_m[:, 0], "k--", lw=1.6, label="reference")
    for j in iterations:
        p = records[j].pos_ned_m
        ax.plot(p[:, 1], p[:, 0], lw=1.1, color=colors[j], label=f"j = {j}")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="center left")
    ax.set_title("Horizontal path per iteration (paper Fig. 4)")
    return fig


def _two_axes(plt: Any, title: str) -> tuple[Any, Any]:
    fig, axs = plt.subplots(2, 1, figsize=(9, 6.2), sharex=True)
    fig.suptitle(title)
    axs[1].set_xlabel("t [s]")
    for ax in axs:
        ax.grid(True, alpha=0.3)
    return fig, axs


def _fig_position(plt: Any, ref: Any, records: dict, iterations: list[int]) -> Any:
    colors = _colors(iterations)
    fig, axs = _two_axes(plt, "Position per iteration (paper Fig. 5, both axes)")
    for ax, (name, c) in zip(axs, AXES, strict=True):
        ax.plot(ref.t_s, ref.pos_ned_m[:, c], "k--", lw=1.6, label="reference")
        for j in iterations:
            r = records[j]
            ax.plot(r.t_s, r.pos_ned_m[:, c], lw=1.1, color=colors[j], label=f"j = {j}")
        ax.set_ylabel(f"{name} [m]")
    axs[0].legend(fontsize=8, ncol=len(iterations) + 1, loc="lower left")  # the hover: empty
    return fig


def _fig_setpoints(plt: Any, run: RunDir, ref: Any, records: dict, iterations: list[int]) -> Any:
    profile = run.profile()
    colors = _colors(iterations)
    fig, axs = _two_axes(plt, "Setpoints flown per iteration, against the reference and limits")
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
            ax.step(t_u, sp, where="post", lw=1.0, color=colors[j], label=f"u, j = {j}")
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


def _fig_error(plt: Any, ref: Any, records: dict, iterations: list[int]) -> Any:
    colors = _colors(iterations)
    fig, axs = _two_axes(plt, "Tracking error per iteration (position - reference)")
    for ax, (name, c) in zip(axs, AXES, strict=True):
        for j in iterations:
            r = records[j]
            ax.plot(r.t_s, r.pos_ned_m[:, c] - ref.pos_ned_m[:, c], lw=1.0, color=colors[j],
                    label=f"j = {j}")  # fmt: skip
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_ylabel(f"{name} error [m]")
    axs[0].legend(fontsize=8, ncol=len(iterations), loc="lower left")
    return fig


def _fig_epos(plt: Any, rows: list[IterationMetrics], algorithm: str) -> Any:
    from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter

    e0 = rows[0].epos_m
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    js = [r.iteration for r in rows]
    ax.semilogy(js, [r.epos_m for r in rows], "o-", color="C0")
    for r in rows:
        ax.annotate(f"{r.epos_pct:.1f} %", (r.iteration, r.epos_m), textcoords="offset points",
                    xytext=(7, 3), ha="left", fontsize=8)  # fmt: skip
    ax.set_xlabel("iteration j")
    ax.set_ylabel("e_pos,j [m]")
    ax.set_xticks(js)
    ax.set_xlim(min(js) - 0.4, max(js) + 0.4)
    low = min(r.epos_m for r in rows)
    ax.set_ylim(low / 1.6, e0 * 1.6)
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
    ax.set_title(f"Average position error per iteration ({algorithm}; paper Fig. 2)")
    return fig


def _fig_disturbance(plt: Any, run: RunDir, iterations: list[int]) -> Any | None:
    estimates = {}
    for j in iterations:
        if (run.path / f"estimate-{j:03d}.csv").exists():
            estimates[j] = run.read_estimate(j)[0]
    if not estimates:
        return None
    colors = _colors(list(estimates))
    fig, axs = _two_axes(plt, "Learned repetitive disturbance D (learning coordinates)")
    t = np.arange(1, run.n_samples + 1) * run.t_ilc_s
    for ax, (name, c) in zip(axs, AXES, strict=True):
        for j, d in estimates.items():
            ax.plot(t, d[:, c], lw=1.0, color=colors[j], label=f"from trial {j}")
        ax.set_ylabel(f"d {name} [m]")
    axs[0].legend(fontsize=8, ncol=len(estimates), loc="lower left")
    return fig


def report_figures(run: RunDir, iterations: list[int]) -> dict[str, Any]:
    """The report's figures, by name (matplotlib figures; the caller saves and closes them).

    ``xy``: horizontal path per iteration over the reference (paper Fig. 4); ``position``:
    north and east against time per iteration (Fig. 5, both axes); ``setpoints``: the
    setpoints flown per iteration against the reference, the ``max_deviation_m`` band and the
    arena; ``error``: position minus reference against time per iteration; ``epos``: e_pos,j
    per iteration, log scale, with its percentage of e_pos,0 (Fig. 2); ``disturbance``: the
    learned D per iteration (only where estimates exist).

    Parameters
    ----------
    run : RunDir
        The run directory (trial 0 complete; see :func:`run_metrics`).
    iterations : list of int
        Complete trials to draw (:func:`choose_iterations`).

    Returns
    -------
    dict of str to matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = run_metrics(run)
    records = {j: run.read_trial(j) for j in iterations}
    ref = run.reference()
    try:
        run.profile()
    except ProfileError as exc:
        raise RunLogError(f"{run.path}/manifest.json: {exc}") from None
    figures = {
        "xy": _fig_xy(plt, ref, records, iterations),
        "position": _fig_position(plt, ref, records, iterations),
        "setpoints": _fig_setpoints(plt, run, ref, records, iterations),
        "error": _fig_error(plt, ref, records, iterations),
        "epos": _fig_epos(plt, rows, run.algorithm),
    }
    disturbance = _fig_disturbance(plt, run, iterations)
    if disturbance is not None:
        figures["disturbance"] = disturbance
    return figures


def write_plots(run: RunDir, out_dir: Path, iterations: list[int] | None = None) -> list[Path]:
    """Write the report's figures as PNG files ``<name>.png`` (see :func:`report_figures`).

    Parameters
    ----------
    run : RunDir
        The run directory.
    out_dir : Path
        Where to write (created if missing).
    iterations : list of int, optional
        Trials to draw (default: 0, 1, 2 and the last).

    Returns
    -------
    list of Path
    """
    chosen = choose_iterations(run, iterations)
    figures = report_figures(run, chosen)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return [save_figure(fig, out_dir / f"{name}.png") for name, fig in figures.items()]


_CAPTIONS = {
    "xy": "Horizontal path of each iteration over the reference (dashed).",
    "position": "North and east position against time: reference (dashed) and iterations.",
    "setpoints": "Setpoints flown (what ILC changes) against the reference, the "
    "max_deviation_m band the update keeps to, and the arena (dotted).",
    "error": "Position minus reference against time, per iteration and axis.",
    "epos": "e_pos,j (eq. 10) per iteration; right axis in % of e_pos,0.",
    "disturbance": "Repetitive disturbance D estimated from each trial, per axis.",
}

_CSS = (
    "body{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}"
    "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px;"
    "text-align:right}th{background:#eee}figure{margin:1.5em 0}img{max-width:100%}"
    "figcaption{font-size:90%;color:#444}.meta td{text-align:left}"
)


def write_html(run: RunDir, path: Path, iterations: list[int] | None = None) -> Path:
    """Write one self-contained HTML report: run facts, the table, notes and every figure.

    The figures are embedded as base64 PNG; the file refers to nothing outside itself and
    can be mailed as it is.

    Parameters
    ----------
    run : RunDir
        The run directory.
    path : Path
        The HTML file (written atomically; its directory created if missing).
    iterations : list of int, optional
        Trials to draw (default: 0, 1, 2 and the last).

    Returns
    -------
    Path
    """
    rows = run_metrics(run)
    rates = trial_clock_rates(run)
    if all(rate is None for rate in rates.values()):
        rates = None
    chosen = choose_iterations(run, iterations)
    figures = {name: figure_png(fig) for name, fig in report_figures(run, chosen).items()}
    m = run.manifest
    e = html.escape
    facts = [
        ("run", str(run.path)), ("algorithm", run.algorithm),
        ("profile", str(m["profile"].get("name"))),
        ("trajectory", str(m["trajectory"].get("name"))),
        ("samples", f"{run.n_samples} at {run.t_ilc_s:g} s"),
        ("created (UTC)", str(m.get("created_utc"))), ("gcs", str(m.get("gcs_version"))),
        ("iterations drawn", ", ".join(map(str, chosen))),
    ]  # fmt: skip
    headers = ["j", "e_pos [m]", "e_pos/e_pos0 [%]", "|Δe_pos|/prev [%]", "max err [m]"]
    if rates is not None:
        headers.append("clock [x]")
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>gcs report: {e(run.path.name)}</title><style>{_CSS}</style></head><body>",
        f"<h1>gcs report: {e(run.path.name)}</h1>",
        '<table class="meta">'
        + "".join(f"<tr><th>{e(k)}</th><td>{e(v)}</td></tr>" for k, v in facts)
        + "</table>",
        "<h2>Learning table (paper Table IV)</h2><table><tr>"
        + "".join(f"<th>{e(h)}</th>" for h in headers)
        + "</tr>",
        *("<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>"
          for row in _table_cells(rows, rates)),
        "</table>",
    ]  # fmt: skip
    notes = trial_notes(trial_overview(run), aborted_attempts(run)) + session_lines(run)
    if notes:
        parts.append("<ul>" + "".join(f"<li>{e(n)}</li>" for n in notes) + "</ul>")
    parts.append("<h2>Figures</h2>")
    for name, png in figures.items():
        data = base64.b64encode(png).decode("ascii")
        parts.append(
            f'<figure><img alt="{name}" src="data:image/png;base64,{data}">'
            f"<figcaption>{e(_CAPTIONS[name])}</figcaption></figure>"
        )
    parts.append("</body></html>\n")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, "\n".join(parts))
    return path


def figure_png(fig: Any) -> bytes:
    """A matplotlib figure as PNG bytes; the figure is closed.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.

    Returns
    -------
    bytes
    """
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


def save_figure(fig: Any, path: Path) -> Path:
    """Write a matplotlib figure as PNG atomically (temporary file + rename) and close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : Path
        Destination (.png).

    Returns
    -------
    Path
    """
    import matplotlib.pyplot as plt

    tmp = path.with_name(f".{path.name}.tmp.png")
    fig.tight_layout()
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)
    return path
