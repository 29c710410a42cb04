"""``gcs report`` as asked: its request, every input and output checked, and the sequence.

The numbers come from :mod:`gcs.app.report` (one run) and :mod:`gcs.app.report_compare`
(several), the files from :mod:`gcs.app.report_export`, :mod:`gcs.app.report_figures` and
:mod:`gcs.app.report_html`; a :class:`ReportView` (the terminal's:
:class:`gcs.app.report_view.ReportDisplay`) shows the table or the JSON and what was written.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from gcs.errors import RunLogError
from gcs.io.rundir import RunDir

__all__ = ["FIGURE_FORMATS", "ReportRequest", "report"]

#: Figure formats ``--format`` takes (matplotlib writes each by the file's extension).
FIGURE_FORMATS = ("png", "svg", "pdf")


@dataclass(frozen=True)
class ReportRequest:
    """``gcs report`` as asked: its options, before anything is checked.

    Parameters
    ----------
    runs : tuple of Path
        The run directories (``logs/latest`` is reported under the run's own id); two or
        more compare the runs.
    as_json : bool
        ``--json``: print the JSON document (docs/report.md) instead of the table.
    plot : Path or None
        ``--plot``: write the figures here.
    html : Path or None
        ``--html``: write the self-contained HTML report here (one run).
    iterations : str or None
        ``--iterations``: trials to draw, e.g. ``"0,2,5"`` (one run).
    csv : Path or None
        ``--csv``: write the table as CSV here.
    figure_format : str
        ``--format``: ``png``, ``svg`` or ``pdf``, the figures of ``--plot``.
    export_setpoints : Path or None
        ``--export-setpoints``: write the best learned trial's setpoints here (one run).
    """

    runs: tuple[Path, ...]
    as_json: bool = False
    plot: Path | None = None
    html: Path | None = None
    iterations: str | None = None
    csv: Path | None = None
    figure_format: str = "png"
    export_setpoints: Path | None = None


class ReportView(Protocol):
    """What ``gcs report`` shows."""

    def document(self, document: dict[str, Any]) -> None:
        """The JSON document, on stdout."""

    def table(self, run: RunDir, rows: list[Any], rates: Any, entries: Any, learning: Any) -> None:
        """One run's table, legend, verdict and notes."""

    def compared(
        self, runs: list[Any], headers: list[str], summary: list[list[str]], per_trial: Any
    ) -> None:
        """Several runs side by side."""

    def figures(self, label: str) -> AbstractContextManager[Callable[[int, int], None]]:
        """The progress of figures being drawn, ``progress(done, total)``."""

    def wrote(self, line: str) -> None:
        """A file written (``wrote PATH``, and what it holds), on stderr."""


def _check_request(request: ReportRequest) -> None:
    """The options alone: the figure format, what reports one run only, the CSV paths."""
    from gcs.io.paths import check_output_file

    runs = request.runs
    if request.figure_format not in FIGURE_FORMATS:
        raise RunLogError(
            f"--format {request.figure_format}: not a figure format (one of "
            f"{', '.join(FIGURE_FORMATS)})"
        )
    if len(runs) > 1:
        for option, value in (("--html", request.html), ("--iterations", request.iterations),
                              ("--export-setpoints", request.export_setpoints)):  # fmt: skip
            if value is not None:
                raise RunLogError(
                    f"{option}: reports one run; {len(runs)} runs given (compare them without "
                    f"{option}, or give one run)"
                )
    if request.csv is not None:
        check_output_file(request.csv, "--csv")
        if request.csv.suffix.lower() != ".csv":
            raise RunLogError(f"--csv {request.csv}: the file must end in .csv")
    if request.export_setpoints is not None:
        check_output_file(request.export_setpoints, "--export-setpoints")
        if request.export_setpoints.suffix.lower() != ".csv":
            raise RunLogError(
                f"--export-setpoints {request.export_setpoints}: the file must end in .csv (a "
                "samples file, docs/trajectories.md)"
            )


def report(request: ReportRequest, view: ReportView) -> None:
    """``gcs report``: check every input and output, then show the table or the JSON and
    write the figures, the CSV, the setpoints and the HTML file.

    Parameters
    ----------
    request : ReportRequest
        The command's options.
    view : ReportView
        What it shows.
    """
    from gcs.app.report import (
        choose_iterations,
        metrics_json,
        parse_iterations,
        report_document,
        run_learning,
        run_metrics,
        trial_clock_rates,
        trial_overview,
    )
    from gcs.io.paths import check_output_dir, check_output_file

    _check_request(request)
    if len(request.runs) > 1:
        _compare(request, view)
        return
    run = RunDir.open(request.runs[0])
    run.profile()  # a damaged manifest is a damaged run, even where the table needs no profile
    rows = run_metrics(run)
    entries = trial_overview(run)
    rates = trial_clock_rates(run)
    given = None if request.iterations is None else parse_iterations(request.iterations)
    chosen = choose_iterations(run, given)
    if request.plot is not None:
        check_output_dir(request.plot, "--plot")
    if request.html is not None:
        check_output_file(request.html, "--html")
    learning = run_learning(run) if run.kind == "learning" else None
    export_trial = None
    if request.export_setpoints is not None:
        from gcs.app.report_export import best_learned_trial

        if learning is None:
            raise RunLogError(
                f"--export-setpoints: {run.path} is an identification run; it learned no setpoints"
            )
        export_trial = best_learned_trial(run, learning)
    if request.as_json:
        view.document(report_document(run, rows, rates, entries, learning))
    else:
        view.table(run, rows, rates, entries, learning)
    if request.csv is not None:
        from gcs.app.report_export import write_table_csv

        written_csv = write_table_csv(request.csv, metrics_json(rows, rates, entries, learning))
        view.wrote(f"wrote {written_csv}")
    if request.export_setpoints is not None and export_trial is not None:
        from gcs.app.report_export import write_setpoints

        written = write_setpoints(run, request.export_setpoints, export_trial)
        view.wrote(
            f"wrote {written}: the setpoints of trial {export_trial}, the best learned, as a "
            f"samples file (docs/report.md#exports): stream them at {run.t_ilc_s:g} s as they are"
        )
    if request.plot is not None:
        from gcs.app.report_figures import write_plots

        with view.figures("report: figures") as progress:
            paths = write_plots(run, request.plot, chosen, progress, request.figure_format)
        for path in paths:
            view.wrote(f"wrote {path}")
    if request.html is not None:
        from gcs.app.report_html import write_html

        with view.figures("report: HTML figures") as progress:
            written_html = write_html(run, request.html, chosen, progress)
        view.wrote(f"wrote {written_html}")


def _compare(request: ReportRequest, view: ReportView) -> None:
    """``gcs report RUN RUN ...``: the runs side by side."""
    from gcs.app.report_compare import (
        compare_document,
        compare_figure,
        compare_runs,
        compare_table,
    )
    from gcs.io.paths import check_output_dir

    plot, csv = request.plot, request.csv
    if plot is not None:
        check_output_dir(plot, "--plot")
    runs = compare_runs(list(request.runs))
    headers, summary, per_trial = compare_table(runs)
    if request.as_json:
        view.document(compare_document(runs))
    else:
        view.compared(runs, headers, summary, per_trial)
    if csv is not None:
        from gcs.app.report_export import write_rows_csv

        names = [c.name for c in runs]
        rows = [{"trial": int(r[0]), **{n: _float(v) for n, v in zip(names, r[1:], strict=True)}}
                for r in per_trial]  # fmt: skip
        view.wrote(f"wrote {write_rows_csv(csv, rows, comment='e_pos [mm] per trial')}")
    if plot is not None:
        from gcs.app.figures import save_figure

        plot.mkdir(parents=True, exist_ok=True)
        path = save_figure(compare_figure(runs), plot / f"compare-epos.{request.figure_format}")
        view.wrote(f"wrote {path}")


def _float(text: str) -> float | None:
    return None if text == "-" else float(text)
