"""The terminal side of ``gcs fly``: run set-up, the mock drone, and a rich live display."""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import replace
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from gcs.app.fly import (
    FlyPlan,
    FlyRequest,
    converged_reason,
    fly_run,
    newest_record,
    plan_fly,
    record_drift,
    start_run,
)
from gcs.app.learn import LearnOutcome
from gcs.app.progress import progress_lines
from gcs.app.report import drift_sentence
from gcs.app.report_text import decision_lines, metrics_table
from gcs.app.session import check_mock_config, check_url, vehicle_url
from gcs.core.metrics import IterationMetrics
from gcs.core.trials import iteration_of, repeat_of
from gcs.errors import GcsError
from gcs.flight.campaign import Status, TrialFinished, TrialProgress, TrialStarted
from gcs.io.rundir import RunDir

__all__ = [
    "fly_with_display",
    "check_vehicle",
    "live_progress",
    "learning_lines",
    "sized_up_lines",
    "SegmentError",
    "SEGMENT_S",
    "mock_session_seed",
    "resume_command",
    "say",
]


def mock_session_seed(seed: int, session: int, used: Collection[int] = ()) -> int:
    """The mock drone's seed for flight session ``session`` of a run, never one flown before.

    ``--seed`` itself when no earlier session of the run flew it (a new run, or a resume given
    a seed of its own); else a seed drawn from ``(seed, session)`` by NumPy's ``SeedSequence``.
    A resumed run therefore never replays an earlier session's gusts and noise: a repeat of
    trial 0 flown after ``--resume`` with the same ``--seed`` would otherwise fly trial 0's
    gusts again and measure a floor of the replay (millimetres), not of the vehicle. The seed
    flown is kept in the session's record (``mock_seed``).

    Parameters
    ----------
    seed : int
        ``--seed``.
    session : int
        The session's number (1 for the first).
    used : collection of int
        The mock seeds the run's earlier sessions flew.

    Returns
    -------
    int
        ``seed``, or a seed in [0, 2**31) that is not in ``used``.
    """
    if seed not in used:
        return seed
    import numpy as np

    attempt = 0
    while True:
        state = np.random.SeedSequence([seed, session, attempt]).generate_state(1)[0]
        derived = int(state) % 2**31
        if derived not in used:
            return derived
        attempt += 1


def resume_command(
    run_path: Path, request: FlyRequest, iterations: int, again: int | None = None
) -> str:
    """The ``gcs fly --resume`` command that continues ``run_path`` with the same vehicle.

    The vehicle is named as the session named it (``--mock`` with its settings and seed, or
    ``--connect URL``), and motion capture when ``--mocap`` was given: a resumed run takes its
    profile and trajectory from its record, but never its vehicle (which is chosen anew by
    whoever resumes: a port, PX4 SITL or the real vehicle).

    Parameters
    ----------
    run_path : Path
        The run to continue.
    request : FlyRequest
        The session's options (``--mock-config`` as given: None for the default; ``--seed``
        only printed when it is not the default, 0; ``--until-converged`` kept).
    iterations : int
        ``--iter`` of the command.
    again : int or None
        ``--again``: the trial whose setpoints the next trial flies again.

    Returns
    -------
    str
        One shell command line, quoted where needed.
    """
    import shlex

    from gcs.io.paths import packaged_dir

    args = ["gcs", "fly", "--resume", str(run_path)]
    if request.use_mock:
        args.append("--mock")
        if request.mock_config is not None:
            config = request.mock_config
            packaged = config.parent.resolve() == packaged_dir("profile").resolve()
            args += ["--mock-config", config.stem if packaged else str(config)]
        if request.seed != 0:
            args += ["--seed", str(request.seed)]
    elif request.connect is not None:
        args += ["--connect", request.connect]
    if request.mocap is not None:
        args += ["--mocap", request.mocap]
    args += ["--iter", str(iterations)]
    if request.until_converged:
        args.append("--until-converged")
    if again is not None:
        args += ["--again", str(again)]
    return shlex.join(args)


#: Length of the trial segments the live error lines summarise [s of trial time].
SEGMENT_S = 5.0


class SegmentError:
    """The live error of a trial, summarised per segment of ``segment_s`` of trial time.

    Fed every :class:`TrialProgress` of a trial (about 10 per second), it returns a line
    each time a segment is complete: the mean and largest horizontal distance between the
    measured position and the setpoint in force over the segment. That distance includes
    the closed loop's lag behind its setpoint, and on a learned trial the setpoints lead the
    reference on purpose, so it is a live health indicator, not e_pos (which the trial's row
    gives at its end).

    Parameters
    ----------
    trial : int
        The trial.
    n_setpoints : int
        Its setpoints N.
    duration_s : float
        Its length [s].
    segment_s : float
        Segment length [s].
    """

    def __init__(
        self, trial: int, n_setpoints: int, duration_s: float, segment_s: float = SEGMENT_S
    ) -> None:
        self.trial, self.n = trial, n_setpoints
        self.dt_s = duration_s / max(n_setpoints, 1)
        self.every = max(1, round(segment_s / self.dt_s))
        self.start_k, self.errors = 0, []

    def add(self, k: int, err_m: float) -> str | None:
        """Take one progress report; the segment's line when it is complete, else None.

        Parameters
        ----------
        k : int
            Setpoint index (N once the final hover has begun).
        err_m : float
            Live distance to the setpoint in force [m].

        Returns
        -------
        str or None
        """
        if k < self.start_k or self.start_k >= self.n:  # the final hover reports k = N again
            return None
        self.errors.append(float(err_m))
        if k < min(self.start_k + self.every, self.n):
            return None
        errors, t0, t1 = self.errors, self.start_k * self.dt_s, min(k, self.n) * self.dt_s
        self.start_k, self.errors = k, []
        return (
            f"trial {self.trial} {t0:.1f}-{t1:.1f} s: mean {sum(errors) / len(errors):.3f} m, "
            f"largest {max(errors):.3f} m from the setpoint in force (lag included)"
        )


def live_progress(console: Console) -> tuple[Progress, Callable[[object], None]]:
    """A rich progress bar for a campaign and the event callback that drives it.

    Status lines are printed dimmed (warnings in yellow), each trial start is printed with its
    length, the bar follows the setpoint index with the live error, each flown trial is
    printed with its vehicle-time rate, and an incomplete trial in red. Use the progress as a
    context manager around the flight. When the console is not a terminal (a pipe, a file, a
    batch job) the bar is invisible: each trial's progress is then a plain line now and then
    (:func:`gcs.app.progress.progress_lines`). On both, every :data:`SEGMENT_S` of a trial a
    line gives the live error of that segment (:class:`SegmentError`).

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
    plain: list[Callable[[int, int], None] | None] = [None]
    segment: list[SegmentError | None] = [None]

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
            segment[0] = SegmentError(event.trial, event.n_setpoints, event.duration_s)
            if not console.is_terminal:
                plain[0] = progress_lines(
                    lambda line: console.print(line, markup=False, highlight=False),
                    f"trial {event.trial}",
                    "setpoints",
                )
        elif isinstance(event, TrialProgress):
            progress.update(task, completed=event.k, err=f"error {event.err_m:.3f} m")
            if plain[0] is not None:
                plain[0](event.k, event.n)
            line = segment[0].add(event.k, event.err_m) if segment[0] is not None else None
            if line is not None:
                progress.console.print(f"[dim]{escape(line)}[/]", highlight=False)
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
    floor"; "converged" in green), a drift up from the floor once reached
    (:func:`gcs.core.floor.floor_drift`, with the trial whose setpoints were best there), a
    safeguard's fall back, a refreshed model and how far it moved, and what comes next; a
    repeat of trial 0 says so.

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
            f"± {1e3 * floor['scatter_m']:.1f}), {_scatters(v['z'])}: {word}"
        )
        drift = record_drift(record)
        if drift is not None:
            lines.append(f"  [yellow]{escape(drift_sentence(drift))}[/]")
    for line in decision_lines(record):  # the report has them all; live, what changed
        if line.startswith(("model kept", "estimate")):
            continue
        style = {"safeguard": "yellow", "model refreshed": "cyan"}.get(line.split(":")[0], "dim")
        lines.append(f"  [{style}]{escape(line)}[/]")
    return lines


def _scatters(z: float) -> str:
    """The z statistic in words: how many scatters of one trial above (below) the floor."""
    side = "above" if z >= 0 else "below"
    return f"{abs(z):.1f} scatters {side} it (z = (e_pos - floor) / scatter = {z:.1f})"


def check_vehicle(
    console: Console,
    plan: FlyPlan,
    connect: str | None,
    use_mock: bool,
    mock_config: Path | None,
    seed: int,
) -> None:
    """Read the vehicle's parameters and print the real-vehicle checklist's verdicts.

    Connects (or starts the mock drone), reads every parameter, sends nothing, and judges
    them for the flight's navigation: motion capture when the plan has one, else GPS
    (:mod:`gcs.flight.checklist`, docs/real-vehicle.md).

    Parameters
    ----------
    console : Console
        Where the checklist goes.
    plan : FlyPlan
        The checked flight.
    connect : str or None
        URL of a real vehicle.
    use_mock : bool
        Start the mock drone instead.
    mock_config : Path or None
        Mock settings.
    seed : int
        Mock seed.

    Raises
    ------
    VehicleError
        A parameter is refused (the line names it and the fix), or the vehicle is unreachable.
    """
    import asyncio

    from gcs.errors import VehicleError
    from gcs.flight.checklist import checklist_lines, judge, read_params, refusal

    navigation = "mocap" if plan.mocap is not None else "gps"
    with vehicle_url(connect, use_mock, mock_config, seed, say(console)) as (url, _):
        params = asyncio.run(read_params(url, plan.settings))
    verdicts = judge(params, navigation)
    console.print(f"checklist for {navigation} (docs/real-vehicle.md), vehicle at {url}:")
    colour = {"ok": "green", "warn": "yellow", "refuse": "bold red"}
    for v, line in zip(verdicts, checklist_lines(verdicts), strict=True):
        console.print(f"[{colour[v.level]}]{escape(line)}[/]", highlight=False)
    reason = refusal(verdicts)
    if reason is not None:
        raise VehicleError(reason)


def fly_with_display(console: Console, request: FlyRequest) -> RunDir | None:
    """Validate everything, then set up (or resume) a run and fly it with a live display.

    Nothing is created, moved or flown before every input has been checked
    (:func:`gcs.app.fly.plan_fly`, the connection URL, the mock's settings). With
    ``request.check_only`` it says what would be flown and stops; with ``until_converged`` a
    resumed run that has converged (or left the floor) already is not flown.

    Parameters
    ----------
    console : Console
        Terminal output.
    request : FlyRequest
        The command's options.

    Returns
    -------
    RunDir or None
        The run flown (None with ``check_only``).
    """
    plan = plan_fly(request)
    mock_config = request.mock_config
    given_mock_config = mock_config
    if (
        request.use_mock
        and mock_config is None
        and plan.mocap is not None
        and plan.mocap.source is None
    ):
        from gcs.io.paths import resolve_named

        mock_config = resolve_named("mock-mocap", "profile", "--mock-config")  # vision only
    if request.use_mock:
        check_mock_config(mock_config)
    else:
        assert request.connect is not None
        check_url(request.connect)
    if request.until_converged and plan.run is not None and request.again is None:
        record = newest_record(plan.run)
        drift = record_drift(record)
        reason = converged_reason(record) or (
            None
            if drift is None
            else f"{drift_sentence(drift)} (--again {drift.best_trial} flies them)"
        )
        if reason is not None:
            console.print(f"{plan.run.path}: {reason}; nothing flown", highlight=False)
            return plan.run
    if request.check_only:
        where = plan.run.path if plan.run is not None else (plan.run_path or plan.logs)
        console.print(
            f"checked: profile '{plan.profile.name}', trajectory '{plan.trajectory.name}' "
            f"({plan.reference.n_samples} samples of {plan.profile.t_ilc_s:g} s), "
            f"{plan.algorithm}, trials {plan.first_trial}.."
            f"{plan.first_trial + request.iterations - 1} "
            f"in {where}; nothing flown"
        )
        if plan.mocap is not None:
            console.print(f"checked: {plan.mocap.describe()}")
        for line in sized_up_lines(plan, request.iterations):
            console.print(escape(line), highlight=False)
        if not request.offline:
            check_vehicle(
                console, plan, request.connect, request.use_mock, mock_config, request.seed
            )
        return None
    run = start_run(plan)
    settings = plan.settings
    earlier = run.sessions()
    used = {s["mock_seed"] for s in earlier if isinstance(s.get("mock_seed"), int)}
    session_seed = mock_session_seed(request.seed, len(earlier) + 1, used)
    if request.use_mock and session_seed != request.seed:
        say(console)(
            f"mock seed {session_seed}: --seed {request.seed} was flown by an earlier session of "
            "this run, and a resumed run never replays its gusts"
        )

    def resume_hint(n: int, again: int | None = None) -> str:
        return resume_command(run.path, replace(request, mock_config=given_mock_config), n, again)

    console.print(f"run [bold]{run.path}[/] ({run.algorithm}), next trial {run.next_trial()}")

    progress, on_event = live_progress(console)

    ln = run.profile().learning
    repeats = ln.repeats
    from gcs.app.report import is_three_d

    three_d = is_three_d(run)

    def on_row(rows: list[IterationMetrics]) -> None:
        r = rows[-1]
        delta = ""
        if len(rows) > 1:  # signed, unlike Table IV's |change|: a worse trial shows as +
            change = 100.0 * (r.epos_m - rows[-2].epos_m) / rows[-2].epos_m
            delta = f", {change:+.1f} % vs previous"
        which, base = f"trial {r.iteration}", "j=0"
        if ln.adaptive is not None:  # trial number and the paper's j differ after a repeat
            repeat = ", a repeat" if repeat_of(r.iteration, repeats) is not None else ""
            which += f" (j = {iteration_of(r.iteration, repeats)}{repeat})"
            base = "trial 0"
        progress.console.print(
            f"{which}: e_pos {r.epos_m:.4f} m ({r.epos_pct:5.1f} % of {base}{delta}), "
            f"max {r.max_err_m:.3f} m"
        )
        if three_d and r.epos_3d_m is not None:
            progress.console.print(
                f"  3-D e_pos {r.epos_3d_m:.4f} m; RMS north {r.rms_north_m:.4f}, "
                f"east {r.rms_east_m:.4f}, down {r.rms_down_m:.4f} m"
            )

    def on_learn(outcome: LearnOutcome) -> None:
        for line in learning_lines(outcome):
            progress.console.print(line, highlight=False)
        drift = record_drift(outcome.record)
        if drift is not None:
            progress.console.print(
                f"  [yellow]to fly them again: {escape(resume_hint(1, drift.best_trial))}[/]",
                highlight=False,
                soft_wrap=True,
            )

    if (
        not request.use_mock
    ):  # said at once: a vehicle that is not there is silent until the timeout
        say(console)(
            f"waiting up to {settings.connect_timeout_s:g} s for a vehicle on {request.connect} "
            "(flight.connect_timeout_s)"
        )
    try:
        with (
            vehicle_url(
                request.connect,
                request.use_mock,
                mock_config,
                session_seed,
                say(console),
                plan.mocap,
            ) as (
                url,
                link,
            ),
            progress,
        ):
            fly_run(
                url,
                run,
                request.iterations,
                settings,
                on_event,
                on_row,
                on_learn,
                request.until_converged,
                mocap=link,
                mock_seed=session_seed if request.use_mock else None,
            )
    except KeyboardInterrupt:
        left = max(1, request.iterations - (run.next_trial() - plan.first_trial))
        console.print(
            f"interrupted; completed trials are in {run.path}. "
            f"Continue with: {escape(resume_hint(left))}",
            highlight=False,
            soft_wrap=True,
        )
        raise
    except GcsError as exc:
        left = max(1, request.iterations - (run.next_trial() - plan.first_trial))
        kept = f"completed trials are in {run.path}" if run.complete_trials() else (
            f"no trial was flown; the run is set up in {run.path}"
        )  # fmt: skip
        console.print(
            f"[dim]{kept}; once the cause is fixed, continue with: {escape(resume_hint(left))}[/]",
            highlight=False,
            soft_wrap=True,
        )
        raise exc
    newest = newest_record(run)
    drift = record_drift(newest)
    if request.until_converged and drift is not None:
        console.print(
            f"--until-converged: landed, learning left the floor; to fly trial "
            f"{drift.best_trial}'s setpoints again: {escape(resume_hint(1, drift.best_trial))}",
            highlight=False,
            soft_wrap=True,
        )
    elif request.until_converged and converged_reason(newest) is None:
        console.print(
            f"--until-converged: learning has not converged within --iter {request.iterations}; "
            f"continue with: {escape(resume_hint(request.iterations))}",
            highlight=False,
            soft_wrap=True,
        )
    from gcs.app.report import (
        is_three_d,
        run_facts,
        run_learning,
        run_metrics,
        run_verdict,
        trial_clock_rates,
    )
    from gcs.app.report_text import shows_step, table_legend

    title = run_facts(run).title()
    learning = run_learning(run)
    rates = trial_clock_rates(run)
    rows = run_metrics(run)
    three_d = is_three_d(run)
    console.print(metrics_table(rows, title, rates, learning, console.width, three_d))
    shown = shows_step(rows, rates, learning, console.width, three_d)
    for line in table_legend(learning, shown) + run_verdict(rows, learning).lines():
        console.print(escape(line), highlight=False)
    return run


def say(console: Console) -> Callable[[str], None]:
    """A printer of the flight session's set-up lines (dimmed), for :func:`vehicle_url`.

    Parameters
    ----------
    console : Console
        Terminal output.

    Returns
    -------
    callable
        Takes one line of text.
    """
    return lambda text: console.print(f"[dim]{escape(text)}[/]")


def sized_up_lines(plan: FlyPlan, iterations: int) -> list[str]:
    """What the flight asks of the vehicle, before it flies: the trial's duration, its peak
    speed and acceleration against the profile's limits, the box it sweeps and its closest
    distance to the arena's walls.

    Parameters
    ----------
    plan : FlyPlan
        The checked flight.
    iterations : int
        Trials to fly.

    Returns
    -------
    list of str
    """
    import numpy as np

    ref, prof = plan.reference, plan.profile
    pos, vel, acc = ref.pos_ned_m, ref.vel_ned_m_s, ref.acc_ned_m_s2
    duration = float(ref.t_s[-1] - ref.t_s[0])
    speed_h = float(np.max(np.hypot(vel[:, 0], vel[:, 1])))
    accel_h = float(np.max(np.hypot(acc[:, 0], acc[:, 1])))
    speed_v, accel_v = float(np.max(np.abs(vel[:, 2]))), float(np.max(np.abs(acc[:, 2])))
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    bounds = np.asarray(prof.arena.bounds(), dtype=float)  # (3, 2): low, high per axis
    gaps = np.concatenate([pos - bounds[:, 0], bounds[:, 1] - pos], axis=1)
    wall = ("the north minimum", "the east minimum", "the ceiling", "the north maximum",
            "the east maximum", "the floor")  # fmt: skip
    k, w = np.unravel_index(int(np.argmin(gaps)), gaps.shape)
    most = prof.learning.max_deviation_m
    deviation = "learned setpoints stay inside the arena" + (
        "" if most is None else f", at most {most:g} m from the reference"
    )
    return [
        f"sized up: each trial flies {duration:.1f} s ({iterations} trials: "
        f"{iterations * duration / 60:.1f} min of trajectory, plus take-off, hover and landing)",
        f"sized up: peak speed {speed_h:.2f} m/s of {prof.max_speed_m_s:g} "
        f"({100 * speed_h / prof.max_speed_m_s:.0f} %), acceleration {accel_h:.2f} m/s² of "
        f"{prof.max_accel_m_s2:g} ({100 * accel_h / prof.max_accel_m_s2:.0f} %); vertical "
        f"{speed_v:.2f} m/s of {prof.max_vertical_speed_m_s:g}, {accel_v:.2f} m/s² of "
        f"{prof.max_vertical_accel_m_s2:g}",
        f"sized up: the reference sweeps north {lo[0]:.2f}..{hi[0]:.2f}, east "
        f"{lo[1]:.2f}..{hi[1]:.2f}, down {lo[2]:.2f}..{hi[2]:.2f} m; closest to the arena's "
        f"walls {gaps[k, w]:.2f} m ({wall[w]}, at {ref.t_s[k]:.1f} s); {deviation}",
    ]
