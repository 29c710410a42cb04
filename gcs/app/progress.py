"""Progress of long work: a rich bar on a terminal, plain periodic lines elsewhere.

On a terminal the bar redraws in place and disappears when done. When the output is a pipe or
a file (a batch job, ``nohup``, a CI log), a bar would be invisible or a mess of control codes;
there the progress is a plain line every ``interval_s`` seconds and one at the end::

    study: 12/48 chunks, 00:01:10 elapsed, about 00:03:30 remaining
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

__all__ = ["progress_lines", "track", "clock"]

#: Seconds between two plain progress lines.
INTERVAL_S = 10.0


def clock(seconds: float) -> str:
    """``HH:MM:SS`` of a duration.

    ``seconds``: duration [s].
    """
    s = int(round(max(seconds, 0.0)))
    return f"{s // 3600:02d}:{s % 3600 // 60:02d}:{s % 60:02d}"


def progress_lines(
    say: Callable[[str], None],
    label: str,
    unit: str,
    interval_s: float = INTERVAL_S,
    now: Callable[[], float] = time.monotonic,
) -> Callable[[int, int], None]:
    """A ``progress(done, total)`` callback that says a plain line now and then.

    A line is said at the first call, then when ``interval_s`` has passed since the last one,
    and when ``done == total``.

    ``label``, ``unit``: ``"<label>: <done>/<total> <unit>, ..."``. ``interval_s``: seconds between
    lines. ``now``: monotonic clock [s] (a parameter for tests).
    """
    start = now()
    last: list[float | None] = [None]

    def progress(done: int, total: int) -> None:
        t = now()
        if last[0] is not None and t - last[0] < interval_s and done < total:
            return
        last[0] = t
        elapsed = t - start
        text = f"{label}: {done}/{total} {unit}, {clock(elapsed)} elapsed"
        if 0 < done < total:
            text += f", about {clock(elapsed * (total - done) / done)} remaining"
        say(text)

    return progress


@contextmanager
def track(
    console: Console, label: str, unit: str, interval_s: float = INTERVAL_S
) -> Iterator[Callable[[int, int], None]]:
    """Progress on ``console``: a bar on a terminal, else plain periodic lines.

    ``unit``: what is counted (``"chunks"``). ``interval_s``: seconds between plain lines.

    Yields: callable, ``progress(done, total)``.
    """
    if not console.is_terminal:
        yield progress_lines(
            lambda line: console.print(line, markup=False, highlight=False), label, unit, interval_s
        )
        return
    columns = (
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn(unit),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=console, transient=True) as bar:
        task = bar.add_task(label, total=None)
        yield lambda done, total: bar.update(task, completed=done, total=total)
