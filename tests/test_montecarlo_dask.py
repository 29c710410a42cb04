"""``gcs montecarlo`` on Dask: today's tables and JSON, whatever the cluster.

``tests/data`` holds the output of ``gcs montecarlo`` recorded before the study ran on Dask:
the default study (its table, and its ``--json`` as the learning regression records it), and a
small ``--adaptive`` study. On this machine two workers give the rows of one process bit for
bit; against the records, made on another CPU, the rows agree within ``RTOL_STUDY`` and the
printed table within one unit of its last digit (docs/results.md, "Reproducibility").
"""

from __future__ import annotations

import json
from pathlib import Path

from records import assert_json_close, assert_text_close
from test_learning_regression import study_atol
from typer.testing import CliRunner

from gcs.cli import app

DATA = Path(__file__).parent / "data"
TABLE_ATOL = 0.0101  # the table prints 2 decimals: a last-bit change may flip one rounding


def run_cli(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, list(args), env={"COLUMNS": "80"})
    return result.exit_code, result.output


def without_seconds(document: dict) -> dict:
    return document | {"comparison": [
        {k: v for k, v in c.items() if k != "seconds"} for c in document["comparison"]
    ]}  # fmt: skip


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


def test_the_default_study_on_two_workers_is_the_record(tmp_path: Path) -> None:
    out = tmp_path / "mc.json"
    code, output = run_cli("montecarlo", "--workers", "2", "--json", str(out))
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
