"""``gcs montecarlo`` on Dask: today's tables and JSON, whatever the cluster.

``tests/data`` holds the output of ``gcs montecarlo`` recorded before the study ran on Dask:
the default study (its table, and its ``--json`` as the learning regression records it), and a
small ``--adaptive`` study.
"""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from gcs.cli import app

DATA = Path(__file__).parent / "data"


def run_cli(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, list(args), env={"COLUMNS": "80"})
    return result.exit_code, result.output


def without_seconds(document: dict) -> dict:
    return document | {"comparison": [
        {k: v for k, v in c.items() if k != "seconds"} for c in document["comparison"]
    ]}  # fmt: skip


def test_a_small_adaptive_study_on_two_workers_is_todays_bit_for_bit(tmp_path: Path) -> None:
    out = tmp_path / "mc.json"
    code, output = run_cli(
        "montecarlo", "--levels", "0.05,0.4", "--plants", "6", "--repeats", "2", "--samples",
        "60", "--adaptive", "--workers", "2", "--json", str(out),
    )  # fmt: skip
    assert code == 0, output
    recorded = json.loads((DATA / "montecarlo_small_adaptive.json").read_text())
    assert without_seconds(json.loads(out.read_text())) == without_seconds(recorded)


def test_the_default_study_on_two_workers_is_todays_bit_for_bit(tmp_path: Path) -> None:
    # the local workers compute with as many BLAS threads as this process does (the order of a
    # sum follows the threads): the table and the JSON are those recorded in one process
    out = tmp_path / "mc.json"
    code, output = run_cli("montecarlo", "--workers", "2", "--json", str(out))
    assert code == 0, output
    table = (DATA / "montecarlo_default_table.txt").read_text()
    assert table.strip("\n") in output
    assert out.read_bytes() == (DATA / "montecarlo-default.json").read_bytes()


def test_a_size_beyond_memory_is_one_line() -> None:
    code, output = run_cli("montecarlo", "--samples", "10000000")
    assert code == 2 and "GB" in output and "--samples" in output
    assert len(output.strip().splitlines()) == 1


def test_a_scheduler_that_is_not_an_address_is_one_line() -> None:
    for bad in ("localhost:8786", "tcp://host", "http://127.0.0.1:8786", "tcp://h:99999"):
        code, output = run_cli("montecarlo", "--scheduler", bad)
        assert code == 2 and "not a scheduler address" in output, output
        assert len(output.strip().splitlines()) == 1
