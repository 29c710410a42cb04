"""How a command ends: its exit code, and what a failure says in one line.

Every command ends the same way. Done: 0. A :class:`gcs.errors.GcsError` (bad input, a
vehicle that was unreachable, refused a command or aborted a trial) and an operating-system
error (it names its file): its message in one line, 2. Ctrl-C: 130 (a flight said already
where its run is). Anything else is a bug: one line asking for a report, 1 (``GCS_DEBUG=1``
lets it through, with its traceback). The command line prints the line and exits with the
code; this module decides both.

Options that do not go together, or a value the numerics refuse, are an :class:`OptionError`:
the command line reports it as it reports a bad option value of its own (exit code 2).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from gcs.errors import GcsError

__all__ = [
    "EXIT_OK",
    "EXIT_INTERNAL",
    "EXIT_BAD_INPUT",
    "EXIT_INTERRUPTED",
    "Failure",
    "OptionError",
    "failure",
    "one_line",
]

#: Exit codes, as every command's --help states them.
EXIT_OK, EXIT_INTERNAL, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130


class OptionError(GcsError, ValueError):
    """A command's options that do not go together, or an option's value that is refused.

    Parameters
    ----------
    message : str
        What is wrong, without the option's name.
    option : str or None
        The option, as the command line spells it (``"--levels"``); None when the message
        names the options itself ("give exactly one of --mock and --connect").
    """

    def __init__(self, message: str, option: str | None = None) -> None:
        super().__init__(message if option is None else f"{option}: {message}")
        self.message, self.option = message, option


@dataclass(frozen=True)
class Failure:
    """How a command that raised ends.

    Parameters
    ----------
    code : int
        Exit code.
    line : str or None
        The one line to print on stderr (None: nothing more to say).
    """

    code: int
    line: str | None


def one_line(message: str) -> str:
    """A message on one line: its lines joined, each stripped.

    Parameters
    ----------
    message : str
        Any message.

    Returns
    -------
    str
    """
    return " ".join(line.strip() for line in message.splitlines())


def failure(exc: BaseException) -> Failure | None:
    """The exit code and the one line of a command that raised ``exc``.

    Parameters
    ----------
    exc : BaseException
        What the command raised.

    Returns
    -------
    Failure or None
        None for an exception that is not a command's failure (``SystemExit``, and with
        ``GCS_DEBUG`` set an internal error: let it through, with its traceback).
    """
    if isinstance(exc, GcsError):
        return Failure(EXIT_BAD_INPUT, one_line(str(exc)))
    if isinstance(exc, KeyboardInterrupt):  # a flight landed the vehicle and said where its run is
        return Failure(EXIT_INTERRUPTED, None)
    if isinstance(exc, OSError):
        where = exc.filename if exc.filename is not None else "operating system"
        return Failure(EXIT_BAD_INPUT, one_line(f"{where}: {exc.strerror or exc}"))
    if not isinstance(exc, Exception) or os.environ.get("GCS_DEBUG"):
        return None
    return Failure(
        EXIT_INTERNAL,
        one_line(f"internal error, please report it: {type(exc).__name__}: {exc}"),
    )
