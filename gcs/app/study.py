"""``gcs montecarlo``: the paper's Sec. IV study, and the options beyond it on the same plants.

The command line parses its options and prints; this room builds the study from them, runs it
(the paper's method, then, with ``adaptive``, the new options on the same plants and noise) and
turns the outcome into the JSON document ``--json`` writes.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from gcs.app.study_view import study_json
from gcs.core.learning import AdaptiveSettings
from gcs.core.montecarlo import (
    ComparisonRow,
    StudyRow,
    StudySettings,
    check_adaptive_size,
    compare_study,
    run_study,
)

__all__ = ["StudyOutcome", "study_settings", "run_montecarlo", "study_document"]

#: Progress callback: ``progress(done, total)``.
Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class StudyOutcome:
    """What :func:`run_montecarlo` computed.

    Parameters
    ----------
    rows : list of StudyRow
        Tables II/III rows: the paper's method, then the new options' rows when asked for.
    comparison : list of ComparisonRow
        One per level when the new options were run, else empty.
    seconds : float
        Wall time of the paper's study [s].
    """

    rows: list[StudyRow]
    comparison: list[ComparisonRow]
    seconds: float


def study_settings(
    levels: str,
    plants: int,
    repeats: int,
    iterations: int,
    samples: int,
    seed: int,
    keep_diverged: bool,
    adaptive: bool,
) -> StudySettings:
    """The study the options describe, checked before anything is simulated.

    Parameters
    ----------
    levels : str
        Comma-separated uncertainty levels (fractions of the nominal wn and zeta).
    plants, repeats, iterations, samples, seed : int
        As :class:`gcs.core.montecarlo.StudySettings` (``samples`` is ``n_samples``).
    keep_diverged : bool
        Keep plants whose learning diverged in the statistics.
    adaptive : bool
        The new options will run too: their per-run operators must fit in memory.

    Returns
    -------
    StudySettings

    Raises
    ------
    ValueError
        ``"--levels: ..."`` for the level list, else StudySettings' own message naming its
        field (``"StudySettings.<field> ..."``).
    """
    try:
        values = tuple(float(v) for v in levels.split(",") if v.strip())
    except ValueError:
        raise ValueError(f"--levels: not a list of numbers: {levels!r}") from None
    if not values:
        raise ValueError("--levels: give at least one level, e.g. 0.05")
    settings = StudySettings(
        levels=values, plants=plants, repeats=repeats, iterations=iterations,
        n_samples=samples, seed=seed, diverged_rule="include" if keep_diverged else "exclude",
    )  # fmt: skip
    if adaptive:
        check_adaptive_size(settings)
    return settings


def run_montecarlo(
    settings: StudySettings,
    adaptive: bool,
    progress: Callable[[str], Progress],
) -> StudyOutcome:
    """Run the paper's study and, with ``adaptive``, the new options on the same plants.

    Parameters
    ----------
    settings : StudySettings
        The study.
    adaptive : bool
        Also learn with the noise model from the data and the model refresh
        (``AdaptiveSettings(noise="data", refresh=True)``, docs/learning-floor.md).
    progress : callable
        ``progress(label)`` returns the callback that follows one simulation.

    Returns
    -------
    StudyOutcome
    """
    start = time.perf_counter()
    rows = run_study(settings, progress("simulating"))
    seconds = time.perf_counter() - start
    comparison: list[ComparisonRow] = []
    if adaptive:
        options = AdaptiveSettings(noise="data", refresh=True)
        new_rows, comparison = compare_study(
            settings, options, "smoother", progress("simulating the adaptive options")
        )
        rows = rows + new_rows
    return StudyOutcome(rows, comparison, seconds)


def study_document(outcome: StudyOutcome, settings: StudySettings) -> Any:
    """The JSON document of ``--json``: the rows, and the comparison when there is one.

    Parameters
    ----------
    outcome : StudyOutcome
        What :func:`run_montecarlo` computed.
    settings : StudySettings
        The study (for the rules in the rows).

    Returns
    -------
    list or dict
        The rows (the paper's study alone), or ``{"rows": ..., "comparison": ...}``.
    """
    rows = study_json(outcome.rows, settings)
    if not outcome.comparison:
        return rows
    return {"rows": rows, "comparison": [dataclasses.asdict(c) for c in outcome.comparison]}
