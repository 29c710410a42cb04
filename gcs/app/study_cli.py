"""The ``gcs study`` command and the Dask options it shares with ``gcs montecarlo``.

Light on imports: :mod:`gcs.cli` imports the option types at start-up; the command imports
the numerics when it runs.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

__all__ = ["WorkersOption", "SchedulerOption", "cluster_of", "study"]

WorkersOption = Annotated[
    int | None,
    typer.Option(
        min=0,
        help="Dask workers of a local cluster (one thread each); 0: no Dask, in this process. "
        "Default: in this process for a short study, one worker per core for a long one "
        "(estimated first). Results do not depend on it.",
    ),
]
SchedulerOption = Annotated[
    str | None,
    typer.Option(
        help="Run on an existing Dask cluster: the scheduler's address tcp://HOST:PORT (what "
        "`dask scheduler` prints). Its workers need gcs installed.",
    ),
]


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


def study(
    definition: Annotated[
        Path,
        typer.Argument(
            help="The study file (YAML; fields in docs/studies.md).", show_default=False
        ),
    ],
    out: Annotated[
        Path | None,
        typer.Option(
            help="Output directory; default study-<name> here. A directory holding the same "
            "study resumes it: only the missing chunks run.",
        ),
    ] = None,
    workers: WorkersOption = None,
    scheduler: SchedulerOption = None,
    check: Annotated[
        bool, typer.Option("--check", help="Check the study file and say its size; run nothing.")
    ] = False,
) -> None:
    """Compare learning settings on simulated copies of your vehicle, before flying.

    The study file names your profile (the model the plants are drawn around), your
    trajectory, the uncertainty of the true plants (spread of each mode's frequency, damping
    and gain, or of the Markov parameters; extra delay; output noise and a repeatable
    disturbance, from a run's floor.json if you like) and the settings to compare (a list and
    a grid: weights, smoother Q/R, the adaptive options, other profiles). Every plant learns
    with every setting, as `gcs fly` would, for the given iterations.

    Printed: one row per setting and level (e_pos per flight, flights to the floor, steady
    state, diverged plants, setpoints, limits) and the recommended setting with its reason.
    Written to the output directory: study.json (definition, summaries, every plant), one
    file per finished chunk, epos.png and tradeoff.png.

    Runs in this process when the study is short, on a local Dask cluster of one worker per
    core when it is long enough to gain from it (one plant of each setting is timed first; one
    line says which, and why; docs/studies.md); --workers N for a local cluster of that size
    (0: in this process), --scheduler tcp://HOST:PORT for a running cluster. Every chunk of
    plants is seeded from the study's seed and its index: the results are the same, bit for
    bit, on any number of workers.

    Example: gcs study study.yaml --out study-antx

    Exit codes: 0 done; 2 bad input, named on one line (a file, field or option); 130
    interrupted (Ctrl-C; finished chunks are kept, run it again to resume); 1 an internal
    error (a bug; GCS_DEBUG=1 shows the traceback).
    \f
    Parameters
    ----------
    definition : Path
        The study file.
    out : Path or None
        Output directory.
    workers : int or None
        LocalCluster size (0: in this process).
    scheduler : str or None
        Address of a running Dask scheduler.
    check : bool
        Check and say the size only.
    """
    from rich.console import Console

    from gcs.app.progress import track
    from gcs.app.study_cluster import connect
    from gcs.app.study_own import (
        build_plan,
        check_study_memory,
        definition_document,
        open_output,
        place_study,
        run_study_chunks,
        study_document,
        summarise_study,
    )
    from gcs.app.study_own_view import study_table, write_study_figures
    from gcs.io.atomic import atomic_write_text
    from gcs.io.paths import check_output_dir
    from gcs.io.study import load_study

    console, err = Console(), Console(stderr=True)
    cluster = cluster_of(workers, scheduler)
    spec = load_study(definition)
    plan = build_plan(spec)
    check_study_memory(plan)
    runs = len(plan.settings) * len(plan.uncertainty.levels) * plan.plants
    tasks = len(plan.settings) * len(plan.uncertainty.levels) * plan.chunks
    size = (
        f"{spec.name}: {len(plan.settings)} settings x {len(plan.uncertainty.levels)} levels x "
        f"{plan.plants} plants = {runs} plant-runs of {plan.iterations} iterations at "
        f"N = {plan.n_samples}, in {tasks} chunks"
    )
    target = out if out is not None else Path(f"study-{spec.name}")
    if check:
        from gcs.app.study_cluster import machine_workers
        from gcs.app.study_own import estimate_study

        err.print(size, highlight=False)
        n = 1 if cluster.workers == 0 else cluster.workers or machine_workers()  # type: ignore[attr-defined]
        if cluster.scheduler is None:  # type: ignore[attr-defined]
            err.print(estimate_study(plan, n).line(), highlight=False)
        else:
            err.print(
                "estimate: "
                + estimate_study(plan, 1).line().removeprefix("estimate: ")
                + " (one worker; divide by the scheduler's workers)",
                highlight=False,
            )
        return
    check_output_dir(target, "--out")
    document = definition_document(spec, plan)
    placement = place_study(plan, cluster, tasks)  # type: ignore[arg-type]
    with connect(placement.cluster) as client:
        output = open_output(target, document)
        err.print(size, highlight=False)
        err.print(placement.line, highlight=False)
        if output.resumed:
            err.print(f"resuming: {output.resumed} of {tasks} chunks already in {target}")
        try:
            with track(err, spec.name, "chunks") as follow:
                results = run_study_chunks(plan, output, client, follow)
        except KeyboardInterrupt:
            kept = sum(1 for _ in output.chunks.glob("s*-l*-c*.json"))
            err.print(
                f"interrupted: {kept} of {tasks} chunks kept in {target}; the same command resumes",
                highlight=False,
            )
            raise
    outcome = summarise_study(plan, results)
    atomic_write_text(
        target / "study.json", json.dumps(study_document(document, plan, outcome), indent=1) + "\n"
    )
    figures = write_study_figures(outcome.summaries, target)
    title = f"{spec.name}: {plan.plants} plants per level, N = {plan.n_samples}"
    console.print(study_table(outcome.summaries, title))
    console.print(f"recommended: {outcome.recommended} ({outcome.reason})", highlight=False)
    console.print(
        f"written: {target / 'study.json'}, " + ", ".join(str(p) for p in figures),
        highlight=False,
    )
