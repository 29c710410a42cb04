"""``python -m gcs.mock.mocap``: the mock motion capture (OptiTrack Motive) as a program."""

import typer

from gcs.mock.mocap.cli import mocap_command


def main() -> None:
    """Run :func:`gcs.mock.mocap.cli.mocap_command`."""
    app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)
    app.command()(mocap_command)
    app()


if __name__ == "__main__":
    main()
