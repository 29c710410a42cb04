"""The terminal side of ``gcs report``: the table or the JSON, runs compared side by side, and
the files written (:func:`gcs.app.report_run.report` checks and sequences, this only shows).

The numbers come from :mod:`gcs.app.report`, the text from :mod:`gcs.app.report_text`.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from rich.console import Console
from rich.markup import escape

from gcs.app.progress import track
from gcs.app.report import is_three_d, run_facts, run_verdict
from gcs.app.report_text import (
    metrics_table,
    mocap_lines,
    report_notes,
    shows_step,
    table_legend,
)
from gcs.core.metrics import IterationMetrics
from gcs.io.rundir import RunDir

__all__ = ["ReportDisplay"]


class ReportDisplay:
    """``gcs report`` on the terminal (:class:`gcs.app.report_run.ReportView`).

    Parameters
    ----------
    console, err_console : rich.console.Console
        The table or the JSON (stdout); the progress and the "wrote" lines (stderr).
    """

    def __init__(self, console: Console, err_console: Console) -> None:
        self.console, self.err = console, err_console

    def document(self, document: dict[str, Any]) -> None:
        """The JSON document, indented, as it is (no markup, no highlighting).

        Parameters
        ----------
        document : dict
            A run's (docs/report.md) or a comparison's.
        """
        self.console.out(json.dumps(document, indent=2, allow_nan=False), highlight=False)

    def table(
        self,
        run: RunDir,
        rows: list[IterationMetrics],
        rates: Any,
        entries: Any,
        learning: Any,
    ) -> None:
        """One run's table (Table IV's columns and more), its legend, verdict and notes.

        Parameters
        ----------
        run : RunDir
            The run.
        rows : list of IterationMetrics
            Its rows (:func:`gcs.app.report.run_metrics`).
        rates : dict
            Vehicle clock rate per trial (:func:`gcs.app.report.trial_clock_rates`).
        entries : list
            Every trial's status (:func:`gcs.app.report.trial_overview`).
        learning : RunLearning or None
            The learning run's extras (None for an identification run).
        """
        title = run_facts(run).title()
        three_d = run.kind == "learning" and is_three_d(run)
        width = self.console.width
        self.console.print(metrics_table(rows, title, rates, learning, width, three_d))
        verdict = run_verdict(rows, learning).lines() if learning is not None else []
        shown = shows_step(rows, rates, learning, width, three_d)
        lines = table_legend(learning, shown) + verdict + report_notes(run, entries, learning)
        for line in lines + mocap_lines(run):
            self.console.print(escape(line), highlight=False)

    def compared(
        self,
        runs: list[Any],
        headers: list[str],
        summary: list[list[str]],
        per_trial: list[list[str]],
    ) -> None:
        """Runs side by side: a summary row per run, e_pos per trial and run, what differs.

        Parameters
        ----------
        runs : list of ComparedRun
            From :func:`gcs.app.report_compare.compare_runs`.
        headers : list of str
            The summary's columns.
        summary : list of list of str
            One row per run.
        per_trial : list of list of str
            e_pos [mm] per trial (rows) and run (columns).
        """
        from rich import box
        from rich.table import Table

        from gcs.app.report_compare import compare_lines

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
        self.console.print(table)
        trials = Table(title=escape("e_pos [mm] per trial"), box=box.SIMPLE_HEAD, show_edge=False)
        trials.add_column("trial", justify="right")
        for name in shown:
            trials.add_column(escape(name), justify="right")
        for row in per_trial:
            trials.add_row(*row)
        self.console.print(trials)
        if short:
            for label, name in zip(shown, names, strict=True):
                self.console.print(escape(f"{label}: {name}"), highlight=False)
        for line in compare_lines(runs):
            self.console.print(escape(line), highlight=False)

    @contextmanager
    def figures(self, label: str) -> Iterator[Callable[[int, int], None]]:
        """The progress of figures being drawn, on stderr.

        Parameters
        ----------
        label : str
            What is drawn.

        Yields
        ------
        callable
            ``progress(done, total)``.
        """
        with track(self.err, label, "figures") as progress:
            yield progress

    def wrote(self, line: str) -> None:
        """A file written, on stderr.

        Parameters
        ----------
        line : str
            ``wrote PATH`` and what it holds.
        """
        self.err.print(line)
