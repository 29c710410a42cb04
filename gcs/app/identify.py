"""``gcs identify``: the identification run (its directory, its trial source, its flight) and
the command's sequence: plan, fly or read, identify, write the profile and the figures.

Planning is :mod:`gcs.app.identify_plan`, PBSID :mod:`gcs.app.identify_fit`, the profile
:mod:`gcs.app.identify_profile`, the figures :mod:`gcs.app.identify_figures`; what is shown
is :mod:`gcs.app.identify_view`'s. The run's trial 0 is the fitting experiment, trial 1 the
validation experiment.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from gcs.app.identify_figures import write_identification_plots
from gcs.app.identify_fit import AxisResult, identify_run
from gcs.app.identify_plan import (
    ALGORITHM,
    TRAJECTORY_TYPE,
    Experiments,
    IdentifyPlan,
    IdentifyRequest,
    plan_identify,
    run_source,
)
from gcs.app.identify_profile import identified_profile_text, write_profile
from gcs.app.session import (
    SessionRecorder,
    flight_fence,
    flyable_setpoints,
    raw_mocap,
    to_record,
    trial_extra,
    vehicle_url,
)
from gcs.app.source_worker import Notify, WorkerSource
from gcs.core.trajectory import Reference
from gcs.flight.campaign import CampaignPlan, run_campaign
from gcs.flight.mocap.link import MocapLink
from gcs.flight.trial import TrialRecording
from gcs.io.config import Profile, TrajectorySpec
from gcs.io.records import TrialRecord, TrialStatus
from gcs.io.rundir import RunDir
from gcs.io.settings import FlightSettings, IdentifySettings

__all__ = [
    "run_identify",
    "create_identification_run",
    "IdentificationSource",
    "identification_source",
    "fly_identification",
]


class IdentifyDisplay(Protocol):
    """What ``gcs identify`` shows (:class:`gcs.app.identify_view.IdentifyView`)."""

    def checked(self, plan: IdentifyPlan) -> None: ...
    def started(self, plan: IdentifyPlan, run: RunDir) -> None: ...
    def flight(self) -> tuple[AbstractContextManager, Callable[[object], None]]: ...
    def say(self, text: str) -> None: ...
    def interrupted(self, run: RunDir) -> None: ...
    def results(self, results: list[AxisResult], profile_name: str) -> None: ...
    def wrote_profile(self, path: Path, new: bool) -> None: ...
    def wrote(self, path: Path) -> None: ...


def run_identify(request: IdentifyRequest, display: IdentifyDisplay) -> Path | None:
    """Check everything, fly the two experiments (or read them), identify, write the profile.

    Parameters
    ----------
    request : IdentifyRequest
    display : IdentifyDisplay
        Shows every step.

    Returns
    -------
    Path or None
        The profile written (None with ``check_only``).
    """
    plan = plan_identify(request)
    if request.check_only:
        display.checked(plan)
        return None
    run = plan.run if plan.run is not None else _fly(plan, display)
    results = identify_run(run, plan.settings, plan.profile, request.axis)
    display.results(results, plan.profile.name)
    target = Path(request.out) if request.out is not None else run.identified_path
    text = identified_profile_text(
        plan.profile, results, str(run.path), str(target), run.manifest.get("created_utc")
    )
    display.wrote_profile(target, write_profile(target, run.path, text))
    if request.plot is not None:
        for p in write_identification_plots(results, plan.profile, request.plot):
            display.wrote(p)
    return target


def _fly(plan: IdentifyPlan, display: IdentifyDisplay) -> RunDir:
    request, experiments = plan.request, plan.experiments
    assert experiments is not None
    root, run_id = (
        (request.logs, None) if request.run is None else (request.run.parent, request.run.name)
    )
    run = create_identification_run(root, plan.profile, plan.settings, experiments, run_id)
    display.started(plan, run)
    progress, on_event = display.flight()
    try:
        with (
            vehicle_url(
                request.connect, request.use_mock, plan.mock_config, plan.settings.seed,
                display.say, plan.mocap,
            ) as (url, link),
            progress,
        ):  # fmt: skip
            fly_identification(url, run, plan.profile.flight, on_event, link)
    except KeyboardInterrupt:
        display.interrupted(run)
        raise
    return run


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
    """Record both experiments as a new run (algorithm ``identify``, trials 0 fit, 1 validation).

    The manifest's ``trajectory`` holds the settings, the axes, the hover point and the seeds
    of both experiments; the reference is the fitting experiment.

    Parameters
    ----------
    root : Path
        Parent directory of runs.
    profile : Profile
    settings : IdentifySettings
    experiments : Experiments
    run_id : str or None
        Directory name (default ``<UTC time>-identification-identify``).
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
    """The flight layer's trial source of the two experiments: hover at ``center_ned_m``
    (3,) [m], fly, record; nothing is learned."""

    run: RunDir
    center_ned_m: np.ndarray
    session: int | None = None

    def setpoints_for(self, j: int) -> np.ndarray:
        """Experiment j's setpoints (N, 3), refused if any leaves the arena.

        Parameters
        ----------
        j : int
        """
        return flyable_setpoints(self.run, j)

    def hover_point_for(self, j: int) -> np.ndarray:
        """The hover point before experiment j.

        Parameters
        ----------
        j : int
        """
        return np.asarray(self.center_ned_m, dtype=float)

    def record(self, j: int, recording: TrialRecording) -> None:
        """Write a complete experiment.

        Parameters
        ----------
        j : int
        recording : TrialRecording
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
        recording : TrialRecording
        reason : str
        """
        record = _to_record(self.run, j, recording)
        status = TrialStatus(
            j, False, reason=reason, interpolated_share=recording.interpolated_share,
            extra=trial_extra(recording, self.session),
        )  # fmt: skip
        self.run.write_trial(j, record, status, raw_mocap(recording))


def identification_source(
    run: RunDir, center_ned_m: np.ndarray, *, notify: Notify
) -> IdentificationSource:
    """The trial source as its worker process builds it (``notify`` unused: nothing to say).

    Parameters
    ----------
    run : RunDir
    center_ned_m : ndarray, shape (3,)
        Hover point [m].
    notify : callable
    """
    return IdentificationSource(run, center_ned_m)


def fly_identification(
    url: str,
    run: RunDir,
    settings: FlightSettings,
    on_event: Callable[[object], None] | None = None,
    mocap: MocapLink | None = None,
) -> None:
    """Fly both experiments (take off, two trials, land), recorded by a worker process.

    Parameters
    ----------
    url : str
        MAVSDK connection URL.
    run : RunDir
    settings : FlightSettings
    on_event : callable, optional
        Receives the campaign events.
    mocap : MocapLink or None
        A started motion-capture link.
    """
    center = np.asarray(run_source(run)["center_ned_m"], dtype=float)
    fence = flight_fence(run.profile(), settings)
    plan = CampaignPlan(url, 0, 2, run.t_ilc_s, settings, fence)
    with WorkerSource(identification_source, (run, center)) as source:
        run_campaign(plan, source, on_event, mocap=mocap)
