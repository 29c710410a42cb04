"""``gcs identify`` planned: its request, the excitation, and every check made before anything
is created, flown or identified."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from gcs.app.session import MocapPlan, check_mock_config, check_url, mock_config_for, plan_mocap
from gcs.core.excitation import multisine, prbs
from gcs.core.trajectory import Box, points_outside
from gcs.errors import IdentificationError, PathError, ProfileError, RunLogError, TrajectoryError
from gcs.io.config import Profile, load_profile
from gcs.io.paths import check_new_dir, check_output_dir, check_output_file
from gcs.io.rundir import RunDir
from gcs.io.settings import AXES, IdentifySettings

__all__ = [
    "ALGORITHM",
    "TRAJECTORY_TYPE",
    "IdentifyRequest",
    "Experiments",
    "IdentifyPlan",
    "plan_identify",
    "plan_experiments",
    "run_source",
    "run_axes",
    "require_experiment",
    "in_run",
]

#: Run-directory algorithm name and trajectory type of identification runs.
ALGORITHM = "identify"
TRAJECTORY_TYPE = "excitation"
#: VARX parameters need this many regression windows each (as :mod:`gcs.core.pbsid`).
_SAMPLES_PER_PARAMETER = 4


@dataclass(frozen=True)
class IdentifyRequest:
    """``gcs identify`` as asked: its options, before anything is checked."""

    profile: Path | None = None  # None: default_profile when flying, the run's offline
    default_profile: Path | None = None
    axis: str | None = None  # x, y, z, both or all; None: both flying, the run's offline
    out: Path | None = None  # None: identified.yaml in the run directory
    from_log: Path | None = None  # a run to identify again offline (nothing flown)
    plot: Path | None = None  # directory of the validation and Bode figures
    seed: int | None = None  # the excitation's (overrides the profile's) and the mock's
    connect: str | None = None
    use_mock: bool = False
    mock_config: Path | None = None
    logs: Path = Path("logs")
    run: Path | None = None  # exact path of the new run
    check_only: bool = False
    mocap: str | None = None  # a URL, "mock" or None (the profile's mocap.url)


@dataclass(frozen=True)
class Experiments:
    """Setpoints of the two experiments: ``(fit, validation)``, each (N, 3) absolute NED [m],
    the excited axes and the hover point ``center_ned_m`` (3,) [m]."""

    setpoints_ned_m: tuple[np.ndarray, np.ndarray]
    axes: tuple[str, ...]
    center_ned_m: np.ndarray


@dataclass(frozen=True)
class IdentifyPlan:
    """Everything ``gcs identify`` needs, checked: ``run`` offline, ``experiments`` flying."""

    request: IdentifyRequest
    profile: Profile
    settings: IdentifySettings
    run: RunDir | None = None
    experiments: Experiments | None = None
    mocap: MocapPlan | None = None
    mock_config: Path | None = None


def plan_identify(request: IdentifyRequest) -> IdentifyPlan:
    """Check every input of ``request``; nothing is created, connected or identified here.

    Parameters
    ----------
    request : IdentifyRequest
    """
    if request.plot is not None:
        check_output_dir(request.plot, "--plot")
    if request.from_log is not None:
        return _plan_offline(request, request.from_log)
    path = request.profile or request.default_profile
    assert path is not None
    profile, where = load_profile(path), str(path)
    settings = profile.identification
    if request.seed is not None:
        settings = replace(settings, seed=int(request.seed))
    mocap = plan_mocap(profile, where, request.mocap, request.use_mock)
    mock_config = mock_config_for(request.mock_config, request.use_mock, mocap)
    experiments = plan_experiments(
        settings, profile.t_ilc_s, request.axis or "both", profile.arena, where
    )
    if request.run is not None:
        check_new_dir(request.run, "--run")
    else:
        check_output_dir(request.logs, "--logs")
    _check_target(request.out, None)
    if request.use_mock:
        check_mock_config(mock_config)
    else:
        check_url(str(request.connect))
    return IdentifyPlan(
        request, profile, settings, experiments=experiments, mocap=mocap, mock_config=mock_config
    )


def _plan_offline(request: IdentifyRequest, from_log: Path) -> IdentifyPlan:
    run = RunDir.open(from_log)
    run.require_kind("identification", "gcs identify --from-log")
    profile = run.profile() if request.profile is None else load_profile(request.profile)
    run_axes(run, request.axis)
    for j in (0, 1):
        require_experiment(run, j)
        run.read_trial(j)
    _check_target(request.out, run.path)
    return IdentifyPlan(request, profile, profile.identification, run=run)


def require_experiment(run: RunDir, j: int) -> None:
    """Refuse a run without its experiment j (0 fitting, 1 validation).

    Parameters
    ----------
    run : RunDir
    j : int
    """
    if not run.status_path(j).exists():
        what = ("fitting", "validation")[j]
        raise RunLogError(f"{run.path}: trial {j} ({what} experiment) is missing")


def in_run(target: Path, run_path: Path) -> bool:
    """Whether ``target`` is a file directly in the run directory ``run_path``.

    Parameters
    ----------
    target, run_path : Path
    """
    return target.absolute().parent.resolve() == run_path.absolute().resolve()


def _check_target(out: Path | None, run_path: Path | None) -> None:
    """``--out`` (or the default in the run directory) can be written."""
    if out is None:
        if run_path is not None:  # identifying an existing run again: it must take the file
            RunDir.open(run_path).check_writable()
        return
    if run_path is not None and in_run(out, run_path):
        if out.name != RunDir.IDENTIFIED_FILE:
            raise PathError(
                f"--out {out}: inside the run directory only {RunDir.IDENTIFIED_FILE} is written"
            )
        RunDir.open(run_path).check_writable()
        return
    check_output_file(out, "--out")


def _parse_axes(axis: str) -> tuple[str, ...]:
    if axis == "both":
        return ("x", "y")
    if axis == "all":
        return ("x", "y", "z")
    if axis in AXES:
        return (axis,)
    raise IdentificationError(f"axis must be x, y, z, both or all, got {axis!r}")


def plan_experiments(
    settings: IdentifySettings,
    t_ilc_s: float,
    axis: str,
    arena: Box | None = None,
    where: str = "<profile>",
) -> Experiments:
    """Excitation setpoints of both experiments, refused if one leaves the arena.

    Independent seeds per axis and per experiment; a ``duration_s`` too short for the PBSID
    windows is refused too (:class:`ProfileError`).

    Parameters
    ----------
    settings : IdentifySettings
    t_ilc_s : float
        Sample time [s].
    axis : str
        ``x``, ``y``, ``z``, ``both`` (x and y at once) or ``all``.
    arena : Box or None
        Every setpoint and the hover point must lie inside.
    where : str
        The profile's name in error messages.
    """
    axes = _parse_axes(axis)
    n = settings.n_samples(t_ilc_s)
    # the fit uses one experiment of N + 1 samples: as many windows as gcs.core.pbsid needs
    p, d = settings.past, settings.max_delay
    need = _SAMPLES_PER_PARAMETER * (2 * p + d) + p + d
    if n + 1 < need:
        raise ProfileError(
            f"{where}: field 'identification.duration_s' is too short: {settings.duration_s:g} s "
            f"gives {n + 1} samples, but past = {p} and max_delay = {d} need {need} "
            f"({need * t_ilc_s:g} s)"
        )
    center = np.asarray(settings.center_ned_m, dtype=float)
    out = []
    for e in (0, 1):
        sp = np.tile(center, (n, 1))
        for a in axes:
            seed, level = settings.seed_for(e, a), settings.amplitude_for(a)
            if settings.excitation == "prbs":
                seq = prbs(n, t_ilc_s, level, settings.bandwidth_hz, seed)
            else:
                seq = multisine(n, t_ilc_s, level, settings.f_min_hz, settings.f_max_hz, seed)
            sp[:, AXES[a]] += seq
        out.append(sp)
    if arena is not None:
        _check_in_arena(out, center, axes, arena)
    return Experiments((out[0], out[1]), axes, center)


def _check_in_arena(
    setpoints: list[np.ndarray], center: np.ndarray, axes: tuple[str, ...], arena: Box
) -> None:
    if points_outside(center[None, :], arena).size:
        raise TrajectoryError(
            f"identification hover point {center.tolist()} is outside the arena {arena}; "
            "change identification.center_ned_m"
        )
    fields = ["vertical_amplitude_m" if a == "z" else "amplitude_m" for a in axes]
    level_field = " / ".join(dict.fromkeys(fields))
    for e, sp in enumerate(setpoints):
        bad = points_outside(sp, arena)
        if bad.size:
            k = int(bad[0])
            raise TrajectoryError(
                f"identification experiment {e}: setpoint k = {k} "
                f"{np.round(sp[k], 3).tolist()} is outside the arena {arena}; reduce "
                f"identification.{level_field} or move identification.center_ned_m; not flown"
            )


def run_source(run: RunDir) -> dict:
    """The manifest's ``trajectory`` of an identification run, refused for any other run.

    Parameters
    ----------
    run : RunDir
    """
    source = run.manifest.get("trajectory")
    if not isinstance(source, dict) or source.get("type") != TRAJECTORY_TYPE:
        raise RunLogError(
            f"{run.path}: not an identification run (manifest trajectory type is not "
            f"'{TRAJECTORY_TYPE}'); record one with 'gcs identify --mock' or '--connect'"
        )
    for key in ("axes", "center_ned_m"):
        if key not in source:
            raise RunLogError(f"{run.manifest_path}: field 'trajectory.{key}' is missing")
    return source


def run_axes(run: RunDir, axis: str | None = None) -> tuple[str, ...]:
    """The axes to identify: ``axis`` (each excited in the run), or all the run excited.

    Parameters
    ----------
    run : RunDir
    axis : str or None
        ``x``, ``y``, ``z``, ``both``, ``all`` or None (the run's axes).
    """
    excited = tuple(run_source(run)["axes"])
    if axis is None:
        return excited
    wanted = _parse_axes(axis)
    for a in wanted:
        if a not in excited:
            raise IdentificationError(
                f"{run.path}: axis {a} was not excited in this run (excited: {', '.join(excited)})"
            )
    return wanted
