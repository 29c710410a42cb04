"""The terminal side of ``gcs montecarlo``: Tables II and III next to the paper's numbers."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from gcs.app.progress import track
from gcs.core.montecarlo import PAPER_TABLES, ComparisonRow, MontecarloSettings, StudyRow

__all__ = ["MontecarloDisplay", "study_tables", "study_json", "comparison_lines"]


class MontecarloDisplay:
    """``gcs montecarlo`` on the terminal (:class:`gcs.app.montecarlo.MontecarloView`).

    Parameters
    ----------
    console, err_console : rich.console.Console
        The tables (stdout); the progress and the placement line (stderr).
    """

    def __init__(self, console: Console, err_console: Console) -> None:
        self.console, self.err = console, err_console

    @contextmanager
    def tasks(self) -> Iterator[Callable[[int, int], None]]:
        """The progress of the study's tasks.

        Yields
        ------
        callable
            ``progress(done, total)``.
        """
        with track(self.err, "montecarlo", "tasks") as follow:
            yield follow

    def say(self, line: str) -> None:
        """One line on stderr.

        Parameters
        ----------
        line : str
            Plain text.
        """
        self.err.print(line, highlight=False)

    def show(
        self,
        rows: list[StudyRow],
        comparison: list[ComparisonRow],
        seconds: float,
        settings: MontecarloSettings,
    ) -> None:
        """Tables II and III, the comparison lines (``--adaptive``), the wall time.

        Parameters
        ----------
        rows : list of StudyRow
            The tables' rows.
        comparison : list of ComparisonRow
            The new options against the paper's method (empty without ``--adaptive``).
        seconds : float
            Wall time of the paper's study [s].
        settings : MontecarloSettings
            The study.
        """
        self.console.print(study_tables(rows, settings))
        for line in comparison_lines(comparison):
            self.console.print(line)
        self.console.print(f"[dim]{seconds:.1f} s[/]")


_NAMES = {"smoother": "smoother", "kilc": "K-ILC"}


def _pm(mean: float, std: float) -> str:
    return f"{mean:.2f}±{std:.2f}" if abs(mean) < 1e3 else f"{mean:.1e}±{std:.0e}"


def study_tables(rows: list[StudyRow], settings: MontecarloSettings) -> Table:
    """One rich table: every (algorithm, level) row with the paper's values beside ours.

    Parameters
    ----------
    rows : list of StudyRow
        Results of :func:`gcs.core.montecarlo.run_study`.
    settings : MontecarloSettings
        The study (for the title).

    Returns
    -------
    rich.table.Table
    """
    title = (
        f"||E_j||_2 [m], {settings.plants} plants x {settings.repeats} repeats, "
        f"N = {settings.n_samples} (paper: Tables II, III)"
    )
    table = Table(title=escape(title))
    for header in ("method", "level", "first", "paper", "steady", "paper", "diverged"):
        table.add_column(header, justify="left" if header == "method" else "right", no_wrap=True)
    for r in sorted(rows, key=lambda r: (r.algorithm != "smoother", r.uncertainty)):
        paper = PAPER_TABLES.get((r.algorithm, round(r.uncertainty, 4)))
        table.add_row(
            _NAMES.get(r.algorithm, r.algorithm),
            f"±{100 * r.uncertainty:g} %",
            _pm(r.first_mean, r.first_std),
            _pm(paper[0], paper[1]) if paper else "-",
            _pm(r.steady_mean, r.steady_std),
            _pm(paper[2], paper[3]) if paper else "-",
            f"{r.diverged}/{r.plants + (r.diverged if settings.diverged_rule == 'exclude' else 0)}",
        )
    return table


def study_json(rows: list[StudyRow], settings: MontecarloSettings) -> list[dict]:
    """Rows as JSON objects (the study's keys plus the counts behind ``excluded``).

    ``excluded`` is the number of plants left out of the statistics: plants whose learning
    diverged when ``diverged_rule`` is "exclude", plus non-physical draws when
    ``invalid_plant_rule`` is "exclude".

    Parameters
    ----------
    rows : list of StudyRow
        Results.
    settings : MontecarloSettings
        The study (for the rules).

    Returns
    -------
    list of dict
    """
    out = []
    for r in rows:
        left_out_diverged = r.diverged if settings.diverged_rule == "exclude" else 0
        left_out_invalid = r.excluded if settings.invalid_plant_rule == "exclude" else 0
        rule = (
            f"{r.excluded_rule}; plants whose learning diverged (mean error of trials "
            f"{settings.steady_from}-{settings.steady_to} above trial 0's) "
            + ("left out" if settings.diverged_rule == "exclude" else "kept")
        )
        out.append(
            {
                "algorithm": r.algorithm,
                "uncertainty": r.uncertainty,
                "first_mean": r.first_mean,
                "first_std": r.first_std,
                "steady_mean": r.steady_mean,
                "steady_std": r.steady_std,
                "excluded": left_out_diverged + left_out_invalid,
                "excluded_rule": rule,
                "plants": r.plants,
                "diverged": r.diverged,
                "rejected_draws": r.excluded,
            }
        )
    return out


def comparison_lines(comparison: list[ComparisonRow]) -> list[str]:
    """One line per level: the paper's method against the new options (``--adaptive``).

    Parameters
    ----------
    comparison : list of ComparisonRow
        Results of :func:`gcs.core.montecarlo.compare_study`.

    Returns
    -------
    list of str
    """
    return [
        f"±{100 * c.uncertainty:g} %: mean ||E_j||_2 over j = 2..5 {c.paper_mean_2_5:.3f} "
        f"(paper's method) -> {c.new_mean_2_5:.3f} (adaptive), {c.change_pct:+.1f} % "
        f"(plants that diverge under neither: {c.paper_kept_2_5:.3f} -> "
        f"{c.new_kept_2_5:.3f}); diverged {c.paper_diverged} -> {c.new_diverged} of "
        f"{c.plants}; models refreshed in {c.refreshed_pct:.0f} % of the runs; "
        f"{c.seconds:.0f} s"
        for c in comparison
    ]
