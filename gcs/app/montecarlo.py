"""``gcs montecarlo`` as asked: its request, checked, and the sequence that runs it.

The study itself (plants, tasks, rows, the JSON document) is
:mod:`gcs.app.montecarlo_study`; its tables are :mod:`gcs.app.montecarlo_view`. Here: the
options become :class:`MontecarloSettings` (a refusal names
the option, not the field), the cluster they describe with the BLAS threads of this process,
the ``--json`` file checked, then the study run and shown, then the JSON written; and the
BLAS threads the command computes with (:func:`blas_policy`, before numpy is imported: this
module imports the numerics only when the study runs).
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, MutableMapping, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from gcs.app.failures import OptionError

if TYPE_CHECKING:
    from gcs.core.montecarlo import ComparisonRow, MontecarloSettings, StudyRow

__all__ = [
    "MontecarloRequest",
    "blas_policy",
    "blas_threads",
    "montecarlo",
    "montecarlo_settings",
]


@dataclass(frozen=True)
class MontecarloRequest:
    """``gcs montecarlo`` as asked: its options, before anything is checked.

    Parameters
    ----------
    levels : str
        ``--levels``: comma-separated uncertainty levels.
    plants, repeats, iterations, samples, seed : int
        ``--plants``, ``--repeats``, ``--iterations``, ``--samples``, ``--seed``.
    keep_diverged : bool
        ``--keep-diverged``.
    adaptive : bool
        ``--adaptive``: also learn with the options beyond the paper.
    json_path : Path or None
        ``--json``: also write the rows here.
    workers : int or None
        ``--workers``.
    scheduler : str or None
        ``--scheduler``.
    """

    levels: str = "0.05,0.1,0.2,0.4"
    plants: int = 100
    repeats: int = 10
    iterations: int = 30
    samples: int = 200
    seed: int = 20240601
    keep_diverged: bool = False
    adaptive: bool = False
    json_path: Path | None = None
    workers: int | None = None
    scheduler: str | None = None


class MontecarloView(Protocol):
    """What ``gcs montecarlo`` shows (:class:`gcs.app.montecarlo_view.MontecarloDisplay`)."""

    def tasks(self) -> AbstractContextManager[Callable[[int, int], None]]:
        """The progress of the study's tasks, ``progress(done, total)``."""

    def say(self, line: str) -> None:
        """One line: where the study runs, and why."""

    def show(
        self,
        rows: list[StudyRow],
        comparison: list[ComparisonRow],
        seconds: float,
        settings: MontecarloSettings,
    ) -> None:
        """Tables II and III, the comparison of the new options, the wall time."""


#: MontecarloSettings fields and the options that set them.
_OPTIONS = {
    "levels": "--levels", "plants": "--plants", "repeats": "--repeats",
    "iterations": "--iterations", "n_samples": "--samples", "seed": "--seed",
}  # fmt: skip


def montecarlo_settings(request: MontecarloRequest) -> MontecarloSettings:
    """The study the options describe; a refusal names the option that set the field.

    Parameters
    ----------
    request : MontecarloRequest
        The options.

    Returns
    -------
    MontecarloSettings

    Raises
    ------
    OptionError
        Naming the option (``--levels``, ``--plants``, ...) whose value is refused.
    """
    from gcs.app.montecarlo_study import study_settings

    try:
        return study_settings(
            request.levels, request.plants, request.repeats, request.iterations,
            request.samples, request.seed, request.keep_diverged, request.adaptive,
        )  # fmt: skip
    except ValueError as exc:
        message = str(exc)
    if message.startswith("--levels: "):
        raise OptionError(message.removeprefix("--levels: "), "--levels") from None
    for field, option in _OPTIONS.items():
        if message.startswith(f"MontecarloSettings.{field} "):
            raise OptionError(
                message.removeprefix(f"MontecarloSettings.{field} "), option
            ) from None
    raise OptionError(message.removeprefix("MontecarloSettings.")) from None


#: BLAS threads of ``gcs montecarlo`` unless ``OPENBLAS_NUM_THREADS`` says otherwise.
MONTECARLO_BLAS_THREADS = 1


def blas_policy(argv: Sequence[str], environ: MutableMapping[str, str] | None = None) -> None:
    """The BLAS threads of ``gcs montecarlo``: one, unless ``OPENBLAS_NUM_THREADS`` is set.

    In this process the study's tasks share the cores on threads, one per core
    (:func:`gcs.app.study_cluster.place`); OpenBLAS's own threads on top of them only contend
    for the same cores (docs/montecarlo.md, "Speed"). OpenBLAS reads
    ``OPENBLAS_NUM_THREADS`` once, when numpy is imported: the command line calls this first,
    and it does nothing once numpy is imported (the variable would then misstate the threads
    that :func:`blas_threads` gives the local workers). Other commands are left alone.

    Parameters
    ----------
    argv : sequence of str
        The command line (``sys.argv``): the policy applies when its command is ``montecarlo``.
    environ : mutable mapping, optional
        The environment to set; default ``os.environ``.
    """
    if "numpy" in sys.modules:
        return
    command = next((a for a in argv[1:] if not a.startswith("-")), None)
    if command == "montecarlo":
        env = os.environ if environ is None else environ
        env.setdefault("OPENBLAS_NUM_THREADS", str(MONTECARLO_BLAS_THREADS))


def blas_threads() -> int:
    """BLAS threads of each local worker: the count this process's OpenBLAS runs with.

    OpenBLAS read its thread count from ``OPENBLAS_NUM_THREADS`` when numpy was imported (one
    per core when unset); the local workers get the same count, so that the rows are the same,
    bit for bit, as computed in this process (a sum's order follows the threads).

    Returns
    -------
    int
    """
    from gcs.app.study_cluster import machine_workers

    blas = os.environ.get("OPENBLAS_NUM_THREADS")
    return int(blas) if blas and blas.isdigit() else machine_workers()


def montecarlo(request: MontecarloRequest, view: MontecarloView) -> None:
    """Check the options, run the study where they say, show it, write ``--json``.

    Parameters
    ----------
    request : MontecarloRequest
        The options.
    view : MontecarloView
        Where the progress, the tables and the placement line go.
    """
    from gcs.app.montecarlo_study import run_montecarlo, study_document
    from gcs.app.study import cluster_of
    from gcs.io.atomic import atomic_write_text
    from gcs.io.paths import check_output_file

    threads = blas_threads()
    settings = montecarlo_settings(request)
    cluster = cluster_of(request.workers, request.scheduler, threads)
    if request.json_path is not None:
        check_output_file(request.json_path, "--json")
    with view.tasks() as follow:
        outcome = run_montecarlo(
            settings,
            request.adaptive,
            lambda label: follow,
            cluster,  # type: ignore[arg-type]
            view.say,
        )
    view.show(outcome.rows, outcome.comparison, outcome.seconds, settings)
    if request.json_path is not None:
        document = study_document(outcome, settings)
        atomic_write_text(request.json_path, json.dumps(document, indent=2) + "\n")
