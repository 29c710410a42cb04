"""``gcs study``: learning settings compared on simulated copies of the user's vehicle.

This room turns a checked study file (:mod:`gcs.io.study`) into a :class:`StudyPlan`, splits
it into tasks (a chunk of plants, one setting, one level), runs them on Dask
(:mod:`gcs.app.study_cluster`), keeps every finished chunk in the output directory as soon as
it arrives (atomic, write-once files: an interrupted study resumes where it stopped), and
reduces the chunks to the summaries, the recommendation and the JSON document.

Output directory::

    definition.json        the study's full definition (written first, checked on resume)
    chunks/sSSS-lLL-cCCCCC.json   one per (setting, level, chunk): per-plant results
    study.json             definition, summaries, recommendation, per-plant results
    epos.png, tradeoff.png the figures
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcs import __version__, learner_settings
from gcs.app.fly import flown_reference
from gcs.app.study_cluster import Cluster, Placement, Task, place, run_tasks
from gcs.core.study import (
    SettingSummary,
    StudyPlan,
    StudySetting,
    Uncertainty,
    check_nominal,
    fly_plant,
    recommend,
    run_chunk,
    summarise_setting,
)
from gcs.core.trajectory import MAX_SAMPLES
from gcs.errors import GcsError, StudyError
from gcs.io.atomic import atomic_write_text
from gcs.io.study import StudyDefinition

__all__ = [
    "build_plan",
    "definition_document",
    "StudyOutput",
    "open_output",
    "run_study_chunks",
    "StudyOutcome",
    "summarise_study",
    "study_document",
    "check_study_memory",
    "StudyEstimate",
    "estimate_study",
    "place_study",
]


def build_plan(study: StudyDefinition) -> StudyPlan:
    """The numerical study a checked definition describes.

    Parameters
    ----------
    study : StudyDefinition
        From :func:`gcs.io.study.load_study`.

    Returns
    -------
    StudyPlan

    Raises
    ------
    StudyError
        The trajectory does not suit the profile, a setting's profile has another sample
        time, or the uncertainty's centre is an unstable plant; one line naming the field.
    """
    where = study.path
    try:
        ref = flown_reference(study.profile, study.trajectory, f"{where}: field 'trajectory'")
    except GcsError as exc:
        raise StudyError(str(exc)) from None
    try:
        uncertainty = Uncertainty(**study.uncertainty)
        for model in study.profile.models():
            check_nominal(model, uncertainty)
    except ValueError as exc:
        raise StudyError(f"{where}: field 'uncertainty': {exc}") from None
    settings = []
    for i, spec in enumerate(study.settings):
        if abs(spec.profile.t_ilc_s - study.profile.t_ilc_s) > 1e-12:
            raise StudyError(
                f"{where}: field 'settings[{i}].profile': t_ilc_s {spec.profile.t_ilc_s:g} s, "
                f"the study's profile has {study.profile.t_ilc_s:g} s"
            )
        learning = spec.profile.learning
        if learning.axes != (0, 1):
            raise StudyError(
                f"{where}: field 'settings[{i}].profile': learning.axes has down; a study "
                "learns north and east (its plants are horizontal)"
            )
        settings.append(
            StudySetting(
                name=spec.name,
                settings=learner_settings(spec.profile),
                adaptive=learning.adaptive,
                repeats=learning.repeats,
                source=spec.overrides,
            )
        )
    return StudyPlan(
        ref_ne_m=ref.pos_ned_m[:, :2].copy(),
        models=study.profile.models(),
        uncertainty=uncertainty,
        settings=tuple(settings),
        plants=study.plants,
        iterations=study.iterations,
        seed=study.seed,
        chunk_plants=study.chunk_plants,
        steady_trials=study.steady_trials,
    )


def check_study_memory(plan: StudyPlan, memory_bytes: float | None = None) -> None:
    """Refuse a study whose trials would not fit in a worker's memory.

    One plant keeps its history of setpoints and positions (``flights x N x 2`` each) and the
    learning's banded problem, a few hundred values per sample.

    Parameters
    ----------
    plan : StudyPlan
        The study.
    memory_bytes : float, optional
        Memory one task may use; default half of this machine's.

    Raises
    ------
    StudyError
        The trial is longer than gcs flies, or a plant needs more than the memory.
    """
    n = plan.n_samples
    if n > MAX_SAMPLES:
        raise StudyError(f"trials of {n} samples: gcs flies at most {MAX_SAMPLES}")
    flights = 1 + max(s.repeats for s in plan.settings) + plan.iterations
    need = 8.0 * n * (8.0 * flights + 400.0)
    if memory_bytes is None:
        memory_bytes = 0.5 * os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    if need > memory_bytes:
        raise StudyError(
            f"one plant needs about {need / 1e9:.3g} GB ({n} samples x {flights} flights), "
            f"more than the {memory_bytes / 1e9:.3g} GB a task may use"
        )


def _jsonable(value: Any) -> Any:
    return json.loads(json.dumps(value, default=str))


def definition_document(study: StudyDefinition, plan: StudyPlan) -> dict:
    """The study's full definition, as recorded in ``definition.json`` and ``study.json``.

    Parameters
    ----------
    study : StudyDefinition
        The checked file.
    plan : StudyPlan
        The plan built from it.

    Returns
    -------
    dict
        Seed, sizes, the profiles' and the trajectory's YAML, the uncertainty, the settings
        and the gcs version: enough to rerun the study and to merge its results with another.
    """
    return _jsonable(
        {
            "gcs_version": __version__,
            "name": study.name,
            "file": study.path,
            "study": study.source,
            "seed": plan.seed,
            "plants": plan.plants,
            "iterations": plan.iterations,
            "chunk_plants": plan.chunk_plants,
            "chunks": plan.chunks,
            "steady_trials": plan.steady_trials,
            "n_samples": plan.n_samples,
            "t_ilc_s": study.profile.t_ilc_s,
            "profile": study.profile.source,
            "trajectory": study.trajectory.source,
            "uncertainty": plan.uncertainty.as_dict(),
            "settings": [
                {"name": s.name, "overrides": s.source, "repeats": s.repeats} for s in plan.settings
            ],
            "setting_profiles": {spec.name: spec.profile.source for spec in study.settings},
        }
    )


def _chunk_name(setting: int, level: int, chunk: int) -> str:
    return f"s{setting:03d}-l{level:02d}-c{chunk:06d}.json"


@dataclass(frozen=True)
class StudyOutput:
    """The output directory of a study.

    Parameters
    ----------
    path : Path
        The directory.
    resumed : int
        Chunks found there from an earlier run of the same study.
    """

    path: Path
    resumed: int

    @property
    def chunks(self) -> Path:
        """The folder of the chunk files."""
        return self.path / "chunks"

    def chunk_file(self, setting: int, level: int, chunk: int) -> Path:
        """The file of one chunk.

        Parameters
        ----------
        setting, level, chunk : int
            Which chunk.

        Returns
        -------
        Path
        """
        return self.chunks / _chunk_name(setting, level, chunk)


def open_output(path: Path, definition: dict) -> StudyOutput:
    """Create the output directory, or resume one that holds the same study.

    Parameters
    ----------
    path : Path
        The directory (``--out``).
    definition : dict
        :func:`definition_document`.

    Returns
    -------
    StudyOutput

    Raises
    ------
    StudyError
        The directory holds another study (its ``definition.json`` differs), or is not a
        study's directory; nothing in it is touched.
    """
    text = json.dumps(definition, indent=1, sort_keys=True) + "\n"
    recorded = path / "definition.json"
    if path.exists():
        if not path.is_dir():
            raise StudyError(f"--out {path}: not a directory")
        if recorded.is_file():
            if recorded.read_text() != text:
                raise StudyError(
                    f"--out {path}: holds another study (its definition.json differs); give "
                    "another directory"
                )
        elif any(path.iterdir()):
            raise StudyError(f"--out {path}: not empty and not a study's directory")
    path.mkdir(parents=True, exist_ok=True)
    (path / "chunks").mkdir(exist_ok=True)
    if not recorded.is_file():
        atomic_write_text(recorded, text)
    resumed = sum(1 for _ in (path / "chunks").glob("s*-l*-c*.json"))
    return StudyOutput(path, resumed)


def run_study_chunks(
    plan: StudyPlan,
    output: StudyOutput,
    client: Any,
    progress: Callable[[int, int], None] | None = None,
) -> dict[tuple[int, int, int], dict]:
    """Run the chunks that are not in ``output`` yet; return every chunk's result.

    Parameters
    ----------
    plan : StudyPlan
        The study.
    output : StudyOutput
        Where finished chunks are kept (each written as soon as it arrives).
    client : distributed.Client or None
        From :func:`gcs.app.study_cluster.connect` (None: in this process).
    progress : callable, optional
        ``progress(done, total)`` in chunks, finished ones from earlier runs included.

    Returns
    -------
    dict
        ``(setting, level, chunk) -> run_chunk's dict``.
    """
    keys = [
        (s, lv, c)
        for s in range(len(plan.settings))
        for lv in range(len(plan.uncertainty.levels))
        for c in range(plan.chunks)
    ]
    results: dict[tuple[int, int, int], dict] = {}
    for key in keys:
        path = output.chunk_file(*key)
        if path.is_file():
            results[key] = json.loads(path.read_text())
    missing = [k for k in keys if k not in results]
    if progress is not None:
        progress(len(results), len(keys))
    tasks = [Task(f"study-{_chunk_name(*k)[:-5]}", run_chunk, (plan, *k)) for k in missing]

    def done(task: Task, result: dict) -> None:
        key = (result["setting"], result["level"], result["chunk"])
        text = json.dumps(result, sort_keys=True) + "\n"
        atomic_write_text(output.chunk_file(*key), text)
        results[key] = json.loads(text)  # what a resumed run reads back
        if progress is not None:
            progress(len(results), len(keys))

    run_tasks(client, tasks, done)
    return results


@dataclass(frozen=True)
class StudyOutcome:
    """The reduced study.

    Parameters
    ----------
    summaries : list of SettingSummary
        Every setting at every level (settings outer, levels inner).
    recommended : str
        The setting to fly.
    reason : str
        Why.
    plants : dict
        ``(setting, level) -> per-plant results`` in plant order.
    """

    summaries: list[SettingSummary]
    recommended: str
    reason: str
    plants: dict[tuple[int, int], list[dict]]


def summarise_study(plan: StudyPlan, results: dict[tuple[int, int, int], dict]) -> StudyOutcome:
    """Summaries per setting and level, and the recommendation.

    Parameters
    ----------
    plan : StudyPlan
        The study.
    results : dict
        :func:`run_study_chunks`.

    Returns
    -------
    StudyOutcome
    """
    summaries, plants = [], {}
    for s in range(len(plan.settings)):
        for lv in range(len(plan.uncertainty.levels)):
            rows = [p for c in range(plan.chunks) for p in results[(s, lv, c)]["plants"]]
            plants[(s, lv)] = rows
            summaries.append(summarise_setting(plan, s, lv, rows))
    name, reason = recommend(summaries)
    return StudyOutcome(summaries, name, reason, plants)


def study_document(definition: dict, plan: StudyPlan, outcome: StudyOutcome) -> dict:
    """``study.json``: the definition, the summaries, the recommendation, every plant.

    Parameters
    ----------
    definition : dict
        :func:`definition_document`.
    plan : StudyPlan
        The study.
    outcome : StudyOutcome
        :func:`summarise_study`.

    Returns
    -------
    dict
    """
    return {
        "definition": definition,
        "recommended": {"setting": outcome.recommended, "reason": outcome.reason},
        "results": [
            {
                **summary.as_dict(),
                "plants_results": outcome.plants[(s, lv)],
            }
            for (s, lv), summary in zip(
                [
                    (s, lv)
                    for s in range(len(plan.settings))
                    for lv in range(len(plan.uncertainty.levels))
                ],
                outcome.summaries,
                strict=True,
            )
        ],
    }


@dataclass(frozen=True)
class StudyEstimate:
    """How long a study will take, from one plant of each setting flown here.

    Parameters
    ----------
    plant_s : tuple of float
        Wall time of one plant (every iteration, the first level) per setting [s].
    cpu_s : float
        The whole study at that pace: each setting's time x levels x plants [s].
    workers : int
        Workers the study is shared among.
    wall_s : float
        ``cpu_s / workers`` [s]: the estimate, if the cores are free.
    """

    plant_s: tuple[float, ...]
    cpu_s: float
    workers: int
    wall_s: float

    def line(self) -> str:
        """The estimate in words, saying how it was measured.

        Returns
        -------
        str
        """
        each = ", ".join(f"{t:.2f}" for t in self.plant_s)
        return (
            f"estimate: about {_duration(self.wall_s)} on {self.workers} worker"
            f"{'s' if self.workers != 1 else ''} ({_duration(self.cpu_s)} of computing); "
            f"measured by flying one simulated plant of each setting here ({each} s) and "
            "scaling by levels x plants; a loaded machine or a cluster's start-up adds to it"
        )


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def place_study(plan: StudyPlan, cluster: Cluster, tasks: int) -> Placement:
    """Where the study runs: the options' choice, else a local cluster only if it pays.

    Parameters
    ----------
    plan : StudyPlan
        The study.
    cluster : Cluster
        What ``--workers`` / ``--scheduler`` describe.
    tasks : int
        Its chunks (settings x levels x chunks).

    Returns
    -------
    Placement
        See :func:`gcs.app.study_cluster.place`; the estimate is :func:`estimate_study`'s
        computing time (one plant of each setting flown here, scaled).
    """
    return place(cluster, lambda: estimate_study(plan, 1).cpu_s, tasks)


def estimate_study(plan: StudyPlan, workers: int) -> StudyEstimate:
    """Time one plant of each setting (plant 0 at the first level, in this process) and scale.

    Parameters
    ----------
    plan : StudyPlan
        The study.
    workers : int
        Workers it will share the plants among (at least 1).

    Returns
    -------
    StudyEstimate
    """
    import time

    times = []
    for setting in plan.settings:
        start = time.perf_counter()
        fly_plant(plan, setting, 0, 0)
        times.append(time.perf_counter() - start)
    cpu = sum(times) * len(plan.uncertainty.levels) * plan.plants
    workers = max(1, int(workers))
    return StudyEstimate(tuple(times), cpu, workers, cpu / workers)
