"""``gcs report RUN RUN ...``: several runs side by side.

One row per run (e_pos of trial 0, the best trial, the change, the floor, converged), e_pos of
every trial side by side, what differed between the runs (profile, trajectory, model, learning
settings, algorithm, vehicle: from the manifests and the session records), the e_pos curves
overlaid in one figure, and the same as one JSON document.

Runs of different trajectories are compared (e_pos is a mean distance in metres whatever the
manoeuvre), and the comparison says so on its first line: their numbers measure different
manoeuvres.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from gcs.app.report import (
    RunFacts,
    Verdict,
    report_document,
    rounded,
    run_facts,
    run_learning,
    run_metrics,
    run_verdict,
    trial_clock_rates,
    trial_overview,
)
from gcs.core.metrics import IterationMetrics
from gcs.errors import RunLogError
from gcs.io.rundir import RunDir

__all__ = [
    "COMPARE_FORMAT",
    "COMPARE_VERSION",
    "ComparedRun",
    "compare_runs",
    "differences",
    "compare_table",
    "compare_lines",
    "compare_document",
    "compare_figure",
]

#: The ``format`` and ``version`` of ``gcs report RUN RUN --json``.
COMPARE_FORMAT, COMPARE_VERSION = "gcs-report-compare", 1

#: Groups of manifest keys, in the order the differences are told.
_GROUPS = (
    ("model", ("profile.model", "profile.model_y", "profile.model_z")),
    ("learning", ("profile.learning", "profile.weights", "profile.noise")),
    ("arena and limits", ("profile.arena", "profile.limits")),
    ("flight", ("profile.flight", "profile.mocap")),
    ("trajectory", ("trajectory",)),
)


@dataclass(frozen=True)
class ComparedRun:
    """One run of a comparison.

    ``rows``: its complete trials (``iteration``: the trial number). ``name``: how the comparison
    names it: the run's id, or the path as given where two runs have the same id.
    """

    run: RunDir
    facts: RunFacts
    rows: list[IterationMetrics]
    verdict: Verdict
    name: str = ""


def compare_runs(paths: list[Path]) -> list[ComparedRun]:
    """Open and read every run to compare; each must be a learning run with a complete trial 0.

    ``paths``: two or more run directories.
    """
    out = []
    for path in paths:
        run = RunDir.open(path)
        run.profile()
        if run.kind != "learning":
            raise RunLogError(
                f"{path}: an identification run ({run.algorithm}); only learning runs are compared"
            )
        rows = run_metrics(run)
        facts = run_facts(run)
        out.append(
            ComparedRun(run, facts, rows, run_verdict(rows, run_learning(run)), facts.run_id)
        )
    ids = [c.name for c in out]
    return [c if ids.count(c.name) == 1 else replace(c, name=str(c.run.path)) for c in out]


def _flat(value: Any, prefix: str) -> dict[str, Any]:
    if isinstance(value, dict):
        out: dict[str, Any] = {}
        for k, v in value.items():
            out |= _flat(v, f"{prefix}.{k}")
        return out
    return {prefix: value}


def _vehicle(run: RunDir) -> str:
    nav, seeds = set(), []
    for s in run.sessions():
        n = s.get("navigation")
        nav.add(n.get("source", "unknown") if isinstance(n, dict) else "unknown")
        if isinstance(s.get("mock_seed"), int):
            seeds.append(s["mock_seed"])
    where = "the mock" if seeds else "a vehicle"
    return f"{where}, navigation {', '.join(sorted(nav)) or 'unknown'}"


def differences(runs: list[ComparedRun]) -> list[str]:
    """What differed between the runs, one line per kind: algorithm, profile, trajectory,
    model, learning settings, arena, flight settings, vehicle and seed.

    Returns: empty when the manifests agree in everything but the run's own name and time.
    """
    names = [c.name for c in runs]
    lines = []

    def told(what: str, values: list[str]) -> None:
        if len(set(values)) > 1:
            pairs = ", ".join(f"{n}: {v}" for n, v in zip(names, values, strict=True))
            lines.append(f"{what} differs: {pairs}")

    told("algorithm", [c.facts.algorithm for c in runs])
    told("profile", [c.facts.profile for c in runs])
    told("trajectory", [c.facts.trajectory for c in runs])
    flats = [
        _flat(c.run.manifest["profile"], "profile")
        | _flat(c.run.manifest["trajectory"], "trajectory")
        for c in runs
    ]
    keys = sorted(set().union(*flats))
    for group, prefixes in _GROUPS:
        changed = [
            k for k in keys
            if k.startswith(prefixes) and not k.endswith(".name")
            and len({repr(f.get(k)) for f in flats}) > 1
        ]  # fmt: skip
        if changed:
            more = f" and {len(changed) - 4} more" if len(changed) > 4 else ""
            shown = ", ".join(changed[:4]) + more
            lines.append(f"{group} differs: {shown}")
    told("vehicle", [_vehicle(c.run) for c in runs])
    told("seeds", [c.facts.seed_text() for c in runs])
    return lines


def compare_lines(runs: list[ComparedRun]) -> list[str]:
    """The lines under the comparison table: a warning when the trajectories differ, what
    differed, and each run's verdict.
    """
    out = []
    trajectories = [c.facts.trajectory for c in runs]
    if len(set(trajectories)) > 1:
        out.append(
            "note: these runs fly different trajectories ("
            + ", ".join(dict.fromkeys(trajectories))
            + "): their e_pos measure different manoeuvres"
        )
    out += differences(runs) or ["the runs' manifests agree (profile, trajectory, vehicle)"]
    for c in runs:
        out += [f"{c.name}: {line.removeprefix('verdict: ')}" for line in c.verdict.lines()]
    return out


def _mm(value: float | None) -> str:
    return "-" if value is None else f"{1e3 * value:.1f}"


def compare_table(runs: list[ComparedRun]) -> tuple[list[str], list[list[str]], list[list[str]]]:
    """The two tables of a comparison as text cells.

    Returns: ``headers``: of the summary: run, trajectory, trials, e0 [mm], best [mm], best trial,
    change [%], floor [mm], converged. ``summary``: one row per run. ``per_trial``: e_pos [mm] of
    every trial (rows) per run (columns), ``-`` where a run has none; the first cell of each row is
    the trial number.
    """
    headers = ["run", "trajectory", "trials", "e0 [mm]", "best [mm]", "best trial",
               "change [%]", "floor [mm]", "converged"]  # fmt: skip
    summary = []
    for c in runs:
        v = c.verdict
        summary.append([
            c.name, c.facts.trajectory, str(v.flights), _mm(v.first_epos_m),
            _mm(v.best_epos_m), str(v.best_trial), f"{v.change_pct:+.1f}", _mm(v.floor_m),
            "-" if v.converged_trial is None else f"trial {v.converged_trial}",
        ])  # fmt: skip
    epos = [{r.iteration: r.epos_m for r in c.rows} for c in runs]
    last = max(max(e) for e in epos)
    per_trial = [[str(j), *(_mm(e.get(j)) for e in epos)] for j in range(last + 1)]
    return headers, summary, per_trial


def compare_document(runs: list[ComparedRun]) -> dict[str, Any]:
    """The JSON document of ``gcs report RUN RUN --json``.

    Returns: ``format`` ("gcs-report-compare"), ``version`` (1), ``differences`` (lines of words),
    ``same_trajectory`` and ``runs``: each run's report document (docs/report.md).
    """
    docs = []
    for c in runs:
        learning = run_learning(c.run)
        docs.append(
            report_document(
                c.run, c.rows, trial_clock_rates(c.run), trial_overview(c.run), learning
            )
        )
    return rounded(
        {
            "format": COMPARE_FORMAT,
            "version": COMPARE_VERSION,
            "same_trajectory": len({c.facts.trajectory for c in runs}) == 1,
            "differences": differences(runs),
            "runs": docs,
        }
    )


def compare_figure(runs: list[ComparedRun]) -> Any:
    """The e_pos curves of the runs overlaid (log scale), each run's floor dotted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 4.4))
    for i, c in enumerate(runs):
        color = f"C{i}"
        x = [r.iteration for r in c.rows]
        label = f"{c.name} ({c.facts.profile}, {c.facts.trajectory})"
        ax.semilogy(x, [r.epos_m for r in c.rows], "o-", color=color, label=label)
        if c.verdict.floor_m is not None:
            ax.axhline(c.verdict.floor_m, color=color, ls=":", lw=1.2)
    ax.set_xlabel("trial (order of flight)")
    ax.set_ylabel("e_pos [m] (eq. 10)")
    ax.set_title("e_pos per trial, runs compared (dotted: each run's floor)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return fig
