"""``gcs montecarlo`` on Dask: today's tables and JSON, whatever the cluster.

``tests/data`` holds the output of ``gcs montecarlo`` recorded before the study ran on Dask:
the default study (its table, and its ``--json`` as the learning regression records it), and a
small ``--adaptive`` study. On this machine two workers give the rows of one process bit for
bit; against the records, made on another CPU, the rows agree within ``RTOL_STUDY`` and the
printed table within one unit of its last digit (docs/results.md, "Reproducibility").
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from cli_runner import invoke as gcs_invoke
from records import assert_json_close, assert_text_close
from test_learning_regression import study_atol

from gcs.app import study_cluster
from gcs.app.study_cluster import Cluster, place

DATA = Path(__file__).parent / "data"
TABLE_ATOL = 0.0101  # the table prints 2 decimals: a last-bit change may flip one rounding


def run_cli(*args: str) -> tuple[int, str]:
    result = gcs_invoke(list(args), env={"COLUMNS": "80"})
    return result.exit_code, result.output


def without_seconds(document: dict) -> dict:
    return document | {"comparison": [
        {k: v for k, v in c.items() if k != "seconds"} for c in document["comparison"]
    ]}  # fmt: skip


@pytest.mark.processes
def test_a_small_adaptive_study_on_two_workers_is_one_process_s_bit_for_bit(tmp_path: Path) -> None:
    args = ["montecarlo", "--levels", "0.05,0.4", "--plants", "6", "--repeats", "2", "--samples",
            "60", "--adaptive"]  # fmt: skip
    rows = {}
    for workers in ("2", "0"):
        out = tmp_path / f"mc-{workers}.json"
        code, output = run_cli(*args, "--workers", workers, "--json", str(out))
        assert code == 0, output
        rows[workers] = without_seconds(json.loads(out.read_text()))
    assert rows["2"] == rows["0"]  # this machine, this configuration: every bit
    recorded = without_seconds(json.loads((DATA / "montecarlo_small_adaptive.json").read_text()))
    assert_json_close(rows["2"], recorded, 0.0, study_atol(recorded), "rows")


def test_the_default_study_is_the_record(tmp_path: Path) -> None:
    # in this process: that two workers give its rows bit for bit is shown above on a study
    # with both kinds of task (the paper's rows and the adaptive ones) at a quarter of the CPU;
    # the default study on two workers cost three times the CPU of one process (25 s, 8 s)
    out = tmp_path / "mc.json"
    code, output = run_cli("montecarlo", "--workers", "0", "--json", str(out))
    assert code == 0, output
    table = (DATA / "montecarlo_default_table.txt").read_text().strip("\n")
    lines = output.splitlines()
    first = next(i for i, line in enumerate(lines) if line == table.splitlines()[0])
    now = "\n".join(lines[first : first + len(table.splitlines())])
    assert_text_close(now, table, 0.0, TABLE_ATOL, "table")
    recorded = json.loads((DATA / "montecarlo-default.json").read_text())
    assert_json_close(json.loads(out.read_text()), recorded, 0.0, study_atol(recorded), "json")


def test_a_size_beyond_memory_is_one_line() -> None:
    code, output = run_cli("montecarlo", "--samples", "10000000")
    assert code == 2 and "GB" in output and "--samples" in output
    assert len(output.strip().splitlines()) == 1


def test_a_scheduler_that_is_not_an_address_is_one_line() -> None:
    for bad in ("localhost:8786", "tcp://host", "http://127.0.0.1:8786", "tcp://h:99999"):
        code, output = run_cli("montecarlo", "--scheduler", bad)
        assert code == 2 and "not a scheduler address" in output, output
        assert len(output.strip().splitlines()) == 1


SMALL = ["montecarlo", "--levels", "0.05,0.4", "--plants", "6", "--repeats", "2", "--samples", "60"]


def test_a_short_studys_here_on_threads_by_default_with_the_rows_of_workers_0(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # two threads here (one per core) against --workers 0, the tasks one after the other
    monkeypatch.setattr(study_cluster, "machine_workers", lambda: 2)
    monkeypatch.setattr(study_cluster, "busy_cores", lambda: 0.0)  # not the machine's load
    # nor its speed: the estimate is timed on the wall clock, and a starved run must not start
    # a cluster here (the placement between the two is the next test's, on given estimates)
    monkeypatch.setattr(study_cluster, "LOCAL_CLUSTER_COST_S", math.inf)
    rows, lines = {}, {}
    for name, extra in (("default", []), ("0", ["--workers", "0"])):
        out = tmp_path / f"mc-{name}.json"
        code, output = run_cli(*SMALL, *extra, "--json", str(out))
        assert code == 0, output
        rows[name] = json.loads(out.read_text())
        lines[name] = " ".join(output.split())
    assert "in this process on 2 threads: the study is short (est. " in lines["default"]
    assert "in this process (as asked)" in lines["0"]
    assert rows["default"] == rows["0"]  # every bit


@pytest.mark.processes
def test_a_study_judged_long_moves_its_other_tasks_to_a_local_cluster(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a cluster that costs nothing: any saving pays, so the tasks after the first (timed here)
    # go to a local cluster; the rows are still those of one process
    monkeypatch.setattr(study_cluster, "LOCAL_CLUSTER_COST_S", 0.0)
    monkeypatch.setattr(study_cluster, "machine_workers", lambda: 2)
    monkeypatch.setattr(study_cluster, "busy_cores", lambda: 0.0)  # not the machine's load
    out, here = tmp_path / "mc.json", tmp_path / "mc-0.json"
    code, output = run_cli(*SMALL, "--json", str(out))
    assert code == 0, output
    assert "on a local Dask cluster of 2 workers: the study is long (est. " in " ".join(
        output.split()
    )
    code, output = run_cli(*SMALL, "--workers", "0", "--json", str(here))
    assert code == 0, output
    assert json.loads(out.read_text()) == json.loads(here.read_text())


def test_a_short_study_is_placed_here_and_a_long_one_on_a_cluster() -> None:
    short = place(Cluster(), lambda: 3.0, tasks=8, cores=2, busy=0, cluster_cost_s=14.0)
    assert short.cluster.workers == 0 and short.estimate_s == 3.0
    assert short.line.startswith("in this process: the study is short (est. 3.0 s")
    # on threads here when the tasks release the GIL: one per core, no more than the tasks
    threads = place(
        Cluster(), lambda: 3.0, tasks=8, cores=2, busy=0, cluster_cost_s=14.0, threads=True
    )
    assert threads.cluster == Cluster(workers=0, threads=2)
    assert threads.line.startswith("in this process on 2 threads: the study is short (est. 3.0")
    assert place(Cluster(), lambda: 3.0, 1, cores=2, busy=0, threads=True).cluster.threads == 1
    assert place(Cluster(), lambda: 1e4, 8, cores=2, busy=0, threads=True).cluster.workers == 2
    long = place(
        Cluster(blas_threads=2), lambda: 100.0, tasks=8, cores=2, busy=0, cluster_cost_s=14.0
    )
    assert long.cluster == Cluster(workers=2, blas_threads=2)
    assert long.line.startswith("on a local Dask cluster of 2 workers: the study is long")
    # the saving (half of 30 s on two workers) is just above the cost, then just below
    assert (
        place(Cluster(), lambda: 30.0, 8, cores=2, busy=0, cluster_cost_s=14.0).cluster.workers == 2
    )
    assert (
        place(Cluster(), lambda: 26.0, 8, cores=2, busy=0, cluster_cost_s=14.0).cluster.workers == 0
    )
    # no more workers than tasks; one core or one task: nothing to share
    assert (
        place(Cluster(), lambda: 1e4, 3, cores=8, busy=0, cluster_cost_s=14.0).cluster.workers == 3
    )
    assert (
        place(Cluster(), lambda: 1e4, 8, cores=1, busy=0, cluster_cost_s=14.0).cluster.workers == 0
    )
    assert (
        place(Cluster(), lambda: 1e4, 1, cores=8, busy=0, cluster_cost_s=14.0).cluster.workers == 0
    )
    # cores other work keeps busy are not the study's: at load 3 on 2 cores the long study
    # stays here, and says why; on 8 cores at load 5 (4 busy besides this process) 4 workers
    loaded = place(Cluster(), lambda: 1e4, 8, cores=2, busy=2.4, cluster_cost_s=14.0)
    assert loaded.cluster.workers == 0
    assert "2 cores, about 2 kept busy by other work: nothing to share" in loaded.line
    assert place(Cluster(), lambda: 1e4, 8, cores=8, busy=4.0).cluster.workers == 4
    assert place(Cluster(), lambda: 1e4, 8, cores=8, busy=40.0).cluster.workers == 0


def test_workers_and_scheduler_given_are_obeyed_without_an_estimate() -> None:
    def never() -> float:
        raise AssertionError("estimated although the options decided")

    for given in (Cluster(workers=0), Cluster(workers=3), Cluster(scheduler="tcp://h:8786")):
        placed = place(given, never, tasks=8, cores=2, cluster_cost_s=14.0, busy=0)
        assert placed.cluster == given and placed.estimate_s is None
        assert placed.line == given.describe() + " (as asked)"


@pytest.mark.parametrize(
    ("argv", "given", "expected"),
    [
        (["gcs", "montecarlo", "--levels", "0.05"], None, "1"),  # set before numpy is imported
        (["gcs", "montecarlo"], "2", "2"),  # the user's own value is kept
        (["gcs", "study", "montecarlo.yaml"], None, "None"),  # other commands are left alone
        (["gcs", "--help"], None, "None"),
    ],
)
def test_gcs_montecarlo_computes_with_one_blas_thread_unless_told(
    argv: list[str], given: str | None, expected: str
) -> None:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    code = (
        f"import sys; sys.argv = {argv!r}; import gcs.cli, os; "
        "print(os.environ.get('OPENBLAS_NUM_THREADS'), 'numpy' in sys.modules)"
    )
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [expected, "True"]  # gcs.cli imports numpy after the policy
