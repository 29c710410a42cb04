"""Learning on a run directory: complete trials -> estimate -> next setpoints.

This is the one function behind both ``gcs learn`` and the learning between trials of
``gcs fly``. It is deterministic and idempotent: learning twice from the same trial writes the
same files.

Both go through the public learner (:class:`gcs.Learner`), resumed from what the run directory
recorded, so that a resumed run learns exactly as an uninterrupted one. Two ways, chosen by the
run's profile. Without ``learning.adaptive`` (the paper's method, ``profiles/antx.yaml``): the
paper's step on the newest complete trial (K-ILC from the state recorded after the previous
trial). With it (``profiles/antx-adaptive.yaml``): trial 0 is flown again
``learning.adaptive.repeats`` times with identical setpoints (the floor), then every step learns
from every complete trial, from the models of the previous step (read back from the run
directory), and records every decision (``learn-JJJ.json``), every refreshed model
(``model-JJJ.yaml``) and the floor (``floor.json``).

Indexing: :mod:`gcs.core.trials`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from gcs.api import Learner, learner_settings
from gcs.app.failures import OptionError
from gcs.core.estimators import KilcState
from gcs.core.floor import floor_flights, prediction_noise_ratio
from gcs.core.learner import LearnerStep, Trial
from gcs.core.metrics import epos
from gcs.core.model import DiscreteModel, predicted_output, relative_degree
from gcs.core.trajectory import Reference, check_setpoints
from gcs.core.trials import iteration_of, setpoint_deviation
from gcs.errors import GcsError, ProfileError, RunLogError, TrajectoryError
from gcs.io.config import ALGORITHMS, Profile, load_profile
from gcs.io.records import TrialRecord
from gcs.io.rundir import RunDir

__all__ = [
    "LearnOutcome",
    "LearnRequest",
    "learn",
    "check_algorithm",
    "learn_run",
    "models_in_use",
    "Prediction",
    "trial_prediction",
    "check_history",
    "check_learned",
    "check_learnable",
    "differing_field",
]


@dataclass(frozen=True)
class Prediction:
    """What the learning step before a trial predicted of it, against what it flew.

    The step planned the trial's setpoints with its model and its estimate of the
    disturbance (``Y = F U + D``); the measured positions differ from that prediction by one
    flight's noise (the floor) and the estimate's, and by whatever the model did not foresee.

    ``predicted_epos_m``: e_pos (eq. 10) the step predicted for the trial [m].
    ``miss_m``: mean horizontal distance between the measured and the predicted positions
    [m]. ``limits_active``: setpoint samples at a limit in that step's update (both axes),
    None where the run does not record it. ``noise_ratio``: the distance from the prediction
    that noise alone gives, in floors (:func:`gcs.core.floor.prediction_noise_ratio` of the
    step's trial weights, the mean of the axes); None where the run does not record them.
    """

    predicted_epos_m: float
    miss_m: float
    limits_active: int | None
    noise_ratio: float | None = None


@dataclass(frozen=True)
class LearnOutcome:
    """What :func:`learn_run` did.

    Parameters
    ----------
    trial : int
        The trial learned from.
    next_trial : int
        The trial whose setpoints were written.
    setpoints_path : Path
        The file written.
    methods : tuple of str
        Solver path per axis ("direct" or "clarabel"; "-" for a repeat).
    active_constraints : int
        Active setpoint limits, every axis.
    next_iteration : int
        The paper's iteration j of the next trial (learning updates so far).
    repeat_of : int or None
        The trial the next trial repeats (identical setpoints, nothing learned), or None.
    record : dict or None
        The decision record written to ``learn-JJJ.json`` (profiles with
        ``learning.adaptive``), or None.
    prediction : Prediction or None
        What the step before predicted of the trial learned from, and how it flew
        (:func:`trial_prediction`); None when no step predicted it.
    """

    trial: int
    next_trial: int
    setpoints_path: Path
    methods: tuple[str, ...]
    active_constraints: int
    next_iteration: int
    repeat_of: int | None = None
    record: dict | None = None
    prediction: Prediction | None = None


@dataclass(frozen=True)
class LearnRequest:
    """``gcs learn`` as asked: its options, before anything is checked.

    Parameters
    ----------
    run : Path
        The run directory.
    algorithm : str or None
        ``--algorithm``: must be the run's own when given.
    profile : Path or None
        ``--profile``: must match the profile recorded in the run's manifest.
    """

    run: Path
    algorithm: str | None = None
    profile: Path | None = None


class LearnView(Protocol):
    """What ``gcs learn`` shows (the terminal's: :class:`gcs.app.learn_view.LearnDisplay`)."""

    def learned(self, run: RunDir, outcome: LearnOutcome) -> None:
        """The setpoints written, and what the learning step decided."""


def check_algorithm(algorithm: str | None) -> None:
    """Refuse an ``--algorithm`` that is not one gcs learns with.

    Parameters
    ----------
    algorithm : str or None
        ``--algorithm`` (None: not given).

    Raises
    ------
    OptionError
    """
    if algorithm is not None and algorithm not in ALGORITHMS:
        raise OptionError(f"must be one of {', '.join(ALGORITHMS)}", "--algorithm")


def learn(request: LearnRequest, view: LearnView) -> LearnOutcome:
    """``gcs learn``: learn from the run's newest complete trial, write the next setpoints.

    Parameters
    ----------
    request : LearnRequest
        The command's options.
    view : LearnView
        What it shows.

    Returns
    -------
    LearnOutcome
    """
    check_algorithm(request.algorithm)
    run = RunDir.open(request.run)
    outcome = learn_run(run, request.algorithm, request.profile)
    view.learned(run, outcome)
    return outcome


def differing_field(given: Any, recorded: Any, prefix: str = "") -> str | None:
    """The first field (dotted path, sorted) where two parsed YAML documents differ, or None.

    Parameters
    ----------
    given, recorded : Any
        Parsed documents (dicts, lists, scalars).
    prefix : str
        Path of the documents themselves (for recursion).

    Returns
    -------
    str or None
        ``"<top>"`` when the documents themselves differ in type.
    """
    if given == recorded:
        return None
    if isinstance(given, dict) and isinstance(recorded, dict):
        for key in sorted(set(given) | set(recorded), key=str):
            if given.get(key, ...) != recorded.get(key, ...):
                name = f"{prefix}.{key}" if prefix else str(key)
                return differing_field(given.get(key), recorded.get(key), name) or name
    return prefix or "<top>"


def _check_profile(run: RunDir, profile_path: Path | None) -> Profile:
    profile = run.profile()
    if profile_path is not None:
        given = load_profile(profile_path)
        key = differing_field(given.source, run.manifest["profile"])
        if key is not None:
            raise RunLogError(
                f"{profile_path}: does not match the profile in {run.manifest_path} "
                f"(field '{key}' differs)"
            )
    return profile


def check_learned(
    sp_ned_m: np.ndarray,
    profile: Profile,
    ref: Reference,
    models: tuple[DiscreteModel, ...] | None = None,
) -> None:
    """Refuse setpoints that break a limit of the profile's learning, on the grid flown.

    Arena, step per sample and deviation from the reference (aligned by each model's
    relative degree), as :func:`gcs.core.trajectory.check_setpoints`.

    Parameters
    ----------
    sp_ned_m : ndarray, shape (N, 3)
        Learned setpoints, local NED [m].
    profile : Profile
        The run's profile (arena, limits, models).
    ref : Reference
        The run's reference.
    models : tuple of DiscreteModel, optional
        The models of the learned axes the setpoints were learned with (a refreshed model may
        have another delay); default the profile's.

    Raises
    ------
    TrajectoryError
        Naming the limit, sample and axis.
    """
    ln = profile.learning
    learned = models if models is not None else profile.learned_models()
    vertical = (ln.max_vertical_step_m, ln.max_vertical_deviation_m) if 2 in ln.axes else None
    check_setpoints(
        sp_ned_m, ref, profile.arena, ln.max_step_m, ln.max_deviation_m,
        tuple(relative_degree(m) for m in learned), vertical=vertical,
    )  # fmt: skip


def check_learnable(profile: Profile, ref: Reference, algorithm: str, where: str) -> None:
    """Refuse a profile and reference whose first learning update cannot be computed.

    Runs the learning step on a trial that tracked the reference exactly, before anything is
    flown: the models must fit the trial's length, and the setpoint limits (arena, step,
    deviation) must admit a sequence; both depend on the reference, not on the data, so a
    refusal here is one that would otherwise come after the first trial, in the air.

    Parameters
    ----------
    profile : Profile
        The profile.
    ref : Reference
        The reference to be flown.
    algorithm : str
        ``"smoother"`` or ``"kilc"``.
    where : str
        Name of the profile (file) for messages.

    Raises
    ------
    ProfileError, ModelError, UpdateInfeasible
        Naming the profile.
    """
    try:
        settings = learner_settings(profile, algorithm)
        learnt = ref.pos_ned_m[:, settings.axes]
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            u_next = Learner(settings, learnt).step(learnt[:-1], learnt[1:])
        sp = _setpoints(u_next, settings.axes, ref)
        check_learned(sp, profile, ref)
    except GcsError as exc:
        raise type(exc)(f"{where}: learning cannot start on this trajectory: {exc}") from None
    except (ValueError, ArithmeticError, RuntimeError) as exc:  # a solver that fails numerically
        raise ProfileError(
            f"{where}: learning cannot start on this trajectory: {exc} (check learning.weights "
            "and the models)"
        ) from None


def _kilc_prior(run: RunDir, j: int) -> tuple[KilcState, ...] | None:
    if j == 0:
        return None
    d_hat, p = run.read_estimate(j - 1)
    return tuple(KilcState(d_hat[:, a].copy(), float(p[0, a]), j) for a in range(d_hat.shape[1]))


def learn_run(
    run: RunDir, algorithm: str | None = None, profile_path: Path | None = None
) -> LearnOutcome:
    """Learn from the newest complete trial of ``run`` and write the next trial's setpoints.

    Parameters
    ----------
    run : RunDir
        The run directory.
    algorithm : str, optional
        Must match the run's algorithm when given (one run, one algorithm: K-ILC's state
        carries over from trial to trial).
    profile_path : Path, optional
        A profile file that must match the one recorded in the manifest.

    Returns
    -------
    LearnOutcome
    """
    run.require_kind("learning", "gcs learn")
    if algorithm is not None and algorithm != run.algorithm:
        raise RunLogError(
            f"{run.path}: the run learns with '{run.algorithm}', not '{algorithm}' "
            "(start a new run to compare algorithms)"
        )
    profile = _check_profile(run, profile_path)
    run.check_writable()
    j = run.newest_complete()
    if j is None:
        raise RunLogError(f"{run.path}: no complete trial to learn from")
    if profile.learning.adaptive is not None:
        return _learn_history(run, profile, j)
    record = run.measured_trial(j, profile.mocap.measurement)
    ref = run.reference()
    if np.max(np.abs(record.ref_ned_m - ref.pos_ned_m)) > 1e-6:
        raise RunLogError(f"{run.trial_path(j)}: reference columns differ from the run's")
    kilc_prior = _kilc_prior(run, j) if run.algorithm == "kilc" else None
    where = f"{run.trial_path(j)}: the learning update failed on this trial"
    with _failure(where):
        settings = learner_settings(profile, run.algorithm)
        axes = settings.axes
        learner = Learner(settings, ref.pos_ned_m[:, axes], kilc_states=kilc_prior)
        learner.step(record.sp_ned_m[:-1, axes], record.pos_ned_m[1:, axes])
    step = learner.last
    assert step is not None and step.d_hat_m is not None and step.p_m2 is not None
    sp = _setpoints(step.setpoints_m, axes, ref)
    try:  # the QP keeps these limits; this guards against a solver that did not
        check_learned(sp, profile, ref)
    except TrajectoryError as exc:
        raise RunLogError(f"{run.path}: learned from trial {j}: {exc}; nothing written") from None
    # read everything before writing: a damaged estimate refuses the step with nothing written
    prediction = trial_prediction(run, profile, j, record, None)
    path = run.write_learned(j, step.d_hat_m, step.p_m2, sp)
    return LearnOutcome(
        trial=j,
        next_trial=j + 1,
        setpoints_path=path,
        methods=step.methods,
        active_constraints=step.active_constraints,
        next_iteration=j + 1,
        prediction=prediction,
    )


def _setpoints(learnt_m: np.ndarray, axes: tuple[int, ...], ref: Reference) -> np.ndarray:
    """A trial's setpoints u(0..N-1), shape (N, 3): the learnt axes, the reference elsewhere."""
    sp = ref.pos_ned_m[:-1].copy()
    sp[:, list(axes)] = learnt_m
    return sp


@contextlib.contextmanager
def _failure(where: str) -> Iterator[None]:
    """Numerical failures of a learning step as one line naming ``where``; GcsErrors pass
    (they name their cause)."""
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            yield
    except GcsError:
        raise
    except (ArithmeticError, RuntimeError, ValueError) as exc:
        raise RunLogError(f"{where} ({exc}); nothing written") from None


# ----------------------------------------------------------------------- learning with history


def _history(run: RunDir, j: int, measurement: str) -> list[TrialRecord]:
    """Trials 0..j as learning sees them (``measurement``), every one complete and on the
    run's reference (a gap is refused)."""
    done = set(run.complete_trials())
    missing = [t for t in range(j + 1) if t not in done]
    if missing:
        raise RunLogError(
            f"{run.path}: trial {missing[0]} is not complete, but learning with history needs "
            f"every trial 0..{j} ({run.status_path(missing[0]).name})"
        )
    ref = run.reference().pos_ned_m
    records = [run.measured_trial(t, measurement) for t in range(j + 1)]
    for t, record in enumerate(records):
        if np.max(np.abs(record.ref_ned_m - ref)) > 1e-6:
            raise RunLogError(f"{run.trial_path(t)}: reference columns differ from the run's")
    return records


def check_history(run: RunDir, profile: Profile, j: int) -> None:
    """Refuse a run whose history cannot be learned from: trials 0..j complete and on the
    run's reference, every decision record and refreshed model from the first step on.

    Parameters
    ----------
    run : RunDir
        A learning run whose profile has ``learning.adaptive``.
    profile : Profile
        Its profile.
    j : int
        The newest complete trial.
    """
    _history(run, j, profile.mocap.measurement)
    for k in range(profile.learning.repeats, j + 1):
        if run.read_learn_record(k)["model_file"] is not None:
            run.read_model(k)


def trial_prediction(
    run: RunDir, profile: Profile, t: int, trial: TrialRecord, step_record: dict | None
) -> Prediction | None:
    """What the learning step from trial ``t - 1`` predicted of trial ``t`` (:class:`Prediction`).

    The step's models (the refreshed ones it ended with, or the profile's) and its estimate
    (``estimate-(t-1).csv``) predict the positions at the setpoints trial ``t`` flew.

    Parameters
    ----------
    run : RunDir
        The learning run.
    profile : Profile
        Its profile.
    t : int
        The trial.
    trial : TrialRecord
        Trial ``t``, complete and measured as the run measures.
    step_record : dict or None
        The decision record of the step from trial ``t - 1`` (``learn-(t-1).json``; None for
        the paper's profile).

    Returns
    -------
    Prediction or None
        None when the step made no prediction of it: trial 0, a repeat of trial 0, a trial
        flying another's setpoints again, no estimate on file.
    """
    history = profile.learning.adaptive is not None
    repeats = profile.learning.repeats if history else 0
    if t <= repeats or run.again_of(t) is not None or not run.estimate_path(t - 1).exists():
        return None
    models = models_in_use(run, profile, t)[0] if history else profile.models()
    ref = run.reference().pos_ned_m
    start = ref[0, :2]
    d_hat = run.read_estimate(t - 1)[0][:, :2]
    u = trial.sp_ned_m[:-1, :2] - start
    y = trial.pos_ned_m[1:, :2] - start
    y_hat = np.column_stack([predicted_output(models[a], u[:, a], d_hat[:, a]) for a in (0, 1)])
    active = noise = None
    if step_record is not None and step_record.get("decision"):
        axes = step_record["decision"]["axes"]
        active = sum(a["update"]["active_constraints"] for a in axes)
        noise = float(np.mean([prediction_noise_ratio(a["noise"]["weights"]) for a in axes]))
    return Prediction(epos(ref[1:, :2] - start, y_hat), epos(y_hat, y), active, noise)


def models_in_use(
    run: RunDir, profile: Profile, j: int
) -> tuple[tuple[DiscreteModel, DiscreteModel], str]:
    """The models the learning step from trial j starts from: the newest refreshed ones.

    Walks the decision records back from ``learn-(j-1).json`` to the first learning step; the
    newest that refreshed a model gives ``model-KKK.yaml`` (checked against its record), none
    gives the profile's models. Every step on the way must have its record.

    Parameters
    ----------
    run : RunDir
        A learning run whose profile has ``learning.adaptive``.
    profile : Profile
        Its profile.
    j : int
        The newest trial the step learns from.

    Returns
    -------
    models : tuple of DiscreteModel
        (north, east).
    source : str
        ``"model-KKK.yaml"`` or ``"profile"``.
    """
    for k in range(j - 1, profile.learning.repeats - 1, -1):
        if run.read_learn_record(k)["model_file"] is not None:
            return run.read_model(k), run.model_path(k).name
    return profile.models(), "profile"


def _learn_history(run: RunDir, profile: Profile, j: int) -> LearnOutcome:
    """A repeat of trial 0, or a step of the learner on trials 0..j, recorded."""
    repeats = profile.learning.repeats
    records = _history(run, j, profile.mocap.measurement)
    ref = run.reference()
    models, source = models_in_use(run, profile, j)
    with _failure(f"{run.path}: the learning update from trials 0..{j} failed"):
        axes = learner_settings(profile).axes
        trials = [Trial(r.sp_ned_m[:-1, axes], r.pos_ned_m[1:, axes]) for r in records]
        learner = Learner.from_profile(
            profile, ref, run.algorithm, models=models, history=trials[:-1]
        )
        learner.step(trials[-1].u_m, trials[-1].y_m)
    step = learner.last
    assert step is not None
    if step.repeat_of is not None:
        path = run.write_repeat(j + 1)
        return LearnOutcome(j, j + 1, path, step.methods, 0, 0, repeat_of=step.repeat_of)
    before = run.read_learn_record(j - 1) if j > repeats else None
    prediction = trial_prediction(run, profile, j, records[-1], before)
    assert step.record is not None and step.d_hat_m is not None and step.p_m2 is not None
    sp = _setpoints(step.setpoints_m, axes, ref)
    try:  # the QP keeps these limits; this guards against a solver that did not
        check_learned(sp, profile, ref, step.models)
    except TrajectoryError as exc:
        raise RunLogError(f"{run.path}: learned from trial {j}: {exc}; nothing written") from None
    refreshed = any(a.refresh is not None and a.refresh.accepted for a in step.record.axes)
    rms, largest = setpoint_deviation(sp, ref.pos_ned_m)
    record = {
        "format": 1,
        "trial": j,
        "next_trial": j + 1,
        "next_iteration": iteration_of(j + 1, repeats),
        "learned_from": list(range(j + 1)),
        "repeats": repeats,
        "models_from": source,
        "model_file": run.model_path(j).name if refreshed else None,
        "setpoints": {"rms_m": rms, "max_m": largest},
        "decision": step.record.as_dict(),
    }
    model_text = _refreshed_profile(run, profile, step.models, j) if refreshed else None
    floor = _floor_record(records, step)
    path = run.write_plan(j, step.d_hat_m, step.p_m2, record, sp, model_text, floor)
    return LearnOutcome(
        trial=j,
        next_trial=j + 1,
        setpoints_path=path,
        methods=step.methods,
        active_constraints=step.active_constraints,
        next_iteration=record["next_iteration"],
        record=run.read_learn_record(j),
        prediction=prediction,
    )


def _floor_record(records: list[TrialRecord], step: LearnerStep) -> dict | None:
    """``floor.json``: the step's floor and the trials of identical setpoints it came from."""
    assert step.record is not None
    floor = step.record.floor
    if floor is None:
        return None
    trials = floor_flights(np.array([r.sp_ned_m[:-1, :2] for r in records]))
    return {"trials": trials, **floor.as_dict()}


def _refreshed_profile(
    run: RunDir, profile: Profile, models: tuple[DiscreteModel, ...], j: int
) -> str:
    """The run's profile with the refreshed models, as YAML a user can fly (no clock in it:
    learning again from trial j gives the same bytes)."""
    import copy

    import yaml

    from gcs.io.config import profile_from_dict

    data = copy.deepcopy(profile.source)
    name = str(data.get("name", profile.name))
    data["name"] = name if name.endswith("-refreshed") else f"{name}-refreshed"
    data["description"] = (
        f"Profile '{name}' with the models refreshed by gcs learn from trials 0..{j} of the "
        f"run created {run.manifest.get('created_utc')} (trajectory "
        f"'{run.manifest['trajectory'].get('name')}')."
    )
    data["model"], data["model_y"] = models[0].as_dict(), models[1].as_dict()
    ordered = {k: data[k] for k in ("name", "description", "t_ilc_s", "model", "model_y")}
    ordered.update({k: v for k, v in data.items() if k not in ordered})
    header = (
        f"# Written by gcs learn: the models refreshed from trials 0..{j} of this run (the\n"
        f"# decisions are in {run.learn_path(j).name}). model / model_y: discrete state spaces at\n"
        f"# t_ilc_s = {profile.t_ilc_s:g} s. Everything else is the run's profile. Fly it with\n"
        "# gcs fly --profile <this file>.\n"
    )
    text = header + yaml.safe_dump(ordered, sort_keys=False, default_flow_style=None, width=100)
    profile_from_dict(yaml.safe_load(text), f"{run.model_path(j)}")  # it must load
    return text
