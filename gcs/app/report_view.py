"""The terminal side of ``gcs report``: every input and output checked, then the table or the
JSON printed and the figures and the HTML file written (the CLI only wires its options here).

The numbers come from :mod:`gcs.app.report`, the text from :mod:`gcs.app.report_text`, the
figures from :mod:`gcs.app.report_figures`, the HTML file from :mod:`gcs.app.report_html`.
"""

from __future__ import annotations

import json
from pathlib import Path

from rich.console import Console
from rich.markup import escape

from gcs.app.progress import track
from gcs.app.report import (
    choose_iterations,
    is_three_d,
    parse_iterations,
    report_document,
    run_facts,
    run_learning,
    run_metrics,
    trial_clock_rates,
    trial_overview,
)
from gcs.app.report_text import metrics_table, mocap_lines, report_notes
from gcs.io.rundir import RunDir

__all__ = ["show_report"]


def show_report(
    console: Console,
    err_console: Console,
    run_dir: Path,
    as_json: bool = False,
    plot: Path | None = None,
    html: Path | None = None,
    iterations: str | None = None,
) -> None:
    """``gcs report``: check every input and output, then print the table or the JSON and
    write the figures and the HTML file.

    Parameters
    ----------
    console, err_console : rich.console.Console
        Where the table (stdout) and the "wrote" lines (stderr) go.
    run_dir : Path
        The run directory (``logs/latest`` is reported under the run's own id).
    as_json : bool
        Print the JSON document (docs/report.md) instead of the table.
    plot : Path or None
        Write the figures as PNG here.
    html : Path or None
        Write the self-contained HTML report here.
    iterations : str or None
        Trials to draw, e.g. ``"0,2,5"`` (default: 0, 1, 2 and the last).
    """
    from gcs.app.report_figures import write_plots
    from gcs.app.report_html import write_html
    from gcs.io.paths import check_output_dir, check_output_file

    run = RunDir.open(run_dir)
    run.profile()  # a damaged manifest is a damaged run, even where the table needs no profile
    rows = run_metrics(run)
    entries = trial_overview(run)
    rates = trial_clock_rates(run)
    chosen = choose_iterations(run, None if iterations is None else parse_iterations(iterations))
    if plot is not None:
        check_output_dir(plot, "--plot")
    if html is not None:
        check_output_file(html, "--html")
    learning = run_learning(run) if run.kind == "learning" else None
    if as_json:
        document = report_document(run, rows, rates, entries, learning)
        console.out(json.dumps(document, indent=2, allow_nan=False), highlight=False)
    else:
        title = run_facts(run).title()
        three_d = run.kind == "learning" and is_three_d(run)
        console.print(metrics_table(rows, title, rates, learning, console.width, three_d))
        for line in report_notes(run, entries, learning) + mocap_lines(run):
            console.print(escape(line), highlight=False)
    if plot is not None:
        with track(err_console, "report: figures", "figures") as progress:
            paths = write_plots(run, plot, chosen, progress)
        for path in paths:
            err_console.print(f"wrote {path}")
    if html is not None:
        with track(err_console, "report: HTML figures", "figures") as progress:
            written = write_html(run, html, chosen, progress)
        err_console.print(f"wrote {written}")
