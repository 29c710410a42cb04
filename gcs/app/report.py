"""What a run's report says, as data: provenance, the Table IV rows, learning, the JSON document.

Percentages are always relative to trial 0 (a run whose trial 0 is missing or incomplete, or
whose e_pos,0 is zero, has no percentages and is refused); trials that are missing or
incomplete are listed, never silently left out. Every learning run also gets the setpoints'
RMS distance from the reference per trial. A run whose profile has ``learning.adaptive`` gets
the rest of what learning knows: which trial is a repeat and the paper's iteration j of each,
e_pos against the floor (the repeat's) with the verdicts "at the floor" and "converged"
(docs/learning-floor.md), and the decisions of every learning step from its
``learn-JJJ.json``.

The text is :mod:`gcs.app.report_text`, the figures :mod:`gcs.app.report_figures`, the HTML
file :mod:`gcs.app.report_html`, all composed by :mod:`gcs.app.report_view`; the JSON
document's schema is in docs/report.md.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from gcs.app.learn import Prediction, trial_prediction
from gcs.core.floor import (
    Floor,
    FloorDrift,
    FloorVerdict,
    floor_drift,
    floor_flights,
    floor_from_flights,
    floor_verdicts,
)
from gcs.core.learning import AdaptiveSettings
from gcs.core.metrics import IterationMetrics, iteration_table, start_offset
from gcs.core.trials import (
    iteration_of,
    repeat_of,
    setpoint_deviation,
    trial_errors,
    trial_errors_3d,
)
from gcs.errors import RunLogError
from gcs.io.records import TrialRecord, json_safe
from gcs.io.rundir import RunDir

__all__ = [
    "REPORT_FORMAT",
    "REPORT_VERSION",
    "RunFacts",
    "run_facts",
    "TrialEntry",
    "TrialLearning",
    "RunLearning",
    "run_learning",
    "trial_overview",
    "aborted_attempts",
    "flown_again",
    "drift_sentence",
    "run_metrics",
    "is_three_d",
    "METRIC_KEYS",
    "change_pct",
    "trial_clock_rates",
    "metrics_json",
    "report_document",
    "rounded",
    "parse_iterations",
    "choose_iterations",
    "complete_records",
    "Verdict",
    "run_verdict",
    "VERDICT_FIT_TRIALS",
]

#: The ``format`` and ``version`` fields of ``gcs report --json`` (docs/report.md).
REPORT_FORMAT, REPORT_VERSION = "gcs-report", 6

#: Significant digits of every number in the JSON document.
JSON_DIGITS = 9


@dataclass(frozen=True)
class RunFacts:
    """Where a report comes from: the run and what it was flown with.

    ``run_id``: the run directory's own name (``logs/latest`` resolved to the run it points at).
    ``algorithm``: ``smoother``, ``kilc`` or ``identify``. ``profile``, ``trajectory``: names of the
    profile and the trajectory recorded in the manifest. ``seeds``: the mock drone's seed of each
    flight session, in order (empty on a real vehicle, or where it was not recorded).
    ``created_utc``: when the run was created (ISO 8601, UTC). ``t_ilc_s``: sample time of the
    learning grid [s].
    """

    run_id: str
    path: str
    algorithm: str
    profile: str
    trajectory: str
    seeds: tuple[int, ...]
    gcs_version: str
    created_utc: str
    n_samples: int
    t_ilc_s: float

    def title(self) -> str:
        """The report's title: run id, algorithm, profile, trajectory, seed and gcs version."""
        return (
            f"{self.run_id} ({self.algorithm}) · profile {self.profile} · trajectory "
            f"{self.trajectory} · {self.seed_text()} · gcs {self.gcs_version}"
        )

    def seed_text(self) -> str:
        """``"seed 3"``, ``"seeds 3, 4"`` (one per session) or ``"seed -"`` (none recorded)."""
        if not self.seeds:
            return "seed -"
        unique = list(dict.fromkeys(self.seeds))
        return ("seed " if len(unique) == 1 else "seeds ") + ", ".join(map(str, unique))


def run_facts(run: RunDir) -> RunFacts:
    """The provenance of ``run`` from its manifest and session records.

    ``run``: the run directory (``logs/latest`` is resolved to the run it points at).
    """
    m = run.manifest
    seeds = tuple(
        s["mock_seed"]
        for s in run.sessions()
        if isinstance(s.get("mock_seed"), int) and not isinstance(s.get("mock_seed"), bool)
    )
    return RunFacts(
        run_id=run.path.resolve().name,
        path=str(run.path),
        algorithm=run.algorithm,
        profile=str(m["profile"].get("name")),
        trajectory=str(m["trajectory"].get("name")),
        seeds=seeds,
        gcs_version=str(m.get("gcs_version")),
        created_utc=str(m.get("created_utc")),
        n_samples=run.n_samples,
        t_ilc_s=run.t_ilc_s,
    )


@dataclass(frozen=True)
class TrialEntry:
    """What the run directory says about one trial index.

    ``status``: ``"complete"``, ``"incomplete"`` or ``"missing"`` (no sidecar although a later trial
    has one). ``reason``: why an incomplete trial stopped (or what is missing).
    """

    trial: int
    status: str
    reason: str | None = None


def trial_overview(run: RunDir) -> list[TrialEntry]:
    """Every trial index from 0 to the newest on disk, with its status.

    Returns: by index; a gap is ``"missing"``, a CSV without its sidecar ``"incomplete"``.
    """
    statuses = {s.trial: s for s in run.statuses()}
    csv_only = {j for j in run.csv_trials() if j not in statuses}
    last = max([*statuses, *csv_only], default=-1)
    out = []
    for j in range(last + 1):
        if j in statuses:
            s = statuses[j]
            out.append(TrialEntry(j, "complete" if s.complete else "incomplete", s.reason))
        elif j in csv_only:
            reason = f"{run.trial_path(j).name} without its .json"
            out.append(TrialEntry(j, "incomplete", reason))
        else:
            out.append(TrialEntry(j, "missing", f"no {run.status_path(j).name}"))
    return out


def aborted_attempts(run: RunDir) -> dict[int, int]:
    """Incomplete attempts of each trial that was flown again, kept in ``aborted/``."""
    return run.aborted_attempts()


def flown_again(run: RunDir) -> dict[int, int]:
    """Trials that flew an earlier trial's setpoints again (``gcs fly --again``)."""
    out = {}
    for j in run.again_trials():
        k = run.again_of(j)
        if k is not None:
            out[j] = k
    return out


def complete_records(run: RunDir, measurement: str | None = None) -> dict[int, TrialRecord]:
    """Every complete trial of ``run``, by index, measured as asked.

    ``measurement``: ``"mocap"`` or ``"estimate"`` (:meth:`TrialRecord.measured`); None: the run's
    own (``mocap.measurement`` of its profile, default mocap where a trial has it).
    """
    measurement = measurement or run.profile().mocap.measurement
    return {j: run.measured_trial(j, measurement) for j in run.complete_trials()}


def run_metrics(run: RunDir, measurement: str | None = None) -> list[IterationMetrics]:
    """Table IV rows of the complete trials of ``run`` (computed from the CSV files).

    Percentages are relative to trial 0, and the change column compares consecutive trials
    only (``-`` after a gap).

    ``measurement``: ``"mocap"`` or ``"estimate"``; None: the run's own.

    Raises ``RunLogError``: no complete trial 0 (missing or incomplete), or e_pos,0 = 0.
    """
    records = complete_records(run, measurement)
    if 0 not in records:
        what = "incomplete" if run.status_path(0).exists() else "missing"
        raise RunLogError(
            f"{run.path}: trial 0 is {what}; e_pos,j / e_pos,0 needs it (complete trials: "
            f"{', '.join(map(str, records)) or 'none'})"
        )
    errors = {j: trial_errors(r) for j, r in records.items()}
    if not errors[0][0] > 0:
        raise RunLogError(
            f"{run.trial_path(0)}: e_pos,0 = 0 (the positions equal the reference); "
            "no percentages relative to it"
        )
    order = sorted(errors)
    rows = iteration_table([errors[j][0] for j in order], [errors[j][1] for j in order], order)
    out = []
    for i, r in enumerate(rows):
        record = records[r.iteration]
        e3, rms_n, rms_e, rms_d = trial_errors_3d(record)
        start_m = start_offset(record.ref_ned_m[:, :2], record.pos_ned_m[:, :2])
        r = replace(r, epos_3d_m=e3, rms_north_m=rms_n, rms_east_m=rms_e, rms_down_m=rms_d,
                    start_offset_m=start_m)  # fmt: skip
        out.append(r if i == 0 or order[i] - order[i - 1] == 1 else replace(r, delta_pct=None))
    return out


def is_three_d(run: RunDir) -> bool:
    """True when the run learns down or its reference moves vertically: its table and live
    lines then show the 3-D e_pos and the down RMS beside eq. (10)'s horizontal e_pos.
    """
    if 2 in run.profile().learning.axes:
        return True
    return bool(np.ptp(run.reference().pos_ned_m[:, 2]) > 0.0)


@dataclass(frozen=True)
class TrialLearning:
    """What learning says about one complete trial.

    ``iteration``: the paper's iteration j (learning updates before it; a repeat is j = 0).
    ``repeat_of``: the trial it repeats, or None. ``sp_rms_m``, ``sp_max_m``: RMS and largest
    horizontal distance of its setpoints from the reference [m]. ``verdict``: e_pos against the
    floor (None without a floor). ``record``: the decision record of the learning step from this
    trial (``learn-JJJ.json``). ``prediction``: what the step before it predicted of it (None
    for trial 0, a repeat, a trial flying another's setpoints again, or a step without an
    estimate on file).
    """

    trial: int
    iteration: int
    repeat_of: int | None
    sp_rms_m: float
    sp_max_m: float
    verdict: FloorVerdict | None = None
    record: dict | None = None
    prediction: Prediction | None = None


@dataclass(frozen=True)
class RunLearning:
    """What learning says about a run.

    ``history``: the profile has ``learning.adaptive`` (every trial learned from, decisions
    recorded). ``repeats``: repeats of trial 0. ``floor``: the floor, from trial 0 and its repeats
    (:func:`gcs.core.floor.floor_flights`). ``floor_z``: threshold of the "at the floor" statistic.
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

    ``records``: its complete trials, if read already (:func:`complete_records`).
    """
    records = complete_records(run) if records is None else records
    ref = run.reference().pos_ned_m
    profile = run.profile()
    ln = profile.learning
    history = ln.adaptive is not None and run.kind == "learning"
    floor_z = (ln.adaptive or AdaptiveSettings()).floor_z
    repeats = ln.repeats if history else 0
    order = sorted(records)
    floor, group, verdicts = None, (), {}
    if history and len(order) > 1:
        sp_all = np.array([records[t].sp_ned_m[:-1, :2] for t in order])
        flights = floor_flights(sp_all)
        if flights:
            group = tuple(order[i] for i in flights)
            floor = floor_from_flights(np.array([records[t].pos_ned_m[1:, :2] for t in group]))
            epos_all = [trial_errors(records[t])[0] for t in order]
            found = floor_verdicts(np.array(epos_all), floor, floor_z, sp_all)
            verdicts = {order[i]: v for i, v in enumerate(found)}
    learned = run.learn_records() if history else {}
    trials = {}
    for t in order:
        rms, largest = setpoint_deviation(records[t].sp_ned_m[:-1], ref)
        trials[t] = TrialLearning(
            t, iteration_of(t, repeats), repeat_of(t, repeats), rms, largest,
            verdicts.get(t), learned.get(t),
            trial_prediction(run, profile, t, records[t], learned.get(t - 1)),
        )  # fmt: skip
    return RunLearning(history, repeats, floor, group, floor_z, trials)


def trial_clock_rates(run: RunDir) -> dict[int, float | None]:
    """The vehicle-time / wall-time rate each trial was flown at, from the sidecars.

    Returns: by trial index; None where it was not recorded (runs flown before it was).
    """
    rates: dict[int, float | None] = {}
    for status in run.statuses():
        rate = (status.extra or {}).get("vehicle_time_rate")
        ok = isinstance(rate, int | float) and not isinstance(rate, bool)
        rates[status.trial] = float(rate) if ok else None
    return rates


#: The metric keys of a JSON row (null for a trial that is not complete).
METRIC_KEYS = (
    "epos_m", "epos_pct", "change_pct", "max_err_m", "epos_3d_m", "rms_north_m", "rms_east_m",
    "rms_down_m", "start_offset_m",
)  # fmt: skip


def metrics_json(
    rows: list[IterationMetrics],
    rates: dict[int, float | None] | None = None,
    entries: list[TrialEntry] | None = None,
    learning: RunLearning | None = None,
) -> list[dict]:
    """One JSON object per trial: iteration, status, epos_m, epos_pct, change_pct, max_err_m,
    epos_3d_m, rms_north_m, rms_east_m, rms_down_m, start_offset_m (every key is defined in
    docs/report.md).

    Table IV's unsigned change (``IterationMetrics.delta_pct``) is not a key: ``change_pct``
    carries the same number with its sign (version 3 of the document).

    ``rows``: the rows of the complete trials (``iteration``: the trial number). ``rates``:
    Vehicle-time rate per trial: adds the key ``vehicle_time_rate`` (null if unknown). ``entries``:
    every trial (:func:`trial_overview`): missing and incomplete trials are listed too, with
    ``status``, ``reason`` and null metrics. ``learning``: what learning says
    (:func:`run_learning`): adds ``trial`` (the trial number; then ``iteration`` is the paper's j, 0
    for a repeat), ``repeat_of`` (the trial repeated, or null), ``sp_rms_m`` and ``sp_max_m`` (the
    setpoints' distance from the reference); with a floor ``floor_m``, ``floor_scatter_m``,
    ``floor_ratio``, ``floor_z``, ``at_floor``, ``converged``; with ``learning.adaptive``
    ``learning`` (the record of the learning step from the trial: ``learn-JJJ.json``, or null).
    """
    changes = change_pct(rows)
    by_trial = {
        r.iteration: {**_without_delta(asdict(r)), "change_pct": changes[r.iteration],
                      "status": "complete", "reason": None}
        for r in rows
    }  # fmt: skip
    for e in entries or []:
        if e.status != "complete":
            empty = dict.fromkeys(METRIC_KEYS)
            by_trial[e.trial] = {"iteration": e.trial, **empty, "status": e.status,
                                 "reason": e.reason}  # fmt: skip
    out = [by_trial[j] for j in sorted(by_trial)]
    if rates is not None:
        for row in out:
            row["vehicle_time_rate"] = rates.get(row["iteration"])
    if learning is not None:
        out = [_learning_json(row, learning) for row in out]
    return out


def _without_delta(row: dict) -> dict:
    row.pop("delta_pct", None)
    return row


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
    pr = None if t is None else t.prediction
    out["predicted_epos_m"] = None if pr is None else pr.predicted_epos_m
    out["prediction_miss_m"] = None if pr is None else pr.miss_m
    out["limits_active"] = None if pr is None else pr.limits_active
    if f is not None:
        out["prediction_miss_ratio"] = None if pr is None else pr.miss_m / f.epos_m
        out["prediction_noise_ratio"] = None if pr is None else pr.noise_ratio
    if learning.history:
        out["learning"] = None if t is None else t.record
    return out


def parse_iterations(text: str) -> list[int]:
    """``"0,2,5"`` as ``[0, 2, 5]`` (sorted, unique); refused with the option's name."""
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

    ``wanted``: from ``--iterations``.
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


def change_pct(rows: list[IterationMetrics]) -> dict[int, float | None]:
    """The signed change of e_pos from the previous trial, by trial.

    Table IV's column is ``|Δe_pos|``: an improvement and a worse trial read alike. This is
    ``100 (e_pos,j - e_pos,j-1) / e_pos,j-1``: negative is better, positive worse.

    ``rows``: from :func:`run_metrics` (``delta_pct`` None after a gap).

    Returns the change [%] by trial number; None for trial 0 and after a gap.
    """
    out: dict[int, float | None] = {}
    for i, r in enumerate(rows):
        prev = rows[i - 1] if i > 0 else None
        ok = prev is not None and r.delta_pct is not None
        out[r.iteration] = 100.0 * (r.epos_m - prev.epos_m) / prev.epos_m if ok else None
    return out


def rounded(value: Any, digits: int = JSON_DIGITS) -> Any:
    """``value`` as strict JSON with every float to ``digits`` significant digits.

    Returns: NaN and infinities as None (``100.00000000000001`` becomes ``100.0``).
    """
    value = json_safe(value)
    if isinstance(value, dict):
        return {k: rounded(v, digits) for k, v in value.items()}
    if isinstance(value, list):
        return [rounded(v, digits) for v in value]
    if isinstance(value, float) and math.isfinite(value):
        return float(f"{value:.{digits}g}")
    return value


def report_document(
    run: RunDir,
    rows: list[IterationMetrics],
    rates: dict[int, float | None] | None = None,
    entries: list[TrialEntry] | None = None,
    learning: RunLearning | None = None,
) -> dict[str, Any]:
    """The JSON document of ``gcs report --json`` (schema: docs/report.md).

    Returns: ``format`` ("gcs-report"), ``version`` (3), ``run`` (:class:`RunFacts` as an object),
    ``verdict`` (:class:`Verdict` as an object, null for an identification run) and ``rows``
    (:func:`metrics_json`), numbers rounded (:func:`rounded`).
    """
    verdict = run_verdict(rows, learning) if run.kind == "learning" else None
    return rounded(
        {
            "format": REPORT_FORMAT,
            "version": REPORT_VERSION,
            "run": asdict(run_facts(run)),
            "verdict": None if verdict is None else verdict.as_dict(),
            "rows": metrics_json(rows, rates, entries, learning),
        }
    )


#: Trials (newest first) the estimate of the flights left is fitted on.
VERDICT_FIT_TRIALS = 4


@dataclass(frozen=True)
class Verdict:
    """The run in plain words: what was learned, how far above the floor, converged or not,
    and how many flights are likely left.

    ``first_epos_m``: e_pos of trial 0 (the reference flown as setpoints) [m]. ``best_trial``: the
    complete trial with the smallest e_pos. ``best_epos_m``: its e_pos [m]. ``best_updates``:
    learning updates before it (the paper's iteration j). ``change_pct``: 100 (best - first) / first
    [%]: negative is better. ``last_epos_m``: its e_pos [m]. ``floor_m``: the floor, when the run
    measured one (repeats of trial 0) [m]. ``floor_z``: the best trial's z = (e_pos - floor) /
    scatter. ``floor_z_max``: the z of the verdict "at floor" (``learning.adaptive.floor_z``).
    ``converged_trial``: the first trial with the verdict "converged". ``flights_left``: likely
    flights until "converged" (0 when converged); None when it cannot be estimated.
    ``flights_left_how``: how ``flights_left`` was estimated, or why it cannot be. ``drift_trials``:
    the newest trials, above the floor after an earlier trial reached it
    (:func:`gcs.core.floor.floor_drift`); empty when learning did not drift up.
    ``drift_reached_trial``: the first trial at the floor, when it drifted. ``drift_best_trial``:
    the trial at the floor with the smallest e_pos, when it drifted: its setpoints are the ones
    worth flying again. ``prediction_trial``: the newest trial the learning step before it
    predicted (:class:`Prediction`), None if none; ``prediction``: that prediction.
    """

    flights: int
    first_epos_m: float
    best_trial: int
    best_epos_m: float
    best_updates: int
    change_pct: float
    last_trial: int
    last_epos_m: float
    floor_m: float | None
    floor_ratio: float | None
    floor_z: float | None
    floor_z_max: float
    converged_trial: int | None
    flights_left: int | None
    flights_left_how: str
    drift_trials: list[int] = field(default_factory=list)
    drift_reached_trial: int | None = None
    drift_best_trial: int | None = None
    prediction_trial: int | None = None
    prediction: Prediction | None = None

    def lines(self) -> list[str]:
        """The verdict as a few lines of plain words (terminal and HTML)."""
        flights = f"{self.flights} flight" + ("s" if self.flights != 1 else "")
        updates = f"{self.best_updates} learning update" + ("s" if self.best_updates != 1 else "")
        out = [
            f"verdict: e_pos {_mm(self.first_epos_m)} at trial 0 -> {_mm(self.best_epos_m)} at "
            f"trial {self.best_trial} ({self.change_pct:+.1f} %, after {updates}); "
            f"{flights} in all"
        ]
        if self.last_trial != self.best_trial:
            out.append(
                f"verdict: the newest trial {self.last_trial} flew {_mm(self.last_epos_m)}, "
                f"not the best"
            )
        if self.floor_m is None:
            out.append(
                "verdict: floor not measured (no repeat of trial 0: the paper's profile); how "
                "close learning came to what the vehicle can repeat is unknown"
            )
        else:
            out.append(
                f"verdict: best e_pos {self.floor_ratio:.2f}x the floor of {_mm(self.floor_m)}: "
                f"{_mm(self.best_epos_m - self.floor_m)} or {self.floor_z:.1f} scatters of one "
                f"trial above it (z; 'at floor' from z <= {self.floor_z_max:g})"
            )
        if self.drift_trials:
            assert self.drift_reached_trial is not None and self.drift_best_trial is not None
            drift = FloorDrift(
                self.drift_reached_trial, self.drift_best_trial, tuple(self.drift_trials)
            )
            out.append(
                f"verdict: {drift_sentence(drift)}; gcs fly --resume <run> --again "
                f"{drift.best_trial} flies them again (docs/learning-floor.md)"
            )
        if self.prediction is not None:
            out.append(f"verdict: {self._prediction_sentence()}")
        if self.converged_trial is not None:
            out.append(
                f"verdict: converged at trial {self.converged_trial}: more flights cannot show "
                "an improvement over the floor"
            )
        else:
            left = "" if self.flights_left is None else f"likely {self.flights_left} more; "
            out.append(f"verdict: not converged; {left}{self.flights_left_how}")
        return out

    def _prediction_sentence(self) -> str:
        """What the newest learning step predicted of the trial it planned, in words."""
        pr, t = self.prediction, self.prediction_trial
        assert pr is not None
        limits = f" with {pr.limits_active} setpoint samples at a limit" if pr.limits_active else ""
        said = (
            f"the step before trial {t} predicted it at {_mm(pr.predicted_epos_m)}{limits}; it "
            f"flew {_mm(pr.miss_m)} from that prediction"
        )
        if self.floor_m is None:
            return said
        noise = "about 1x" if pr.noise_ratio is None else f"about {pr.noise_ratio:.2f}x"
        return (
            f"{said}, {pr.miss_m / self.floor_m:.2f}x the floor (the flight's noise and the "
            f"estimate's alone give {noise}; more is what the model did not foresee: "
            "docs/learning-floor.md)"
        )

    def as_dict(self) -> dict:
        """JSON-ready dictionary: the fields, and ``text`` (:meth:`lines`)."""
        return {**asdict(self), "text": self.lines()}


def _mm(value_m: float) -> str:
    return f"{1e3 * value_m:.1f} mm"


def run_verdict(rows: list[IterationMetrics], learning: RunLearning | None) -> Verdict:
    """The verdict of a run from its Table IV rows and what learning says.

    The flights left are estimated only where there is a level to converge to (a floor):
    the excess of e_pos over the floor, ``e_j - floor``, of the newest
    :data:`VERDICT_FIT_TRIALS` learned trials (trial 0 counts, repeats do not) is fitted
    with a geometric decay ``c r^j`` (least squares on its logarithm); the flights until
    the excess falls below ``floor_z`` scatters (the verdict "at floor"), plus one to
    confirm it ("converged": two trials at the floor). Without a floor, with fewer than two
    such trials, or with an excess that did not fall, it is not estimated and the reason is
    said instead.

    ``rows``: from :func:`run_metrics` (``iteration``: the trial number). ``learning``: from
    :func:`run_learning` (None: an identification run has no learning).
    """
    epos = {r.iteration: r.epos_m for r in rows}
    best = min(epos, key=lambda t: (epos[t], t))
    last = max(epos)
    repeats = learning.repeats if learning is not None else 0
    floor = learning.floor if learning is not None else None
    verdicts = learning.trials if learning is not None else {}
    v_best = verdicts[best].verdict if best in verdicts else None
    converged = [t for t, tl in verdicts.items() if tl.verdict and tl.verdict.converged]
    left, how = None, ""
    if converged:
        left, how = 0, "converged"
    elif floor is None:
        how = "the flights left cannot be estimated without a floor to converge to"
    else:
        v_last = verdicts[last].verdict
        z_max = learning.floor_z if learning is not None else 2.0
        if v_last is not None and v_last.at_floor:
            left, how = 1, "the newest trial is at the floor: one more there confirms it"
        else:
            left, how = _flights_left(epos, repeats, floor, z_max)
    return Verdict(
        flights=len(epos),
        first_epos_m=epos[0],
        best_trial=best,
        best_epos_m=epos[best],
        best_updates=iteration_of(best, repeats),
        change_pct=100.0 * (epos[best] - epos[0]) / epos[0],
        last_trial=last,
        last_epos_m=epos[last],
        floor_m=None if floor is None else floor.epos_m,
        floor_ratio=None if v_best is None else v_best.ratio,
        floor_z=None if v_best is None else v_best.z,
        floor_z_max=learning.floor_z if learning is not None else 2.0,
        converged_trial=converged[0] if converged else None,
        flights_left=left,
        flights_left_how=how,
        **_drift_fields(verdicts),
        **_prediction_fields(verdicts),
    )


def _prediction_fields(trials: dict) -> dict:
    """The verdict's prediction fields: the newest trial with a :class:`Prediction`."""
    predicted = [t for t in sorted(trials) if trials[t].prediction is not None]
    if not predicted:
        return {}
    return {"prediction_trial": predicted[-1], "prediction": trials[predicted[-1]].prediction}


def drift_sentence(drift: FloorDrift) -> str:
    """A drift up from the floor in words, as the live lines, the landing and the verdict
    say it.

    E.g. "drifting up: trial 3 reached the floor, trials 5 and 6 are above it again; the
    best setpoints at the floor are trial 4's".
    """
    above = " and ".join(map(str, drift.above))
    return (
        f"drifting up: trial {drift.reached_trial} reached the floor, trials {above} are above "
        f"it again; the best setpoints at the floor are trial {drift.best_trial}'s"
    )


def _drift_fields(trials: dict) -> dict:
    """The verdict's drift fields from the trials' floor verdicts (none: no drift)."""
    row = tuple(trials[t].verdict for t in sorted(trials) if trials[t].verdict is not None)
    drift = floor_drift(row)
    if drift is None:
        return {}
    return {
        "drift_trials": list(drift.above),
        "drift_reached_trial": drift.reached_trial,
        "drift_best_trial": drift.best_trial,
    }


def _flights_left(
    epos: dict[int, float], repeats: int, floor: Floor, z_max: float
) -> tuple[int | None, str]:
    """Flights until converged from the geometric decay of the excess (see run_verdict)."""
    learned = [t for t in sorted(epos) if repeat_of(t, repeats) is None]
    fit = learned[-VERDICT_FIT_TRIALS:]
    excess = np.array([epos[t] - floor.epos_m for t in fit])
    if len(fit) < 2:
        return None, "the flights left need two learned trials to estimate"
    if np.any(excess <= 0):
        return None, "the flights left cannot be estimated: e_pos scatters about the floor"
    x = np.array([iteration_of(t, repeats) for t in fit], dtype=float)
    slope = float(np.polyfit(x, np.log(excess), 1)[0])
    rate = float(np.exp(slope))
    span = "trials " + ", ".join(map(str, fit))
    if rate >= 0.95:
        return None, (
            f"the flights left cannot be estimated: e_pos - floor did not fall over {span} "
            f"({100 * (rate - 1):+.0f} % per flight)"
        )
    target = z_max * float(np.hypot(floor.scatter_m, floor.floor_scatter_m))
    n = max(0, math.ceil(math.log(max(target, 1e-12) / excess[-1]) / math.log(rate)))
    return n + 1, (
        f"estimated from e_pos - floor falling {100 * (1 - rate):.0f} % per flight over "
        f"{span} (a geometric fit), until z <= {z_max:g}, plus one flight to confirm"
    )
