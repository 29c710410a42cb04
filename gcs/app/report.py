"""Reports of a run: the Table IV rows, as a rich table, as JSON, and as plots."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any

from rich.markup import escape
from rich.table import Table

from gcs.app.learn import trial_errors
from gcs.core.metrics import IterationMetrics, iteration_table
from gcs.errors import RunLogError
from gcs.io.runlog import RunDir, TrialRecord

__all__ = [
    "run_metrics",
    "trial_clock_rates",
    "session_lines",
    "metrics_table",
    "metrics_json",
    "write_plots",
    "complete_records",
    "save_figure",
]


def complete_records(run: RunDir) -> dict[int, TrialRecord]:
    """Every complete trial of ``run``, by index.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    dict of int to TrialRecord
    """
    return {j: run.read_trial(j) for j in run.complete_trials()}


def run_metrics(run: RunDir) -> list[IterationMetrics]:
    """Table IV rows of the complete trials of ``run`` (computed from the CSV files).

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    list of IterationMetrics
    """
    records = complete_records(run)
    if not records:
        raise RunLogError(f"{run.path}: no complete trial to report")
    errors = [trial_errors(r) for r in records.values()]
    return iteration_table([e for e, _ in errors], [m for _, m in errors], list(records))


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
        rates[status.trial] = None if rate is None else float(rate)
    return rates


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
        nav = (s.get("navigation") or {}).get("source", "unknown")
        line = f"session {s.get('session')} (from trial {s.get('first_trial')}): navigation {nav}"
        hovers = s.get("hovers") or []
        if hovers:
            stats = hovers[0].get("stats") or {}
            line += (
                f"; hover {stats.get('offset_m', float('nan')):.2f} m off, at most "
                f"{stats.get('distance_max_m', float('nan')):.2f} m, "
                f"{100 * stats.get('noise_m', float('nan')):.1f} cm fast noise"
            )
        tolerance = s.get("tolerance_m")
        if tolerance is not None:
            line += f"; settle tolerance {tolerance:.2f} m"
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
    for r in rows:
        delta = "-" if r.delta_pct is None else f"{r.delta_pct:.2f}"
        cells = [
            str(r.iteration), f"{r.epos_m:.4f}", f"{r.epos_pct:.2f}", delta, f"{r.max_err_m:.4f}"
        ]  # fmt: skip
        if rates is not None:
            rate = rates.get(r.iteration)
            cells.append("-" if rate is None else f"{rate:.3f}")
        table.add_row(*cells)
    return table


def metrics_json(
    rows: list[IterationMetrics], rates: dict[int, float | None] | None = None
) -> list[dict]:
    """Rows as JSON objects with keys iteration, epos_m, epos_pct, delta_pct, max_err_m.

    Parameters
    ----------
    rows : list of IterationMetrics
        The rows.
    rates : dict of int to float or None, optional
        Vehicle-time rate per trial: adds the key ``vehicle_time_rate`` (null if unknown).

    Returns
    -------
    list of dict
    """
    out = [asdict(r) for r in rows]
    if rates is not None:
        for row in out:
            row["vehicle_time_rate"] = rates.get(row["iteration"])
    return out


def write_plots(run: RunDir, out_dir: Path, iterations: list[int] | None = None) -> list[Path]:
    """Write the paper's figures for a run as PNG files.

    ``xy.png``: north-east paths of selected iterations over the reference (Fig. 4);
    ``north_t.png``: north position against time per iteration (Fig. 5);
    ``epos.png``: e_pos by iteration (Fig. 2, semilog).

    Parameters
    ----------
    run : RunDir
        The run directory.
    out_dir : Path
        Where to write (created if missing).
    iterations : list of int, optional
        Trials to draw in the path plots (default: 0, 1, 2 and the last).

    Returns
    -------
    list of Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    records = complete_records(run)
    if not records:
        raise RunLogError(f"{run.path}: no complete trial to plot")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if iterations is None:
        last = max(records)
        iterations = sorted({j for j in (0, 1, 2, last) if j in records})
    ref = run.reference()
    paths = []

    fig, ax = plt.subplots(figsize=(6, 5))
    ax.plot(ref.pos_ned_m[:, 1], ref.pos_ned_m[:, 0], "k--", lw=1.5, label="reference")
    for j in iterations:
        p = records[j].pos_ned_m
        ax.plot(p[:, 1], p[:, 0], lw=1, label=f"j = {j}")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal")
    ax.legend()
    ax.set_title("Horizontal path per iteration")
    paths.append(save_figure(fig, out_dir / "xy.png"))

    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(ref.t_s, ref.pos_ned_m[:, 0], "k--", lw=1.5, label="reference")
    for j in iterations:
        r = records[j]
        ax.plot(r.t_s, r.pos_ned_m[:, 0], lw=1, label=f"j = {j}")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("north [m]")
    ax.legend()
    ax.set_title("North position per iteration")
    paths.append(save_figure(fig, out_dir / "north_t.png"))

    rows = run_metrics(run)
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.semilogy([r.iteration for r in rows], [r.epos_m for r in rows], "o-")
    ax.set_xlabel("iteration j")
    ax.set_ylabel("e_pos,j [m]")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(f"Average position error ({run.algorithm})")
    paths.append(save_figure(fig, out_dir / "epos.png"))
    return paths


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
