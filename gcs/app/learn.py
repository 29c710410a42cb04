"""Learning on a run directory: newest complete trial -> estimate -> next setpoints.

This is the one function behind both ``gcs learn`` and the learning between trials of
``gcs fly``. It is deterministic and idempotent: learning twice from the same trial writes the
same files.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gcs.core.estimators import KilcState
from gcs.core.learning import LearningInputs, learning_step
from gcs.core.metrics import epos, max_error
from gcs.core.model import relative_degree
from gcs.core.trajectory import Reference, check_setpoints
from gcs.errors import GcsError, ProfileError, RunLogError, TrajectoryError
from gcs.io.config import Profile, load_profile
from gcs.io.runlog import RunDir, TrialRecord

__all__ = [
    "LearnOutcome",
    "learning_inputs",
    "learn_run",
    "trial_errors",
    "check_learned",
    "check_learnable",
    "differing_field",
]


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
        Solver path per axis ("direct" or "clarabel").
    active_constraints : int
        Active setpoint limits, both axes.
    """

    trial: int
    next_trial: int
    setpoints_path: Path
    methods: tuple[str, str]
    active_constraints: int


def learning_inputs(profile: Profile, algorithm: str) -> LearningInputs:
    """The learning settings of a profile, for one algorithm.

    Parameters
    ----------
    profile : Profile
        The run's profile.
    algorithm : str
        ``"smoother"`` or ``"kilc"``.

    Returns
    -------
    LearningInputs
    """
    ln = profile.learning
    return LearningInputs(
        models=profile.models(),
        algorithm=algorithm,
        weights=ln.weights,
        smoother=ln.smoother,
        kilc=ln.kilc,
        arena=profile.arena,
        max_step_m=ln.max_step_m,
        max_deviation_m=ln.max_deviation_m,
    )


def trial_errors(record: TrialRecord) -> tuple[float, float]:
    """e_pos (eq. 10) and the maximum horizontal error of a trial, over k = 1..N [m].

    Parameters
    ----------
    record : TrialRecord
        A complete trial.

    Returns
    -------
    tuple of float
    """
    ref, pos = record.ref_ned_m[1:, :2], record.pos_ned_m[1:, :2]
    return epos(ref, pos), max_error(ref, pos)


def run_measurement(profile: Profile) -> str:
    """What learning and e_pos use: the profile's ``mocap.measurement`` (default ``mocap``).

    ``mocap`` takes a trial's motion-capture columns where it has them and the estimate in
    trials without (flown without mocap); ``estimate`` always takes the vehicle's estimate.

    Parameters
    ----------
    profile : Profile
        The run's profile.

    Returns
    -------
    str
        ``"mocap"`` or ``"estimate"``.
    """
    from gcs.flight.mocap.settings import mocap_settings

    return mocap_settings(profile.mocap, f"profile '{profile.name}'").measurement


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
                f"{profile_path}: does not match the profile in {run.path}/manifest.json "
                f"(field '{key}' differs)"
            )
    return profile


def check_learned(sp_ned_m: np.ndarray, profile: Profile, ref: Reference) -> None:
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

    Raises
    ------
    TrajectoryError
        Naming the limit, sample and axis.
    """
    ln = profile.learning
    check_setpoints(
        sp_ned_m, ref, profile.arena, ln.max_step_m, ln.max_deviation_m,
        (relative_degree(profile.model_x), relative_degree(profile.model_y)),
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
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            step = learning_step(
                learning_inputs(profile, algorithm),
                ref.pos_ned_m[:, :2], ref.pos_ned_m[:-1, :2], ref.pos_ned_m[:, :2],
            )  # fmt: skip
        sp = np.column_stack([step.setpoints_ne_m, ref.pos_ned_m[:-1, 2]])
        check_learned(sp, profile, ref)
    except GcsError as exc:
        raise type(exc)(f"{where}: learning cannot start on this trajectory: {exc}") from None
    except (ValueError, ArithmeticError, RuntimeError) as exc:  # a solver that fails numerically
        raise ProfileError(
            f"{where}: learning cannot start on this trajectory: {exc} (check learning.weights "
            "and the models)"
        ) from None


def _kilc_prior(run: RunDir, j: int) -> tuple[KilcState, KilcState] | None:
    if j == 0:
        return None
    d_hat, p = run.read_estimate(j - 1)
    return tuple(KilcState(d_hat[:, a].copy(), float(p[0, a]), j) for a in range(2))  # type: ignore[return-value]


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
    try:
        record = run.read_trial(j).measured(run_measurement(profile))
    except RunLogError as exc:
        raise RunLogError(f"{run.path}/trial-{j:03d}.csv: {exc}") from None
    ref = run.reference()
    if np.max(np.abs(record.ref_ned_m - ref.pos_ned_m)) > 1e-6:
        raise RunLogError(f"{run.path}/trial-{j:03d}.csv: reference columns differ from the run's")
    kilc_prior = _kilc_prior(run, j) if run.algorithm == "kilc" else None
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            step = learning_step(
                learning_inputs(profile, run.algorithm),
                ref.pos_ned_m[:, :2],
                record.sp_ned_m[:-1, :2],
                record.pos_ned_m[:, :2],
                kilc_prior,
            )
    except (ArithmeticError, RuntimeError) as exc:  # GcsErrors pass: they name their cause
        if isinstance(exc, GcsError):
            raise
        raise RunLogError(
            f"{run.path}/trial-{j:03d}.csv: the learning update failed on this trial ({exc}); "
            "nothing written"
        ) from None
    sp = np.column_stack([step.setpoints_ne_m, ref.pos_ned_m[:-1, 2]])
    try:  # the QP keeps these limits; this guards against a solver that did not
        check_learned(sp, profile, ref)
    except TrajectoryError as exc:
        raise RunLogError(f"{run.path}: learned from trial {j}: {exc}; nothing written") from None
    path = run.write_learned(j, step.d_hat_ne_m, step.p_ne_m2, sp)
    return LearnOutcome(
        trial=j,
        next_trial=j + 1,
        setpoints_path=path,
        methods=(step.updates[0].method, step.updates[1].method),
        active_constraints=sum(u.active_constraints for u in step.updates),
    )
