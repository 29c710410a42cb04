"""Every command, walked with bad paths, files and values (the catalogue of tests/badinputs.py).

Each case must exit with code 2 and one line that names what is wrong, and leave everything in
its workspace as it was: nothing created, written or moved (a flight's run directory, a moved
``logs/latest``, a figure, a profile). ``tools/bad_inputs.py`` writes ``docs/bad-inputs.md``
from the same catalogue.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from badinputs import Templates, catalogue, run_case

CASES = catalogue()


@pytest.fixture(scope="module")
def templates(tmp_path_factory: pytest.TempPathFactory) -> Templates:
    return Templates(tmp_path_factory.mktemp("templates"))


def test_the_catalogue_walks_every_command() -> None:
    commands = {case.command for case in CASES}
    assert commands == {"fly", "learn", "report", "identify", "montecarlo", "mock", "study"}
    assert len(CASES) >= 150


@pytest.mark.parametrize("case", CASES, ids=[f"{c.command}: {c.what}" for c in CASES])
def test_bad_input_is_one_line_exit_2_and_changes_nothing(
    case, templates: Templates, tmp_path: Path
) -> None:
    outcome = run_case(case, tmp_path, templates)
    assert outcome.exit_code == 2, outcome.output
    assert len(outcome.lines) == 1, outcome.output
    assert outcome.lines[0].startswith("error: "), outcome.output
    assert case.expect in outcome.output, outcome.output
    assert outcome.changed == [], outcome.changed


def test_docs_table_lists_exactly_the_catalogue() -> None:
    """docs/bad-inputs.md is generated from this catalogue: a case added or renamed without
    running tools/bad_inputs.py leaves the table stale, which this catches cheaply (the
    behaviour of every case is asserted above)."""
    doc = Path(__file__).resolve().parents[1] / "docs" / "bad-inputs.md"
    rows = doc.read_text().split("## Every case", 1)[1].splitlines()
    listed = []
    for row in rows:
        if not row.startswith("| ") or row.startswith(("| class ", "|---")):
            continue
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", row)[1:-1]]
        listed.append((cells[0], cells[1], cells[2]))
    expected = [(c.klass, c.command, c.what.replace("|", "\\|")) for c in CASES]
    assert listed == expected, "docs/bad-inputs.md is stale: run tools/bad_inputs.py"
