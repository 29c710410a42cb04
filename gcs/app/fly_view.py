"""The terminal side of ``gcs fly``: run set-up, the mock drone, and a rich live display."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from gcs.app.fly import MocapPlan, check_mock_config, check_url, fly_run, plan_fly, start_run
from gcs.app.report import metrics_table
from gcs.core.metrics import IterationMetrics
from gcs.errors import GcsError
from gcs.flight.campaign import Status, TrialFinished, TrialProgress, TrialStarted
from gcs.flight.mocap.link import MocapLink
from gcs.io.runlog import RunDir

__all__ = ["fly_with_display", "live_progress", "vehicle_url"]


@contextlib.contextmanager
def vehicle_url(
    connect: str | None,
    use_mock: bool,
    mock_config: Path | None,
    seed: int,
    console: Console,
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
    console : Console
        Where to print the mock's URL.
    mocap : MocapPlan or None
        The flight's motion capture.

    Yields
    ------
    tuple of (str, MocapLink or None)
    """
    with contextlib.ExitStack() as stack:
        url, mocap_url = connect, None
        if use_mock:
            from gcs.mock.mocap.arena import ArenaOptions
            from gcs.mock.process import MockProcess

            arena = None
            if mocap is not None and mocap.source is None:
                s = mocap.settings
                arena = ArenaOptions(
                    room=s.frame or "optitrack", yaw_offset_deg=s.yaw_offset_deg, seed=seed
                )
            mock = stack.enter_context(MockProcess(config_path=mock_config, seed=seed, arena=arena))
            url, mocap_url = mock.url, mock.mocap_url or None
            console.print(f"[dim]mock drone at {mock.url}[/]")
            if mocap_url:
                console.print(f"[dim]mock motion capture at {mocap_url}[/]")
        link = None
        if mocap is not None:
            link = stack.enter_context(mocap.link(mocap_url))
            console.print(f"[dim]mocap: {link.source.url()} streaming[/]")
        assert url is not None
        yield url, link


def live_progress(console: Console) -> tuple[Progress, Callable[[object], None]]:
    """A rich progress bar for a campaign and the event callback that drives it.

    Status lines are printed dimmed (warnings in yellow), each trial start is printed with its
    length, the bar follows the setpoint index with the live error, each flown trial is
    printed with its vehicle-time rate, and an incomplete trial in red. Use the progress as a
    context manager around the flight.

    Parameters
    ----------
    console : Console
        Terminal output.

    Returns
    -------
    progress : Progress
        The (transient) progress display.
    on_event : callable
        Campaign event callback for :func:`gcs.flight.campaign.fly_campaign`.
    """
    progress = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.fields[err]}"),
        TimeRemainingColumn(),
        console=console,
        transient=True,
    )
    task = progress.add_task("waiting", total=1, err="")

    def on_event(event: object) -> None:
        if isinstance(event, Status) and event.warning:
            progress.console.print(f"[bold yellow]warning:[/] {escape(event.text)}")
        elif isinstance(event, Status):
            progress.console.print(f"[dim]{escape(event.text)}[/]")
        elif isinstance(event, TrialStarted):
            progress.console.print(
                f"trial {event.trial} started: {event.n_setpoints} setpoints, "
                f"{event.duration_s:.1f} s ({event.number}/{event.iterations})"
            )
            progress.update(
                task,
                description=f"trial {event.trial} ({event.number}/{event.iterations})",
                total=event.n_setpoints,
                completed=0,
            )
        elif isinstance(event, TrialProgress):
            progress.update(task, completed=event.k, err=f"error {event.err_m:.3f} m")
        elif isinstance(event, TrialFinished) and not event.recording.complete:
            progress.console.print(f"[red]trial {event.trial} incomplete[/]")
        elif isinstance(event, TrialFinished):
            clock = event.recording.clock
            rate = "unknown" if clock is None else f"{clock.rate:.3f}x wall time"
            progress.console.print(f"trial {event.trial} flown: vehicle clock {rate}")

    return progress, on_event


def fly_with_display(
    *,
    console: Console,
    iterations: int,
    connect: str | None,
    mock_config: Path | None,
    seed: int,
    profile_path: Path | None,
    trajectory_path: Path | None,
    algorithm: str | None,
    run_path: Path | None,
    resume: Path | None,
    logs: Path,
    use_mock: bool,
    check_only: bool = False,
    mocap: str | None = None,
) -> RunDir | None:
    """Validate everything, then set up (or resume) a run and fly it with a live display.

    Nothing is created, moved or flown before every input has been checked
    (:func:`gcs.app.fly.plan_fly`, the connection URL, the mock's settings).

    Parameters
    ----------
    console : Console
        Terminal output.
    iterations : int
        Trials to fly.
    connect : str or None
        URL of a real vehicle.
    mock_config : Path or None
        Mock settings for ``use_mock``.
    seed : int
        Mock seed.
    profile_path : Path or None
        Profile of a new run; with ``resume``, must be the run's if given.
    trajectory_path : Path or None
        Trajectory of a new run; with ``resume``, must be the run's if given.
    algorithm : str or None
        Learning algorithm (default: the profile's, or the resumed run's).
    run_path : Path or None
        Exact path of a new run.
    resume : Path or None
        Run to continue.
    logs : Path
        Parent of new runs.
    use_mock : bool
        Fly the mock drone.
    check_only : bool
        Validate and say what would be flown, then stop: nothing is created or connected.
    mocap : str or None
        ``--mocap``: a URL, ``mock`` (the mock's arena), or None (the profile's
        ``mocap.url``, if any).

    Returns
    -------
    RunDir or None
        The run flown (None with ``check_only``).
    """
    plan = plan_fly(
        profile_path, trajectory_path, algorithm, run_path, resume, logs, mocap, use_mock
    )
    if use_mock and mock_config is None and plan.mocap is not None and plan.mocap.source is None:
        from gcs.io.paths import resolve_named

        mock_config = resolve_named("mock-mocap", "profile", "--mock-config")  # vision only
    if use_mock:
        check_mock_config(mock_config)
    else:
        assert connect is not None
        check_url(connect)
    if check_only:
        where = plan.run.path if plan.run is not None else (plan.run_path or plan.logs)
        console.print(
            f"checked: profile '{plan.profile.name}', trajectory '{plan.trajectory.name}' "
            f"({plan.reference.n_samples} samples of {plan.profile.t_ilc_s:g} s), "
            f"{plan.algorithm}, trials {plan.first_trial}..{plan.first_trial + iterations - 1} "
            f"in {where}; nothing flown"
        )
        if plan.mocap is not None:
            console.print(f"checked: {plan.mocap.describe()}")
        return None
    run = start_run(plan)
    settings = plan.settings
    console.print(f"run [bold]{run.path}[/] ({run.algorithm}), next trial {run.next_trial()}")

    progress, on_event = live_progress(console)

    def on_row(rows: list[IterationMetrics]) -> None:
        r = rows[-1]
        delta = ""
        if len(rows) > 1:  # signed, unlike Table IV's |change|: a worse trial shows as +
            change = 100.0 * (r.epos_m - rows[-2].epos_m) / rows[-2].epos_m
            delta = f", {change:+.1f} % vs previous"
        progress.console.print(
            f"trial {r.iteration}: e_pos {r.epos_m:.4f} m ({r.epos_pct:5.1f} % of j=0{delta}), "
            f"max {r.max_err_m:.3f} m"
        )

    try:
        with (
            vehicle_url(connect, use_mock, mock_config, seed, console, plan.mocap) as (url, link),
            progress,
        ):
            fly_run(url, run, iterations, settings, on_event, on_row, link)
    except KeyboardInterrupt:
        console.print(
            f"interrupted; completed trials are in {run.path}. "
            f"Continue with: gcs fly --resume {run.path}"
        )
        raise
    except GcsError as exc:
        console.print(f"[dim]completed trials are in {run.path}[/]")
        raise exc
    from gcs.app.report import run_metrics, trial_clock_rates

    title = f"{run.path.name} ({run.algorithm})"
    console.print(metrics_table(run_metrics(run), title, trial_clock_rates(run)))
    return run
