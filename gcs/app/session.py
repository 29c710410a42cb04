"""The flight session that ``gcs fly`` and ``gcs identify`` share.

Before flying: the connection and the mock's settings checked (:func:`check_url`,
:func:`check_mock_config`), the motion capture planned (:func:`plan_mocap`), the live fence
(:func:`flight_fence`). While flying: the vehicle (:func:`vehicle_url`, which starts the mock
drone and its arena when asked), the setpoints read back as they will be flown
(:func:`flyable_setpoints`), and every flown trial and flight session recorded in the run
directory (:func:`to_record`, :func:`trial_extra`, :func:`raw_mocap`,
:class:`SessionRecorder`).
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gcs.app.learn import check_learned, models_in_use
from gcs.core.trajectory import points_outside
from gcs.errors import PathError, ProfileError, TrajectoryError
from gcs.flight.backend import is_registered
from gcs.flight.campaign import FlightSession
from gcs.flight.fence import Fence
from gcs.flight.mocap.campaign import MocapReport
from gcs.flight.mocap.link import MocapLink
from gcs.flight.trial import TrialRecording
from gcs.io.config import Profile
from gcs.io.mocap_source import MocapSource
from gcs.io.records import TrialRecord
from gcs.io.rundir import RunDir
from gcs.io.settings import FlightSettings, MocapSettings

__all__ = [
    "MOCK_MOCAP",
    "MocapPlan",
    "plan_mocap",
    "check_url",
    "check_mock_config",
    "mock_config_for",
    "flight_fence",
    "vehicle_url",
    "flyable_setpoints",
    "to_record",
    "trial_extra",
    "session_record",
    "SessionRecorder",
    "raw_mocap",
]


def flight_fence(profile: Profile, settings: FlightSettings) -> Fence:
    """The live fence of a flight: the profile's arena and vehicle limits, the flight settings.

    Parameters
    ----------
    profile : Profile
        The profile (``arena``, ``vehicle``).
    settings : FlightSettings
        Its flight settings (``fence_*``).

    Returns
    -------
    Fence
    """
    return Fence.around(
        profile.arena.bounds(), settings, profile.max_speed_m_s, profile.max_vertical_speed_m_s
    )


#: MAVSDK connection URLs (MAVSDK 2: udpin/udpout/tcpin/tcpout/serial/serial_flowcontrol;
#: udp:// and tcp:// are its older spellings of udpin and tcpout).
_URL = re.compile(
    r"^(?:(?:udpin|udpout|udp|tcpin|tcpout|tcp)://[^/:\s]*:(?P<port>\d{1,5})"
    r"|(?:serial|serial_flowcontrol)://\S+?(?::\d+)?)$"
)


def check_url(url: str) -> str:
    """Refuse a MAVSDK connection URL that MAVSDK would not open.

    Parameters
    ----------
    url : str
        E.g. ``udpin://0.0.0.0:14540``, ``udpout://127.0.0.1:14540``,
        ``serial:///dev/ttyUSB0:57600``.

    Returns
    -------
    str
        ``url``.

    Raises
    ------
    PathError
        Unknown scheme, no port, or a port outside 1..65535.
    """
    if is_registered(url):  # a link registered in-process (the tests' simulated drone)
        return url
    match = _URL.match(url)
    port = match.group("port") if match else None
    if match is None or (port is not None and not 1 <= int(port) <= 65535):
        raise PathError(
            f"--connect {url}: not a MAVSDK connection URL (udpin://HOST:PORT, "
            "udpout://HOST:PORT, tcpout://HOST:PORT, serial:///dev/DEVICE:BAUD)"
        )
    return url


def check_mock_config(path: Path | None) -> None:
    """Load the mock drone's settings once, so that a bad file is refused before flying.

    Parameters
    ----------
    path : Path or None
        ``--mock-config``; None for the defaults.
    """
    if path is not None:
        from gcs.mock.config import load_mock_config

        load_mock_config(path)


MOCK_MOCAP = "mock"
"""``--mocap mock``: the mock drone's own arena (with ``--mock``)."""


@dataclass(frozen=True)
class MocapPlan:
    """The motion capture of a flight, checked before anything starts.

    Parameters
    ----------
    settings : MocapSettings
        The profile's ``mocap`` section.
    source : MocapSource or None
        Where to read; None for the mock drone's arena (its URL is known once it runs).
    """

    settings: MocapSettings
    source: MocapSource | None

    def link(self, mock_url: str | None = None) -> MocapLink:
        """The (not yet started) link of this plan.

        Parameters
        ----------
        mock_url : str or None
            The arena's URL, for a plan of the mock's arena.

        Returns
        -------
        MocapLink
        """
        from gcs.io.mocap_source import parse_mocap_url

        source = self.source or parse_mocap_url(mock_url or "")
        return MocapLink(source, self.settings.mapping(source), self.settings)

    def describe(self) -> str:
        """One line: source, mapping, forwarding, measurement.

        Returns
        -------
        str
        """
        where = self.source.url() if self.source is not None else "the mock drone's arena"
        s = self.settings
        forward = f"forwarded as {s.message}" if s.forward else "not forwarded"
        return f"mocap {where} ({forward}; learning on {s.measurement})"


def plan_mocap(profile: Profile, where: str, mocap: str | None, use_mock: bool) -> MocapPlan | None:
    """Check the profile's ``mocap`` section and ``--mocap``; None when no mocap is used.

    Parameters
    ----------
    profile : Profile
        The profile (its ``mocap`` section checked when it was loaded).
    where : str
        The profile's file, for messages.
    mocap : str or None
        ``--mocap``: a URL, ``mock`` (with ``--mock``) or None (the profile's ``mocap.url``).
    use_mock : bool
        The flight is on the mock drone.

    Returns
    -------
    MocapPlan or None
    """
    settings = profile.mocap
    if mocap == MOCK_MOCAP:
        if not use_mock:
            raise PathError("--mocap mock: the mock's arena needs --mock (a real arena: its URL)")
        settings.mapping(MocapSource("optitrack", "127.0.0.1", 1510, "drone"))  # axes valid
        return MocapPlan(settings, None)
    source = settings.source(mocap)
    if source is None:
        return None
    try:
        settings.mapping(source)
    except ValueError as exc:
        raise ProfileError(f"{where}: field 'mocap': {exc}") from None
    return MocapPlan(settings, source)


def mock_config_for(
    mock_config: Path | None, use_mock: bool, mocap: MocapPlan | None
) -> Path | None:
    """The mock drone's settings for a flight: ``--mock-config`` as given, else the default
    set-up of a flight on the mock's own motion capture (``--mocap mock``): the packaged
    ``mock-mocap`` profile, vision only (no GPS), as EKF2 indoors.

    Parameters
    ----------
    mock_config : Path or None
        ``--mock-config`` (None: not given).
    use_mock : bool
        ``--mock``.
    mocap : MocapPlan or None
        The flight's motion capture (:func:`plan_mocap`).

    Returns
    -------
    Path or None
        None: the mock's defaults (or no mock).
    """
    if use_mock and mock_config is None and mocap is not None and mocap.source is None:
        from gcs.io.paths import resolve_named

        return resolve_named("mock-mocap", "profile", "--mock-config")
    return mock_config


@contextlib.contextmanager
def vehicle_url(
    connect: str | None,
    use_mock: bool,
    mock_config: Path | None,
    seed: int,
    say: Callable[[str], None],
    mocap: MocapPlan | None = None,
) -> Iterator[tuple[str, MocapLink | None]]:
    """Yield the MAVSDK URL to fly and the started mocap link (None without mocap).

    A real vehicle's URL, or a mock drone started for the flight (with its arena's mock
    Motive when ``mocap`` reads the mock's arena). The mocap link is started here and
    stopped after the flight (the stream keeps feeding the vehicle while it lands).

    Parameters
    ----------
    connect : str or None
        URL of a real vehicle (used when ``use_mock`` is False).
    use_mock : bool
        Start the mock drone as a subprocess on a free loopback port and stop it afterwards.
    mock_config : Path or None
        Mock drone settings (YAML).
    seed : int
        Seed of the mock drone.
    say : callable
        Told (one line each) where the mock drone, its arena and the mocap stream are.
    mocap : MocapPlan or None
        The flight's motion capture.

    Yields
    ------
    tuple of (str, MocapLink or None)
    """
    with contextlib.ExitStack() as stack:
        url, mocap_url = connect, None
        if use_mock:
            from gcs.mock.mocap.arena import ArenaOptions  # pymavlink only for the mock
            from gcs.mock.process import MockProcess

            arena = None
            if mocap is not None and mocap.source is None:
                s = mocap.settings
                arena = ArenaOptions(
                    room=s.frame or "optitrack", yaw_offset_deg=s.yaw_offset_deg, seed=seed
                )
            mock = stack.enter_context(MockProcess(config_path=mock_config, seed=seed, arena=arena))
            url, mocap_url = mock.url, mock.mocap_url or None
            say(f"mock drone at {mock.url}")
            if mocap_url:
                say(f"mock motion capture at {mocap_url}")
        link = None
        if mocap is not None:
            link = stack.enter_context(mocap.link(mocap_url))
            say(f"mocap: {link.source.url()} streaming")
        if url is None:
            raise ValueError("no vehicle: give a connection URL or use the mock drone")
        yield url, link


def to_record(
    run: RunDir, recording: TrialRecording, ref_ned_m: np.ndarray | None = None
) -> TrialRecord:
    """A flight recording as a row-per-sample trial record of the run.

    Parameters
    ----------
    run : RunDir
        The run (for its reference).
    recording : TrialRecording
        What the flight layer sent and measured.
    ref_ned_m : ndarray, shape (N+1, 3), optional
        Reference rows of the record; default the run's reference (an identification
        experiment passes its own excitation).

    Returns
    -------
    TrialRecord
    """
    if ref_ned_m is None:
        ref_ned_m = run.reference().pos_ned_m
    sp = recording.setpoints_ned_m
    return TrialRecord(
        t_s=np.arange(run.n_samples + 1) * run.t_ilc_s,
        ref_ned_m=ref_ned_m,
        sp_ned_m=np.vstack([sp, sp[-1]]),
        pos_ned_m=recording.pos_ned_m,
        vel_ned_m_s=recording.vel_ned_m_s,
        sp_sent_s=np.append(recording.sent_s, np.nan),
        interpolated=recording.interpolated,
        mocap_ned_m=None if recording.mocap is None else recording.mocap.pos_ned_m,
    )


def trial_extra(recording: TrialRecording, session: int | None) -> dict[str, Any]:
    """Timing of a flown trial for its sidecar: send delays, vehicle clock, flight session.

    Parameters
    ----------
    recording : TrialRecording
        What the flight layer sent and measured.
    session : int or None
        Number of the session record it was flown in.

    Returns
    -------
    dict
        ``max_send_late_s``, ``max_sent_offset_s`` (largest distance of a setpoint's first send
        from its sample boundary, on the vehicle's clock: how well the stream kept to the
        vehicle's grid), ``vehicle_time_rate`` (vehicle-time / wall-time rate of the trial,
        None if unknown), ``clock_latency_p50_s`` (median receipt delay above the
        clock fit), ``t0_vehicle_s`` (the trial's k = 0 on the vehicle's clock: time since
        boot for PX4, to find the trial in its own log), ``session``; with motion capture
        also ``mocap_lag_s`` (how far the estimate lags the mocap), ``mocap_samples``,
        ``mocap_tracked_share`` and ``mocap_max_gap_s`` (the longest interval between tracked
        samples, interpolated across on the grid up to the watch's limits).
    """
    clock = recording.clock
    offset = np.abs(recording.sent_s - recording.t_s[:-1])
    mocap = {}
    if recording.mocap is not None:
        series = recording.mocap.series
        mocap = {
            "mocap_lag_s": recording.mocap.lag_s,
            "mocap_samples": len(series),
            "mocap_tracked_share": float(np.mean(series.tracked)) if len(series) else None,
            "mocap_max_gap_s": _largest_gap(series.t_receipt_s[series.tracked]),
        }
    return mocap | {
        "max_send_late_s": recording.max_send_late_s,
        "max_sent_offset_s": float(np.nanmax(offset)) if np.any(np.isfinite(offset)) else None,
        "t0_vehicle_s": recording.t0_vehicle_s,
        "vehicle_time_rate": None if clock is None else clock.rate,
        "clock_latency_p50_s": None if clock is None else clock.latency_p50_s,
        "session": session,
    }


def _largest_gap(t_s: np.ndarray) -> float | None:
    return float(np.max(np.diff(t_s))) if t_s.size >= 2 else None


def session_record(session: FlightSession) -> dict[str, Any]:
    """A flight session as the JSON object of ``session-SSS.json``.

    Parameters
    ----------
    session : FlightSession
        What the campaign found out about the vehicle.

    Returns
    -------
    dict
        ``url``, ``first_trial``, ``navigation`` (source name, line, parameters),
        ``tolerance_m``, ``speed_tolerance_m_s``, ``hovers`` (statistics, verdict and
        clock rate of each judged hover), ``fence`` (arena, margin and limits watched),
        ``geofence`` (the vehicle's own fence as set up before take-off), ``mocap`` (source,
        mapping, forwarding, EKF2 findings, pre-flight checks; None without), ``abort_reason``
        (why the session stopped early, or None), plus ``written_utc``.
    """
    from datetime import UTC, datetime

    nav = session.navigation
    return {
        "url": session.url,
        "first_trial": session.first_trial,
        "navigation": {"source": nav.name, "text": nav.text, "params": nav.params},
        "fence": None if session.fence is None else asdict(session.fence),
        "geofence": None if session.geofence is None else asdict(session.geofence),
        "abort_reason": session.abort_reason,
        "mocap": None if session.mocap is None else _mocap_record(session.mocap),
        "tolerance_m": session.tolerance_m,
        "speed_tolerance_m_s": session.speed_tolerance_m_s,
        "hovers": [asdict(h) for h in session.hovers],
        "written_utc": datetime.now(UTC).isoformat(timespec="seconds"),
    }


def _mocap_record(report: MocapReport) -> dict[str, Any]:
    """The session's motion capture as the JSON object of its ``mocap`` field: EKF2's
    parameters and findings, the agreement before arming, the frame checks (when flown), then
    the link's description (once the session ended)."""
    out: dict[str, Any] = {"ekf2": report.ekf2.params, "findings": list(report.ekf2.findings)}
    arming = report.arming
    out |= {"agreement_m": arming.agreement_m, "origin": list(arming.origin),
            "origin_set": arming.origin_set}  # fmt: skip
    if report.moves is not None:
        out["moves"] = [check.as_record() for check in report.moves]
    return out | (report.link or {})


def flyable_setpoints(run: RunDir, j: int) -> np.ndarray:
    """Trial j's setpoints from the run directory, refused if any breaks a limit, on its grid.

    Every sequence must lie inside the profile's arena. A learned sequence of a learning run
    (j >= 1) must also keep the learning's limits (step per sample, deviation from the
    reference aligned by the models it was learned with; :func:`gcs.app.learn.check_learned`):
    the file on disk is what is flown, and it is checked as such, whoever wrote it. A repeat
    of trial 0 must have trial 0's setpoints exactly; a trial that flies an earlier trial's
    setpoints again (:meth:`gcs.io.rundir.RunDir.again_of`) is checked as that trial.

    Parameters
    ----------
    run : RunDir
        The run.
    j : int
        Trial index.

    Returns
    -------
    ndarray, shape (N, 3)
        Absolute local NED [m].
    """
    sp = run.read_setpoints(j)
    profile = run.profile()
    arena = profile.arena
    outside = points_outside(sp, arena)
    if outside.size:
        k = outside[0]
        raise TrajectoryError(
            f"{run.setpoints_path(j).name}: setpoint k = {k} {np.round(sp[k], 3).tolist()} is "
            f"outside the arena {arena}; not flown"
        )
    if run.kind != "learning" or j == 0:
        return sp
    again = run.again_of(j)
    if again is not None:  # trial k's setpoints byte for byte: kept the limits k was flown with
        flyable_setpoints(run, again)
        return sp
    repeats = profile.learning.repeats
    if j <= repeats:
        if not np.array_equal(sp, run.read_setpoints(0)):
            raise TrajectoryError(
                f"{run.setpoints_path(j)}: trial {j} repeats trial 0, but its setpoints "
                f"differ from {run.setpoints_path(0).name}; not flown"
            )
        return sp
    models = models_in_use(run, profile, j)[0] if profile.learning.adaptive else None
    try:
        check_learned(sp, profile, run.reference(), models)
    except TrajectoryError as exc:
        raise TrajectoryError(f"{run.setpoints_path(j)}: {exc}; not flown") from None
    return sp


class SessionRecorder:
    """What the run-directory trial sources share: the record of their flight session.

    Subclasses provide ``run`` (:class:`RunDir`), ``session`` (int or None, the record's
    number once written) and may set ``mock_seed`` (the mock drone's seed, or None).
    """

    run: RunDir
    session: int | None
    mock_seed: int | None = None

    def record_session(self, session: FlightSession) -> None:
        """Write (or update) this flight session's record in the run directory.

        Parameters
        ----------
        session : FlightSession
            Navigation source, hover measurements, settle tolerances.
        """
        record = session_record(session) | {"mock_seed": self.mock_seed}
        self.session = self.run.write_session(self.session, record)


def raw_mocap(recording: TrialRecording) -> Any:
    """A recording's raw mocap samples (None without mocap).

    Parameters
    ----------
    recording : TrialRecording
        What the flight layer recorded.

    Returns
    -------
    MocapSeries or None
    """
    return None if recording.mocap is None else recording.mocap.series
