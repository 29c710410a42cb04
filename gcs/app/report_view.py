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
    metrics_json,
    parse_iterations,
    report_document,
    run_facts,
    run_learning,
    run_metrics,
    run_verdict,
    trial_clock_rates,
    trial_overview,
)
from gcs.app.report_text import (
    metrics_table,
    mocap_lines,
    report_notes,
    shows_step,
    table_legend,
)
from gcs.errors import RunLogError
from gcs.io.rundir import RunDir

__all__ = ["show_report", "FIGURE_FORMATS"]


#: Figure formats ``--format`` takes (matplotlib writes each by the file's extension).
FIGURE_FORMATS = ("png", "svg", "pdf")


def show_report(
    console: Console,
    err_console: Console,
    run_dir: Path | list[Path],
    as_json: bool = False,
    plot: Path | None = None,
    html: Path | None = None,
    iterations: str | None = None,
    csv: Path | None = None,
    figure_format: str = "png",
    export_setpoints: Path | None = None,
) -> None:
    """``gcs report``: check every input and output, then print the table or the JSON and
    write the figures, the CSV, the setpoints and the HTML file.

    Parameters
    ----------
    console, err_console : rich.console.Console
        Where the table (stdout) and the "wrote" lines (stderr) go.
    run_dir : Path or list of Path
        The run directory (``logs/latest`` is reported under the run's own id); two or more
        compare the runs (:mod:`gcs.app.report_compare`).
    as_json : bool
        Print the JSON document (docs/report.md) instead of the table.
    plot : Path or None
        Write the figures here (``figure_format``).
    html : Path or None
        Write the self-contained HTML report here (one run).
    iterations : str or None
        Trials to draw, e.g. ``"0,2,5"`` (default: 0, 1, 2 and the last; one run).
    csv : Path or None
        Write the table as CSV here (compared runs: e_pos per trial and run).
    figure_format : str
        ``png``, ``svg`` or ``pdf``: the figures of ``--plot``.
    export_setpoints : Path or None
        Write the best learned trial's setpoints here as a ``samples`` CSV (one run).
    """
    from gcs.io.paths import check_output_dir, check_output_file

    runs = [Path(run_dir)] if isinstance(run_dir, str | Path) else [Path(p) for p in run_dir]
    if figure_format not in FIGURE_FORMATS:
        raise RunLogError(
            f"--format {figure_format}: not a figure format (one of {', '.join(FIGURE_FORMATS)})"
        )
    if len(runs) > 1:
        for option, value in (("--html", html), ("--iterations", iterations),
                              ("--export-setpoints", export_setpoints)):  # fmt: skip
            if value is not None:
                raise RunLogError(
                    f"{option}: reports one run; {len(runs)} runs given (compare them without "
                    f"{option}, or give one run)"
                )
    if csv is not None:
        check_output_file(csv, "--csv")
        if csv.suffix.lower() != ".csv":
            raise RunLogError(f"--csv {csv}: the file must end in .csv")
    if export_setpoints is not None:
        check_output_file(export_setpoints, "--export-setpoints")
        if export_setpoints.suffix.lower() != ".csv":
            raise RunLogError(
                f"--export-setpoints {export_setpoints}: the file must end in .csv (a samples "
                "file, docs/trajectories.md)"
            )
    if len(runs) > 1:
        _compare(console, err_console, runs, as_json, plot, csv, figure_format)
        return
    run = RunDir.open(runs[0])
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
    export_trial = None
    if export_setpoints is not None:
        from gcs.app.report_export import best_learned_trial

        if learning is None:
            raise RunLogError(
                f"--export-setpoints: {run.path} is an identification run; it learned no setpoints"
            )
        export_trial = best_learned_trial(run, learning)
    if as_json:
        document = report_document(run, rows, rates, entries, learning)
        console.out(json.dumps(document, indent=2, allow_nan=False), highlight=False)
    else:
        title = run_facts(run).title()
        three_d = run.kind == "learning" and is_three_d(run)
        console.print(metrics_table(rows, title, rates, learning, console.width, three_d))
        verdict = run_verdict(rows, learning).lines() if learning is not None else []
        shown = shows_step(rows, rates, learning, console.width, three_d)
        lines = table_legend(learning, shown) + verdict + report_notes(run, entries, learning)
        for line in lines + mocap_lines(run):
            console.print(escape(line), highlight=False)
    if csv is not None:
        from gcs.app.report_export import write_table_csv

        written_csv = write_table_csv(csv, metrics_json(rows, rates, entries, learning))
        err_console.print(f"wrote {written_csv}")
    if export_setpoints is not None and export_trial is not None:
        from gcs.app.report_export import write_setpoints

        written = write_setpoints(run, export_setpoints, export_trial)
        err_console.print(
            f"wrote {written}: the setpoints of trial {export_trial}, the best learned, as a "
            f"samples file (docs/report.md#exports): stream them at {run.t_ilc_s:g} s as they are"
        )
    if plot is not None:
        from gcs.app.report_figures import write_plots

        with track(err_console, "report: figures", "figures") as progress:
            paths = write_plots(run, plot, chosen, progress, figure_format)
        for path in paths:
            err_console.print(f"wrote {path}")
    if html is not None:
        from gcs.app.report_html import write_html

        with track(err_console, "report: HTML figures", "figures") as progress:
            written_html = write_html(run, html, chosen, progress)
        err_console.print(f"wrote {written_html}")


def _compare(
    console: Console,
    err_console: Console,
    paths: list[Path],
    as_json: bool,
    plot: Path | None,
    csv: Path | None,
    figure_format: str,
) -> None:
    """``gcs report RUN RUN ...``: the runs side by side."""
    from rich import box
    from rich.table import Table

    from gcs.app.report_compare import (
        compare_document,
        compare_figure,
        compare_lines,
        compare_runs,
        compare_table,
    )
    from gcs.io.paths import check_output_dir

    if plot is not None:
        check_output_dir(plot, "--plot")
    runs = compare_runs(paths)
    headers, summary, per_trial = compare_table(runs)
    if as_json:
        document = compare_document(runs)
        console.out(json.dumps(document, indent=2, allow_nan=False), highlight=False)
    else:
        names = [c.name for c in runs]
        short = max(map(len, names)) > 12 or len(names) > 3  # numbered, named below
        shown = [f"run {i + 1}" for i in range(len(names))] if short else names
        table = Table(
            title=f"{len(runs)} runs compared", box=box.SIMPLE_HEAD, show_edge=False,
            pad_edge=False, padding=(0, 1), collapse_padding=True,
        )  # fmt: skip
        for i, h in enumerate(headers):
            cells = [row[i] for row in summary]
            width = max(len(w) for w in (*h.split(), *cells)) if i else None
            left = h in ("run", "trajectory")
            table.add_column(
                escape(h), justify="left" if left else "right", min_width=width, max_width=width
            )
        for row, name in zip(summary, shown, strict=True):
            table.add_row(*map(escape, [name, *row[1:]]))
        console.print(table)
        trials = Table(title=escape("e_pos [mm] per trial"), box=box.SIMPLE_HEAD, show_edge=False)
        trials.add_column("trial", justify="right")
        for name in shown:
            trials.add_column(escape(name), justify="right")
        for row in per_trial:
            trials.add_row(*row)
        console.print(trials)
        if short:
            for label, name in zip(shown, names, strict=True):
                console.print(escape(f"{label}: {name}"), highlight=False)
        for line in compare_lines(runs):
            console.print(escape(line), highlight=False)
    if csv is not None:
        from gcs.app.report_export import write_rows_csv

        names = [c.name for c in runs]
        rows = [{"trial": int(r[0]), **{n: _float(v) for n, v in zip(names, r[1:], strict=True)}}
                for r in per_trial]  # fmt: skip
        err_console.print(f"wrote {write_rows_csv(csv, rows, comment='e_pos [mm] per trial')}")
    if plot is not None:
        from gcs.app.figures import save_figure

        plot.mkdir(parents=True, exist_ok=True)
        path = save_figure(compare_figure(runs), plot / f"compare-epos.{figure_format}")
        err_console.print(f"wrote {path}")


def _float(text: str) -> float | None:
    return None if text == "-" else float(text)
