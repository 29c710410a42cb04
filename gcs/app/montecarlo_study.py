"""``gcs montecarlo``: the paper's Sec. IV study, and the options beyond it on the same plants.

The command line parses its options and prints; this room builds the study from them, runs it
(the paper's method, then, with ``adaptive``, the new options on the same plants and noise) and
turns the outcome into the JSON document ``--json`` writes.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass, replace
from typing import Any

from gcs.app import study_cluster
from gcs.app.montecarlo_view import study_json
from gcs.app.study_cluster import (
    Cluster,
    Task,
    connect,
    finish_here,
    place,
    run_tasks,
    start_here,
)
from gcs.core.learning import AdaptiveSettings
from gcs.core.montecarlo import (
    ComparisonRow,
    MontecarloSettings,
    StudyRow,
    check_adaptive_size,
    check_study_size,
    compare_study,
    error_norms,
    sample_plants,
    summarise,
)

__all__ = [
    "StudyOutcome",
    "study_settings",
    "paper_row",
    "adaptive_level",
    "estimate_adaptive_s",
    "run_montecarlo",
    "study_document",
]

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
) -> MontecarloSettings:
    """The study the options describe, checked before anything is simulated.

    Parameters
    ----------
    levels : str
        Comma-separated uncertainty levels (fractions of the nominal wn and zeta).
    plants, repeats, iterations, samples, seed : int
        As :class:`gcs.core.montecarlo.MontecarloSettings` (``samples`` is ``n_samples``).
    keep_diverged : bool
        Keep plants whose learning diverged in the statistics.
    adaptive : bool
        The new options will run too: every trial of every run must fit in memory.

    Returns
    -------
    MontecarloSettings

    Raises
    ------
    ValueError
        ``"--levels: ..."`` for the level list, else MontecarloSettings' own message naming its
        field (``"MontecarloSettings.<field> ..."``); or the study would not fit in memory.
    """
    try:
        values = tuple(float(v) for v in levels.split(",") if v.strip())
    except ValueError:
        raise ValueError(f"--levels: not a list of numbers: {levels!r}") from None
    if not values:
        raise ValueError("--levels: give at least one level, e.g. 0.05")
    settings = MontecarloSettings(
        levels=values, plants=plants, repeats=repeats, iterations=iterations,
        n_samples=samples, seed=seed, diverged_rule="include" if keep_diverged else "exclude",
    )  # fmt: skip
    check_study_size(settings)
    if adaptive:
        check_adaptive_size(settings)
    return settings


def paper_row(settings: MontecarloSettings, level: float, algorithm: str) -> StudyRow:
    """One row of Tables II/III: one level with one algorithm (a task of the study).

    Parameters
    ----------
    settings : MontecarloSettings
        The study.
    level : float
        Uncertainty level.
    algorithm : str
        ``"smoother"`` or ``"kilc"``.

    Returns
    -------
    StudyRow
        What :func:`gcs.core.montecarlo.run_study` gives for this level and algorithm.
    """
    plants = sample_plants(settings, level)
    norms = error_norms(settings, level, algorithm)
    return summarise(settings, norms, level, algorithm, plants.excluded)


def adaptive_level(
    settings: MontecarloSettings, level: float, options: AdaptiveSettings
) -> tuple[StudyRow, ComparisonRow]:
    """The new options against the paper's method at one level (a task of ``--adaptive``).

    Parameters
    ----------
    settings : MontecarloSettings
        The study.
    level : float
        Uncertainty level.
    options : AdaptiveSettings
        The new options.

    Returns
    -------
    row : StudyRow
        The new options' row.
    comparison : ComparisonRow
        The comparison at this level.
    """
    rows, comparison = compare_study(replace(settings, levels=(level,)), options, "smoother")
    return rows[0], comparison[0]


def estimate_adaptive_s(settings: MontecarloSettings) -> float:
    """Computing time of the new options' tasks in this process, from a small unit [s].

    One task of the new options on 2 plants x 1 repeat at the first level, timed here and
    scaled by the study's plant-runs and levels: an upper bound (its fixed part is counted
    once per plant-run).

    Parameters
    ----------
    settings : MontecarloSettings
        The study.

    Returns
    -------
    float
    """
    level = settings.levels[0]
    unit = replace(settings, levels=(level,), plants=2, repeats=1)
    start = time.perf_counter()
    adaptive_level(unit, level, AdaptiveSettings(noise="data", refresh=True))
    unit_s = time.perf_counter() - start
    return len(settings.levels) * unit_s * settings.plants * settings.repeats / 2.0


def run_montecarlo(
    settings: MontecarloSettings,
    adaptive: bool,
    progress: Callable[[str], Progress],
    cluster: Cluster | None = None,
    say: Callable[[str], None] | None = None,
) -> StudyOutcome:
    """Run the paper's study and, with ``adaptive``, the new options on the same plants.

    Every (level, algorithm) row of the paper's study, and every level of the new options, is
    one task; each task draws its plants and noise from the seed and its level alone, so the
    rows are those of :func:`gcs.core.montecarlo.run_study` and
    :func:`gcs.core.montecarlo.compare_study`, bit for bit, wherever they run.

    Where: ``--workers`` / ``--scheduler`` as given. Otherwise (``Cluster()``, neither
    given) the first tasks start here, one per thread, one thread per core; the rest of the
    study is estimated from the first one done (the paper's tasks alike; the new options'
    from :func:`estimate_adaptive_s`) and :func:`gcs.app.study_cluster.place` decides whether
    a local cluster gains more than it costs for the tasks not started yet; if not, they run
    on these threads. ``say`` receives the decision in one line.

    Parameters
    ----------
    settings : MontecarloSettings
        The study.
    adaptive : bool
        Also learn with the noise model from the data and the model refresh
        (``AdaptiveSettings(noise="data", refresh=True)``, docs/learning-floor.md).
    progress : callable
        ``progress(label)`` returns the callback that follows the tasks.
    cluster : Cluster, optional
        Where to run; default: in this process. ``Cluster()`` (no workers, no scheduler):
        decided as above.
    say : callable, optional
        Receives the line saying where the study runs and why.

    Returns
    -------
    StudyOutcome
    """
    options = AdaptiveSettings(noise="data", refresh=True)
    tasks = [
        Task(f"montecarlo-{level:g}-{algorithm}", paper_row, (settings, level, algorithm))
        for level in settings.levels
        for algorithm in settings.algorithms
    ]
    if adaptive:
        tasks += [
            Task(f"montecarlo-{level:g}-adaptive", adaptive_level, (settings, level, options))
            for level in settings.levels
        ]
    results: dict[str, Any] = {}
    follow = progress("simulating" + (" (with the adaptive options)" if adaptive else ""))

    def done(task: Task, result: Any) -> None:
        results[task.key] = result
        follow(len(results), len(tasks))

    start = time.perf_counter()
    cluster = cluster or Cluster(workers=0)
    if cluster.scheduler is not None or cluster.workers is not None:
        line = place(cluster, lambda: 0.0, len(tasks)).line
        with connect(cluster) as client:
            if say is not None:
                say(line)
            run_tasks(client, tasks, done, cluster.threads)
    else:
        _run_placed(settings, adaptive, tasks, cluster, done, start, say)
    seconds = time.perf_counter() - start
    rows = [results[t.key] for t in tasks if t.fn is paper_row]
    comparison: list[ComparisonRow] = []
    for t in tasks:
        if t.fn is adaptive_level:
            row, comp = results[t.key]
            rows.append(row)
            comparison.append(comp)
    return StudyOutcome(rows, comparison, seconds)


def _run_placed(
    settings: MontecarloSettings,
    adaptive: bool,
    tasks: list[Task],
    cluster: Cluster,
    done: Callable[[Task, Any], None],
    start: float,
    say: Callable[[str], None] | None,
) -> None:
    """The default placement: the first tasks start here, one per thread (one per core);
    the first one done gives the estimate of the rest on these threads (its wall time per
    thread), :func:`gcs.app.study_cluster.place` decides where the tasks not started yet go:
    to these threads, or to a local cluster."""
    n = max(1, min(study_cluster.machine_workers(), len(tasks)))
    pool = ThreadPoolExecutor(n, "gcs-task")
    try:
        running = start_here(pool, tasks[:n])
        finished, _ = wait(running, return_when=FIRST_COMPLETED)
        # n tasks ran at once: the rest costs about first_s per n tasks here, on these threads
        # (timed per task it counted the others' share of the cores: under load it sent a
        # short study to a cluster that cost it 3 times the time)
        first_s = (time.perf_counter() - start) / n
        for future in finished:
            done(running.pop(future), future.result())
        rest = tasks[n:]
        left = [*running.values(), *rest]
        paper_left = sum(1 for t in left if t.fn is paper_row)

        def estimate() -> float:
            return first_s * paper_left + (estimate_adaptive_s(settings) if adaptive else 0.0)

        placement = place(cluster, estimate, len(left), threads=True)
        if placement.cluster.workers == 0:
            if say is not None:
                say(placement.line)
            running |= start_here(pool, rest)
        else:
            with connect(placement.cluster) as client:
                if say is not None:
                    say(placement.line)
                run_tasks(client, rest, done)
        finish_here(running, done)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def study_document(outcome: StudyOutcome, settings: MontecarloSettings) -> Any:
    """The JSON document of ``--json``: the rows, and the comparison when there is one.

    Parameters
    ----------
    outcome : StudyOutcome
        What :func:`run_montecarlo` computed.
    settings : MontecarloSettings
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
