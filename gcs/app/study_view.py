"""The terminal and the figures of ``gcs study``: one row per setting and level."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from rich import box
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from gcs.app.progress import track
from gcs.core.study import FLOOR_FACTOR, SettingSummary

__all__ = ["StudyDisplay", "study_table", "write_study_figures"]


class StudyDisplay:
    """``gcs study`` on the terminal (:class:`gcs.app.study.StudyView`).

    Parameters
    ----------
    console, err_console : rich.console.Console
        The table (stdout); the size, placement and progress lines (stderr).
    """

    def __init__(self, console: Console, err_console: Console) -> None:
        self.console, self.err = console, err_console

    def say(self, line: str) -> None:
        """One line on stderr.

        Parameters
        ----------
        line : str
            Plain text.
        """
        self.err.print(line, highlight=False)

    @contextmanager
    def chunks(self, name: str) -> Iterator[Callable[[int, int], None]]:
        """The progress of the study's chunks.

        Parameters
        ----------
        name : str
            The study's name.

        Yields
        ------
        callable
            ``progress(done, total)``.
        """
        with track(self.err, name, "chunks") as follow:
            yield follow

    def figures(self, summaries: list[SettingSummary], out: Path) -> list[Path]:
        """Write epos.png and tradeoff.png (:func:`write_study_figures`).

        Parameters
        ----------
        summaries : list of SettingSummary
            Per setting and level.
        out : Path
            The output directory.

        Returns
        -------
        list of Path
        """
        return write_study_figures(summaries, out)

    def show(
        self, summaries: list[SettingSummary], title: str, recommended: str, written: list[Path]
    ) -> None:
        """The table, the recommendation and the files written.

        Parameters
        ----------
        summaries : list of SettingSummary
            Per setting and level.
        title : str
            The table's title.
        recommended : str
            The recommended setting and its reason, one line.
        written : list of Path
            The files written.
        """
        self.console.print(study_table(summaries, title))
        self.console.print(recommended, highlight=False)
        self.console.print("written: " + ", ".join(str(p) for p in written), highlight=False)


def _mm(x: float) -> str:
    if not math.isfinite(x):
        return "-"
    return f"{1000 * x:.0f}" if abs(x) >= 0.1 else f"{1000 * x:.1f}"


def _pm(mean: float, std: float) -> str:
    return "-" if not math.isfinite(mean) else f"{_mm(mean)}±{_mm(std)}"


def _flights(s: SettingSummary) -> str:
    """Median flights to the floor of the plants that got there, and how many did."""
    if not s.floor_m > 0:
        return "-"
    if s.reached_floor == 0:
        return "never"
    median = f"{s.flights_to_floor:g}"
    return median if s.reached_floor == s.plants else f"{median} ({s.reached_floor}/{s.plants})"


def study_table(summaries: list[SettingSummary], title: str) -> Table:
    """Every setting at every level: e_pos, floor, divergence, setpoints and limits.

    Parameters
    ----------
    summaries : list of SettingSummary
        The study's summaries.
    title : str
        Table title.

    Returns
    -------
    rich.table.Table
    """
    table = Table(title=escape(title), box=box.SIMPLE_HEAD, padding=(0, 1), pad_edge=False)
    headers = ("setting", "±", "j=0", "j=1", "steady", "floor", "div.", "u rms", "limit")
    for h in headers:
        table.add_column(h, justify="left" if h == "setting" else "right", no_wrap=h != "setting")
    for s in summaries:
        table.add_row(
            escape(s.setting),
            f"{100 * s.level:g}%",
            _mm(s.epos_mean_m[0]),
            _mm(s.epos_mean_m[1]) if len(s.epos_mean_m) > 1 else "-",
            _pm(s.steady_mean_m, s.steady_std_m),
            _flights(s),
            f"{s.diverged}/{s.plants}",
            _mm(s.setpoint_rms_m),
            f"{100 * s.limit_active:.0f}%",
        )
    table.caption = escape(
        "e_pos [mm], mean over the plants that did not diverge (steady: ± std over them) of "
        "trial 0, the first learned trial and the steady state (the last learned trials, "
        "docs/studies.md); floor: median flights until e_pos <= "
        f"{FLOOR_FACTOR:g} x the noise's own e_pos over the plants that got there (n/m: how "
        "many did; never: none); div.: diverged plants; u rms: the "
        "last setpoints' distance from the reference [mm]; limit: updates with a limit active"
    )
    return table


def write_study_figures(summaries: list[SettingSummary], out: Path) -> list[Path]:
    """``epos.png`` (e_pos per trial, one panel per level) and ``tradeoff.png``.

    The trade-off plots, per setting and level, the e_pos of the first learned trial (how fast
    the learning goes) against the steady e_pos (how far it gets), the marker's size growing
    with the diverged plants.

    Parameters
    ----------
    summaries : list of SettingSummary
        The study's summaries.
    out : Path
        Directory.

    Returns
    -------
    list of Path
        The files written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.ticker import MaxNLocator

    levels = list(dict.fromkeys(s.level for s in summaries))
    names = list(dict.fromkeys(s.setting for s in summaries))
    colours = {n: plt.get_cmap("tab10")(i % 10) for i, n in enumerate(names)}
    fig, axes = plt.subplots(1, len(levels), figsize=(5.5 * len(levels), 4.2), squeeze=False)
    for ax, level in zip(axes[0], levels, strict=True):
        for s in (s for s in summaries if s.level == level):
            mean = 1000 * np.asarray(s.epos_mean_m)
            std = 1000 * np.asarray(s.epos_std_m)
            j = np.arange(mean.size)
            ax.plot(j, mean, marker="o", ms=3, color=colours[s.setting], label=s.setting)
            low = np.maximum(mean - std, 0.0)
            ax.fill_between(j, low, mean + std, color=colours[s.setting], alpha=0.12)
        floor = next(s.floor_m for s in summaries if s.level == level)
        if floor > 0:
            ax.axhline(1000 * floor, color="k", ls=":", lw=1, label="noise floor")
        ax.set_title(f"±{100 * level:g} % uncertainty")
        ax.set_xlabel("trial j (0: the reference; the repeats of trial 0 left out)")
        ax.set_ylabel("e_pos [mm], mean ± std over the plants")
        ax.set_ylim(bottom=0.0)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # trials are whole numbers
        ax.grid(True, alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    paths = []
    for name, figure in (("epos.png", fig), ("tradeoff.png", _tradeoff(plt, summaries, colours))):
        path = out / name
        tmp = out / f".{name}.tmp"
        figure.savefig(tmp, format="png", dpi=110)
        plt.close(figure)
        os.replace(tmp, path)  # atomic: a reader never sees half a figure
        paths.append(path)
    return paths


def _tradeoff(plt: object, summaries: list[SettingSummary], colours: dict) -> object:
    fig, ax = plt.subplots(figsize=(6.5, 4.8))  # type: ignore[attr-defined]
    markers = "osD^v<>"
    levels = list(dict.fromkeys(s.level for s in summaries))
    for s in summaries:
        if len(s.epos_mean_m) < 2 or not math.isfinite(s.steady_mean_m):
            continue
        ax.scatter(
            1000 * s.epos_mean_m[1],
            1000 * s.steady_mean_m,
            s=30 + 15 * s.diverged,
            color=colours[s.setting],
            marker=markers[levels.index(s.level) % len(markers)],
            label=f"{s.setting}, ±{100 * s.level:g} %",
        )
    ax.set_xlabel("e_pos of the first learned flight [mm] (lower: faster)")
    ax.set_ylabel("steady e_pos [mm] (lower: closer)")
    ax.set_title("Speed against accuracy; larger markers: more diverged plants")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=6)
    fig.tight_layout()
    return fig
