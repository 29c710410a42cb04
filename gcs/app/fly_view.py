"""The terminal side of ``gcs fly``: set-up lines, a rich live display, the run's table.

It only shows: :func:`gcs.app.fly.fly` checks and sequences the flight and tells a
:class:`FlyDisplay` what happened.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from gcs.app.fly import FlyPlan, record_drift
from gcs.app.learn import LearnOutcome
from gcs.app.progress import progress_lines
from gcs.app.report import drift_sentence
from gcs.app.report_text import decision_lines, metrics_table
from gcs.core.metrics import IterationMetrics
from gcs.core.trials import iteration_of, repeat_of
from gcs.flight.campaign import Status, TrialFinished, TrialProgress, TrialStarted
from gcs.io.rundir import RunDir

__all__ = [
    "FlyDisplay",
    "live_progress",
    "learning_lines",
    "sized_up_lines",
    "SegmentError",
    "SEGMENT_S",
    "say",
]


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
    (:func:`gcs.core.floor.floor_drift`, with the trial whose setpoints were best there), how far
    the newest trial flew from what the step before it predicted (against what noise alone
    gives), a safeguard's fall back, a refreshed model and how far it moved, and what comes next; a
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
        pr = outcome.prediction
        if pr is not None and pr.noise_ratio is not None:
            lines.append(
                f"  trial {outcome.trial}: {1e3 * pr.miss_m:.1f} mm from what the step before it "
                f"predicted, {pr.miss_m / floor['epos_m']:.2f}x the floor (noise alone: about "
                f"{pr.noise_ratio:.2f}x)"
            )
    for line in decision_lines(record):  # the report has them all; live, what changed
        if line.startswith(("model kept", "estimate")):
            continue
        styles = {"safeguard": "yellow", "model refreshed": "cyan", "step cut": "cyan"}
        style = styles.get(line.split(":")[0], "dim")
        lines.append(f"  [{style}]{escape(line)}[/]")
    return lines


def _scatters(z: float) -> str:
    """The z statistic in words: how many scatters of one trial above (below) the floor."""
    side = "above" if z >= 0 else "below"
    return f"{abs(z):.1f} scatters {side} it (z = (e_pos - floor) / scatter = {z:.1f})"


class FlyDisplay:
    """``gcs fly`` on the terminal (:class:`gcs.app.fly.FlyView`): set-up lines dimmed, the live
    progress and rows, learning decisions, and the run's table at the end.

    Parameters
    ----------
    console : Console
        Terminal output.
    """

    def __init__(self, console: Console) -> None:
        self.console = console

    def say(self, text: str) -> None:
        """One set-up line, dimmed (:func:`say`).

        Parameters
        ----------
        text : str
            Plain text.
        """
        say(self.console)(text)

    def nothing_flown(self, run: RunDir, reason: str) -> None:
        """Why a resumed run is not flown.

        Parameters
        ----------
        run : RunDir
            The run.
        reason : str
            Learning converged, or left the floor.
        """
        self.console.print(f"{run.path}: {reason}; nothing flown", highlight=False)

    def checked(self, plan: FlyPlan, iterations: int) -> None:
        """What would be flown, and what it asks of the vehicle (:func:`sized_up_lines`).

        Parameters
        ----------
        plan : FlyPlan
            The checked flight.
        iterations : int
            Trials to fly.
        """
        where = plan.run.path if plan.run is not None else (plan.run_path or plan.logs)
        self.console.print(
            f"checked: profile '{plan.profile.name}', trajectory '{plan.trajectory.name}' "
            f"({plan.reference.n_samples} samples of {plan.profile.t_ilc_s:g} s), "
            f"{plan.algorithm}, trials {plan.first_trial}..{plan.first_trial + iterations - 1} "
            f"in {where}; nothing flown"
        )
        if plan.mocap is not None:
            self.console.print(f"checked: {plan.mocap.describe()}")
        for line in sized_up_lines(plan, iterations):
            self.console.print(escape(line), highlight=False)

    def checklist(self, navigation: str, url: str, verdicts: list[Any]) -> None:
        """The real-vehicle checklist's verdicts, coloured by level.

        Parameters
        ----------
        navigation : str
            ``"gps"`` or ``"mocap"``.
        url : str
            The vehicle's URL.
        verdicts : list of Verdict
            From :func:`gcs.flight.checklist.judge`.
        """
        from gcs.flight.checklist import checklist_lines

        self.console.print(f"checklist for {navigation} (docs/real-vehicle.md), vehicle at {url}:")
        colour = {"ok": "green", "warn": "yellow", "refuse": "bold red"}
        for v, line in zip(verdicts, checklist_lines(verdicts), strict=True):
            self.console.print(f"[{colour[v.level]}]{escape(line)}[/]", highlight=False)

    def started(self, run: RunDir) -> None:
        """The run about to be flown, and its next trial.

        Parameters
        ----------
        run : RunDir
            The run.
        """
        self.console.print(
            f"run [bold]{run.path}[/] ({run.algorithm}), next trial {run.next_trial()}"
        )

    def live(
        self, run: RunDir
    ) -> tuple[Progress, Callable[[object], None], Callable[[list[IterationMetrics]], None]]:
        """The live progress (:func:`live_progress`) and the printer of each new table row.

        Parameters
        ----------
        run : RunDir
            The run being flown.

        Returns
        -------
        progress : Progress
            The display, a context manager around the flight.
        on_event : callable
            Campaign event callback.
        on_row : callable
            Takes the table's rows after each complete trial; prints the newest.
        """
        progress, on_event = live_progress(self.console)
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

        return progress, on_event, on_row

    def learned(self, outcome: LearnOutcome, again: str | None) -> None:
        """What a learning step decided (:func:`learning_lines`), and how to fly the best
        setpoints again once learning left the floor.

        Parameters
        ----------
        outcome : LearnOutcome
            From :func:`gcs.app.learn.learn_run`.
        again : str or None
            The command that flies them again.
        """
        for line in learning_lines(outcome):
            self.console.print(line, highlight=False)
        if again is not None:
            self.console.print(
                f"  [yellow]to fly them again: {escape(again)}[/]", highlight=False, soft_wrap=True
            )

    def interrupted(self, run: RunDir, resume: str) -> None:
        """Ctrl-C: where the completed trials are and how to continue.

        Parameters
        ----------
        run : RunDir
            The run.
        resume : str
            The command that continues it.
        """
        self.console.print(
            f"interrupted; completed trials are in {run.path}. Continue with: {escape(resume)}",
            highlight=False,
            soft_wrap=True,
        )

    def stopped(self, run: RunDir, resume: str) -> None:
        """A failure mid-flight: what was kept and how to continue once the cause is fixed.

        Parameters
        ----------
        run : RunDir
            The run.
        resume : str
            The command that continues it.
        """
        kept = f"completed trials are in {run.path}" if run.complete_trials() else (
            f"no trial was flown; the run is set up in {run.path}"
        )  # fmt: skip
        self.console.print(
            f"[dim]{kept}; once the cause is fixed, continue with: {escape(resume)}[/]",
            highlight=False,
            soft_wrap=True,
        )

    def left_floor(self, best_trial: int, again: str) -> None:
        """``--until-converged`` landed because learning left the floor.

        Parameters
        ----------
        best_trial : int
            The trial whose setpoints were best at the floor.
        again : str
            The command that flies them again.
        """
        self.console.print(
            f"--until-converged: landed, learning left the floor; to fly trial "
            f"{best_trial}'s setpoints again: {escape(again)}",
            highlight=False,
            soft_wrap=True,
        )

    def not_converged(self, iterations: int, resume: str) -> None:
        """``--until-converged`` flew ``--iter`` trials without converging.

        Parameters
        ----------
        iterations : int
            ``--iter``.
        resume : str
            The command that continues.
        """
        self.console.print(
            f"--until-converged: learning has not converged within --iter {iterations}; "
            f"continue with: {escape(resume)}",
            highlight=False,
            soft_wrap=True,
        )

    def finished(self, run: RunDir) -> None:
        """The run's table (as ``gcs report`` prints it), its legend and verdict.

        Parameters
        ----------
        run : RunDir
            The run flown.
        """
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
        width = self.console.width
        self.console.print(metrics_table(rows, title, rates, learning, width, three_d))
        shown = shows_step(rows, rates, learning, width, three_d)
        for line in table_legend(learning, shown) + run_verdict(rows, learning).lines():
            self.console.print(escape(line), highlight=False)


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
