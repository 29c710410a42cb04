"""The ``gcs`` command line: thin wiring of profiles, runs, learning, flight and reports.

Every command turns a :class:`gcs.errors.GcsError` (bad input, unreachable vehicle, ...) into
one line on stderr and exit code 2.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console

from gcs import __version__
from gcs.errors import GcsError

app = typer.Typer(
    name="gcs",
    help=(
        "Ground control station that makes a multirotor fly a repeated manoeuvre more "
        "precisely every time, by learning from its previous flights (smoother-based "
        "iterative learning control, Meraglia and Lovera)."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)

DEFAULT_PROFILE = Path("profiles/antx.yaml")
DEFAULT_TRAJECTORY = Path("trajectories/eight.yaml")
DEFAULT_LOGS = Path("logs")

Algorithm = Annotated[
    str | None,
    typer.Option(
        "--algorithm",
        "-a",
        help="Disturbance estimator: 'smoother' (the paper's RTS smoother) or 'kilc' "
        "(iteration-domain Kalman filter baseline). Default: the profile's or the run's.",
    ),
]


def one_line_errors(func: Callable[..., Any]) -> Callable[..., Any]:
    """Report a GcsError as one line on stderr and exit with code 2."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except GcsError as exc:
            err_console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
            raise typer.Exit(2) from None

    return wrapper


def _check_algorithm(algorithm: str | None) -> None:
    from gcs.io.config import ALGORITHMS

    if algorithm is not None and algorithm not in ALGORITHMS:
        raise typer.BadParameter(
            f"must be one of {', '.join(ALGORITHMS)}", param_hint="--algorithm"
        )


@app.callback(invoke_without_command=True)
def main(
    version: Annotated[
        bool, typer.Option("--version", help="Print the version and exit.", is_eager=True)
    ] = False,
) -> None:
    """Learn a repeated manoeuvre, flight after flight."""
    if version:
        console.print(f"gcs {__version__}")
        raise typer.Exit()


@app.command()
@one_line_errors
def learn(
    run_dir: Annotated[Path, typer.Argument(help="Run directory, e.g. logs/latest.")],
    algorithm: Algorithm = None,
    profile: Annotated[
        Path | None,
        typer.Option(help="Profile that must match the one recorded in the run's manifest."),
    ] = None,
) -> None:
    """Learn from the newest complete trial and write the next trial's setpoints.

    Estimates the repetitive disturbance D of the newest complete trial (RTS smoother or
    K-ILC), solves the input update of eq. (8) with the run's limits, and writes
    setpoints-<j+1>.csv and estimate-<j>.csv. Deterministic and idempotent; a log with NaNs,
    a wrong length or time grid, or a mismatching profile is refused and nothing is written.

    Example: gcs learn logs/latest
    """
    from gcs.io.runlog import RunDir
    from gcs.learn import learn_run

    _check_algorithm(algorithm)
    run = RunDir.open(run_dir)
    outcome = learn_run(run, algorithm, profile)
    console.print(
        f"learned from trial {outcome.trial} ({run.algorithm}); "
        f"setpoints for trial {outcome.next_trial}: {outcome.setpoints_path} "
        f"[dim](solver {'/'.join(outcome.methods)}, "
        f"{outcome.active_constraints} active limits)[/]"
    )


@app.command()
@one_line_errors
def report(
    run_dir: Annotated[Path, typer.Argument(help="Run directory, e.g. logs/latest.")],
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help="Print a JSON list of {iteration, epos_m, epos_pct, delta_pct, max_err_m}.",
        ),
    ] = False,
    plot: Annotated[
        Path | None,
        typer.Option(help="Write PNG figures (xy paths, north(t), e_pos by iteration) here."),
    ] = None,
) -> None:
    """Show the learning table of a run: one row per complete trial.

    Columns as the paper's Table IV: e_pos,j (eq. 10), e_pos,j / e_pos,0, the relative change
    from the previous trial, and the largest horizontal error.

    Example: gcs report logs/latest --plot plots/
    """
    from gcs.io.runlog import RunDir
    from gcs.report import metrics_json, metrics_table, run_metrics, write_plots

    run = RunDir.open(run_dir)
    rows = run_metrics(run)
    if as_json:
        typer.echo(json.dumps(metrics_json(rows), indent=2))
    else:
        console.print(metrics_table(rows, f"{run.path.name} ({run.algorithm})"))
    if plot is not None:
        for path in write_plots(run, plot):
            err_console.print(f"wrote {path}")


def run() -> None:  # pragma: no cover - console-script entry point alias
    """Entry point."""
    app()
