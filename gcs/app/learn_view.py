"""The terminal side of ``gcs learn``: the setpoints written and what the step decided."""

from __future__ import annotations

from rich.console import Console
from rich.markup import escape

from gcs.app.learn import LearnOutcome
from gcs.app.report_text import decision_lines
from gcs.io.rundir import RunDir

__all__ = ["LearnDisplay"]


class LearnDisplay:
    """``gcs learn`` on the terminal (:class:`gcs.app.learn.LearnView`).

    Parameters
    ----------
    console : rich.console.Console
        Where the lines go.
    """

    def __init__(self, console: Console) -> None:
        self.console = console

    def learned(self, run: RunDir, outcome: LearnOutcome) -> None:
        """The setpoints written (or the repeat of trial 0), then every decision recorded.

        Parameters
        ----------
        run : RunDir
            The run learned on.
        outcome : LearnOutcome
            What :func:`gcs.app.learn.learn_run` did.
        """
        if outcome.repeat_of is not None:
            self.console.print(
                f"trial {outcome.next_trial} repeats trial {outcome.repeat_of} (identical "
                f"setpoints, j = 0: it measures the floor): {outcome.setpoints_path}"
            )
            return
        self.console.print(
            f"learned from trial {outcome.trial} ({run.algorithm}); "
            f"setpoints for trial {outcome.next_trial}: {outcome.setpoints_path} "
            f"[dim](solver {'/'.join(outcome.methods)}, "
            f"{outcome.active_constraints} active limits)[/]"
        )
        for line in decision_lines(outcome.record) if outcome.record is not None else []:
            self.console.print(f"  {escape(line)}", highlight=False)
