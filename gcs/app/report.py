"""Reports of a run: the Table IV rows (rich table, JSON), figures, and one HTML file.

Percentages are always relative to trial 0 (a run whose trial 0 is missing or incomplete, or
whose e_pos,0 is zero, has no percentages and is refused); trials that are missing or
incomplete are listed, never silently left out. The figures follow the paper's (Fig. 2, 4
and 5) for both horizontal axes, and add what ILC changes: the setpoints against the
reference and the limits, the error over time, and the learned disturbance.

Every learning run also gets the setpoints' RMS distance from the reference per trial. A run
whose profile has ``learning.adaptive`` gets the rest of what learning knows: which trial is a
repeat and the paper's iteration j of each, e_pos against the floor (the repeat's) with the
verdicts "at the floor" and "converged" (docs/learning-floor.md), and the decisions of every
learning step (refresh, safeguard, noise weights) from its ``learn-JJJ.json``.
"""

from __future__ import annotations

import base64
import html
import io
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from rich.markup import escape
from rich.table import Table

from gcs.app.learn import measured_trial, run_measurement
from gcs.core.floor import Floor, FloorVerdict, floor_from_flights, floor_verdicts, identical_groups
from gcs.core.metrics import IterationMetrics, iteration_table
from gcs.core.model import relative_degree
from gcs.core.trials import iteration_of, repeat_of, setpoint_deviation, trial_errors
from gcs.errors import ProfileError, RunLogError
from gcs.io.runlog import RunDir, TrialRecord, atomic_write_text

__all__ = [
    "TrialEntry",
    "TrialLearning",
    "RunLearning",
    "run_learning",
    "decision_summary",
    "decision_lines",
    "floor_line",
    "learning_notes",
    "trial_overview",
    "trial_notes",
    "aborted_attempts",
    "run_metrics",
    "trial_clock_rates",
    "session_lines",
    "mocap_lines",
    "metrics_table",
    "metrics_json",
    "parse_iterations",
    "choose_iterations",
    "report_figures",
    "write_plots",
    "write_html",
    "complete_records",
    "figure_png",
    "save_figure",
]

AXES = (("north", 0), ("east", 1))
FIGURES = ("xy", "position", "setpoints", "error", "epos", "disturbance")


@dataclass(frozen=True)
class TrialEntry:
    """What the run directory says about one trial index.

    Parameters
    ----------
    trial : int
        Trial index j.
    status : str
        ``"complete"``, ``"incomplete"`` or ``"missing"`` (no sidecar although a later trial
        has one).
    reason : str or None
        Why an incomplete trial stopped (or what is missing).
    """

    trial: int
    status: str
    reason: str | None = None


def trial_overview(run: RunDir) -> list[TrialEntry]:
    """Every trial index from 0 to the newest on disk, with its status.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    list of TrialEntry
        By index; a gap is ``"missing"``, a CSV without its sidecar ``"incomplete"``.
    """
    statuses = {s.trial: s for s in run.statuses()}
    csv_only = {
        int(p.stem.split("-")[1])
        for p in run.path.glob("trial-[0-9][0-9][0-9].csv")
        if int(p.stem.split("-")[1]) not in statuses
    }
    last = max([*statuses, *csv_only], default=-1)
    out = []
    for j in range(last + 1):
        if j in statuses:
            s = statuses[j]
            out.append(TrialEntry(j, "complete" if s.complete else "incomplete", s.reason))
        elif j in csv_only:
            out.append(TrialEntry(j, "incomplete", f"trial-{j:03d}.csv without its .json"))
        else:
            out.append(TrialEntry(j, "missing", f"no trial-{j:03d}.json"))
    return out


def trial_notes(entries: list[TrialEntry], aborted: dict[int, int] | None = None) -> list[str]:
    """One line per trial that is not in the table (missing or incomplete), and per trial
    flown again after an incomplete attempt.

    Parameters
    ----------
    entries : list of TrialEntry
        From :func:`trial_overview`.
    aborted : dict of int to int, optional
        Incomplete attempts kept in ``aborted/``, by trial (:func:`aborted_attempts`).

    Returns
    -------
    list of str
    """
    out = []
    for e in entries:
        if e.status != "complete":
            reason = f" ({e.reason})" if e.reason else ""
            out.append(f"trial {e.trial}: {e.status}{reason}, not in the table")
    for j, n in sorted((aborted or {}).items()):
        attempts = "attempt" if n == 1 else "attempts"
        out.append(f"trial {j}: {n} earlier incomplete {attempts} kept in aborted/")
    return out


def aborted_attempts(run: RunDir) -> dict[int, int]:
    """Incomplete attempts of each trial that was flown again, kept in ``aborted/``.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    dict of int to int
        Number of attempts by trial index.
    """
    counts: dict[int, int] = {}
    for p in (run.path / "aborted").glob("trial-[0-9][0-9][0-9]-attempt-*.json"):
        j = int(p.name.split("-")[1])
        counts[j] = counts.get(j, 0) + 1
    return counts


def complete_records(run: RunDir, measurement: str | None = None) -> dict[int, TrialRecord]:
    """Every complete trial of ``run``, by index, measured as asked.

    Parameters
    ----------
    run : RunDir
        The run directory.
    measurement : str or None
        ``"mocap"`` or ``"estimate"`` (:meth:`TrialRecord.measured`); None: the run's own
        (``mocap.measurement`` of its profile, default mocap where a trial has it).

    Returns
    -------
    dict of int to TrialRecord
    """
    measurement = measurement or run_measurement(run.profile())
    return {j: measured_trial(run, j, measurement) for j in run.complete_trials()}


def mocap_lines(run: RunDir) -> list[str]:
    """With motion capture: e_pos by the mocap and by the estimate per trial, and the lag.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    list of str
        Empty when no complete trial has mocap columns.
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
        lines.insert(0, f"measurement: {run_measurement(run.profile())} (mocap.measurement)")
    return lines


def run_metrics(run: RunDir, measurement: str | None = None) -> list[IterationMetrics]:
    """Table IV rows of the complete trials of ``run`` (computed from the CSV files).

    Percentages are relative to trial 0, and the change column compares consecutive trials
    only (``-`` after a gap).

    Parameters
    ----------
    run : RunDir
        The run directory.
    measurement : str or None
        ``"mocap"`` or ``"estimate"``; None: the run's own.

    Returns
    -------
    list of IterationMetrics

    Raises
    ------
    RunLogError
        No complete trial 0 (missing or incomplete), or e_pos,0 = 0.
    """
    records = complete_records(run, measurement)
    if 0 not in records:
        what = "incomplete" if (run.path / "trial-000.json").exists() else "missing"
        raise RunLogError(
            f"{run.path}: trial 0 is {what}; e_pos,j / e_pos,0 needs it (complete trials: "
            f"{', '.join(map(str, records)) or 'none'})"
        )
    errors = {j: trial_errors(r) for j, r in records.items()}
    if not errors[0][0] > 0:
        raise RunLogError(
            f"{run.path}/trial-000.csv: e_pos,0 = 0 (the positions equal the reference); "
            "no percentages relative to it"
        )
    order = sorted(errors)
    rows = iteration_table([errors[j][0] for j in order], [errors[j][1] for j in order], order)
    return [
        r if i == 0 or order[i] - order[i - 1] == 1 else replace(r, delta_pct=None)
        for i, r in enumerate(rows)
    ]


@dataclass(frozen=True)
class TrialLearning:
    """What learning says about one complete trial.

    Parameters
    ----------
    trial : int
        Trial number (order of flight).
    iteration : int
        The paper's iteration j (learning updates before it; a repeat is j = 0).
    repeat_of : int or None
        The trial it repeats, or None.
    sp_rms_m, sp_max_m : float
        RMS and largest horizontal distance of its setpoints from the reference [m].
    verdict : FloorVerdict or None
        e_pos against the floor (None without a floor).
    record : dict or None
        The decision record of the learning step from this trial (``learn-JJJ.json``).
    """

    trial: int
    iteration: int
    repeat_of: int | None
    sp_rms_m: float
    sp_max_m: float
    verdict: FloorVerdict | None = None
    record: dict | None = None


@dataclass(frozen=True)
class RunLearning:
    """What learning says about a run.

    Parameters
    ----------
    history : bool
        The profile has ``learning.adaptive`` (every trial learned from, decisions recorded).
    repeats : int
        Repeats of trial 0.
    floor : Floor or None
        The floor, from the largest group of complete trials flown with identical setpoints.
    floor_trials : tuple of int
        The trials it was measured from.
    floor_z : float
        Threshold of the "at the floor" statistic.
    trials : dict of int to TrialLearning
        By trial number (complete trials).
    """

    history: bool
    repeats: int
    floor: Floor | None
    floor_trials: tuple[int, ...]
    floor_z: float
    trials: dict[int, TrialLearning]


def run_learning(run: RunDir, records: dict[int, TrialRecord] | None = None) -> RunLearning:
    """Setpoint deviation, iteration, repeats, floor, verdicts and decisions of every trial.

    The floor and the verdicts are computed from the trials themselves with the functions the
    learning uses (:mod:`gcs.core.floor`), so that a trial not yet learned from has its verdict
    too.

    Parameters
    ----------
    run : RunDir
        A learning run.
    records : dict of int to TrialRecord, optional
        Its complete trials, if read already (:func:`complete_records`).

    Returns
    -------
    RunLearning
    """
    records = complete_records(run) if records is None else records
    ref = run.reference().pos_ned_m
    ln = run.profile().learning
    history = ln.history and run.kind == "learning"
    repeats = ln.repeats if history else 0
    order = sorted(records)
    floor, group, verdicts = None, (), {}
    if history and len(order) > 1:
        groups = identical_groups(np.array([records[t].sp_ned_m[:-1, :2] for t in order]))
        if groups:
            group = tuple(order[i] for i in max(groups, key=len))
            floor = floor_from_flights(np.array([records[t].pos_ned_m[1:, :2] for t in group]))
            epos_all = [trial_errors(records[t])[0] for t in order]
            found = floor_verdicts(np.array(epos_all), floor, ln.adaptive.floor_z)
            verdicts = {order[i]: v for i, v in enumerate(found)}
    learned = run.learn_records() if history else {}
    trials = {}
    for t in order:
        rms, largest = setpoint_deviation(records[t].sp_ned_m[:-1], ref)
        trials[t] = TrialLearning(
            t, iteration_of(t, repeats), repeat_of(t, repeats), rms, largest,
            verdicts.get(t), learned.get(t),
        )  # fmt: skip
    return RunLearning(history, repeats, floor, group, ln.adaptive.floor_z, trials)


def floor_line(learning: RunLearning) -> str | None:
    """One line on the floor: its e_pos, scatter and RMS, the trials it came from.

    Parameters
    ----------
    learning : RunLearning
        From :func:`run_learning`.

    Returns
    -------
    str or None
        None when the run has no floor.
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

    Parameters
    ----------
    record : dict
        A ``learn-JJJ.json`` record.

    Returns
    -------
    str
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

    Parameters
    ----------
    record : dict
        A ``learn-JJJ.json`` record.

    Returns
    -------
    list of str
    """
    decision, j = record["decision"], record["trial"]
    lines = []
    guard = decision.get("safeguard")
    if isinstance(guard, dict) and guard.get("action") == "revert":
        lines.append(
            f"safeguard: trial {j} came out worse than trial {guard.get('best_trial')} "
            f"(e_pos {1e3 * _num(guard.get('epos_m')):.1f} mm > "
            f"{1e3 * _num(guard.get('threshold_m')):.1f} mm): fell back to trial "
            f"{guard.get('anchor_trial')} with step {_num(guard.get('step')):g}"
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
        if r["accepted"]:
            refresh.append(f"{name} moved {100 * _num(r.get('moved')):.0f} %")
        else:
            refresh.append(f"{name} kept ({r.get('reason')})")
    if refresh:
        lines.append(("model refreshed: " if accepted else "model kept: ") + "; ".join(refresh))
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
    """The floor, and the decisions of every learning step, as lines below the table.

    Parameters
    ----------
    learning : RunLearning
        From :func:`run_learning`.

    Returns
    -------
    list of str
    """
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


def trial_clock_rates(run: RunDir) -> dict[int, float | None]:
    """The vehicle-time / wall-time rate each trial was flown at, from the sidecars.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    dict of int to float or None
        By trial index; None where it was not recorded (runs flown before it was).
    """
    rates: dict[int, float | None] = {}
    for status in run.statuses():
        rate = (status.extra or {}).get("vehicle_time_rate")
        ok = isinstance(rate, int | float) and not isinstance(rate, bool)
        rates[status.trial] = float(rate) if ok else None
    return rates


def _num(value: Any) -> float:
    return (
        float(value) if isinstance(value, int | float) and not isinstance(value, bool) else np.nan
    )


def session_lines(run: RunDir) -> list[str]:
    """One line per flight session: trials, navigation source, hover and settle tolerances.

    Parameters
    ----------
    run : RunDir
        The run directory.

    Returns
    -------
    list of str
    """
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
) -> Table:
    """A rich table with one row per trial (the columns of the paper's Table IV, and more).

    Parameters
    ----------
    rows : list of IterationMetrics
        The rows (``iteration``: the trial number).
    title : str
        Table title.
    rates : dict of int to float or None, optional
        Vehicle-time rate per trial (:func:`trial_clock_rates`): adds a column when one is
        known.
    learning : RunLearning, optional
        What learning says (:func:`run_learning`): adds the setpoints' RMS distance from the
        reference; with ``learning.adaptive`` the trial number beside the iteration j (a
        repeat is j = 0), and with a floor e_pos / floor and the verdict; and the decisions of
        the learning step from each trial.

    Returns
    -------
    rich.table.Table
    """
    table = Table(title=title or None)
    headers, cells = _table(rows, rates, learning)
    for header in headers:
        # headers may wrap in a narrow terminal; the numbers never do
        short = header in ("j", "trial")
        table.add_column(escape(header), justify="right", min_width=len(header) if short else 6)
    for row in cells:
        table.add_row(*row)
    return table


def _table(
    rows: list[IterationMetrics],
    rates: dict[int, float | None] | None,
    learning: RunLearning | None,
) -> tuple[list[str], list[list[str]]]:
    """Headers and cells of the table (the rich table and the HTML report share them)."""
    headers = ["j", "e_pos [m]", "e_pos/e_pos0 [%]", "|Δe_pos|/prev [%]", "max err [m]"]
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
        headers += ["e_pos/floor", "verdict"]
    if history:
        headers.append("learning step")
    out = []
    for r in rows:
        delta = "-" if r.delta_pct is None else f"{r.delta_pct:.2f}"
        cells = [
            str(r.iteration), f"{r.epos_m:.4f}", f"{r.epos_pct:.2f}", delta, f"{r.max_err_m:.4f}"
        ]  # fmt: skip
        if rates is not None:
            rate = rates.get(r.iteration)
            cells.append("-" if rate is None else f"{rate:.3f}")
        if learning is not None:
            cells = _with_learning(cells, learning, r.iteration)
        out.append(cells)
    return headers, out


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
        step = "next: repeat of 0"
    else:
        step = "-"
    j = f"{t.iteration} (repeat)" if t.repeat_of is not None else str(t.iteration)
    return [str(trial), j, *cells[1:], step]


def metrics_json(
    rows: list[IterationMetrics],
    rates: dict[int, float | None] | None = None,
    entries: list[TrialEntry] | None = None,
    learning: RunLearning | None = None,
) -> list[dict]:
    """One JSON object per trial: iteration, status, epos_m, epos_pct, delta_pct, max_err_m.

    Parameters
    ----------
    rows : list of IterationMetrics
        The rows of the complete trials (``iteration``: the trial number).
    rates : dict of int to float or None, optional
        Vehicle-time rate per trial: adds the key ``vehicle_time_rate`` (null if unknown).
    entries : list of TrialEntry, optional
        Every trial (:func:`trial_overview`): missing and incomplete trials are listed too,
        with ``status``, ``reason`` and null metrics.
    learning : RunLearning, optional
        What learning says (:func:`run_learning`): adds ``trial`` (the trial number; then
        ``iteration`` is the paper's j, 0 for a repeat), ``repeat_of`` (the trial repeated,
        or null), ``sp_rms_m`` and ``sp_max_m`` (the setpoints' distance from the
        reference); with a floor ``floor_m``, ``floor_scatter_m``, ``floor_ratio``,
        ``floor_z``, ``at_floor``, ``converged``; with ``learning.adaptive`` ``learning``
        (the record of the learning step from the trial: ``learn-JJJ.json``, or null).

    Returns
    -------
    list of dict
        By trial number.
    """
    by_trial = {r.iteration: {**asdict(r), "status": "complete", "reason": None} for r in rows}
    for e in entries or []:
        if e.status != "complete":
            empty = dict.fromkeys(("epos_m", "epos_pct", "delta_pct", "max_err_m"))
            by_trial[e.trial] = {"iteration": e.trial, **empty, "status": e.status,
                                 "reason": e.reason}  # fmt: skip
    out = [by_trial[j] for j in sorted(by_trial)]
    if rates is not None:
        for row in out:
            row["vehicle_time_rate"] = rates.get(row["iteration"])
    if learning is not None:
        out = [_learning_json(row, learning) for row in out]
    return out


def _learning_json(row: dict, learning: RunLearning) -> dict:
    trial = row["iteration"]
    t = learning.trials.get(trial)
    repeats = learning.repeats
    out = {"trial": trial, **row, "iteration": iteration_of(trial, repeats),
           "repeat_of": repeat_of(trial, repeats)}  # fmt: skip
    out["sp_rms_m"] = None if t is None else t.sp_rms_m
    out["sp_max_m"] = None if t is None else t.sp_max_m
    f = learning.floor
    if f is not None:
        v = None if t is None else t.verdict
        out |= {
            "floor_m": f.epos_m, "floor_scatter_m": f.scatter_m,
            "floor_ratio": None if v is None else v.ratio, "floor_z": None if v is None else v.z,
            "at_floor": None if v is None else v.at_floor,
            "converged": None if v is None else v.converged,
        }  # fmt: skip
    if learning.history:
        out["learning"] = None if t is None else t.record
    return out


def parse_iterations(text: str) -> list[int]:
    """``"0,2,5"`` as ``[0, 2, 5]`` (sorted, unique); refused with the option's name.

    Parameters
    ----------
    text : str
        Comma-separated trial indices.

    Returns
    -------
    list of int
    """
    try:
        values = sorted({int(v) for v in text.split(",") if v.strip()})
    except ValueError:
        raise RunLogError(
            f"--iterations {text}: not a list of trial numbers (e.g. 0,2,5)"
        ) from None
    if not values or values[0] < 0:
        raise RunLogError(f"--iterations {text}: give trial numbers >= 0 (e.g. 0,2,5)")
    return values


def choose_iterations(run: RunDir, wanted: list[int] | None) -> list[int]:
    """The trials to draw: ``wanted`` (each must be complete), or 0, 1, 2 and the last.

    Parameters
    ----------
    run : RunDir
        The run directory.
    wanted : list of int or None
        From ``--iterations``.

    Returns
    -------
    list of int
    """
    done = run.complete_trials()
    if wanted is None:
        return sorted({j for j in (0, 1, 2, max(done, default=0)) if j in done})
    bad = [j for j in wanted if j not in done]
    if bad:
        raise RunLogError(
            f"--iterations: trial {bad[0]} is not a complete trial of {run.path} "
            f"(complete: {', '.join(map(str, done)) or 'none'})"
        )
    return wanted


# ------------------------------------------------------------------------------- figures


def _colors(iterations: list[int]) -> dict[int, Any]:
    import matplotlib

    cmap = matplotlib.colormaps["viridis"]
    n = max(len(iterations) - 1, 1)
    return {j: cmap(0.85 * i / n) for i, j in enumerate(iterations)}


def _fig_xy(plt: Any, ref: Any, records: dict, iterations: list[int], names: dict) -> Any:
    colors = _colors(iterations)
    fig, ax = plt.subplots(figsize=(5.6, 6.0))
    ax.plot(ref.pos_ned_m[:, 1], ref.pos_ned_m[:, 0], "k--", lw=1.6, label="reference")
    for j in iterations:
        p = records[j].pos_ned_m
        ax.plot(p[:, 1], p[:, 0], lw=1.1, color=colors[j], label=names[j])
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="center left")
    ax.set_title("Horizontal path per iteration (paper Fig. 4)")
    return fig


def _two_axes(plt: Any, title: str) -> tuple[Any, Any]:
    fig, axs = plt.subplots(2, 1, figsize=(9, 6.2), sharex=True)
    fig.suptitle(title)
    axs[1].set_xlabel("t [s]")
    for ax in axs:
        ax.grid(True, alpha=0.3)
    return fig, axs


def _fig_position(plt: Any, ref: Any, records: dict, iterations: list[int], names: dict) -> Any:
    colors = _colors(iterations)
    fig, axs = _two_axes(plt, "Position per iteration (paper Fig. 5, both axes)")
    for ax, (name, c) in zip(axs, AXES, strict=True):
        ax.plot(ref.t_s, ref.pos_ned_m[:, c], "k--", lw=1.6, label="reference")
        for j in iterations:
            r = records[j]
            ax.plot(r.t_s, r.pos_ned_m[:, c], lw=1.1, color=colors[j], label=names[j])
        ax.set_ylabel(f"{name} [m]")
    axs[0].legend(fontsize=8, ncol=len(iterations) + 1, loc="lower left")  # the hover: empty
    return fig


def _fig_setpoints(
    plt: Any, run: RunDir, ref: Any, records: dict, iterations: list[int], names: dict
) -> Any:
    profile = run.profile()
    colors = _colors(iterations)
    fig, axs = _two_axes(plt, "Setpoints flown per iteration, against the reference and limits")
    t_u = ref.t_s[:-1]
    limits = profile.arena.bounds()
    models = profile.models()
    dev = profile.learning.max_deviation_m if run.kind == "learning" else None
    for ax, (name, c) in zip(axs, AXES, strict=True):
        ax.plot(ref.t_s, ref.pos_ned_m[:, c], "k--", lw=1.6, label="reference", zorder=3)
        if dev is not None:
            r = relative_degree(models[c])
            yd = ref.pos_ned_m[:, c]
            aligned = np.concatenate([yd[r:], np.full(r - 1, yd[-1])])
            ax.fill_between(
                t_u, aligned - dev, aligned + dev, color="0.85", lw=0,
                label=f"max_deviation_m ±{dev:g} m (about yd(k+{r}))",
            )  # fmt: skip
        for j in iterations:
            sp = records[j].sp_ned_m[:-1, c]
            ax.step(t_u, sp, where="post", lw=1.0, color=colors[j], label=f"u, {names[j]}")
        for edge in limits[c]:
            ax.axhline(edge, color="C3", lw=1.2, ls=":")
        ax.plot([], [], color="C3", lw=1.2, ls=":", label="arena")
        ax.set_ylabel(f"{name} setpoint [m]")
        ax.set_ylim(limits[c][0] - 0.3, limits[c][1] + 0.3)
    # below the figure: the band and the arena leave no empty corner inside
    handles, labels = axs[0].get_legend_handles_labels()
    axs[1].legend(handles, labels, fontsize=8, ncol=4, loc="upper center",
                  bbox_to_anchor=(0.5, -0.2))  # fmt: skip
    return fig


def _fig_error(plt: Any, ref: Any, records: dict, iterations: list[int], names: dict) -> Any:
    colors = _colors(iterations)
    fig, axs = _two_axes(plt, "Tracking error per iteration (position - reference)")
    for ax, (name, c) in zip(axs, AXES, strict=True):
        for j in iterations:
            r = records[j]
            ax.plot(r.t_s, r.pos_ned_m[:, c] - ref.pos_ned_m[:, c], lw=1.0, color=colors[j],
                    label=names[j])  # fmt: skip
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_ylabel(f"{name} error [m]")
    axs[0].legend(fontsize=8, ncol=len(iterations), loc="lower left")
    return fig


def _fig_epos(
    plt: Any, rows: list[IterationMetrics], algorithm: str, learning: RunLearning | None = None
) -> Any:
    from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter

    e0 = rows[0].epos_m
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    js = [r.iteration for r in rows]  # trial numbers
    ax.semilogy(js, [r.epos_m for r in rows], "o-", color="C0", label="e_pos")
    for r in rows:
        ax.annotate(f"{r.epos_pct:.1f} %", (r.iteration, r.epos_m), textcoords="offset points",
                    xytext=(7, 3), ha="left", fontsize=8)  # fmt: skip
    low = min(r.epos_m for r in rows)
    floor = learning.floor if learning is not None else None
    if floor is not None:
        # the band a trial at the floor falls in (z <= floor_z), and the floor itself
        top = floor.epos_m + learning.floor_z * float(
            np.hypot(floor.scatter_m, floor.floor_scatter_m)
        )
        ax.axhspan(
            max(floor.epos_m - floor.scatter_m, floor.epos_m / 3),
            top,
            color="C2",
            alpha=0.15,
            lw=0,
            label=f"at the floor (z <= {learning.floor_z:g})",
        )
        ax.axhline(floor.epos_m, color="C2", lw=1.2,
                   label=f"floor {1e3 * floor.epos_m:.1f} mm (repeat)")  # fmt: skip
        low = min(low, floor.epos_m - floor.scatter_m)
    labels = [str(j) for j in js]
    if learning is not None and learning.history:
        trials = [learning.trials[t] for t in js]
        labels = [f"{t.iteration}{'r' if t.repeat_of is not None else ''}" for t in trials]
        conv = [t.trial for t in trials if t.verdict is not None and t.verdict.converged]
        if conv:
            e = {r.iteration: r.epos_m for r in rows}
            ax.plot(conv, [e[t] for t in conv], "s", mfc="none", mec="C3", ms=10,
                    label="converged")  # fmt: skip
        ax.set_xlabel("iteration j (r: a repeat of j = 0, which measures the floor)")
    else:
        ax.set_xlabel("iteration j")
    ax.set_ylabel("e_pos,j [m]")
    ax.set_xticks(js, labels)
    ax.set_xlim(min(js) - 0.4, max(js) + 0.4)
    ax.set_ylim(max(low, 1e-6) / 1.6, e0 * 1.6)
    # plain numbers on both log axes: 1-2-5 steps read better than powers of ten
    steps = [m * 10.0**e for e in range(-4, 3) for m in (1, 2, 5)]
    ax.yaxis.set_major_locator(FixedLocator(steps))
    ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="major", alpha=0.3)
    right = ax.secondary_yaxis("right", functions=(lambda m: 100 * m / e0, lambda p: p * e0 / 100))
    right.yaxis.set_major_locator(FixedLocator(steps))
    right.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    right.yaxis.set_minor_formatter(NullFormatter())
    right.set_ylabel("e_pos,j / e_pos,0 [%]")
    if floor is not None:
        ax.legend(fontsize=8, loc="upper right")
    ax.set_title(f"Average position error per iteration ({algorithm}; paper Fig. 2)")
    return fig


def _fig_disturbance(plt: Any, run: RunDir, iterations: list[int]) -> Any | None:
    estimates = {}
    for j in iterations:
        if (run.path / f"estimate-{j:03d}.csv").exists():
            estimates[j] = run.read_estimate(j)[0]
    if not estimates:
        return None
    colors = _colors(list(estimates))
    fig, axs = _two_axes(plt, "Learned repetitive disturbance D (learning coordinates)")
    t = np.arange(1, run.n_samples + 1) * run.t_ilc_s
    for ax, (name, c) in zip(axs, AXES, strict=True):
        for j, d in estimates.items():
            ax.plot(t, d[:, c], lw=1.0, color=colors[j], label=f"from trial {j}")
        ax.set_ylabel(f"d {name} [m]")
    axs[0].legend(fontsize=8, ncol=len(estimates), loc="lower left")
    return fig


def _trial_name(t: TrialLearning) -> str:
    """A trial's label in the figures of a run with repeats: its number and its j."""
    return f"trial {t.trial}, j = {t.iteration}" + (" (repeat)" if t.repeat_of is not None else "")


def report_figures(run: RunDir, iterations: list[int]) -> dict[str, Any]:
    """The report's figures, by name (matplotlib figures; the caller saves and closes them).

    ``xy``: horizontal path per iteration over the reference (paper Fig. 4); ``position``:
    north and east against time per iteration (Fig. 5, both axes); ``setpoints``: the
    setpoints flown per iteration against the reference, the ``max_deviation_m`` band and the
    arena; ``error``: position minus reference against time per iteration; ``epos``: e_pos,j
    per iteration, log scale, with its percentage of e_pos,0 (Fig. 2), and with a floor the
    band of e_pos a trial at the floor falls in; ``disturbance``: the learned D per iteration
    (only where estimates exist). In a run with repeats the trials are labelled with their
    number and their iteration j.

    Parameters
    ----------
    run : RunDir
        The run directory (trial 0 complete; see :func:`run_metrics`).
    iterations : list of int
        Complete trials to draw (:func:`choose_iterations`).

    Returns
    -------
    dict of str to matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = run_metrics(run)
    ref = run.reference()
    try:
        measurement = run_measurement(run.profile())
    except ProfileError as exc:
        raise RunLogError(f"{run.path}/manifest.json: {exc}") from None
    records = {j: measured_trial(run, j, measurement) for j in iterations}  # what learning saw
    learning = run_learning(run) if run.kind == "learning" else None
    names = {j: f"j = {j}" for j in iterations}
    if learning is not None and learning.history:
        names = {j: _trial_name(learning.trials[j]) for j in iterations}
    figures = {
        "xy": _fig_xy(plt, ref, records, iterations, names),
        "position": _fig_position(plt, ref, records, iterations, names),
        "setpoints": _fig_setpoints(plt, run, ref, records, iterations, names),
        "error": _fig_error(plt, ref, records, iterations, names),
        "epos": _fig_epos(plt, rows, run.algorithm, learning),
    }
    disturbance = _fig_disturbance(plt, run, iterations)
    if disturbance is not None:
        figures["disturbance"] = disturbance
    return figures


def write_plots(run: RunDir, out_dir: Path, iterations: list[int] | None = None) -> list[Path]:
    """Write the report's figures as PNG files ``<name>.png`` (see :func:`report_figures`).

    Parameters
    ----------
    run : RunDir
        The run directory.
    out_dir : Path
        Where to write (created if missing).
    iterations : list of int, optional
        Trials to draw (default: 0, 1, 2 and the last).

    Returns
    -------
    list of Path
    """
    chosen = choose_iterations(run, iterations)
    figures = report_figures(run, chosen)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return [save_figure(fig, out_dir / f"{name}.png") for name, fig in figures.items()]


_CAPTIONS = {
    "xy": "Horizontal path of each iteration over the reference (dashed).",
    "position": "North and east position against time: reference (dashed) and iterations.",
    "setpoints": "Setpoints flown (what ILC changes) against the reference, the "
    "max_deviation_m band the update keeps to, and the arena (dotted).",
    "error": "Position minus reference against time, per iteration and axis.",
    "epos": "e_pos,j (eq. 10) per iteration; right axis in % of e_pos,0. With a repeat of "
    "trial 0: the floor (one flight's non-repeatable error) and the band a trial at the floor "
    "falls in.",
    "disturbance": "Repetitive disturbance D estimated from each trial, per axis.",
}

_CSS = (
    "body{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}"
    "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px;"
    "text-align:right}th{background:#eee}figure{margin:1.5em 0}img{max-width:100%}"
    "figcaption{font-size:90%;color:#444}.meta td{text-align:left}"
)


def write_html(run: RunDir, path: Path, iterations: list[int] | None = None) -> Path:
    """Write one self-contained HTML report: run facts, the table, notes and every figure.

    The figures are embedded as base64 PNG; the file refers to nothing outside itself and
    can be mailed as it is.

    Parameters
    ----------
    run : RunDir
        The run directory.
    path : Path
        The HTML file (written atomically; its directory created if missing).
    iterations : list of int, optional
        Trials to draw (default: 0, 1, 2 and the last).

    Returns
    -------
    Path
    """
    rows = run_metrics(run)
    rates = trial_clock_rates(run)
    if all(rate is None for rate in rates.values()):
        rates = None
    chosen = choose_iterations(run, iterations)
    figures = {name: figure_png(fig) for name, fig in report_figures(run, chosen).items()}
    m = run.manifest
    e = html.escape
    facts = [
        ("run", str(run.path)), ("algorithm", run.algorithm),
        ("profile", str(m["profile"].get("name"))),
        ("trajectory", str(m["trajectory"].get("name"))),
        ("samples", f"{run.n_samples} at {run.t_ilc_s:g} s"),
        ("created (UTC)", str(m.get("created_utc"))), ("gcs", str(m.get("gcs_version"))),
        ("iterations drawn", ", ".join(map(str, chosen))),
    ]  # fmt: skip
    learning = run_learning(run) if run.kind == "learning" else None
    headers, cells = _table(rows, rates, learning)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>gcs report: {e(run.path.name)}</title><style>{_CSS}</style></head><body>",
        f"<h1>gcs report: {e(run.path.name)}</h1>",
        '<table class="meta">'
        + "".join(f"<tr><th>{e(k)}</th><td>{e(v)}</td></tr>" for k, v in facts)
        + "</table>",
        "<h2>Learning table (paper Table IV)</h2><table><tr>"
        + "".join(f"<th>{e(h)}</th>" for h in headers)
        + "</tr>",
        *("<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>"
          for row in cells),
        "</table>",
    ]  # fmt: skip
    notes = trial_notes(trial_overview(run), aborted_attempts(run)) + session_lines(run)
    if learning is not None:
        notes = learning_notes(learning) + notes
    if notes:
        parts.append("<ul>" + "".join(f"<li>{e(n)}</li>" for n in notes) + "</ul>")
    parts.append("<h2>Figures</h2>")
    for name, png in figures.items():
        data = base64.b64encode(png).decode("ascii")
        parts.append(
            f'<figure><img alt="{name}" src="data:image/png;base64,{data}">'
            f"<figcaption>{e(_CAPTIONS[name])}</figcaption></figure>"
        )
    parts.append("</body></html>\n")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, "\n".join(parts))
    return path


def figure_png(fig: Any) -> bytes:
    """A matplotlib figure as PNG bytes; the figure is closed.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.

    Returns
    -------
    bytes
    """
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


def save_figure(fig: Any, path: Path) -> Path:
    """Write a matplotlib figure as PNG atomically (temporary file + rename) and close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : Path
        Destination (.png).

    Returns
    -------
    Path
    """
    import matplotlib.pyplot as plt

    tmp = path.with_name(f".{path.name}.tmp.png")
    fig.tight_layout()
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)
    return path
