"""``gcs study`` as asked: its request and the sequence that runs it; and the cluster that the
Dask options of ``gcs study`` and ``gcs montecarlo`` describe.

Light on imports: the numerics are imported when the study runs. The study itself (plan,
chunks, summaries, the recommendation) is :mod:`gcs.app.study_chunks`; its table and figures
are :mod:`gcs.app.study_view`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from gcs.core.study import SettingSummary

__all__ = ["StudyRequest", "cluster_of", "study"]


def cluster_of(
    workers: int | None, scheduler: str | None, blas_threads: int | None = None
) -> object:
    """The :class:`gcs.app.study_cluster.Cluster` the options describe, checked.

    Parameters
    ----------
    workers : int or None
        ``--workers``.
    scheduler : str or None
        ``--scheduler``.
    blas_threads : int or None
        BLAS threads of each local worker (None: one).

    Returns
    -------
    Cluster

    Raises
    ------
    ClusterError
        ``--scheduler`` is not an address, or both options are given.
    """
    from gcs.app import study_cluster
    from gcs.errors import ClusterError

    if scheduler is not None:
        if workers is not None:
            raise ClusterError("--workers: the workers are the scheduler's; give one of the two")
        return study_cluster.Cluster(
            scheduler=study_cluster.check_scheduler(scheduler),
            connect_timeout_s=study_cluster.CONNECT_TIMEOUT_S,
        )
    return study_cluster.Cluster(workers=workers, blas_threads=blas_threads)


@dataclass(frozen=True)
class StudyRequest:
    """``gcs study`` as asked: its options, before anything is checked.

    Parameters
    ----------
    definition : Path
        The study file.
    out : Path or None
        ``--out``: the output directory (None: ``study-<name>`` here).
    workers : int or None
        ``--workers``: LocalCluster size (0: in this process).
    scheduler : str or None
        ``--scheduler``: address of a running Dask scheduler.
    check : bool
        ``--check``: check the study file and say its size; run nothing.
    """

    definition: Path
    out: Path | None = None
    workers: int | None = None
    scheduler: str | None = None
    check: bool = False


class StudyView(Protocol):
    """What ``gcs study`` shows (:class:`gcs.app.study_view.StudyDisplay`)."""

    def say(self, line: str) -> None:
        """One line on stderr: the study's size, where it runs, its estimate."""

    def chunks(self, name: str) -> AbstractContextManager[Callable[[int, int], None]]:
        """The progress of the study's chunks, ``progress(done, total)``."""

    def figures(self, summaries: list[SettingSummary], out: Path) -> list[Path]:
        """Write the study's figures into ``out``; the files written."""

    def show(
        self, summaries: list[SettingSummary], title: str, recommended: str, written: list[Path]
    ) -> None:
        """The table, the recommended setting with its reason, the files written."""


def study(request: StudyRequest, view: StudyView) -> None:
    """Check the study file, then say its size (``check``) or run it, resuming finished chunks.

    Parameters
    ----------
    request : StudyRequest
        The options.
    view : StudyView
        Where the lines, the progress, the table and the figures go.
    """
    from gcs.app.study_chunks import (
        build_plan,
        check_study_memory,
        definition_document,
        open_output,
        place_study,
        run_study_chunks,
        study_document,
        summarise_study,
    )
    from gcs.app.study_cluster import connect
    from gcs.io.atomic import atomic_write_text
    from gcs.io.paths import check_output_dir
    from gcs.io.study import load_study

    cluster = cluster_of(request.workers, request.scheduler)
    spec = load_study(request.definition)
    plan = build_plan(spec)
    check_study_memory(plan)
    runs = len(plan.settings) * len(plan.uncertainty.levels) * plan.plants
    tasks = len(plan.settings) * len(plan.uncertainty.levels) * plan.chunks
    size = (
        f"{spec.name}: {len(plan.settings)} settings x {len(plan.uncertainty.levels)} levels x "
        f"{plan.plants} plants = {runs} plant-runs of {plan.iterations} iterations at "
        f"N = {plan.n_samples}, in {tasks} chunks"
    )
    target = request.out if request.out is not None else Path(f"study-{spec.name}")
    if request.check:
        from gcs.app.study_chunks import estimate_study
        from gcs.app.study_cluster import machine_workers

        view.say(size)
        n = 1 if cluster.workers == 0 else cluster.workers or machine_workers()  # type: ignore[attr-defined]
        if cluster.scheduler is None:  # type: ignore[attr-defined]
            view.say(estimate_study(plan, n).line())
        else:
            view.say(
                "estimate: "
                + estimate_study(plan, 1).line().removeprefix("estimate: ")
                + " (one worker; divide by the scheduler's workers)"
            )
        return
    check_output_dir(target, "--out")
    document = definition_document(spec, plan)
    placement = place_study(plan, cluster, tasks)  # type: ignore[arg-type]
    with connect(placement.cluster) as client:
        output = open_output(target, document)
        view.say(size)
        view.say(placement.line)
        if output.resumed:
            view.say(f"resuming: {output.resumed} of {tasks} chunks already in {target}")
        try:
            with view.chunks(spec.name) as follow:
                results = run_study_chunks(plan, output, client, follow)
        except KeyboardInterrupt:
            kept = sum(1 for _ in output.chunks.glob("s*-l*-c*.json"))
            view.say(
                f"interrupted: {kept} of {tasks} chunks kept in {target}; the same command resumes"
            )
            raise
    outcome = summarise_study(plan, results)
    atomic_write_text(
        target / "study.json", json.dumps(study_document(document, plan, outcome), indent=1) + "\n"
    )
    figures = view.figures(outcome.summaries, target)
    view.show(
        outcome.summaries,
        f"{spec.name}: {plan.plants} plants per level, N = {plan.n_samples}",
        f"recommended: {outcome.recommended} ({outcome.reason})",
        [target / "study.json", *figures],
    )
