"""The learning of ``gcs learn`` / ``gcs fly`` and ``gcs montecarlo``'s tables as recorded
(``tests/data/``) with the code before the public learning API existed, within the tolerances of
docs/results.md's "Reproducibility" (the records were made on another CPU).

The learning record holds every learned file of the cases of :mod:`learning_cases`: synthetic
runs (smoother, K-ILC, mocap measurement, learning with history: floor, noise from the data,
refresh, safeguard, robustness "auto", Table I noise) and two PX4 SITL runs learnt again trial by
trial. The Monte Carlo records are ``gcs montecarlo --json`` of the default study, of a smaller
one and of a small ``--adaptive`` comparison. Learned numbers agree within ``RTOL_LEARNED`` (of
the largest value of their file), study rows within ``RTOL_STUDY``; the text of a learned JSON or
YAML file around its numbers, and every decision in it, exactly.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_runner import invoke as gcs_invoke
from learning_cases import CASES, RECORD, learned_case
from records import NUMBER, assert_close, assert_json_close, assert_text_close, printed_unit

DATA = Path(__file__).resolve().parent / "data"
RTOL_LEARNED = 1e-9  # of a learned file's largest magnitude, after several trials
#: the automatic robustness cutoff ("auto") learns from a model refreshed by an iterative fit that
#: stops at a relative loss improvement of 1e-9: the model is determined to about 1e-10, and
#: the cutoff and the smoother amplify that by up to 1e4 (docs/results.md, Reproducibility)
RTOL_LEARNED_CASE = {"auto": 1e-6}
RTOL_STUDY = 1e-12  # of a study's largest error norm
CSV_DIGITS = 9  # significant digits of a run directory's CSV files (gcs.io.records)


def test_the_cases_are_those_recorded() -> None:
    with np.load(RECORD) as recorded:
        assert sorted({key.split("/")[0] for key in recorded.files}) == sorted(CASES)


# one case per test: the cases are the heaviest of the suite and spread over pytest's workers
@pytest.mark.parametrize("case", list(CASES))
def test_learned_files_are_those_recorded(case: str) -> None:
    now = learned_case(case)
    with np.load(RECORD) as recorded:
        keys = [key for key in recorded.files if key.split("/")[0] == case]
        assert sorted(now) == sorted(keys)
        for key in keys:
            b = recorded[key]
            rtol = RTOL_LEARNED_CASE.get(case, RTOL_LEARNED)
            if b.dtype.kind == "U":  # a learned JSON or YAML file: full precision (repr)
                text = str(b)
                scale = max((abs(float(v)) for v in NUMBER.findall(text)), default=0.0)
                assert_text_close(str(now[key]), text, 0.0, rtol * scale, key)
            else:  # setpoints (N, 3) or estimates (2, N, axes) read back from a CSV file
                axis = 1 if key.split("/")[1].startswith("estimate") else 0
                scale = np.max(np.abs(b), axis=axis, keepdims=True)
                atol = rtol * scale + printed_unit(b, CSV_DIGITS)
                assert_close(now[key], b, 0.0, atol, key)


def floats(doc: object) -> list[float]:
    """Every float of a JSON document."""
    if isinstance(doc, dict):
        return [x for v in doc.values() for x in floats(v)]
    if isinstance(doc, list):
        return [x for v in doc for x in floats(v)]
    return [doc] if isinstance(doc, float) else []


def study_atol(doc: object) -> float:
    """``RTOL_STUDY`` of the largest number of a study's JSON (error norms in metres)."""
    return RTOL_STUDY * max(abs(x) for x in floats(doc))


def _without_seconds(doc: object) -> object:
    if isinstance(doc, dict):
        return {k: _without_seconds(v) for k, v in doc.items() if k != "seconds"}
    if isinstance(doc, list):
        return [_without_seconds(v) for v in doc]
    return doc


@pytest.mark.parametrize(
    ("record", "args"),
    [
        ("montecarlo-small.json", ["--plants", "20", "--repeats", "2"]),
        ("montecarlo-adaptive-small.json",
         ["--levels", "0.05,0.4", "--plants", "10", "--repeats", "2", "--adaptive"]),
    ],
)  # fmt: skip
def test_montecarlo_tables_are_those_recorded(tmp_path: Path, record: str, args: list) -> None:
    # in this process: where the default places a study depends on how fast this machine is
    # at the moment (on a loaded one, a local cluster of processes); any placement gives the
    # rows of one process (tests/test_montecarlo_dask.py)
    out = tmp_path / "mc.json"
    argv = ["montecarlo", *args, "--workers", "0", "--json", str(out)]
    result = gcs_invoke(argv)
    assert result.exit_code == 0, result.output
    now = _without_seconds(json.loads(out.read_text()))
    recorded = _without_seconds(json.loads((DATA / record).read_text()))
    assert_json_close(now, recorded, 0.0, study_atol(recorded), record)
    if "--adaptive" in args:  # the comparison line of each level, beside the paper's rows
        assert "(adaptive)" in result.output and "j = 2..5" in result.output, result.output
        assert "diverged" in result.output, result.output
    else:  # the paper's study alone says nothing of the new options
        assert "adaptive" not in result.output, result.output
