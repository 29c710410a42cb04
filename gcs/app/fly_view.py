"""The terminal side of ``gcs fly``: run set-up, the mock drone, and a rich live display."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from gcs.app.fly import (
    MocapPlan,
    check_mock_config,
    check_url,
    converged_reason,
    fly_run,
    newest_record,
    plan_fly,
    start_run,
)
from gcs.app.learn import LearnOutcome, iteration_of, repeat_of
from gcs.app.report import decision_lines, metrics_table
from gcs.core.metrics import IterationMetrics
from gcs.errors import GcsError
from gcs.flight.campaign import Status, TrialFinished, TrialProgress, TrialStarted
from gcs.flight.mocap.link import MocapLink
from gcs.io.runlog import RunDir

__all__ = ["fly_with_display", "live_progress", "vehicle_url", "learning_lines"]


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


def learning_lines(outcome: LearnOutcome) -> list[str]:
    """What a learning step decided, for the live table (rich markup, escaped).

    The newest trial's verdict against the floor (e.g. "trial 6: 1.08x the floor, at the
    floor"; "converged" in green), a safeguard's fall back, a refreshed model and how far it
    moved, and what comes next; a repeat of trial 0 says so.

    Parameters
    ----------
    outcome : LearnOutcome
        From :func:`gcs.app.learn.learn_run`.

    Returns
    -------
    list of str
    """
    if outcome.repeat_of is not None:
        return [
            f"  [cyan]trial {outcome.next_trial} repeats trial {outcome.repeat_of}[/] (identical "
            "setpoints, j = 0): it measures the floor"
        ]
    record = outcome.record
    if record is None:
        return []
    lines = []
    decision = record["decision"]
    floor, verdicts = decision["floor"], decision["verdicts"]
    if floor is not None and verdicts:
        v = verdicts[-1]
        word = (
            "[bold green]converged[/]" if v["converged"]
            else "[green]at the floor[/]" if v["at_floor"] else "above the floor"
        )  # fmt: skip
        lines.append(
            f"  trial {v['trial']}: {v['ratio']:.2f}x the floor ({1e3 * floor['epos_m']:.1f} mm "
            f"± {1e3 * floor['scatter_m']:.1f}), z {v['z']:.1f}: {word}"
        )
    for line in decision_lines(record):  # the report has them all; live, what changed
        if line.startswith(("model kept", "estimate")):
            continue
        style = {"safeguard": "yellow", "model refreshed": "cyan"}.get(line.split(":")[0], "dim")
        lines.append(f"  [{style}]{escape(line)}[/]")
    return lines


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
    until_converged: bool = False,
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
    until_converged : bool
        Land once learning has converged (``iterations`` stays the cap); a resumed run that
        has converged already is not flown.
    mocap : str or None
        ``--mocap``: a URL, ``mock`` (the mock's arena), or None (the profile's
        ``mocap.url``, if any).

    Returns
    -------
    RunDir or None
        The run flown (None with ``check_only``).
    """
    plan = plan_fly(
        profile_path, trajectory_path, algorithm, run_path, resume, logs, until_converged,
        mocap, use_mock,
    )  # fmt: skip
    if use_mock and mock_config is None and plan.mocap is not None and plan.mocap.source is None:
        from gcs.io.paths import resolve_named

        mock_config = resolve_named("mock-mocap", "profile", "--mock-config")  # vision only
    if use_mock:
        check_mock_config(mock_config)
    else:
        assert connect is not None
        check_url(connect)
    if until_converged and plan.run is not None:
        reason = converged_reason(newest_record(plan.run))
        if reason is not None:
            console.print(f"{plan.run.path}: {reason}; nothing flown")
            return plan.run
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

    ln = run.profile().learning
    repeats = ln.repeats if ln.history else 0

    def on_row(rows: list[IterationMetrics]) -> None:
        r = rows[-1]
        delta = ""
        if len(rows) > 1:  # signed, unlike Table IV's |change|: a worse trial shows as +
            change = 100.0 * (r.epos_m - rows[-2].epos_m) / rows[-2].epos_m
            delta = f", {change:+.1f} % vs previous"
        which, base = f"trial {r.iteration}", "j=0"
        if ln.history:  # the trial number and the paper's iteration j differ after a repeat
            again = ", a repeat" if repeat_of(r.iteration, repeats) is not None else ""
            which += f" (j = {iteration_of(r.iteration, repeats)}{again})"
            base = "trial 0"
        progress.console.print(
            f"{which}: e_pos {r.epos_m:.4f} m ({r.epos_pct:5.1f} % of {base}{delta}), "
            f"max {r.max_err_m:.3f} m"
        )

    def on_learn(outcome: LearnOutcome) -> None:
        for line in learning_lines(outcome):
            progress.console.print(line, highlight=False)

    try:
        with (
            vehicle_url(connect, use_mock, mock_config, seed, console, plan.mocap) as (url, link),
            progress,
        ):
            fly_run(
                url,
                run,
                iterations,
                settings,
                on_event,
                on_row,
                on_learn,
                until_converged,
                mocap=link,
            )
    except KeyboardInterrupt:
        console.print(
            f"interrupted; completed trials are in {run.path}. "
            f"Continue with: gcs fly --resume {run.path}"
        )
        raise
    except GcsError as exc:
        console.print(f"[dim]completed trials are in {run.path}[/]")
        raise exc
    if until_converged and converged_reason(newest_record(run)) is None:
        console.print(
            f"--until-converged: learning has not converged within --iter {iterations}; "
            f"continue with: gcs fly --resume {run.path} --iter N --until-converged"
        )
    from gcs.app.report import run_learning, run_metrics, trial_clock_rates

    title = f"{run.path.name} ({run.algorithm})"
    learning = run_learning(run)
    console.print(metrics_table(run_metrics(run), title, trial_clock_rates(run), learning))
    return run
