"""The report as one self-contained HTML file: run facts, the table, notes and every figure."""

from __future__ import annotations

import base64
import html
from collections.abc import Callable
from pathlib import Path

from gcs.app.figures import figure_png
from gcs.app.report import (
    choose_iterations,
    is_three_d,
    run_facts,
    run_learning,
    run_metrics,
    run_verdict,
    trial_clock_rates,
    trial_overview,
)
from gcs.app.report_figures import CAPTIONS, report_figures
from gcs.app.report_text import report_notes, table_cells, table_legend
from gcs.io.atomic import atomic_write_text
from gcs.io.rundir import RunDir

__all__ = ["write_html"]


_CSS = (
    "body{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}"
    "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px;"
    "text-align:right}th{background:#eee}figure{margin:1.5em 0}img{max-width:100%}"
    "figcaption{font-size:90%;color:#444}.verdict{font-size:110%;margin:.3em 0}"
    ".meta td,td.words,th.words{text-align:left}"
)


def write_html(
    run: RunDir,
    path: Path,
    iterations: list[int] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Write one self-contained HTML report: run facts, the table, notes and every figure.

    The figures are embedded as base64 PNG; the file refers to nothing outside itself and
    can be mailed as it is.

    ``path``: the HTML file (written atomically; its directory created if missing). ``iterations``:
    trials to draw (default: 0, 1, 2 and the last). ``progress``: told ``(done, total)`` figures as
    they are drawn.
    """
    rows = run_metrics(run)
    rates = trial_clock_rates(run)
    if all(rate is None for rate in rates.values()):
        rates = None
    chosen = choose_iterations(run, iterations)
    figures = {name: figure_png(fig) for name, fig in report_figures(run, chosen, progress).items()}
    run_info = run_facts(run)
    e = html.escape
    facts = [
        ("run", run_info.run_id), ("directory", run_info.path),
        ("algorithm", run_info.algorithm), ("profile", run_info.profile),
        ("trajectory", run_info.trajectory),
        ("mock seed", run_info.seed_text().split(" ", 1)[1]),
        ("samples", f"{run_info.n_samples} at {run_info.t_ilc_s:g} s"),
        ("created (UTC)", run_info.created_utc), ("gcs", run_info.gcs_version),
        ("iterations drawn", ", ".join(map(str, chosen))),
    ]  # fmt: skip
    learning = run_learning(run) if run.kind == "learning" else None
    three_d = run.kind == "learning" and is_three_d(run)
    verdict = run_verdict(rows, learning).lines() if learning is not None else []
    headers, cells = table_cells(rows, rates, learning, three_d, every_axis=True)
    # words read from the left, numbers from the right
    words = [' class="words"' if h in ("verdict", "learning step") else "" for h in headers]
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>gcs report: {e(run_info.title())}</title><style>{_CSS}</style></head><body>",
        f"<h1>gcs report: {e(run_info.run_id)}</h1>",
        *(f'<p class="verdict">{e(line.removeprefix("verdict: "))}</p>' for line in verdict),
        '<table class="meta">'
        + "".join(f"<tr><th>{e(k)}</th><td>{e(v)}</td></tr>" for k, v in facts)
        + "</table>",
        "<h2>Learning table (paper Table IV)</h2><table><tr>"
        + "".join(f"<th{words[i]}>{e(h)}</th>" for i, h in enumerate(headers))
        + "</tr>",
        *("<tr>" + "".join(f"<td{words[i]}>{e(c)}</td>" for i, c in enumerate(row)) + "</tr>"
          for row in cells),
        "</table>",
    ]  # fmt: skip
    notes = table_legend(learning) + report_notes(run, trial_overview(run), learning)
    if notes:
        parts.append("<ul>" + "".join(f"<li>{e(n)}</li>" for n in notes) + "</ul>")
    parts.append("<h2>Figures</h2>")
    for name, png in figures.items():
        data = base64.b64encode(png).decode("ascii")
        parts.append(
            f'<figure id="{name}"><img alt="{name}" src="data:image/png;base64,{data}">'
            f"<figcaption>{e(CAPTIONS[name])}</figcaption></figure>"
        )
    parts.append("</body></html>\n")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, "\n".join(parts))
    return path
