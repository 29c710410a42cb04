"""gcs's command line run in this process, as the tests run it: the click command built once.

``typer.testing.CliRunner.invoke`` builds the click command from the Typer app at every call:
about half a second of signature inspection for gcs's commands, paid again by each of the
suite's thousands of in-process invocations. :func:`gcs_command` builds it once with Typer's
public ``typer.main.get_command``, and :func:`invoke` runs it the way Typer's runner does,
inside the runner's public ``isolation`` (streams and environment), returning Typer's
``Result``.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Mapping, Sequence

import typer
from typer.testing import CliRunner, Result

from gcs.cli import app


@functools.cache
def gcs_command() -> object:
    """The click command of ``gcs`` (built on first use, then shared)."""
    return typer.main.get_command(app)


def invoke(
    args: Sequence[object],
    env: Mapping[str, str | None] | None = None,
    input: str | None = None,
    catch_exceptions: bool = True,
) -> Result:
    """``gcs ARGS`` in this process: exit code, output (stdout and stderr mixed) and the
    exception, as ``typer.testing.CliRunner().invoke(app, ARGS, ...)`` gives them.

    ``catch_exceptions``: False lets an exception other than ``SystemExit`` propagate."""
    runner = CliRunner()
    command = gcs_command()
    exit_code, exception, exc_info = 0, None, None
    with runner.isolation(input=input, env=env) as (stdout, stderr, output):
        try:
            command.main(args=[str(a) for a in args], prog_name=command.name or "root")  # type: ignore[attr-defined]
        except SystemExit as stop:
            code = 0 if stop.code is None else stop.code
            if code != 0:
                exception, exc_info = stop, sys.exc_info()
            if not isinstance(code, int):
                sys.stdout.write(f"{code}\n")
                code = 1
            exit_code = code
        except Exception as error:
            if not catch_exceptions:
                raise
            exception, exit_code, exc_info = error, 1, sys.exc_info()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
        streams = stdout.getvalue(), stderr.getvalue(), output.getvalue()
    return Result(runner, *streams, None, exit_code, exception, exc_info)  # type: ignore[arg-type]
