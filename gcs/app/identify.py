"""``gcs identify``: excitation flights, PBSID per axis, validation, and the identified profile.

The numerics are in :mod:`gcs.core.pbsid` and :mod:`gcs.core.excitation`; this module is the
glue between them, the profile, the run directory and the flight layer:

1. The profile's ``identification`` section arrives checked
   (:class:`gcs.io.settings.IdentifySettings`, built by :func:`gcs.io.config.profile_from_dict`).
2. :func:`plan_experiments` builds the setpoints of the two experiments, the hover point plus a
   PRBS (or multisine) on every excited horizontal axis, independent seeds per axis and per
   experiment, and refuses them if any setpoint leaves the arena.
3. :func:`create_identification_run` records them as a run directory (algorithm
   ``identify``; trial 0 = the fitting experiment, trial 1 = the validation experiment) and
   :func:`fly_identification` flies both, hovering settled at the hover point before each.
4. :func:`identify_run` reads the two trials back and, per axis, identifies the closed loop on
   trial 0 and validates it by free-run simulation on trial 1 (:class:`AxisResult`).
5. :func:`identified_profile_text` / :func:`write_identified_profile` write the input profile
   with ``model`` / ``model_y`` replaced by the identified discrete state spaces, and
   :func:`write_identification_plots` the validation and Bode figures.

Data conventions (as everywhere in gcs): row k of a trial holds the setpoint ``u(k)`` sent at
``k t_ilc_s`` and the position ``y(k)`` measured then; the models have no feedthrough, so
``u(k)`` acts on ``y(k+1)`` onwards. Both are taken relative to the hover point.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import yaml

from gcs.app.figures import save_figure
from gcs.app.session import (
    SessionRecorder,
    flight_fence,
    flyable_setpoints,
    raw_mocap,
    to_record,
    trial_extra,
)
from gcs.app.source_worker import Notify, WorkerSource
from gcs.core.excitation import multisine, prbs
from gcs.core.model import DiscreteModel, frequency_response
from gcs.core.pbsid import (
    IdentificationResult,
    identify,
    natural_frequency_damping,
    nrmse_fit,
    simulate_free,
    to_continuous_tf,
    vaf,
)
from gcs.core.trajectory import Reference, points_outside
from gcs.errors import IdentificationError, ModelError, ProfileError, RunLogError, TrajectoryError
from gcs.flight.campaign import CampaignPlan, run_campaign
from gcs.flight.mocap.link import MocapLink
from gcs.flight.trial import TrialRecording
from gcs.io.atomic import atomic_write_text
from gcs.io.config import Profile, TrajectorySpec, profile_from_dict
from gcs.io.records import TrialRecord, TrialStatus
from gcs.io.rundir import RunDir
from gcs.io.settings import AXES, FlightSettings, IdentifySettings

__all__ = [
    "IdentifyRequest",
    "Experiments",
    "plan_experiments",
    "create_identification_run",
    "IdentificationSource",
    "identification_source",
    "fly_identification",
    "AxisResult",
    "run_axes",
    "identify_run",
    "identified_profile_text",
    "write_identified_profile",
    "write_identification_plots",
]


@dataclass(frozen=True)
class IdentifyRequest:
    """``gcs identify`` as asked: its options, before anything is checked.

    Parameters
    ----------
    profile : Path or None
        Input profile; None: ``default_profile`` when flying, the run's profile offline.
    default_profile : Path or None
        Profile used when flying without ``profile``.
    axis : str or None
        ``x``, ``y``, ``z``, ``both`` or ``all``; None: both when flying, the run's axes
        offline.
    out : Path or None
        Output profile; None writes ``identified.yaml`` in the run directory.
    from_log : Path or None
        Identification run directory to identify from offline (nothing is flown).
    plot : Path or None
        Directory for the validation and Bode PNGs.
    seed : int or None
        Excitation seed (overrides the profile's); also the mock drone's seed.
    connect : str or None
        URL of a real vehicle.
    use_mock : bool
        Fly the mock drone.
    mock_config : Path or None
        Mock drone settings.
    logs : Path
        Parent of the new identification run.
    run : Path or None
        Exact path of the new run.
    check_only : bool
        Validate and say what would be done, then stop: nothing is created, flown or written.
    mocap : str or None
        ``--mocap``: a URL, ``mock`` (the mock's arena) or None (the profile's ``mocap.url``).
    """

    profile: Path | None = None
    default_profile: Path | None = None
    axis: str | None = None
    out: Path | None = None
    from_log: Path | None = None
    plot: Path | None = None
    seed: int | None = None
    connect: str | None = None
    use_mock: bool = False
    mock_config: Path | None = None
    logs: Path = Path("logs")
    run: Path | None = None
    check_only: bool = False
    mocap: str | None = None


#: Run-directory algorithm name and trajectory type of identification runs.
ALGORITHM = "identify"
TRAJECTORY_TYPE = "excitation"
#: VARX parameters need this many regression windows each (as :mod:`gcs.core.pbsid`).
_SAMPLES_PER_PARAMETER = 4


# ------------------------------------------------------------------------------- settings


# ----------------------------------------------------------------------------- experiments


@dataclass(frozen=True)
class Experiments:
    """Setpoints of the two identification experiments.

    Parameters
    ----------
    setpoints_ned_m : tuple of ndarray
        ``(fit, validation)``, each shape (N, 3), absolute local NED [m].
    axes : tuple of str
        Excited axes, e.g. ``("x", "y")``.
    center_ned_m : ndarray, shape (3,)
        Hover point [m].
    """

    setpoints_ned_m: tuple[np.ndarray, np.ndarray]
    axes: tuple[str, ...]
    center_ned_m: np.ndarray


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
    arena: object | None = None,
    where: str = "<profile>",
) -> Experiments:
    """Excitation setpoints of both experiments, checked against the arena.

    Parameters
    ----------
    settings : IdentifySettings
        Excitation settings.
    t_ilc_s : float
        Sample time [s].
    axis : str
        ``"x"``, ``"y"``, ``"z"``, ``"both"`` (x and y at once, independent seeds) or
        ``"all"`` (x, y and z at once).
    arena : Box or None
        Flight volume; every setpoint and the hover point must lie inside.
    where : str
        Name of the profile (file path) used in error messages.

    Returns
    -------
    Experiments

    Raises
    ------
    ProfileError
        ``duration_s`` too short for the PBSID windows (checked before anything is flown).
    TrajectoryError
        A setpoint (or the hover point) outside the arena.
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
        if points_outside(center[None, :], arena).size:
            raise TrajectoryError(
                f"identification hover point {center.tolist()} is outside the arena {arena}; "
                "change identification.center_ned_m"
            )
        fields = ["vertical_amplitude_m" if a == "z" else "amplitude_m" for a in axes]
        level_field = " / ".join(dict.fromkeys(fields))
        for e, sp in enumerate(out):
            bad = points_outside(sp, arena)
            if bad.size:
                k = int(bad[0])
                raise TrajectoryError(
                    f"identification experiment {e}: setpoint k = {k} "
                    f"{np.round(sp[k], 3).tolist()} is outside the arena {arena}; reduce "
                    f"identification.{level_field} or move identification.center_ned_m; not flown"
                )
    return Experiments((out[0], out[1]), axes, center)


def _reference(sp: np.ndarray, t_ilc_s: float) -> Reference:
    """The flown excitation as a reference, k = 0..N (row N holds the last setpoint)."""
    pos = np.vstack([sp, sp[-1]])
    t = np.arange(pos.shape[0]) * t_ilc_s
    vel = np.gradient(pos, t_ilc_s, axis=0)
    return Reference(t, pos, vel, np.gradient(vel, t_ilc_s, axis=0))


def create_identification_run(
    root: Path,
    profile: Profile,
    settings: IdentifySettings,
    experiments: Experiments,
    run_id: str | None = None,
) -> RunDir:
    """Record both experiments as a run directory: setpoints-000 (fit), setpoints-001 (validation).

    The manifest's ``trajectory`` is ``{"type": "excitation", "name": "identification", "axes":
    [...], "center_ned_m": [...], "seeds": {"fit": {...}, "validation": {...}}, ...}`` plus the
    settings; the algorithm is ``"identify"``; ``reference.csv`` is the fitting experiment.

    Parameters
    ----------
    root : Path
        Parent directory of runs.
    profile : Profile
        The profile flown.
    settings : IdentifySettings
        Excitation and PBSID settings.
    experiments : Experiments
        From :func:`plan_experiments`.
    run_id : str or None
        Directory name (default ``<UTC time>-identification-identify``).

    Returns
    -------
    RunDir
    """
    source = {
        "type": TRAJECTORY_TYPE,
        "name": "identification",
        **{k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(settings).items()},
        "axes": list(experiments.axes),
        "center_ned_m": experiments.center_ned_m.tolist(),
        "seeds": {
            name: {a: settings.seed_for(e, a) for a in experiments.axes}
            for e, name in enumerate(("fit", "validation"))
        },
    }
    spec = TrajectorySpec(name="identification", shape=None, source=source)
    ref = _reference(experiments.setpoints_ned_m[0], profile.t_ilc_s)
    run = RunDir.create(root, profile, spec, ALGORITHM, run_id=run_id, reference=ref)
    run.write_setpoints(1, experiments.setpoints_ned_m[1])
    return run


def _to_record(run: RunDir, j: int, recording: TrialRecording) -> TrialRecord:
    sp = run.read_setpoints(j)
    return to_record(run, recording, np.vstack([sp, sp[-1]]))  # the excitation is its reference


@dataclass
class IdentificationSource(SessionRecorder):
    """Trial source of the flight layer for the two identification experiments.

    Parameters
    ----------
    run : RunDir
        The identification run (from :func:`create_identification_run`).
    center_ned_m : ndarray, shape (3,)
        Hover point before each experiment [m].
    session : int or None
        Number of this flight session's record in the run (set by :meth:`record_session`).
    """

    run: RunDir
    center_ned_m: np.ndarray
    session: int | None = None

    def setpoints_for(self, j: int) -> np.ndarray:
        """Experiment j's setpoints, refused if any leaves the arena.

        Parameters
        ----------
        j : int
            Trial index (0 fit, 1 validation).

        Returns
        -------
        ndarray, shape (N, 3)
        """
        return flyable_setpoints(self.run, j)

    def hover_point_for(self, j: int) -> np.ndarray:
        """The hover point (identification coordinates are relative to it).

        Parameters
        ----------
        j : int
            Trial index.

        Returns
        -------
        ndarray, shape (3,)
        """
        return np.asarray(self.center_ned_m, dtype=float)

    def record(self, j: int, recording: TrialRecording) -> None:
        """Write a complete experiment (no learning).

        Parameters
        ----------
        j : int
            Trial index.
        recording : TrialRecording
            The complete recording.
        """
        from gcs.core.trials import trial_errors

        record = _to_record(self.run, j, recording)
        e, m = trial_errors(record)
        status = TrialStatus(
            j, True, epos_m=e, max_err_m=m, interpolated_share=recording.interpolated_share,
            extra=trial_extra(recording, self.session),
        )  # fmt: skip
        self.run.write_trial(j, record, status, raw_mocap(recording))

    def record_incomplete(self, j: int, recording: TrialRecording, reason: str) -> None:
        """Write an interrupted experiment, marked incomplete (never identified from).

        Parameters
        ----------
        j : int
            Trial index.
        recording : TrialRecording
            The partial recording.
        reason : str
            Why it stopped.
        """
        record = _to_record(self.run, j, recording)
        status = TrialStatus(
            j, False, reason=reason, interpolated_share=recording.interpolated_share,
            extra=trial_extra(recording, self.session),
        )  # fmt: skip
        self.run.write_trial(j, record, status, raw_mocap(recording))


def fly_identification(
    url: str,
    run: RunDir,
    settings: FlightSettings,
    on_event: Callable[[object], None] | None = None,
    mocap: MocapLink | None = None,
) -> None:
    """Fly both experiments of an identification run (take off, 2 trials, land).

    The experiments are written by a worker process of their own
    (:class:`gcs.app.source_worker.WorkerSource`), as the learning runs of ``gcs fly``.

    Parameters
    ----------
    url : str
        MAVSDK connection URL.
    run : RunDir
        The identification run.
    settings : FlightSettings
        Flight settings of the profile.
    on_event : callable, optional
        Receives the campaign events.
    mocap : MocapLink or None
        A started motion-capture link (forwarded, checked, watched, logged).
    """
    center = np.asarray(_run_source(run)["center_ned_m"], dtype=float)
    fence = flight_fence(run.profile(), settings)
    plan = CampaignPlan(url, 0, 2, run.t_ilc_s, settings, fence)
    with WorkerSource(identification_source, (run, center)) as source:
        run_campaign(plan, source, on_event, mocap=mocap)


def identification_source(
    run: RunDir, center_ned_m: np.ndarray, *, notify: Notify
) -> IdentificationSource:
    """The trial source of an identification run as its worker process builds it.

    Parameters
    ----------
    run : RunDir
        The identification run.
    center_ned_m : ndarray, shape (3,)
        Hover point before each experiment [m].
    notify : callable
        Unused (the experiments report nothing back beyond the campaign's events).

    Returns
    -------
    IdentificationSource
    """
    return IdentificationSource(run, center_ned_m)


# --------------------------------------------------------------------------- identification


@dataclass(frozen=True)
class AxisResult:
    """Identification and validation of one axis.

    Parameters
    ----------
    axis : str
        ``"x"`` (north), ``"y"`` (east) or ``"z"`` (down).
    result : IdentificationResult
        PBSID output (fitted on trial 0).
    vaf_pct : float
        VAF of the free-run simulation on the validation experiment [%].
    fit_pct : float
        NRMSE fit on the validation experiment [%].
    vaf_profile_pct : float
        VAF of the input profile's model on the same data [%] (for comparison; NaN for z when
        the profile has no ``model_z``).
    t_s : ndarray, shape (M,)
        Validation time grid [s].
    u_val_m, y_val_m, y_sim_m : ndarray, shape (M,)
        Validation setpoint, measured and simulated position, relative to the hover point [m].
    wn_rad_s, zeta : float or None
        Dominant continuous pole pair (Tustin); None for a first-order model.
    num, den : ndarray
        Tustin transfer function (descending powers of s).
    """

    axis: str
    result: IdentificationResult
    vaf_pct: float
    fit_pct: float
    vaf_profile_pct: float
    t_s: np.ndarray
    u_val_m: np.ndarray
    y_val_m: np.ndarray
    y_sim_m: np.ndarray
    wn_rad_s: float | None
    zeta: float | None
    num: np.ndarray
    den: np.ndarray

    @property
    def model(self) -> DiscreteModel:
        """The identified model."""
        return self.result.model


def _run_source(run: RunDir) -> dict:
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
    """The axes to identify: ``axis`` (checked against the run), or all the run excited.

    Parameters
    ----------
    run : RunDir
        An identification run.
    axis : str or None
        ``"x"``, ``"y"``, ``"z"``, ``"both"``, ``"all"`` or None (the run's axes).

    Returns
    -------
    tuple of str
    """
    excited = tuple(_run_source(run)["axes"])
    if axis is None:
        return excited
    wanted = _parse_axes(axis)
    for a in wanted:
        if a not in excited:
            raise IdentificationError(
                f"{run.path}: axis {a} was not excited in this run (excited: {', '.join(excited)})"
            )
    return wanted


def _trial(run: RunDir, j: int, what: str) -> TrialRecord:
    """Experiment j as identification measures it (``mocap.measurement`` of the run)."""
    if not run.status_path(j).exists():
        raise RunLogError(f"{run.path}: trial {j} ({what} experiment) is missing")
    return run.measured_trial(j)


def identify_run(
    run: RunDir,
    settings: IdentifySettings,
    profile: Profile,
    axis: str | None = None,
) -> list[AxisResult]:
    """Identify every axis of an identification run on trial 0 and validate on trial 1.

    Parameters
    ----------
    run : RunDir
        An identification run with complete trials 0 and 1.
    settings : IdentifySettings
        PBSID windows, order and delay search.
    profile : Profile
        Profile whose models are compared with the identified ones.
    axis : str or None
        Axes to identify (default: those the run excited).

    Returns
    -------
    list of AxisResult

    Raises
    ------
    RunLogError
        Not an identification run, missing, incomplete, truncated or NaN-filled trials.
    IdentificationError
        Too little data, a constant input, a non-exciting input, an unstable model.
    """
    axes = run_axes(run, axis)
    center = np.asarray(_run_source(run)["center_ned_m"], dtype=float)
    fit_trial, val_trial = _trial(run, 0, "fitting"), _trial(run, 1, "validation")
    out = []
    for a in axes:
        c = AXES[a]
        u_fit = fit_trial.sp_ned_m[:, c] - center[c]
        y_fit = fit_trial.pos_ned_m[:, c] - center[c]
        u_val = val_trial.sp_ned_m[:, c] - center[c]
        y_val = val_trial.pos_ned_m[:, c] - center[c]
        try:
            res = identify(
                [(u_fit, y_fit)], run.t_ilc_s, past=settings.past, future=settings.future,
                order=settings.order, max_delay=settings.max_delay,
            )  # fmt: skip
        except IdentificationError as exc:
            raise IdentificationError(f"axis {a}, trial 0: {exc}") from None
        model = res.model
        if not model.is_stable():
            rho = float(np.max(np.abs(np.linalg.eigvals(model.A))))
            raise IdentificationError(
                f"axis {a}: the identified model is unstable (largest |pole| {rho:.3f}); "
                "excite longer or with more amplitude"
            )
        if np.ptp(u_val) <= 0.0:
            raise IdentificationError(f"axis {a}, trial 1: the validation input is constant")
        y_sim = simulate_free(model, u_val)
        prof_model = (*profile.models(), profile.model_z)[c]
        y_prof = None if prof_model is None else simulate_free(prof_model, u_val)
        try:
            wn, zeta = natural_frequency_damping(model)
        except ModelError:
            wn = zeta = None
        num, den, _ = to_continuous_tf(model)
        out.append(
            AxisResult(
                axis=a,
                result=res,
                vaf_pct=vaf(y_val, y_sim),
                fit_pct=nrmse_fit(y_val, y_sim),
                vaf_profile_pct=float("nan") if y_prof is None else vaf(y_val, y_prof),
                t_s=val_trial.t_s,
                u_val_m=u_val,
                y_val_m=y_val,
                y_sim_m=y_sim,
                wn_rad_s=wn,
                zeta=zeta,
                num=num,
                den=den,
            )  # fmt: skip
        )
    return out


# --------------------------------------------------------------------------- the profile


def identified_profile_text(
    profile: Profile,
    results: Sequence[AxisResult],
    origin: str,
    where: str = "<out>",
    recorded_utc: str | None = None,
) -> str:
    """The input profile's YAML with the identified models in ``model`` / ``model_y``.

    An axis that was not identified keeps the input profile's model. The text is checked by
    loading it (:func:`gcs.io.config.profile_from_dict`) before it is returned. It depends on
    the data and the settings only (no clock): identifying the same run again gives the same
    bytes, so that the run's own ``identified.yaml`` is written once and never replaced.

    Parameters
    ----------
    profile : Profile
        The input profile (its ``source`` is copied).
    results : sequence of AxisResult
        Identified axes.
    origin : str
        Where the data came from (run directory), for the header and ``description``.
    where : str
        Name used in error messages if the result does not load.
    recorded_utc : str or None
        When the experiments were flown (the run's ``created_utc``), for the header.

    Returns
    -------
    str
        YAML text.
    """
    data = copy.deepcopy(profile.source)
    old_x = copy.deepcopy(data["model"])
    old_y = copy.deepcopy(data.get("model_y", data["model"]))
    by_axis = {r.axis: r for r in results}
    data["model"] = by_axis["x"].model.as_dict() if "x" in by_axis else old_x
    data["model_y"] = by_axis["y"].model.as_dict() if "y" in by_axis else old_y
    if "z" in by_axis:
        data["model_z"] = by_axis["z"].model.as_dict()
    name = str(data.get("name", profile.name))
    summary = ", ".join(
        f"{r.axis}: order {r.result.order}, delay {r.result.delay_samples}, VAF {r.vaf_pct:.1f} %"
        for r in results
    )
    data["name"] = name if name.endswith("-identified") else f"{name}-identified"
    data["description"] = (
        f"Profile '{name}' with the closed-loop models identified by gcs identify (PBSID-opt) "
        f"from {origin} (trial 0 fit, trial 1 validation; {summary})."
    )
    keys = ("name", "description", "t_ilc_s", "model", "model_y", "model_z")
    ordered = {k: data[k] for k in keys if k in data}
    ordered.update({k: v for k, v in data.items() if k not in ordered})
    flown = f" (experiments flown {recorded_utc})" if recorded_utc else ""
    header = (
        f"# Written by 'gcs identify' from {origin}{flown}.\n"
        f"# model / model_y / model_z: identified discrete state spaces at t_ilc_s = "
        f"{profile.t_ilc_s:g} s\n"
        "# (x(k+1) = A x(k) + B u(k - delay_samples), y = C x; u setpoint, y position, both\n"
        "# relative to the hover point [m]). Everything else is the input profile's.\n"
    )
    text = header + yaml.safe_dump(ordered, sort_keys=False, default_flow_style=None, width=100)
    try:
        profile_from_dict(yaml.safe_load(text), where)
    except ProfileError as exc:
        raise IdentificationError(f"the identified profile does not load: {exc}") from None
    return text


def write_identified_profile(path: Path, text: str) -> Path:
    """Write the profile text atomically (directories created).

    Parameters
    ----------
    path : Path
        Destination.
    text : str
        From :func:`identified_profile_text`.

    Returns
    -------
    Path
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, text)
    return path


# ---------------------------------------------------------------------------- figures


def write_identification_plots(
    results: Sequence[AxisResult], profile: Profile, out_dir: Path
) -> list[Path]:
    """Validation plot (measured vs simulated, as the paper's Fig. 3) and Bode comparison.

    Files: ``identify_validation.png`` (one panel per axis: setpoint, measured and simulated
    position on the validation experiment) and ``identify_bode.png`` (magnitude and phase of the
    identified models against the profile's). PNG, written atomically.

    Parameters
    ----------
    results : sequence of AxisResult
        Identified axes.
    profile : Profile
        The input profile (its models are drawn for comparison).
    out_dir : Path
        Where to write (created if missing).

    Returns
    -------
    list of Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    fig, axs = plt.subplots(len(results), 1, figsize=(9, 3.2 * len(results)), squeeze=False)
    for ax, r in zip(axs[:, 0], results, strict=True):
        label = {"x": "north", "y": "east", "z": "down"}[r.axis]
        ax.step(r.t_s, r.u_val_m, where="post", color="0.75", lw=0.8, label="setpoint")
        ax.plot(r.t_s, r.y_val_m, "k", lw=1.2, label="measured")
        ax.plot(r.t_s, r.y_sim_m, "C3--", lw=1.2, label="identified model (free run)")
        ax.set_ylabel(f"{label} [m]")
        ax.set_title(
            f"axis {r.axis}: validation experiment, VAF {r.vaf_pct:.1f} %, fit {r.fit_pct:.1f} %"
        )
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axs[-1, 0].set_xlabel("t [s]")
    paths.append(save_figure(fig, out_dir / "identify_validation.png"))

    dt = profile.t_ilc_s
    f = np.logspace(-2, math.log10(0.45 / dt), 300)
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    curves = [(f"identified {r.axis}", r.model, "-") for r in results]
    px, py = profile.models()
    curves.append((f"profile '{profile.name}' x", px, "k--"))
    if not (np.array_equal(px.A, py.A) and np.array_equal(px.B, py.B)):
        curves.append((f"profile '{profile.name}' y", py, "k:"))
    for label, model, style in curves:
        h = frequency_response(model, 2 * math.pi * f)
        ax_m.semilogx(f, 20 * np.log10(np.abs(h)), style, label=label)
        ax_p.semilogx(f, np.degrees(np.unwrap(np.angle(h))), style, label=label)
    ax_m.set_ylabel("|G| [dB]")
    ax_p.set_ylabel("phase [deg]")
    ax_p.set_xlabel("f [Hz]")
    ax_m.set_title("Closed loop setpoint -> position")
    for ax in (ax_m, ax_p):
        ax.grid(True, which="both", alpha=0.3)
    ax_m.legend(fontsize=8)
    paths.append(save_figure(fig, out_dir / "identify_bode.png"))
    return paths
