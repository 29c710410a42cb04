"""Tests of the run directory (gcs.io.rundir, .learnlog, .records, .atomic): its atomic files
and every refusal."""

from __future__ import annotations

import csv
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
from synthetic import SHORT, profile

from gcs.core.trajectory import sample_eight
from gcs.errors import RunLogError
from gcs.io.atomic import atomic_write_text
from gcs.io.config import trajectory_from_dict
from gcs.io.records import TRIAL_COLUMNS, TrialRecord, TrialStatus, json_safe
from gcs.io.rundir import RunDir


def new_run(tmp_path: Path, algorithm: str = "smoother") -> RunDir:
    return RunDir.create(tmp_path, profile(), trajectory_from_dict(SHORT), algorithm, "run")


def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], np.array(rows[1:], dtype=float)


def record_for(run: RunDir, seed: int = 0, nan_after: int | None = None) -> TrialRecord:
    ref = run.reference()
    n = run.n_samples
    rng = np.random.default_rng(seed)
    pos = ref.pos_ned_m + rng.normal(0, 0.05, (n + 1, 3))
    if nan_after is not None:
        pos[nan_after:] = np.nan
    sp = np.vstack([run.read_setpoints(0), ref.pos_ned_m[-1]])
    return TrialRecord(
        t_s=ref.t_s.copy(),
        ref_ned_m=ref.pos_ned_m.copy(),
        sp_ned_m=sp,
        pos_ned_m=pos,
        vel_ned_m_s=rng.normal(0, 1, (n + 1, 3)),
        sp_sent_s=np.append(ref.t_s[:-1] + rng.uniform(0, 1e-3, n), np.nan),
        interpolated=rng.uniform(size=n + 1) < 0.1,
    )


def complete(j: int) -> TrialStatus:
    return TrialStatus(j, True, epos_m=0.1, max_err_m=0.2, interpolated_share=0.05)


def tmp_files(path: Path) -> list[Path]:
    return [p for p in path.rglob("*") if p.name.endswith(".tmp") or p.name.startswith(".")]


# ------------------------------------------------------------------------------ creation


def test_create_writes_manifest_reference_and_first_setpoints(tmp_path):
    run = new_run(tmp_path)
    assert run.path == tmp_path / "run"
    manifest = json.loads((run.path / "manifest.json").read_text())
    expected_ref = sample_eight(trajectory_from_dict(SHORT).shape, 0.05)
    assert manifest["format"] == 1
    assert manifest["algorithm"] == "smoother"
    assert manifest["t_ilc_s"] == 0.05
    duration_s = 2 * SHORT["hover_s"] + SHORT["ramp_s"] + SHORT["loops"] * SHORT["period_s"]
    assert manifest["n_samples"] == expected_ref.n_samples == round(duration_s / 0.05)
    assert manifest["profile"] == profile().source
    assert manifest["trajectory"] == SHORT
    assert "numpy" in manifest["packages"] and manifest["gcs_version"]
    header, table = read_csv(run.path / "reference.csv")
    assert header == ["k", "t_s", "ref_north_m", "ref_east_m", "ref_down_m"]
    np.testing.assert_array_equal(table[:, 0], np.arange(expected_ref.n_samples + 1))
    np.testing.assert_allclose(table[:, 1], expected_ref.t_s, rtol=1e-8)
    np.testing.assert_allclose(table[:, 2:], expected_ref.pos_ned_m, rtol=1e-8, atol=1e-12)
    header, sp = read_csv(run.path / "setpoints-000.csv")
    assert header == ["k", "t_s", "sp_north_m", "sp_east_m", "sp_down_m"]
    assert sp.shape == (expected_ref.n_samples, 5)
    np.testing.assert_allclose(sp[:, 2:], expected_ref.pos_ned_m[:-1], rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(run.read_setpoints(0), table[:-1, 2:])
    assert (tmp_path / "latest").resolve() == run.path.resolve()
    assert tmp_files(tmp_path) == []


def test_the_run_names_its_own_files_as_docs_formats_lists_them(tmp_path):
    run = new_run(tmp_path)
    names = {
        run.manifest_path: "manifest.json",
        run.reference_path: "reference.csv",
        run.floor_path: "floor.json",
        run.identified_path: "identified.yaml",
        run.setpoints_path(7): "setpoints-007.csv",
        run.trial_path(7): "trial-007.csv",
        run.status_path(7): "trial-007.json",
        run.mocap_path(7): "mocap-007.csv",
        run.estimate_path(7): "estimate-007.csv",
        run.learn_path(7): "learn-007.json",
        run.model_path(7): "model-007.yaml",
        run.again_path(7): "again-007.json",
        run.session_path(2): "session-002.json",
    }
    assert list(names) == [run.path / name for name in names.values()]
    assert sorted(p.name for p in run.path.iterdir()) == [
        "manifest.json",
        "reference.csv",
        "setpoints-000.csv",
    ]
    docs = (Path(__file__).resolve().parent.parent / "docs" / "formats.md").read_text()
    for name in [*names.values(), f"{RunDir.ABORTED_DIR}/", f"{RunDir.SUPERSEDED_DIR}/"]:
        documented = re.sub(r"-\d{3}\.", "-JJJ.", name.replace("session-002", "session-SSS"))
        assert documented in docs, name


def test_csv_trials_count_a_csv_without_its_sidecar(tmp_path):
    run = new_run(tmp_path)
    run.write_trial(0, record_for(run), complete(0))
    run.trial_path(2).write_text("k,t_s\n")  # a CSV whose sidecar was never written
    assert run.csv_trials() == [0, 2]
    assert [s.trial for s in run.statuses()] == [0]
    assert run.again_trials() == [] and run.aborted_attempts() == {}


def test_open_round_trip(tmp_path):
    run = new_run(tmp_path, "kilc")
    again = RunDir.open(run.path)
    assert again.manifest == run.manifest
    assert again.algorithm == "kilc"
    assert again.n_samples == run.n_samples and again.t_ilc_s == 0.05
    assert again.profile().source == profile().source
    assert again.trajectory().shape == trajectory_from_dict(SHORT).shape
    np.testing.assert_array_equal(again.reference().pos_ned_m, run.reference().pos_ned_m)


def test_create_with_existing_id_refused_and_default_ids_unique(tmp_path):
    new_run(tmp_path)
    with pytest.raises(RunLogError, match="exists"):
        new_run(tmp_path)
    a = RunDir.create(tmp_path, profile(), trajectory_from_dict(SHORT), "smoother")
    b = RunDir.create(tmp_path, profile(), trajectory_from_dict(SHORT), "smoother")
    assert a.path != b.path and a.path.is_dir() and b.path.is_dir()
    assert "tiny" in a.path.name and "smoother" in a.path.name


# ------------------------------------------------------------------------------ trials


def test_trial_round_trip(tmp_path):
    run = new_run(tmp_path)
    rec = record_for(run)
    run.write_trial(0, rec, complete(0))
    back = run.read_trial(0)
    for name in ("t_s", "ref_ned_m", "sp_ned_m", "pos_ned_m", "vel_ned_m_s"):
        np.testing.assert_allclose(getattr(back, name), getattr(rec, name), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(back.sp_sent_s[:-1], rec.sp_sent_s[:-1], rtol=1e-8)
    assert np.isnan(back.sp_sent_s[-1])  # NaN in sp_sent_s (row N) is allowed
    np.testing.assert_array_equal(back.interpolated, rec.interpolated)
    header, _ = read_csv(run.path / "trial-000.csv")
    assert tuple(header) == TRIAL_COLUMNS
    status = run.read_status(0)
    assert status.complete and status.trial == 0
    assert (status.epos_m, status.max_err_m, status.interpolated_share) == (0.1, 0.2, 0.05)
    assert tmp_files(run.path) == []


def test_atomic_write_replaces_and_leaves_no_temp_file_on_failure(tmp_path):
    target = tmp_path / "file.txt"
    atomic_write_text(target, "first\n")
    atomic_write_text(target, "second\n")
    assert target.read_text() == "second\n"
    with pytest.raises(TypeError):
        atomic_write_text(target, 12345)  # type: ignore[arg-type]
    assert target.read_text() == "second\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]


def test_incomplete_trial_not_learned_from_and_archived_when_reflown(tmp_path):
    run = new_run(tmp_path)
    rec_a = record_for(run, seed=1, nan_after=40)
    run.write_trial(0, rec_a, TrialStatus(0, False, reason="watchdog"))
    with pytest.raises(RunLogError, match="incomplete") as info:
        run.read_trial(0)
    assert "trial-000.csv" in str(info.value) and "watchdog" in str(info.value)
    assert run.newest_complete() is None and run.next_trial() == 0
    run.write_trial(0, record_for(run, seed=2), TrialStatus(0, False, reason="link lost"))
    rec_c = record_for(run, seed=3)
    run.write_trial(0, rec_c, complete(0))
    aborted = run.path / "aborted"
    assert sorted(p.name for p in aborted.iterdir()) == [
        "trial-000-attempt-1.csv",
        "trial-000-attempt-1.json",
        "trial-000-attempt-2.csv",
        "trial-000-attempt-2.json",
    ]
    first = json.loads((aborted / "trial-000-attempt-1.json").read_text())
    assert first["status"] == "incomplete" and first["reason"] == "watchdog"
    assert json.loads((aborted / "trial-000-attempt-2.json").read_text())["reason"] == "link lost"
    _, table = read_csv(aborted / "trial-000-attempt-1.csv")
    assert np.all(np.isnan(table[40:, 8:11])) and np.all(np.isfinite(table[:40, 8:11]))
    np.testing.assert_allclose(run.read_trial(0).pos_ned_m, rec_c.pos_ned_m, rtol=1e-8)
    assert run.newest_complete() == 0 and run.next_trial() == 1


def test_complete_trial_never_overwritten(tmp_path):
    run = new_run(tmp_path)
    run.write_trial(0, record_for(run, seed=1), complete(0))
    before = {p.name: p.read_bytes() for p in run.path.iterdir() if p.is_file()}
    for status in (complete(0), TrialStatus(0, False, reason="x")):
        with pytest.raises(RunLogError, match="complete") as info:
            run.write_trial(0, record_for(run, seed=9), status)
        assert "trial-000.json" in str(info.value)
    after = {p.name: p.read_bytes() for p in run.path.iterdir() if p.is_file()}
    assert after == before
    assert not (run.path / "aborted").exists()


def test_wrong_length_record_refused(tmp_path):
    run = new_run(tmp_path)
    rec = record_for(run)
    short = TrialRecord(
        *(None if (v := getattr(rec, f)) is None else v[:-3] for f in rec.__dataclass_fields__)
    )
    with pytest.raises(RunLogError, match="samples"):
        run.write_trial(0, short, complete(0))
    assert not (run.path / "trial-000.csv").exists()


def test_newest_complete_and_next_trial(tmp_path):
    run = new_run(tmp_path)
    assert (run.newest_complete(), run.next_trial(), run.complete_trials()) == (None, 0, [])
    run.write_trial(0, record_for(run), complete(0))
    assert (run.newest_complete(), run.next_trial()) == (0, 1)
    run.write_trial(1, record_for(run), TrialStatus(1, False, reason="ctrl-c"))
    assert (run.newest_complete(), run.next_trial()) == (0, 1)
    assert [s.complete for s in run.statuses()] == [True, False]
    run.write_trial(1, record_for(run), complete(1))
    run.write_trial(2, record_for(run), complete(2))
    assert run.complete_trials() == [0, 1, 2]
    assert (run.newest_complete(), run.next_trial()) == (2, 3)
    # archived attempts in aborted/ are not trials
    assert len(run.statuses()) == 3


# ------------------------------------------------------------------------------ refusals


def _edit_trial_csv(run: RunDir, edit) -> Path:
    path = run.path / "trial-000.csv"
    lines = path.read_text().splitlines()
    lines = edit(lines)
    path.write_text("\n".join(lines) + "\n")
    return path


def _set_cell(lines: list[str], k: int, column: str, value: str) -> list[str]:
    header = lines[0].split(",")
    cells = lines[1 + k].split(",")
    cells[header.index(column)] = value
    lines[1 + k] = ",".join(cells)
    return lines


@pytest.mark.parametrize("column", ["pos_east_m", "ref_north_m", "vel_down_m_s", "sp_north_m"])
def test_nan_in_trial_refused_naming_file_column_and_row(tmp_path, column):
    run = new_run(tmp_path)
    run.write_trial(0, record_for(run), complete(0))
    path = _edit_trial_csv(run, lambda lines: _set_cell(lines, 17, column, "nan"))
    with pytest.raises(RunLogError) as info:
        run.read_trial(0)
    msg = str(info.value)
    assert str(path) in msg and f"'{column}'" in msg and "k = 17" in msg


def test_truncated_trial_refused(tmp_path):
    run = new_run(tmp_path)
    run.write_trial(0, record_for(run), complete(0))
    path = _edit_trial_csv(run, lambda lines: lines[:-5])
    with pytest.raises(RunLogError) as info:
        run.read_trial(0)
    msg = str(info.value)
    assert str(path) in msg and f"{run.n_samples + 1 - 5} rows" in msg
    # a row cut in the middle (fewer values)
    run2 = new_run(tmp_path / "b")
    run2.write_trial(0, record_for(run2), complete(0))
    path = _edit_trial_csv(run2, lambda lines: lines[:-1] + [lines[-1].rsplit(",", 4)[0]])
    with pytest.raises(RunLogError, match="trial-000.csv"):
        run2.read_trial(0)


def test_wrong_time_grid_refused_naming_column(tmp_path):
    run = new_run(tmp_path)
    run.write_trial(0, record_for(run), complete(0))
    path = _edit_trial_csv(run, lambda lines: _set_cell(lines, 9, "t_s", "0.47"))
    with pytest.raises(RunLogError) as info:
        run.read_trial(0)
    msg = str(info.value)
    assert str(path) in msg and "'t_s'" in msg and "k = 9" in msg
    _edit_trial_csv(run, lambda lines: _set_cell(lines, 9, "t_s", "0.45"))
    run.read_trial(0)  # restored
    _edit_trial_csv(run, lambda lines: _set_cell(lines, 9, "k", "10"))
    with pytest.raises(RunLogError, match="'k'"):
        run.read_trial(0)


def test_bad_header_refused(tmp_path):
    run = new_run(tmp_path)
    run.write_trial(0, record_for(run), complete(0))

    def swap(lines):
        lines[0] = lines[0].replace("pos_north_m,pos_east_m", "pos_east_m,pos_north_m")
        return lines

    path = _edit_trial_csv(run, swap)
    with pytest.raises(RunLogError, match="header") as info:
        run.read_trial(0)
    assert str(path) in str(info.value)
    (run.path / "setpoints-000.csv").write_text("k,t,n,e,d\n")
    with pytest.raises(RunLogError, match="setpoints-000.csv"):
        run.read_setpoints(0)


def test_malformed_manifest_and_status_refused(tmp_path):
    run = new_run(tmp_path)
    mpath = run.path / "manifest.json"
    good = mpath.read_text()
    mpath.write_text(good[: len(good) // 2])
    with pytest.raises(RunLogError, match="malformed JSON") as info:
        RunDir.open(run.path)
    assert str(mpath) in str(info.value)
    data = json.loads(good)
    del data["n_samples"]
    mpath.write_text(json.dumps(data))
    with pytest.raises(RunLogError, match="'n_samples'"):
        RunDir.open(run.path)
    mpath.unlink()
    with pytest.raises(RunLogError, match="manifest.json"):
        RunDir.open(run.path)
    with pytest.raises(RunLogError, match="not a run directory"):
        RunDir.open(tmp_path / "missing")
    run2 = new_run(tmp_path / "b")
    run2.write_trial(0, record_for(run2), complete(0))
    (run2.path / "trial-000.json").write_text('{"trial": 0}')
    with pytest.raises(RunLogError, match="trial-000.json"):
        run2.read_trial(0)


def test_setpoints_and_estimates(tmp_path):
    run = new_run(tmp_path)
    n = run.n_samples
    sp = np.random.default_rng(5).normal(size=(n, 3))
    run.write_setpoints(3, sp)
    np.testing.assert_allclose(run.read_setpoints(3), sp, rtol=1e-8, atol=1e-12)
    for bad in (sp[:-1], np.where(np.arange(n)[:, None] == 4, np.nan, sp)):
        with pytest.raises(RunLogError):
            run.write_setpoints(4, bad)
    assert not (run.path / "setpoints-004.csv").exists()
    with pytest.raises(RunLogError, match="setpoints-007.csv"):
        run.read_setpoints(7)
    d, p = np.random.default_rng(6).normal(size=(n, 2)), np.full((n, 2), 0.0123)
    run.write_estimate(0, d, p)
    d2, p2 = run.read_estimate(0)
    np.testing.assert_allclose(d2, d, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(p2, p)
    _, table = read_csv(run.path / "estimate-000.csv")
    np.testing.assert_array_equal(table[:, 0], np.arange(1, n + 1))  # d(1..N)
    with pytest.raises(RunLogError, match="estimate-001.csv"):
        run.read_estimate(1)
    assert tmp_files(run.path) == []


def test_sessions_take_the_next_number_update_their_own_and_never_overwrite(tmp_path):
    run = new_run(tmp_path)
    assert run.sessions() == []
    first = run.write_session(None, {"first_trial": 0, "tolerance_m": float("nan")})
    assert first == 1
    record = json.loads((run.path / "session-001.json").read_text())  # strict JSON: no NaN
    assert record == {"session": 1, "first_trial": 0, "tolerance_m": None}
    # another process took number 2 meanwhile (a resumed run flown twice at once)
    (run.path / "session-002.json").write_text('{"session": 2, "first_trial": 3}')
    second = run.write_session(None, {"first_trial": 3})
    assert second == 3
    assert json.loads((run.path / "session-002.json").read_text())["first_trial"] == 3
    assert run.write_session(first, {"first_trial": 0, "tolerance_m": 0.4}) == 1
    assert [s["session"] for s in run.sessions()] == [1, 2, 3]
    assert run.sessions()[0]["tolerance_m"] == 0.4
    assert not list(run.path.glob(".*tmp"))  # no temporary file left behind


def test_json_safe() -> None:
    value = {"a": (1.0, float("inf")), "b": np.float64("nan"), "c": np.int64(3), "d": "x"}
    assert json_safe(value) == {"a": [1.0, None], "b": None, "c": 3, "d": "x"}


# ------------------------------------------------------------------------------ integrity


def test_write_once_writes_new_files_keeps_identical_ones_and_refuses_others(tmp_path):
    from gcs.io.atomic import write_once

    target = tmp_path / "setpoints-001.csv"
    assert write_once(target, "a\n") is True
    stamp = target.stat().st_mtime_ns
    assert write_once(target, "a\n") is False  # the same bytes: nothing written
    assert target.stat().st_mtime_ns == stamp
    with pytest.raises(RunLogError, match="exists with different content") as info:
        write_once(target, "b\n")
    assert str(target) in str(info.value)
    assert target.read_text() == "a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["setpoints-001.csv"]


def test_setpoints_and_estimates_are_never_rewritten_with_other_values(tmp_path):
    run = new_run(tmp_path)
    sp = run.read_setpoints(0)
    run.write_setpoints(0, sp)  # as recorded: accepted, nothing changes
    with pytest.raises(RunLogError, match="setpoints-000.csv: exists with different"):
        run.write_setpoints(0, sp + 0.01)
    np.testing.assert_allclose(run.read_setpoints(0), sp)
    n = run.n_samples
    run.write_estimate(0, np.zeros((n, 2)), np.ones((n, 2)))
    with pytest.raises(RunLogError, match="estimate-000.csv: exists with different"):
        run.write_estimate(0, np.ones((n, 2)), np.ones((n, 2)))


def test_creation_is_staged_and_leaves_nothing_when_interrupted(tmp_path, monkeypatch):
    import gcs.io.rundir as rundir

    (tmp_path / "old").mkdir()
    (tmp_path / "latest").symlink_to("old")
    real = rundir.atomic_write_text

    def failing(path, text):
        if Path(path).name == "reference.csv":
            raise KeyboardInterrupt  # Ctrl-C between two files of a new run
        real(path, text)

    monkeypatch.setattr(rundir, "atomic_write_text", failing)
    with pytest.raises(KeyboardInterrupt):
        new_run(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["latest", "old"]  # no half-made run
    assert (tmp_path / "latest").readlink() == Path("old")  # and latest did not move
    monkeypatch.setattr(rundir, "atomic_write_text", real)
    run = new_run(tmp_path)
    assert sorted(p.name for p in run.path.iterdir()) == [
        "manifest.json", "reference.csv", "setpoints-000.csv"
    ]  # fmt: skip
    assert (tmp_path / "latest").readlink() == Path("run")
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def _manifest_edit(run: RunDir, key: str, value) -> None:
    path = run.path / "manifest.json"
    data = json.loads(path.read_text())
    node = data
    *parents, last = key.split(".")
    for k in parents:
        node = node[k]
    node[last] = value
    path.write_text(json.dumps(data))


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("n_samples", "140", "field 'n_samples' must be an integer >= 2, got '140'"),
        ("n_samples", 1.5, "field 'n_samples'"),
        ("n_samples", True, "field 'n_samples'"),
        ("t_ilc_s", -0.05, "field 't_ilc_s' must be a positive number"),
        ("t_ilc_s", None, "field 't_ilc_s'"),
        ("algorithm", "ilc", "field 'algorithm' must be one of smoother, kilc, identify"),
        ("algorithm", ["smoother"], "field 'algorithm'"),
        ("profile", "antx", "field 'profile' must be an object"),
        ("trajectory", [], "field 'trajectory' must be an object"),
        ("trajectory.type", "excitation", "identification runs, and only they"),
        ("algorithm", "identify", "identification runs, and only they"),
    ],
)
def test_manifest_fields_of_the_wrong_type_are_refused_naming_them(tmp_path, key, value, message):
    run = new_run(tmp_path)
    _manifest_edit(run, key, value)
    with pytest.raises(RunLogError, match=re.escape(message)) as info:
        RunDir.open(run.path)
    assert str(run.path / "manifest.json") in str(info.value)


def test_run_kind_is_checked_by_writers(tmp_path):
    run = new_run(tmp_path)
    assert run.kind == "learning"
    run.require_kind("learning", "gcs learn")
    with pytest.raises(RunLogError, match="a learning run .*not an identification run, which "
                       "'gcs identify --from-log' needs"):  # fmt: skip
        run.require_kind("identification", "gcs identify --from-log")


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("trial", 1, "field 'trial' must be 0, as the file's name says"),
        ("trial", "0", "field 'trial' must be 0"),
        ("status", "done", "field 'status' must be 'complete' or 'incomplete'"),
        ("epos_m", "0.1", "field 'epos_m' must be a number or null"),
        ("reason", 3, "field 'reason'"),
        ("extra", [1], "field 'extra'"),
    ],
)
def test_trial_sidecars_must_agree_with_their_names_and_types(tmp_path, key, value, message):
    run = new_run(tmp_path)
    run.write_trial(0, record_for(run), complete(0))
    path = run.path / "trial-000.json"
    data = json.loads(path.read_text())
    data[key] = value
    path.write_text(json.dumps(data))
    with pytest.raises(RunLogError, match=re.escape(message)) as info:
        run.statuses()
    assert str(path) in str(info.value)


def test_a_trial_whose_setpoints_are_not_its_files_is_refused(tmp_path):
    run = new_run(tmp_path)
    run.write_trial(0, record_for(run), complete(0))
    other = run.read_setpoints(0) + np.array([0.3, 0.0, 0.0])
    run.write_setpoints(1, other)
    rec = record_for(run, seed=4)
    run.write_trial(1, TrialRecord(**{**rec.__dict__, "sp_ned_m": np.vstack([other, other[-1]])}),
                    complete(1))  # fmt: skip
    run.read_trial(1)  # as flown: agrees
    a, b = run.path / "trial-000.csv", run.path / "trial-001.csv"
    a.rename(run.path / "x")
    b.rename(a)
    (run.path / "x").rename(b)
    with pytest.raises(RunLogError, match="setpoints differ from setpoints-001.csv") as info:
        run.read_trial(1)
    assert "trial-001.csv" in str(info.value)
    (run.path / "trial-001.csv").unlink()
    with pytest.raises(RunLogError, match="missing, but trial-001.json says"):
        run.read_trial(1)


def test_a_csv_without_its_sidecar_is_archived_before_the_trial_is_flown_again(tmp_path):
    run = new_run(tmp_path)
    run.write_trial(0, record_for(run, seed=1), complete(0))
    orphan = (run.path / "trial-000.csv").read_bytes()
    (run.path / "trial-000.json").unlink()  # interrupted between the CSV and its sidecar
    assert run.next_trial() == 0
    run.write_trial(0, record_for(run, seed=2), complete(0))
    assert (run.path / "aborted" / "trial-000-attempt-1.csv").read_bytes() == orphan
    assert not (run.path / "aborted" / "trial-000-attempt-1.json").exists()


def test_a_session_record_must_name_itself(tmp_path):
    run = new_run(tmp_path)
    (run.path / "session-001.json").write_text('{"session": 2}')
    with pytest.raises(RunLogError, match="session-001.json: field 'session' must be 1"):
        run.sessions()


def test_unwritable_run_directory_is_refused(tmp_path):
    from test_paths import read_only

    run = new_run(tmp_path)
    run.check_writable()
    with read_only(run.path), pytest.raises(RunLogError, match="run directory is not writable"):
        run.check_writable()


def test_a_refused_learning_record_leaves_neither_file_behind(tmp_path):
    run = new_run(tmp_path)
    n = run.n_samples
    sp = run.read_setpoints(0)
    (run.path / "setpoints-001.csv").write_text("")  # damaged: other content than learned
    with pytest.raises(RunLogError, match="setpoints-001.csv: exists with different content"):
        run.write_learned(0, np.zeros((n, 2)), np.ones((n, 2)), sp)
    assert not (run.path / "estimate-000.csv").exists()  # not written before the refusal
    (run.path / "setpoints-001.csv").unlink()
    assert run.write_learned(0, np.zeros((n, 2)), np.ones((n, 2)), sp).name == "setpoints-001.csv"
    run.write_learned(0, np.zeros((n, 2)), np.ones((n, 2)), sp)  # again: the same bytes


def test_files_and_runs_get_the_modes_open_and_mkdir_give(tmp_path):
    import stat

    mask = os.umask(0o022)
    os.umask(mask)
    run = new_run(tmp_path)
    run.write_trial(0, record_for(run), complete(0))
    assert stat.S_IMODE(run.path.stat().st_mode) == 0o777 & ~mask  # not mkdtemp's 0700
    for p in run.path.iterdir():
        assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~mask, p.name  # not mkstemp's 0600


# ------------------------------------------------------------------ learning with history


def plan_record(j: int, model_file: str | None = None) -> dict:
    """A minimal ``learn-JJJ.json`` record as gcs.app.learn writes it."""
    refresh = {"accepted": model_file is not None, "moved": 0.2 if model_file else 0.0}
    axis = {"axis": "north", "noise": {}, "refresh": refresh, "robustness": None, "update": {}}
    return {
        "format": 1, "trial": j, "next_trial": j + 1, "next_iteration": j, "repeats": 1,
        "learned_from": list(range(j + 1)), "models_from": "profile", "model_file": model_file,
        "setpoints": {"rms_m": 1.0, "max_m": 2.0},
        "decision": {"axes": [axis, {**axis, "axis": "east"}], "verdicts": [], "converged": False,
                     "safeguard": None, "floor": None, "nan": float("nan")},
    }  # fmt: skip


def write_plan(run: RunDir, j: int, model_file: str | None = None, value: float = 0.0) -> Path:
    n = run.n_samples
    sp = run.read_setpoints(0)
    text = "name: m\n" if model_file else None
    floor = {"trials": [0, 1], "epos_m": 0.02, "scatter_m": 0.003}
    return run.write_plan(
        j, np.full((n, 2), value), np.ones((n, 2)), plan_record(j, model_file), sp, text, floor
    )


def test_a_learning_step_is_written_model_floor_estimate_record_and_setpoints_last(
    tmp_path, monkeypatch
):
    import gcs.io.learnlog as learnlog

    run = new_run(tmp_path)
    order: list[str] = []
    real = learnlog.write_once

    def spy(path: Path, text: str) -> bool:
        order.append(Path(path).name)
        return real(path, text)

    monkeypatch.setattr(learnlog, "write_once", spy)
    assert write_plan(run, 1, "model-001.yaml").name == "setpoints-002.csv"
    assert order == [
        "model-001.yaml", "floor.json", "estimate-001.csv", "learn-001.json", "setpoints-002.csv"
    ]  # fmt: skip
    record = run.read_learn_record(1)
    assert record["decision"]["nan"] is None  # strict JSON: NaN as null
    assert run.read_floor()["trials"] == [0, 1]
    assert run.learn_records() == {1: record}
    # interrupted before the record: learning again completes the step with the same bytes
    (run.path / "learn-001.json").unlink()
    (run.path / "setpoints-002.csv").unlink()

    def fail(path: Path, text: str) -> bool:
        if Path(path).name.startswith("learn-"):
            raise OSError(28, "No space left on device", str(path))
        return real(path, text)

    monkeypatch.setattr(learnlog, "write_once", fail)
    with pytest.raises(OSError):
        write_plan(run, 1, "model-001.yaml")
    assert not (run.path / "setpoints-002.csv").exists()  # the next trial cannot be flown
    monkeypatch.setattr(learnlog, "write_once", real)
    write_plan(run, 1, "model-001.yaml")
    assert (run.path / "setpoints-002.csv").exists() and not tmp_files(run.path)


def test_a_learning_step_that_differs_from_what_is_recorded_writes_nothing(tmp_path):
    run = new_run(tmp_path)
    write_plan(run, 1)
    (run.path / "setpoints-002.csv").unlink()
    before = {p.name: p.read_bytes() for p in run.path.iterdir() if p.is_file()}
    with pytest.raises(RunLogError, match="estimate-001.csv: exists with different content"):
        write_plan(run, 1, value=0.5)
    assert {p.name: p.read_bytes() for p in run.path.iterdir() if p.is_file()} == before
    with pytest.raises(RunLogError, match="names trial 2"):
        run.write_plan(1, *(np.zeros((run.n_samples, 2)),) * 2, plan_record(2),
                       run.read_setpoints(0))  # fmt: skip


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("trial", 2, "field 'trial' must be 1, as the file's name says"),
        ("next_trial", 3, "next_trial"),
        ("learned_from", [1], "learned_from"),
        ("next_iteration", "1", "next_iteration"),
        ("model_file", "model-007.yaml", "model_file"),
        ("decision", [], "field 'decision' must be an object"),
        ("decision.axes", [{}], "decision.axes"),
        ("decision.converged", "yes", "decision.converged"),
        ("setpoints", {"rms_m": "x"}, "setpoints"),
    ],
)
def test_a_learning_record_must_agree_with_its_name_and_types(tmp_path, key, value, message):
    run = new_run(tmp_path)
    write_plan(run, 1)
    path = run.path / "learn-001.json"
    data = json.loads(path.read_text())
    node, *rest = key.split(".")
    if rest:
        data[node][rest[0]] = value
    else:
        data[node] = value
    path.write_text(json.dumps(data))
    with pytest.raises(RunLogError, match=re.escape(message)):
        run.read_learn_record(1)


def test_a_repeat_is_trial_0_byte_for_byte(tmp_path):
    run = new_run(tmp_path)
    assert run.write_repeat(1).read_bytes() == (run.path / "setpoints-000.csv").read_bytes()
    with pytest.raises(RunLogError, match="cannot repeat"):
        run.write_repeat(0)


def test_fly_again_puts_an_earlier_trials_setpoints_in_force_and_keeps_the_learned(
    tmp_path: Path,
) -> None:
    from synthetic import fly_synthetic, make_run

    from gcs.app.learn import learn_run

    run = make_run(tmp_path, trials=3)  # trials 0..2 complete
    learn_run(run)  # setpoints-003 learned
    learned = (run.path / "setpoints-003.csv").read_bytes()
    assert run.again_of(3) is None
    run.fly_again(3, 1)
    assert (run.path / "setpoints-003.csv").read_bytes() == (
        run.path / "setpoints-001.csv"
    ).read_bytes()
    assert (run.path / "superseded" / "setpoints-003-1.csv").read_bytes() == learned
    assert run.again_of(3) == 1
    run.fly_again(3, 1)  # in force already: nothing moved, nothing added
    assert sorted(p.name for p in (run.path / "superseded").iterdir()) == ["setpoints-003-1.csv"]
    run.fly_again(3, 2)  # changed one's mind: trial 1's copy is kept too, the record says both
    assert (run.path / "superseded" / "setpoints-003-2.csv").read_bytes() == (
        run.path / "setpoints-001.csv"
    ).read_bytes()
    record = json.loads((run.path / "again-003.json").read_text())
    assert [e["setpoints_of"] for e in record["again"]] == [1, 2] and run.again_of(3) == 2
    fly_synthetic(run, 3)  # flown: its setpoints columns are trial 2's, as the file says
    assert np.array_equal(run.read_trial(3).sp_ned_m[:-1], run.read_setpoints(2))
    with pytest.raises(RunLogError, match="trial 3 is complete"):
        run.fly_again(3, 0)
    for k in (4, -1):
        with pytest.raises(RunLogError, match=f"trial {k} is not a complete trial before"):
            run.fly_again(4, k)
    assert not tmp_files(run.path)


def test_again_of_believes_its_record_only_while_those_setpoints_are_in_force(
    tmp_path: Path,
) -> None:
    from synthetic import make_run

    from gcs.app.learn import learn_run

    run = make_run(tmp_path, trials=3)
    learn_run(run)
    text = json.dumps({"trial": 3, "again": [{"setpoints_of": 0, "superseded": None}]})
    (run.path / "again-003.json").write_text(text)  # written, then interrupted before the swap
    assert run.again_of(3) is None  # setpoints-003 is still the learned one
    (run.path / "again-003.json").write_text(json.dumps({"trial": 3, "again": [{"x": 1}]}))
    with pytest.raises(RunLogError, match="again-003.json: malformed record"):
        run.again_of(3)
