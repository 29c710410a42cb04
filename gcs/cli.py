"""The ``gcs`` command line: it only wires.

Each command parses its options into one frozen request (:class:`gcs.app.fly.FlyRequest`, ...)
and hands it to its room in :mod:`gcs.app`, with the view that shows it on this terminal. Every
command validates everything it will need before it creates, moves or flies anything (its room
does the checking), and every failure is one line on stderr: how a command ends, its exit code
and its line, is :mod:`gcs.app.failures` (a :class:`gcs.errors.GcsError`, an operating-system
error naming its file and a usage error of the command line: 2; Ctrl-C: 130; anything else is a
bug: 1, ``GCS_DEBUG=1`` shows its traceback). Here: the options, their help, and that line.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from typer.core import TyperCommand, TyperGroup

from gcs import __version__
from gcs.app.failures import EXIT_BAD_INPUT, EXIT_INTERRUPTED, OptionError, failure, one_line
from gcs.app.montecarlo import blas_policy

blas_policy(sys.argv)  # before numpy is imported (by the next line): OpenBLAS reads it once

from gcs.mock.cli import mock_command  # noqa: E402

F = TypeVar("F", bound=Callable[..., Any])


def _say(message: str) -> None:
    Console(stderr=True).print(
        f"[bold red]error:[/] {escape(one_line(message))}", highlight=False, soft_wrap=True
    )


@contextmanager
def _usage_in_one_line() -> Iterator[None]:
    """A usage error of the command line (a bad option value, a missing argument, an unknown
    command: what has a message to format and an exit code) as one line, with its exit code."""
    try:
        yield
    except typer.Abort:
        raise typer.Exit(EXIT_INTERRUPTED) from None
    except Exception as exc:
        message = getattr(exc, "format_message", None)
        code = getattr(exc, "exit_code", None)
        if not callable(message) or not isinstance(code, int):
            raise
        ctx = getattr(exc, "ctx", None)
        where = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
        _say(f"{message()}{where}")
        raise typer.Exit(code) from None


class _FlagsAsFlags:
    """Shows a flag as ``--mock``, not ``--mock <bool>``: Typer shows a type for every option,
    flags too, although a flag takes no value."""

    def get_params(self, ctx: Any) -> list[Any]:
        params = super().get_params(ctx)  # type: ignore[misc]
        for param in params:
            if getattr(param, "is_flag", False) and param.metavar is None:
                param.metavar = ""
        return params


class _Group(_FlagsAsFlags, TyperGroup):
    """Typer's group, with a usage error in one line: its own options, a command's options and
    arguments, an unknown command."""

    def make_context(self, *args: Any, **kwargs: Any) -> Any:
        with _usage_in_one_line():
            return super().make_context(*args, **kwargs)

    def invoke(self, ctx: Any) -> Any:
        with _usage_in_one_line():
            return super().invoke(ctx)


class _Command(_FlagsAsFlags, TyperCommand):
    """Typer's command, its flags shown as flags."""


app = typer.Typer(
    name="gcs",
    cls=_Group,
    help=(
        "Ground control station that makes a multirotor fly a repeated manoeuvre more "
        "precisely every time, by learning from its previous flights (smoother-based "
        "iterative learning control, Meraglia and Lovera)."
    ),
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",  # reflow docstring paragraphs to the terminal width
)
console = Console()
err_console = Console(stderr=True)

DEFAULT_PROFILE = "antx"
DEFAULT_TRAJECTORY = "eight"
DEFAULT_LOGS = Path("logs")
NAMED = "A packaged name ({names}; found from any directory) or a path to a YAML file."

#: The panels of every command's options in --help.
VEHICLE, LEARNING, OUTPUT, SAFETY = "Vehicle", "Learning", "Output", "Safety"
#: The panel of a simulation study's size and seed (gcs montecarlo).
STUDY = "Study"


def _names(kind: str, prefix: str = "") -> str:
    from gcs.io.paths import packaged_names

    return ", ".join(n for n in packaged_names(kind) if n.startswith(prefix)) or "none"


# ------------------------------------------------------------ options shared by commands
# Declared once; a command that needs another wording declares its own.

Algorithm = Annotated[
    str | None,
    typer.Option(
        "--algorithm",
        "-a",
        help="Disturbance estimator: 'smoother' (the paper's RTS smoother) or 'kilc' "
        "(iteration-domain Kalman filter baseline). Default: the profile's or the run's.",
        rich_help_panel=LEARNING,
    ),
]
Mock = Annotated[
    bool,
    typer.Option(
        "--mock",
        help="Fly a simulated drone: start gcs's mock drone (its own process, real MAVLink) "
        "on a free loopback port. For a dry run that flies nothing, see --check.",
        rich_help_panel=VEHICLE,
    ),
]
Connect = Annotated[
    str | None,
    typer.Option(
        "--connect",
        help="MAVSDK connection URL of a real vehicle or PX4 SITL, e.g. udpin://0.0.0.0:14540.",
        rich_help_panel=VEHICLE,
    ),
]
MockConfig = Annotated[
    str | None,
    typer.Option(
        "--mock-config",
        help="Mock drone settings with --mock: "
        + NAMED.format(names=_names("profile", "mock"))
        + " Default: mock (indoor, gusts).",
        rich_help_panel=VEHICLE,
        show_default=False,
    ),
]
Mocap = Annotated[
    str | None,
    typer.Option(
        "--mocap",
        help="Motion capture: SYSTEM://HOST[:PORT]/RIGID_BODY[?interface=IP] (optitrack, "
        "vicon, qualisys, vrpn), or 'mock' with --mock (the mock drone's indoor arena, "
        "vision only). Default: the profile's mocap.url, if any.",
        rich_help_panel=VEHICLE,
    ),
]
Profile = Annotated[
    str | None,
    typer.Option(
        "--profile",
        help="Vehicle profile: "
        + NAMED.format(names=_names("profile"))
        + f" Default: {DEFAULT_PROFILE}; the run's own where a run is continued or read.",
        rich_help_panel=LEARNING,
        show_default=False,
    ),
]
RunPath = Annotated[
    Path | None,
    typer.Option("--run", help="Create the new run exactly here.", rich_help_panel=OUTPUT),
]
Logs = Annotated[
    Path,
    typer.Option("--logs", help="Parent directory of new runs.", rich_help_panel=OUTPUT),
]
Check = Annotated[
    bool,
    typer.Option(
        "--check",
        help="Dry run: validate everything (profile, trajectory or excitation, run, paths, "
        "URL) and say what would be flown; create and fly nothing. 'gcs fly --check' also "
        "reads the vehicle's parameters and judges them against the checklist of "
        "docs/real-vehicle.md (ok, warn, refuse; --offline skips it).",
        rich_help_panel=SAFETY,
    ),
]
RunArgument = Annotated[Path, typer.Argument(help="Run directory, e.g. logs/latest.")]
WorkersOption = Annotated[
    int | None,
    typer.Option(
        min=0,
        help="Dask workers of a local cluster (one thread each); 0: no Dask, in this process. "
        "Default: in this process for a short study, one worker per core for a long one "
        "(estimated first). Results do not depend on it.",
    ),
]
SchedulerOption = Annotated[
    str | None,
    typer.Option(
        help="Run on an existing Dask cluster: the scheduler's address tcp://HOST:PORT (what "
        "`dask scheduler` prints). Its workers need gcs installed.",
    ),
]

EXIT_CODES = (
    "Exit codes: 0 done; 2 bad input, named on one line (a file, field or option); 130 "
    "interrupted (Ctrl-C); 1 an internal error (a bug; GCS_DEBUG=1 shows the traceback)."
)
FLIGHT_EXIT_CODES = (
    "Exit codes: 0 done; 2 bad input, named on one line (a file, field or option), or the "
    "vehicle was unreachable, refused a command, lost the link or aborted a {what} (it was "
    "landed first); 130 interrupted (Ctrl-C or SIGTERM; the vehicle was landed first{extra}); "
    "1 an internal error (a bug; GCS_DEBUG=1 shows the traceback)."
)


def _one_line_errors(func: Callable[..., Any]) -> Callable[..., Any]:
    """Every failure of a command as one line on stderr, with its exit code
    (:func:`gcs.app.failures.failure`); an :class:`OptionError` as a bad option value."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except (typer.Exit, typer.Abort, typer.BadParameter):  # the group reports usage errors
            raise
        except OptionError as exc:
            raise typer.BadParameter(exc.message, param_hint=exc.option) from None
        except BaseException as exc:
            ending = failure(exc)
            if ending is None:
                raise
            if ending.line is not None:
                _say(ending.line)
            raise typer.Exit(ending.code) from None

    return wrapper


def command(name: str | None = None, **settings: Any) -> Callable[[F], F]:
    """Register a command of ``gcs``: the one way every command is registered.

    Its failures are one line each, with their exit codes; its flags are shown as flags.

    Parameters
    ----------
    name : str or None
        The command's name (default: the function's).
    **settings
        As :meth:`typer.Typer.command` (``epilog``, ``help``).

    Returns
    -------
    callable
        The decorator; it returns the function unchanged.
    """

    def register(func: F) -> F:
        app.command(name, cls=_Command, **settings)(_one_line_errors(func))
        return func

    return register


def _named(value: str | Path | None, kind: str, option: str) -> Path | None:
    from gcs.io.paths import resolve_named

    return None if value is None else resolve_named(value, kind, option)


@app.callback(invoke_without_command=True)
def main(
    ctx: typer.Context,
    version: Annotated[
        bool, typer.Option("--version", help="Print the version and exit.", is_eager=True)
    ] = False,
) -> None:
    """Learn a repeated manoeuvre, flight after flight."""
    if version:
        console.print(f"gcs {__version__}")
        raise typer.Exit()
    if ctx.invoked_subcommand is None:  # no command: the help, and a usage error's exit code
        typer.echo(ctx.get_help(), nl=False)
        raise typer.Exit(EXIT_BAD_INPUT)


FLY_DETAILS = """Before anything is created or connected, everything is checked: the profile (every
section), the trajectory on the grid that is flown (speed and acceleration as finite
differences of the samples, the arena), a first learning update (models and setpoint limits
admit one), the run directory (--run must be new; --resume: a writable learning run whose
files agree and whose next setpoints keep the arena and the learning's limits), the
connection URL or the mock's settings. A failure is one line and nothing is written.

Connects through MAVSDK, says what the vehicle navigates on (GPS, vision: PX4's EKF2
parameters), waits for a healthy local position, arms, takes off to the trajectory's altitude
and flies to the start point. There it measures the hover (flight.hover_measure_s, 10 s): a
vehicle that drifts or oscillates is refused; any other sets how close and how still the
vehicle must be before each trial (the settle), kept in the run's session-SSS.json. Each trial
streams its setpoints on the vehicle's own clock, records the measured position on the sample
grid, learns the next trial's setpoints while hovering (the same step as 'gcs learn') and
prints the new row of the e_pos table. After the last trial it lands and disarms.

With a profile that has learning.adaptive (antx-adaptive): trial 0 is flown again with
identical setpoints to measure the floor, one flight's non-repeatable error; then every trial
learns from all the trials so far, and the live table says what each learning step decided
(learn-JJJ.json, model-JJJ.yaml). --iter counts flights, the repeat included: --iter 7 flies
j = 0..5.

Safety: Ctrl-C, a lost link, an offboard rejection or any error mid-trial stops streaming,
holds, lands and disarms; completed trials stay on disk, the interrupted one is marked
incomplete, and --resume continues from the last complete trial. Setpoints outside the
profile's arena are never sent. Before a real vehicle's first flight: docs/real-vehicle.md.

Motion capture (--mocap, the profile's mocap section): the rigid body's pose is mapped to NED
and forwarded to PX4 as external vision; before arming EKF2's parameters are judged, the body
must be tracked and the estimate agree with the mocap; after take-off one small move per
horizontal axis must go the right way. A stale, occluded, frozen or jumping stream aborts like
a lost link (docs/mocap.md).

More examples: gcs fly --mock --profile antx-adaptive --iter 10 --until-converged; gcs fly
--mock --mocap mock --iter 3; gcs fly --connect udpin://0.0.0.0:14540 --iter 5 --check.

""" + FLIGHT_EXIT_CODES.format(what="trial", extra="")


@command(epilog=FLY_DETAILS)
def fly(
    mock: Mock = False,
    connect: Connect = None,
    mocap: Mocap = None,
    mock_config: MockConfig = None,
    seed: Annotated[
        int,
        typer.Option(help="Seed of the mock drone's random gusts.", rich_help_panel=VEHICLE),
    ] = 0,
    iterations: Annotated[
        int, typer.Option("--iter", "-n", min=1, help="Trials to fly.", rich_help_panel=LEARNING)
    ] = 3,
    profile: Profile = None,
    trajectory: Annotated[
        str | None,
        typer.Option(
            help="Trajectory to learn: "
            + NAMED.format(names=_names("trajectory"))
            + " A planner's samples file (.csv, .npy, .npz) is taken as a 'samples' trajectory."
            + f" Default: {DEFAULT_TRAJECTORY}; with --resume, the run's own (a different "
            "one is refused).",
            show_default=False,
            rich_help_panel=LEARNING,
        ),
    ] = None,
    algorithm: Algorithm = None,
    until_converged: Annotated[
        bool,
        typer.Option(
            "--until-converged",
            help="Land as soon as learning has converged: two trials in a row at the floor "
            "(the repeat of trial 0 measures it), their mean within one trial's scatter of "
            "it; or as soon as it has left the floor it reached (two trials in a row above "
            "it), saying which trial's setpoints to fly again with --again. --iter stays the "
            "most trials flown. Needs a profile with learning.adaptive (antx-adaptive).",
            rich_help_panel=LEARNING,
        ),
    ] = False,
    run_dir: RunPath = None,
    resume: Annotated[
        Path | None,
        typer.Option(
            help="Continue this run from its last complete trial.", rich_help_panel=OUTPUT
        ),
    ] = None,
    again: Annotated[
        int | None,
        typer.Option(
            "--again",
            min=0,
            metavar="TRIAL",
            help="With --resume: the next trial flies this complete trial's setpoints again "
            "instead of the ones learned for it (kept in the run's superseded/), e.g. the "
            "best at the floor when learning drifted up from it; learning goes on from there.",
            show_default=False,
            rich_help_panel=OUTPUT,
        ),
    ] = None,
    logs: Logs = DEFAULT_LOGS,
    check: Check = False,
    offline: Annotated[
        bool,
        typer.Option(
            "--offline",
            help="With --check: check the files and options only; connect to no vehicle.",
            rich_help_panel=SAFETY,
        ),
    ] = False,
) -> None:
    """Fly N learning trials: take off, fly, learn, fly again, land.

    Give the vehicle with --connect (a real PX4 or PX4 SITL) or fly the mock drone with
    --mock; every trial learns from the ones before and prints its row of the e_pos table.
    Everything is checked before anything is created or flown (--check stops there).

    Example: gcs fly --mock --iter 3
    """
    from gcs.app.fly import FlyRequest
    from gcs.app.fly import fly as fly_room
    from gcs.app.fly_view import FlyDisplay

    if resume is None:
        profile, trajectory = profile or DEFAULT_PROFILE, trajectory or DEFAULT_TRAJECTORY
    request = FlyRequest(
        iterations=iterations,
        use_mock=mock,
        connect=connect,
        mock_config=_named(mock_config, "profile", "--mock-config"),
        seed=seed,
        profile=_named(profile, "profile", "--profile"),
        trajectory=_named(trajectory, "trajectory", "--trajectory"),
        algorithm=algorithm,
        run=run_dir,
        resume=resume,
        logs=logs,
        check_only=check,
        offline=offline,
        until_converged=until_converged,
        mocap=mocap,
        again=again,
    )
    fly_room(request, FlyDisplay(console))


LEARN_DETAILS = (
    """Estimates the repetitive disturbance D of the newest complete trial (RTS
smoother or K-ILC), solves the input update of eq. (8) with the run's limits, and writes
`setpoints-<j+1>.csv` and `estimate-<j>.csv`. Deterministic and idempotent: learning again
from the same trial writes nothing new, and a file that exists with other content is never
replaced (refused). A log with NaNs, a wrong length or time grid, files that disagree with
their names, an identification run, a read-only run directory or a mismatching profile is
refused and nothing is written. The learned setpoints are checked on their grid against the
arena, max_step_m and max_deviation_m before they are written.

A run whose profile has learning.adaptive (antx-adaptive) learns from every complete trial
instead (docs/learning-floor.md): after trial 0 it writes the setpoints of its repeat (trial
0's, to measure the floor), after that it starts from the models of the previous step and also
writes `learn-<j>.json` (every decision: noise model and weights, model refresh and how far it
moved, safeguard, floor verdicts), `model-<j>.yaml` when a model was refreshed (a profile: fly
it with --profile) and `floor.json`. Every trial 0..j must be complete, and every earlier
record and model must agree with its name.

"""
    + EXIT_CODES
)


@command(epilog=LEARN_DETAILS)
def learn(
    run_dir: RunArgument,
    algorithm: Algorithm = None,
    profile: Annotated[
        str | None,
        typer.Option(
            help="Profile (name or path) that must match the one recorded in the run's manifest.",
            rich_help_panel=LEARNING,
        ),
    ] = None,
) -> None:
    """Learn from the newest complete trial and write the next trial's setpoints.

    The offline half of 'gcs fly': what a flight does between two trials, on a run directory
    (a trial flown by another tool, or again after a change).

    Example: gcs learn logs/latest
    """
    from gcs.app.learn import LearnRequest
    from gcs.app.learn import learn as learn_room
    from gcs.app.learn_view import LearnDisplay

    request = LearnRequest(run_dir, algorithm, _named(profile, "profile", "--profile"))
    learn_room(request, LearnDisplay(console))


REPORT_DETAILS = (
    """Columns as the paper's Table IV: e_pos,j (eq. 10), e_pos,j / e_pos,0
(always relative to trial 0: a run without a complete trial 0, or with e_pos,0 = 0, is
refused), the signed change from the previous trial ('-' after a gap; negative is better),
and the largest horizontal error; then the vehicle's clock rate against the wall clock. Below
the table: every missing or incomplete trial, and one line per flight session. Every learning
run adds the setpoints' RMS distance from the reference per trial; a run whose profile has
learning.adaptive adds the trial number beside the paper's iteration j, e_pos / floor, the
verdicts 'at floor' and 'converged', and each learning step's decisions. Every column and
JSON key is defined in docs/report.md.

The table's title, the JSON's run object, the HTML page and every figure name the run (its
own id, also for logs/latest), the profile, the trajectory, the mock's seed and the gcs
version.

Figures (--plot, --html), for both axes: the horizontal path per iteration with its start and
direction (paper Fig. 4), north and east against time (Fig. 5), the setpoints flown against
the reference, the max_deviation_m band and the arena, the error against time, e_pos per
iteration with a percentage axis (Fig. 2), and the learned disturbance with its ±2σ band. A
3-D run (down learned, or a reference that climbs or sinks) adds the 3-D e_pos and the down
RMS to the table (every axis's RMS in the JSON and the HTML), the altitude against time and
the path from above, the side and the front.

More examples: gcs report logs/latest --html report.html --iterations 0,2,5; gcs report
logs/latest --json

"""
    + EXIT_CODES
)


@command(epilog=REPORT_DETAILS)
def report(
    run_dirs: Annotated[
        list[Path],
        typer.Argument(
            help="Run directory, e.g. logs/latest; two or more compare the runs side by side.",
            metavar="RUN_DIR",
            show_default=False,
        ),
    ],
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help="Print one JSON document instead of the table: format, version, the run's "
            "facts and one row per trial (schema: docs/report.md).",
            rich_help_panel=OUTPUT,
        ),
    ] = False,
    plot: Annotated[
        Path | None,
        typer.Option(
            help="Write the figures here (created if missing): xy, position, setpoints, "
            "error, epos, disturbance; compared runs: compare-epos.",
            rich_help_panel=OUTPUT,
        ),
    ] = None,
    html: Annotated[
        Path | None,
        typer.Option(
            help="Write one self-contained HTML report here (table and figures embedded): "
            "a single file to mail.",
            rich_help_panel=OUTPUT,
        ),
    ] = None,
    iterations: Annotated[
        str | None,
        typer.Option(
            help="Trials to draw in the figures, e.g. 0,2,5 (each a complete trial). "
            "Default: 0, 1, 2 and the last.",
            rich_help_panel=OUTPUT,
        ),
    ] = None,
    figure_format: Annotated[
        str,
        typer.Option(
            "--format",
            help="Format of the --plot figures: png, svg or pdf.",
            rich_help_panel=OUTPUT,
        ),
    ] = "png",
    csv: Annotated[
        Path | None,
        typer.Option(
            help="Write the table as CSV here (one line per trial, SI units); compared runs: "
            "e_pos per trial and run.",
            rich_help_panel=OUTPUT,
        ),
    ] = None,
    export_setpoints: Annotated[
        Path | None,
        typer.Option(
            "--export-setpoints",
            help="Write the best learned trial's setpoints here as a samples CSV "
            "(docs/trajectories.md), for another stack to replay at t_ilc_s. As a gcs fly "
            "--trajectory they are a reference and are usually refused: learned setpoints "
            "step faster than a reference may (docs/report.md).",
            rich_help_panel=OUTPUT,
        ),
    ] = None,
) -> None:
    """Show the learning table of a run and its verdict, or compare several runs.

    Example: gcs report logs/latest --plot plots/

    Compare: gcs report logs/run-a logs/run-b --plot compare/
    """
    from gcs.app.report_run import ReportRequest
    from gcs.app.report_run import report as report_room
    from gcs.app.report_view import ReportDisplay

    request = ReportRequest(
        tuple(run_dirs), as_json, plot, html, iterations, csv, figure_format, export_setpoints
    )
    report_room(request, ReportDisplay(console, err_console))


def run() -> None:  # pragma: no cover - console-script entry point alias
    """Entry point."""
    app()


IDENTIFY_DETAILS = """Flies two experiments from hover (take off, settle at
identification.center_ned_m, fly, settle again, fly, land): trial 0 to fit the model and trial
1, with other seeds, to validate it. Each adds a PRBS (or multisine) of
identification.amplitude_m (z: identification.vertical_amplitude_m) to the hover setpoint on
the chosen axes for identification.duration_s; setpoints that would leave the arena are
refused before take-off.
The run directory (algorithm 'identify') keeps both trials, so --from-log can identify again
offline.

Per axis, PBSID-opt (docs/identify.md) fits an innovation model on trial 0 with the profile's
past/future windows, chooses the order and the input delay, and simulates it free-running on
trial 1. The table shows order, delay, poles, wn and zeta (Tustin), the continuous transfer
function, and the validation VAF and fit beside the VAF of the profile's own model. The output
profile is the input profile with model (x), model_y (y) and model_z (z) replaced by the
identified discrete state spaces; 'gcs fly --profile' uses it as is (model_z is learned with
learning.axes: [north, east, down]).

Too little data, a constant or non-exciting input, NaNs or an incomplete trial are refused
with one line and exit code 2; no profile is written then. The profile, the excitation
against the arena, the run and the output paths (--out, --plot) are checked before anything
is flown or identified. The run's own identified.yaml is written once: identifying the run
again gives the same bytes, or is refused.

More examples: gcs identify --from-log logs/latest --axis x --out x-only.yaml
               gcs identify --mock --axis z --out with-model-z.yaml

""" + FLIGHT_EXIT_CODES.format(what="experiment", extra=", no profile written")


@command(epilog=IDENTIFY_DETAILS)
def identify(
    mock: Mock = False,
    connect: Connect = None,
    mocap: Annotated[
        str | None,
        typer.Option(
            "--mocap",
            help="Motion capture (as for gcs fly): a URL or 'mock' with --mock; the experiments "
            "are then measured by it (mocap.measurement).",
            rich_help_panel=VEHICLE,
        ),
    ] = None,
    mock_config: MockConfig = None,
    seed: Annotated[
        int | None,
        typer.Option(
            help="Excitation seed (overrides identification.seed); also seeds the mock's gusts.",
            rich_help_panel=VEHICLE,
        ),
    ] = None,
    from_log: Annotated[
        Path | None,
        typer.Option(
            "--from-log",
            help="Identify offline from this identification run directory (nothing is flown).",
            rich_help_panel=LEARNING,
        ),
    ] = None,
    profile: Profile = None,
    axis: Annotated[
        str | None,
        typer.Option(
            help="x (north), y (east), z (down), both (x and y excited at once, independent "
            "seeds) or all (x, y and z). Default: both when flying, the axes the run excited "
            "with --from-log.",
            rich_help_panel=LEARNING,
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            help="Write the identified profile here (default: RUN_DIR/identified.yaml).",
            rich_help_panel=OUTPUT,
        ),
    ] = None,
    plot: Annotated[
        Path | None,
        typer.Option(
            help="Write identify_validation.png (measured vs simulated) and identify_bode.png.",
            rich_help_panel=OUTPUT,
        ),
    ] = None,
    run_dir: RunPath = None,
    logs: Logs = DEFAULT_LOGS,
    check: Check = False,
) -> None:
    """Identify the closed loop "position setpoint -> position" with PBSID and write a profile.

    Flies two small excitation experiments from hover (or reads them back with --from-log),
    fits a model per excited axis and writes the profile with the identified models: the
    first thing to do on a new vehicle, before learning (docs/real-vehicle.md).

    Example: gcs identify --mock --out profiles/mock-identified.yaml --plot plots/
    """
    from gcs.app.identify import run_identify
    from gcs.app.identify_plan import IdentifyRequest
    from gcs.app.identify_view import IdentifyView

    if sum((mock, connect is not None, from_log is not None)) != 1:
        raise typer.BadParameter("give exactly one of --mock, --connect and --from-log")
    if axis is not None and axis not in ("x", "y", "z", "both", "all"):
        raise typer.BadParameter("must be x, y, z, both or all", param_hint="--axis")
    if from_log is not None and (run_dir is not None or mock_config is not None):
        raise typer.BadParameter("--run and --mock-config need a flight, not --from-log")
    request = IdentifyRequest(
        profile=_named(profile, "profile", "--profile"),
        default_profile=_named(DEFAULT_PROFILE, "profile", "--profile"),
        axis=axis,
        out=out,
        from_log=from_log,
        plot=plot,
        seed=seed,
        connect=connect,
        use_mock=mock,
        mock_config=_named(mock_config, "profile", "--mock-config"),
        logs=logs,
        run=run_dir,
        check_only=check,
        mocap=mocap,
    )
    run_identify(request, IdentifyView(console, err_console))


@command()
def montecarlo(
    levels: Annotated[
        str,
        typer.Option(
            help="Uncertainty levels (std of wn and zeta, fraction of nominal).",
            rich_help_panel=STUDY,
        ),
    ] = "0.05,0.1,0.2,0.4",
    plants: Annotated[
        int, typer.Option(min=2, help="Plants per level.", rich_help_panel=STUDY)
    ] = 100,
    repeats: Annotated[
        int, typer.Option(min=1, help="Noise realisations per plant.", rich_help_panel=STUDY)
    ] = 10,
    iterations: Annotated[
        int,
        typer.Option(
            min=30,
            help="Learning iterations; at least 30: the steady state is the mean of trials "
            "20 to 30 (the paper's footnote 4).",
            rich_help_panel=STUDY,
        ),
    ] = 30,
    samples: Annotated[
        int, typer.Option(min=10, help="Samples per trial (t_ilc 0.01 s).", rich_help_panel=STUDY)
    ] = 200,
    seed: Annotated[
        int, typer.Option(help="Seed of plants and noise.", rich_help_panel=STUDY)
    ] = 20240601,
    keep_diverged: Annotated[
        bool,
        typer.Option(
            help="Keep plants whose learning diverged in the statistics.", rich_help_panel=LEARNING
        ),
    ] = False,
    json_path: Annotated[
        Path | None,
        typer.Option(
            "--json", help="Also write the rows to this JSON file.", rich_help_panel=OUTPUT
        ),
    ] = None,
    adaptive: Annotated[
        bool,
        typer.Option(
            help="Also learn on the same plants and noise with the options beyond the paper "
            "(noise model from the data, model refresh; docs/learning-floor.md) and compare "
            "the mean error of trials 2-5 and the diverged plants. Takes minutes, not seconds.",
            rich_help_panel=LEARNING,
        ),
    ] = False,
    workers: WorkersOption = None,
    scheduler: SchedulerOption = None,
) -> None:
    """The paper's Sec. IV Monte Carlo study, printed as Tables II and III.

    A mass-spring-damper (wn = 1.8 rad/s, zeta = 0.8) with output disturbance
    0.5 sin^2(t) and noise learns yd = sin(0.5 pi t) for 30 iterations at t_ilc = 0.01 s with
    the nominal model, for 100 plants x 10 repeats at each uncertainty level; both
    algorithms with Table I's parameters. The readings of what the paper leaves open are in
    docs/montecarlo.md. Plants whose learning diverged are counted and, unless
    --keep-diverged, left out of the statistics.

    Every (level, algorithm) row is one task: by default in this process when the study is
    short, on a local Dask cluster of one worker per core when it is long enough to gain from
    it (decided after timing its first task here; one line says which, and why;
    docs/studies.md); --workers N for a local cluster of that size (0: no Dask, in this
    process), --scheduler tcp://HOST:PORT for a running cluster; the rows are the same on any
    of them.

    Example: gcs montecarlo --levels 0.05,0.1 --json montecarlo.json

    Exit codes: 0 done; 2 bad input, named on one line (a file, field or option); 130
    interrupted (Ctrl-C); 1 an internal error (a bug; GCS_DEBUG=1 shows the traceback).
    """
    from gcs.app.montecarlo import MontecarloRequest
    from gcs.app.montecarlo import montecarlo as montecarlo_room
    from gcs.app.montecarlo_view import MontecarloDisplay

    request = MontecarloRequest(
        levels, plants, repeats, iterations, samples, seed, keep_diverged, adaptive,
        json_path, workers, scheduler,
    )  # fmt: skip
    montecarlo_room(request, MontecarloDisplay(console, err_console))


@command()
def study(
    definition: Annotated[
        Path,
        typer.Argument(
            help="The study file (YAML; fields in docs/studies.md).", show_default=False
        ),
    ],
    out: Annotated[
        Path | None,
        typer.Option(
            help="Output directory; default study-<name> here. A directory holding the same "
            "study resumes it: only the missing chunks run.",
        ),
    ] = None,
    workers: WorkersOption = None,
    scheduler: SchedulerOption = None,
    check: Annotated[
        bool, typer.Option("--check", help="Check the study file and say its size; run nothing.")
    ] = False,
) -> None:
    """Compare learning settings on simulated copies of your vehicle, before flying.

    The study file names your profile (the model the plants are drawn around), your
    trajectory, the uncertainty of the true plants (spread of each mode's frequency, damping
    and gain, or of the Markov parameters; extra delay; output noise and a repeatable
    disturbance, from a run's floor.json if you like) and the settings to compare (a list and
    a grid: weights, smoother Q/R, the adaptive options, other profiles). Every plant learns
    with every setting, as `gcs fly` would, for the given iterations.

    Printed: one row per setting and level (e_pos per flight, flights to the floor, steady
    state, diverged plants, setpoints, limits) and the recommended setting with its reason.
    Written to the output directory: study.json (definition, summaries, every plant), one
    file per finished chunk, epos.png and tradeoff.png.

    Runs in this process when the study is short, on a local Dask cluster of one worker per
    core when it is long enough to gain from it (one plant of each setting is timed first; one
    line says which, and why; docs/studies.md); --workers N for a local cluster of that size
    (0: in this process), --scheduler tcp://HOST:PORT for a running cluster. Every chunk of
    plants is seeded from the study's seed and its index: the results are the same, bit for
    bit, on any number of workers.

    Example: gcs study study.yaml --out study-antx

    Exit codes: 0 done; 2 bad input, named on one line (a file, field or option); 130
    interrupted (Ctrl-C; finished chunks are kept, run it again to resume); 1 an internal
    error (a bug; GCS_DEBUG=1 shows the traceback).
    """
    from gcs.app.study import StudyRequest
    from gcs.app.study import study as study_room
    from gcs.app.study_view import StudyDisplay

    request = StudyRequest(definition, out, workers, scheduler, check)
    study_room(request, StudyDisplay(Console(), Console(stderr=True)))


MOCK_EXIT_CODES = (
    "Exit codes: 0 stopped (SIGTERM or Ctrl-C); 2 bad input, named on one line; 1 an "
    "internal error (a bug; GCS_DEBUG=1 shows the traceback)."
)
_MOCK_HEAD, _, _MOCK_TAIL = (mock_command.__doc__ or "").partition("\f")


@command("mock", help=f"{_MOCK_HEAD.rstrip()}\n\n    {MOCK_EXIT_CODES}\n    \f{_MOCK_TAIL}")
@functools.wraps(mock_command)
def mock(**kwargs: Any) -> None:
    # the mock's own command and options; its files checked before it binds or runs
    from gcs.app.mock_drone import check_mock_files

    kwargs["config"] = _named(kwargs.get("config"), "profile", "--config")
    check_mock_files(kwargs["config"], kwargs.get("stats_out"))
    mock_command(**kwargs)
