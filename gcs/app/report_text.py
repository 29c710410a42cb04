"""The report as text: the learning table and the lines below it (terminal and HTML alike).

The numbers come from :mod:`gcs.app.report`; :mod:`gcs.app.report_view` composes the whole
``gcs report``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from rich import box
from rich.markup import escape
from rich.table import Table

from gcs.app.report import (
    RunLearning,
    TrialEntry,
    aborted_attempts,
    change_pct,
    flown_again,
)
from gcs.core.floor import FloorVerdict
from gcs.core.metrics import IterationMetrics
from gcs.core.trials import trial_errors
from gcs.errors import RunLogError
from gcs.io.rundir import RunDir

__all__ = [
    "metrics_table",
    "table_cells",
    "trial_notes",
    "mocap_lines",
    "floor_line",
    "decision_summary",
    "decision_lines",
    "learning_notes",
    "session_lines",
    "report_notes",
    "table_legend",
    "shows_step",
]


def report_notes(run: RunDir, entries: list[TrialEntry], learning: RunLearning | None) -> list[str]:
    """The lines below the table: learning's notes, trials not in the table, sessions.

    ``learning``: what learning says, for a learning run.
    """
    notes = learning_notes(learning) if learning is not None else []
    again = trial_notes(entries, aborted_attempts(run), flown_again(run))
    return notes + again + session_lines(run)


def table_legend(learning: RunLearning | None, shown: bool = True) -> list[str]:
    """What the table's short words mean, one line under it (adaptive profiles only).

    ``shown``: the table shows the learning step column (False: a narrow terminal left it out, and
    the line says where its contents are).

    Returns: empty where the table has no learning step column.
    """
    if learning is None or not learning.history:
        return []
    if not shown:
        return [
            "learning step: too wide for this terminal; each step is told below ('after "
            "trial K: ...'), and a wider terminal or --html shows it as a column"
        ]
    return [
        "learning step: 'from K, step s' fell back to the best trial K and took the fraction s "
        "of the update (safeguard); 'model N 37 %' refreshed the north (N) or east (E) model, "
        "which moved 37 %; 'repeat of 0 next' the next trial repeats trial 0 to measure the "
        "floor (docs/report.md)"
    ]


def _num(value: Any) -> float:
    return (
        float(value) if isinstance(value, int | float) and not isinstance(value, bool) else np.nan
    )


def trial_notes(
    entries: list[TrialEntry],
    aborted: dict[int, int] | None = None,
    again: dict[int, int] | None = None,
) -> list[str]:
    """One line per trial that is not in the table (missing or incomplete), per trial flown
    again after an incomplete attempt, and per trial that flew an earlier one's setpoints.

    ``aborted``: incomplete attempts kept in ``aborted/``, by trial (:func:`aborted_attempts`).
    ``again``: the earlier trial whose setpoints a trial flew again, by trial (:func:`flown_again`).
    """
    out = []
    for e in entries:
        if e.status != "complete":
            reason = f" ({e.reason})" if e.reason else ""
            out.append(f"trial {e.trial}: {e.status}{reason}, not in the table")
    for j, n in sorted((aborted or {}).items()):
        attempts = "attempt" if n == 1 else "attempts"
        out.append(f"trial {j}: {n} earlier incomplete {attempts} kept in aborted/")
    for j, k in sorted((again or {}).items()):
        out.append(
            f"trial {j}: flew trial {k}'s setpoints again (gcs fly --again); the ones learned "
            "for it are kept in superseded/"
        )
    return out


def mocap_lines(run: RunDir) -> list[str]:
    """With motion capture: e_pos by the mocap and by the estimate per trial, and the lag.

    Returns: empty when no complete trial has mocap columns.
    """
    lines = []
    for j in run.complete_trials():
        record = run.read_trial(j)
        if record.mocap_ned_m is None:
            continue
        e_est, _ = trial_errors(record)
        try:
            e_moc = f"{trial_errors(record.measured('mocap'))[0]:.4f} m"
        except RunLogError:
            e_moc = "n/a (mocap gaps)"
        lag = _num((run.read_status(j).extra or {}).get("mocap_lag_s"))
        if not np.isfinite(lag):
            lag_text = "the estimate's lag behind the mocap not measurable"
        elif lag >= 0:
            lag_text = f"the estimate lags the mocap by {lag * 1e3:.0f} ms"
        else:
            lag_text = f"the estimate leads the mocap by {-lag * 1e3:.0f} ms"
        lines.append(
            f"trial {j}: e_pos by mocap {e_moc}, by the estimate {e_est:.4f} m; {lag_text}"
        )
    if lines:
        lines.insert(0, f"measurement: {run.profile().mocap.measurement} (mocap.measurement)")
    return lines


def floor_line(learning: RunLearning) -> str | None:
    """One line on the floor: its e_pos, scatter and RMS, the trials it came from.

    Returns: None when the run has no floor.
    """
    f = learning.floor
    if f is None:
        if learning.history and learning.repeats == 0:
            return "floor: not measured (learning.adaptive.repeats is 0)"
        return None
    trials = ", ".join(map(str, learning.floor_trials))
    return (
        f"floor (one flight's non-repeatable error, trials {trials}: identical setpoints): "
        f"e_pos {1e3 * f.epos_m:.1f} mm, scatter of one trial {1e3 * f.scatter_m:.1f} mm, "
        f"RMS {1e3 * f.rms_m:.1f} mm; 'at floor': z = (e_pos - floor) / scatter <= "
        f"{learning.floor_z:g}; 'converged': two trials at the floor, their mean within one "
        "scatter of it"
    )


def decision_summary(record: dict) -> str:
    """The decisions of one learning step in a few words (a table cell).

    ``record``: a ``learn-JJJ.json`` record.

    E.g. ``"from 3, step 0.5; model N 26 %"``, ``"-"`` when nothing beyond the update.
    """
    decision = record["decision"]
    parts = []
    guard = decision.get("safeguard")
    if isinstance(guard, dict) and guard.get("action") == "revert":
        parts.append(f"from {guard.get('anchor_trial')}, step {_num(guard.get('step')):g}")
    moved = [
        f"{name} {100 * _num(ax['refresh'].get('moved')):.0f} %"
        for name, ax in zip("NE", decision["axes"], strict=True)
        if isinstance(ax.get("refresh"), dict) and ax["refresh"]["accepted"]
    ]
    if moved:
        parts.append("model " + ", ".join(moved))
    return "; ".join(parts) or "-"


def decision_lines(record: dict) -> list[str]:
    """The decisions of one learning step in words, one line each.

    Safeguard (a fall back to the best trial), model refresh per axis (accepted and how far
    it moved, or why not), the estimate's weight of the newest trial and the noise, and the
    next trial's setpoints.

    ``record``: a ``learn-JJJ.json`` record.
    """
    decision, j = record["decision"], record["trial"]
    lines = []
    guard = decision.get("safeguard")
    if isinstance(guard, dict) and guard.get("action") == "revert":
        compared = guard.get("compared_trial", guard.get("best_trial"))
        compared_m = guard.get("compared_epos_m", guard.get("best_epos_m"))
        against = f" against {1e3 * _num(compared_m):.1f} mm" if compared_m is not None else ""
        lines.append(
            f"safeguard: trial {j} came out worse than trial {compared} "
            f"(e_pos {1e3 * _num(guard.get('epos_m')):.1f} mm{against}, "
            f"above its allowance of {1e3 * _num(guard.get('threshold_m')):.1f} mm): "
            f"fell back to trial {guard.get('anchor_trial')} with step "
            f"{_num(guard.get('step')):g}"
        )
        raised = [
            f"{name} {_num(ax.get('step')):.2f}"
            for name, ax in zip(("north", "east"), decision["axes"], strict=True)
            if _num(ax.get("step", guard.get("step"))) > _num(guard.get("step")) + 1e-6
        ]
        if raised:
            lines.append(
                "safeguard: step raised to keep the limits of the model in use (a refresh "
                "changed its delay since the best trial was learned): " + ", ".join(raised)
            )
    refresh, accepted = [], False
    for name, ax in zip(("north", "east"), decision["axes"], strict=True):
        r = ax.get("refresh")
        if not isinstance(r, dict):
            continue
        accepted |= r["accepted"]
        if r["accepted"] and str(r.get("reason", "")).startswith("taken back"):
            refresh.append(f"{name} {r['reason']}")
        elif r["accepted"]:
            refresh.append(f"{name} moved {100 * _num(r.get('moved')):.0f} %")
        else:
            refresh.append(f"{name} kept ({r.get('reason')})")
    if refresh:
        lines.append(("model refreshed: " if accepted else "model kept: ") + "; ".join(refresh))
    shared = [
        f"{name} {_num(ax.get('minmax_step')):.2f}"
        for name, ax in zip(("north", "east"), decision["axes"], strict=True)
        if _num(ax.get("minmax_step", 1.0)) < 1.0
    ]
    if shared:
        lines.append(
            "step cut: the profile's model foresees less from the refreshed model's whole "
            "update than from part of it; fraction taken " + ", ".join(shared)
        )
    noise = []
    for name, ax in zip(("north", "east"), decision["axes"], strict=True):
        n = ax.get("noise") if isinstance(ax.get("noise"), dict) else {}
        weights = n.get("weights") if isinstance(n.get("weights"), list) else []
        if n.get("method") == "data" and weights:
            noise.append(
                f"{name} newest trial's weight {_num(weights[-1]):.2f}, one flight "
                f"{1e3 * np.sqrt(max(_num(n.get('r_m2')), 0.0)):.1f} mm RMS"
            )
    if noise:
        lines.append("estimate: " + "; ".join(noise))
    sp = record["setpoints"]
    lines.append(
        f"trial {record['next_trial']} (j = {record['next_iteration']}): setpoints "
        f"{_num(sp['rms_m']):.2f} m RMS from the reference (largest {_num(sp['max_m']):.2f} m)"
    )
    return lines


def learning_notes(learning: RunLearning) -> list[str]:
    """The floor, and the decisions of every learning step, as lines below the table."""
    out = [line for line in (floor_line(learning),) if line is not None]
    for t in learning.trials.values():
        if t.record is not None:
            out.append(f"after trial {t.trial}: " + "; ".join(decision_lines(t.record)))
    converged = [t.trial for t in learning.trials.values() if t.verdict and t.verdict.converged]
    if converged:
        out.append(
            f"learning has converged at trial {converged[0]}: further trials cannot show an "
            "improvement over the floor"
        )
    return out


def session_lines(run: RunDir) -> list[str]:
    """One line per flight session: trials, navigation source, hover and settle tolerances."""
    lines = []
    for s in run.sessions():
        nav = s.get("navigation")
        nav = nav.get("source", "unknown") if isinstance(nav, dict) else "unknown"
        line = f"session {s.get('session')} (from trial {s.get('first_trial')}): navigation {nav}"
        hovers = s.get("hovers")
        if isinstance(hovers, list) and hovers and isinstance(hovers[0], dict):
            stats = hovers[0].get("stats")
            stats = stats if isinstance(stats, dict) else {}
            line += (
                f"; hover {_num(stats.get('offset_m')):.2f} m off, at most "
                f"{_num(stats.get('distance_max_m')):.2f} m, "
                f"{100 * _num(stats.get('noise_m')):.1f} cm fast noise"
            )
        tolerance = s.get("tolerance_m")
        if tolerance is not None:
            line += f"; settle tolerance {_num(tolerance):.2f} m"
        lines.append(line)
    return lines


def metrics_table(
    rows: list[IterationMetrics],
    title: str = "",
    rates: dict[int, float | None] | None = None,
    learning: RunLearning | None = None,
    width: int | None = None,
    three_d: bool = False,
) -> Table:
    """A rich table with one row per trial (the columns of the paper's Table IV, and more).

    ``rows``: the rows (``iteration``: the trial number). ``rates``: vehicle-time rate per trial
    (:func:`trial_clock_rates`): adds a column when one is known. ``learning``: what learning says
    (:func:`run_learning`): adds the setpoints' RMS distance from the reference; with
    ``learning.adaptive`` the trial number beside the iteration j (a repeat is j = 0), and with a
    floor e_pos / floor and the verdict; and the decisions of the learning step from each trial.
    ``width``: the width it will be printed at (a console's): where the headers on one line do not
    fit, they wrap at spaces (the adaptive table fits 80 columns). ``three_d``: add the 3-D e_pos
    and the down axis's RMS error (:func:`gcs.app.report.is_three_d`).
    """
    # narrow: no vertical rules, one space between columns (the adaptive table fits 80
    # columns); a narrower terminal wraps the headers and the learning step at spaces, a
    # number is never broken and nothing is cut to "…"
    table = Table(
        title=escape(title) if title else None,
        box=box.SIMPLE_HEAD,
        padding=(0, 0),
        pad_edge=False,
        show_edge=False,
    )
    headers, cells = table_cells(rows, rates, learning, three_d)
    if _drops_step(headers, cells, width):  # said in words below the table instead
        at = headers.index("learning step")
        headers, cells = headers[:at], [row[:at] for row in cells]
    natural = [max([len(h), *(len(row[i]) for row in cells)]) for i, h in enumerate(headers)]
    narrow = width is not None and sum(natural) + len(natural) - 1 > width
    # "0 (repeat)" stays on one line wherever the table fits with it so
    split_j = width is not None and _least_width(headers, cells, split_j=False) > width
    for i, header in enumerate(headers):
        column = [row[i] for row in cells]
        words = max(len(w) for w in header.split())
        if header == "learning step" or (header == "j" and split_j):
            least = max([words, *(len(w) for c in column for w in c.split())])
        else:
            least = max([words, *map(len, column)])
        most = None if header == "learning step" else (least if narrow else natural[i])
        table.add_column(
            escape(header),
            justify="left" if header == "learning step" else "right",
            overflow="fold",
            min_width=least,
            max_width=most,
        )
    for row in cells:
        table.add_row(*row)
    return table


def shows_step(
    rows: list[IterationMetrics],
    rates: dict[int, float | None] | None,
    learning: RunLearning | None,
    width: int | None,
    three_d: bool = False,
) -> bool:
    """Whether :func:`metrics_table` at ``width`` shows the learning step column.

    ``rows``, ``rates``, ``learning``, ``three_d``: as for :func:`metrics_table`. ``width``: the
    console's width.
    """
    headers, cells = table_cells(rows, rates, learning, three_d)
    return "learning step" in headers and not _drops_step(headers, cells, width)


def _least_width(headers: list[str], cells: list[list[str]], split_j: bool = True) -> int:
    """The narrowest the table gets: headers folded at spaces, one space between columns."""
    least = []
    for i, header in enumerate(headers):
        column = [row[i] for row in cells]
        words = max(len(w) for w in header.split())
        split = header == "learning step" or (header == "j" and split_j)
        least.append(
            max([words, *((len(w) for c in column for w in c.split()) if split else
                         map(len, column))])
        )  # fmt: skip
    return sum(least) + len(least) - 1


def _drops_step(headers: list[str], cells: list[list[str]], width: int | None) -> bool:
    """True when the learning step column would wrap a cell at ``width``: the table then
    leaves it out and the lines below it ("after trial K: ...") say the same in words."""
    if width is None or "learning step" not in headers:
        return False
    at = headers.index("learning step")
    longest = max((len(row[at]) for row in cells), default=0)
    rest = _least_width(headers[:at], [row[:at] for row in cells])
    return rest + 1 + max(longest, len("learning")) > width


def table_cells(
    rows: list[IterationMetrics],
    rates: dict[int, float | None] | None,
    learning: RunLearning | None,
    three_d: bool = False,
    every_axis: bool = False,
) -> tuple[list[str], list[list[str]]]:
    """Headers and cells of the table (the rich table and the HTML report share them).

    The headers are short enough for 80 columns; each is defined in docs/report.md.

    ``rows``: the rows (``iteration``: the trial number). ``rates``: vehicle-time rate per trial (a
    column when one is known). ``three_d``: add the columns ``e3d [m]`` (3-D e_pos) and ``rms D
    [m]`` (down's RMS error). ``every_axis``: with ``three_d``, north's and east's RMS error as well
    (``rms N [m]``, ``rms E [m]``; the HTML report, where 80 columns do not bind).

    Returns: ``cells``: one list per row, as many cells as headers.
    """
    headers = ["j", "e_pos [m]", "e/e0 [%]", "change [%]", "max err [m]"]
    if three_d:
        headers += ["e3d [m]", "rms N [m]", "rms E [m]", "rms D [m]"][:: 1 if every_axis else 3]
    if rates is not None and all(rate is None for rate in rates.values()):
        rates = None  # a run flown before rates were recorded
    if rates is not None:
        headers.append("clock [x]")
    history = learning is not None and learning.history
    floor = learning.floor if learning is not None else None
    if history:
        headers.insert(0, "trial")
    if learning is not None:
        headers.append("sp RMS [m]")
    if floor is not None:
        headers += ["e/floor", "verdict"]
    if history:
        headers.append("learning step")
    out = []
    changes = change_pct(rows)
    for r in rows:
        change = changes[r.iteration]
        delta = "-" if change is None else f"{change:+.2f}"
        cells = [
            str(r.iteration), f"{r.epos_m:.4f}", f"{r.epos_pct:.2f}", delta, f"{r.max_err_m:.4f}"
        ]  # fmt: skip
        if three_d:
            rms = [r.rms_north_m, r.rms_east_m] if every_axis else []
            cells += [_metre(r.epos_3d_m), *map(_metre, rms), _metre(r.rms_down_m)]
        if rates is not None:
            rate = rates.get(r.iteration)
            cells.append("-" if rate is None else f"{rate:.3f}")
        if learning is not None:
            cells = _with_learning(cells, learning, r.iteration)
        out.append(cells)
    return headers, out


def _metre(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f}"


def _verdict_word(v: FloorVerdict | None) -> str:
    if v is None or not v.at_floor:
        return "-"
    return "converged" if v.converged else "at floor"


def _with_learning(cells: list[str], learning: RunLearning, trial: int) -> list[str]:
    """A row's cells with what learning says about the trial (see :func:`metrics_table`)."""
    t = learning.trials[trial]
    cells = [*cells, f"{t.sp_rms_m:.3f}"]
    if learning.floor is not None:
        v = t.verdict
        cells += ["-" if v is None else f"{v.ratio:.2f}", _verdict_word(v)]
    if not learning.history:
        return cells
    if t.record is not None:
        step = decision_summary(t.record)
    elif trial < learning.repeats:
        step = "repeat of 0 next"
    else:
        step = "-"
    j = f"{t.iteration} (repeat)" if t.repeat_of is not None else str(t.iteration)
    return [str(trial), j, *cells[1:], step]
