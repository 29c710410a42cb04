"""``python -m gcs.mock``: the mock drone as a one-command program."""

import sys

import typer

from gcs.errors import GcsError
from gcs.mock.cli import mock_command


def main() -> None:
    """Run :func:`gcs.mock.cli.mock_command`; a GcsError becomes one line and exit code 2."""
    app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)
    app.command()(mock_command)
    try:
        app()
    except GcsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
