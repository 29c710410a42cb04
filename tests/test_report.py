"""gcs report: trials that are missing or incomplete, percentages of trial 0, figures, HTML."""

from __future__ import annotations

import base64
import json
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from cli_runner import invoke as gcs_invoke
from synthetic import make_run

from gcs.app.report import rounded, run_metrics
from gcs.app.report_figures import report_figures
from gcs.app.report_html import write_html
from gcs.core.trials import trial_errors
from gcs.errors import RunLogError

PNG = b"\x89PNG\r\n\x1a\n"


def invoke(*args: object):
    return gcs_invoke([str(a) for a in args], env={"COLUMNS": "200"})


def test_missing_and_incomplete_trials_are_listed_not_dropped(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=4)
    (run.path / "trial-001.json").unlink()
    (run.path / "trial-001.csv").unlink()
    (run.path / "trial-002.json").rename(run.path / "x")  # a CSV whose sidecar never came
    status = json.loads((run.path / "trial-003.json").read_text())
    status.update(status="incomplete", reason="link lost")
    (run.path / "trial-003.json").write_text(json.dumps(status))
    result = invoke("report", run.path)
    assert result.exit_code == 0, result.output
    assert "trial 1: missing (no trial-001.json), not in the table" in result.output
    assert "trial 3: incomplete (link lost), not in the table" in result.output
    assert "trial 2: incomplete (trial-002.csv without its .json)" in result.output
    rows = json.loads(invoke("report", run.path, "--json").output)["rows"]
    assert [(r["iteration"], r["status"]) for r in rows] == [
        (0, "complete"), (1, "missing"), (2, "incomplete"), (3, "incomplete")
    ]  # fmt: skip
    (run.path / "x").rename(run.path / "trial-002.json")
    rows = json.loads(invoke("report", run.path, "--json").output)["rows"]
    assert rows[3]["reason"] == "link lost" and rows[3]["epos_m"] is None
    # trial 2 compared with trial 0, never with a neighbour it does not have
    e0 = trial_errors(run.read_trial(0))[0]
    e2 = trial_errors(run.read_trial(2))[0]
    assert rows[2]["epos_pct"] == pytest.approx(100 * e2 / e0)
    assert rows[2]["change_pct"] is None and "delta_pct" not in rows[2]


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda p: (p / "trial-000.json").unlink(), "trial 0 is missing"),
        (
            lambda p: (p / "trial-000.json").write_text(
                json.loads((p / "trial-000.json").read_text()) and
                json.dumps({**json.loads((p / "trial-000.json").read_text()),
                            "status": "incomplete"})
            ),
            "trial 0 is incomplete",
        ),
    ],
)  # fmt: skip
def test_without_a_complete_trial_0_there_are_no_percentages(tmp_path: Path, damage, message):
    run = make_run(tmp_path, trials=3)
    damage(run.path)
    result = invoke("report", run.path)
    assert result.exit_code == 2
    assert message in result.output and len(result.output.strip().splitlines()) == 1
    with pytest.raises(RunLogError, match=message):
        run_metrics(run)


def test_a_zero_e_pos_0_is_refused(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=2)
    path = run.path / "trial-000.csv"
    lines = path.read_text().splitlines()
    head = lines[0].split(",")
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        for axis in ("north", "east"):
            cells[head.index(f"pos_{axis}_m")] = cells[head.index(f"ref_{axis}_m")]
        out.append(",".join(cells))
    path.write_text("\n".join(out) + "\n")
    result = invoke("report", run.path, "--json")
    assert result.exit_code == 2 and "e_pos,0 = 0" in result.output


def _labels(fig) -> set[str]:
    return {label for ax in fig.axes for label in ax.get_legend_handles_labels()[1]}


def test_figures_draw_the_chosen_iterations_for_both_axes(tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    run = make_run(tmp_path, trials=4)
    figures = report_figures(run, [0, 3])
    assert set(figures) == {"xy", "position", "setpoints", "error", "epos", "disturbance"}
    for name in ("position", "error"):
        assert {"j = 0", "j = 3"} <= _labels(figures[name])
        assert "j = 1" not in _labels(figures[name])
        assert [ax.get_ylabel().split()[0] for ax in figures[name].axes] == ["north", "east"]
    setpoints = figures["setpoints"]
    assert {"u, j = 0", "u, j = 3", "arena", "reference"} <= _labels(setpoints)
    assert any(label.startswith("max_deviation_m ±2.5 m") for label in _labels(setpoints))
    arena = run.profile().arena.bounds()
    for ax, axis in zip(setpoints.axes, (0, 1), strict=True):
        dotted = [line for line in ax.get_lines() if line.get_linestyle() == ":"]
        levels = {line.get_ydata()[0] for line in dotted if len(line.get_ydata())}
        assert set(arena[axis]) <= levels  # the arena's edges are drawn
    # estimates exist for trials 0..2 only (learned from them)
    labels = _labels(figures["disturbance"])
    assert "from trial 0" in labels and len(labels) == 2
    two_sigma = 1e3 * float(np.median(2 * np.sqrt(run.read_estimate(0)[1])))
    assert f"±2σ (median {two_sigma:.2g} mm)" in labels
    epos = figures["epos"]
    assert epos.axes[0].get_yscale() == "log"
    right = epos.axes[0].child_axes  # the percentage axis
    assert len(right) == 1 and right[0].get_ylabel() == "e_pos,j / e_pos,0 [%]"
    plt.close("all")


class _Collect(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.srcs: list[str] = []
        self.refs: list[str] = []
        self.cells: list[str] = []
        self._cell = False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.srcs.append(attrs.get("src", ""))
        for key in ("href", "src"):
            if key in attrs and tag != "img":
                self.refs.append(attrs[key])
        self._cell = tag == "td"

    def handle_data(self, data):
        if self._cell:
            self.cells.append(data)
            self._cell = False


def test_html_report_is_one_self_contained_file(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=3)
    target = tmp_path / "out" / "report.html"
    result = invoke("report", run.path, "--html", target, "--iterations", "0,2")
    assert result.exit_code == 0, result.output
    text = target.read_text()
    parser = _Collect()
    parser.feed(text)
    assert parser.refs == []  # no stylesheet, script or link to fetch
    assert len(parser.srcs) == 6
    for src in parser.srcs:
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1])[:8] == PNG
    rows = run_metrics(run)
    for r in rows:
        assert f"{r.epos_m:.4f}" in parser.cells and f"{r.epos_pct:.2f}" in parser.cells
    assert "0, 2" in parser.cells  # the iterations drawn
    assert "http" not in text.replace("http-equiv", "")
    assert list(target.parent.iterdir()) == [target]  # one file, nothing beside it


def test_iterations_must_be_complete_trials(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=2)
    for value, message in (("0,5", "trial 5 is not a complete trial"), ("x", "--iterations")):
        result = invoke("report", run.path, "--plot", tmp_path / "p", "--iterations", value)
        assert result.exit_code == 2 and message in result.output
    assert not (tmp_path / "p").exists()
    with pytest.raises(RunLogError, match="trial 4"):
        write_html(run, tmp_path / "r.html", [4])


def test_a_trial_flown_again_says_so(tmp_path: Path) -> None:
    from synthetic import fly_synthetic

    from gcs.io.records import TrialStatus

    run = make_run(tmp_path, trials=2)
    from gcs.app.learn import learn_run

    learn_run(run)
    record = fly_synthetic(run, 2)  # complete: make it an interrupted attempt, then fly again
    (run.path / "trial-002.json").unlink()
    run.write_trial(2, record, TrialStatus(2, False, reason="link lost"))
    fly_synthetic(run, 2, seed=5)
    result = invoke("report", run.path)
    assert result.exit_code == 0, result.output
    assert "trial 2: 1 earlier incomplete attempt kept in aborted/" in result.output


def test_a_run_with_a_repeat_reports_trial_and_j_the_floor_verdicts_and_decisions(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from synthetic import make_adaptive_run

    import gcs.cli

    # the console's width is fixed when it is made (COLUMNS then): wide, so no header wraps
    monkeypatch.setattr(gcs.cli.console, "width", 200)

    run = make_adaptive_run(tmp_path, trials=5, gust_m=0.01)  # the default: two repeats
    rows = json.loads(invoke("report", run.path, "--json").output)["rows"]
    assert [r["trial"] for r in rows] == [0, 1, 2, 3, 4]
    assert [r["iteration"] for r in rows] == [0, 0, 0, 1, 2]  # the paper's j: a repeat is 0
    assert [r["repeat_of"] for r in rows] == [None, 0, 0, None, None]
    # the floor, independently: one flight's non-repeatable error sqrt(3 / 2) (Y_i - mean Y)
    y = np.stack([run.read_trial(t).pos_ned_m[1:, :2] for t in (0, 1, 2)])
    delta = np.sqrt(1.5) * (y - y.mean(axis=0))
    floor = float(np.mean(np.hypot(delta[..., 0], delta[..., 1])))
    ref = run.reference().pos_ned_m
    for r in rows:
        assert r["floor_m"] == pytest.approx(floor)
        assert r["floor_ratio"] == pytest.approx(r["epos_m"] / floor)
        sigma = r["floor_scatter_m"]
        z = (r["epos_m"] - floor) / np.hypot(sigma, sigma / np.sqrt(2))  # three flights
        assert r["floor_z"] == pytest.approx(z) and r["at_floor"] == (z <= 2.0)
        dev = run.read_setpoints(r["trial"])[:, :2] - ref[:-1, :2]
        assert r["sp_rms_m"] == pytest.approx(np.sqrt(np.mean(np.sum(dev**2, axis=1))))
        learned = run.path / f"learn-{r['trial']:03d}.json"
        expected = json.loads(learned.read_text()) if learned.exists() else None
        assert r["learning"] == rounded(expected)  # every number to 9 digits
    assert rows[0]["learning"] is None and rows[1]["learning"] is None
    assert rows[2]["learning"]["next_iteration"] == 1
    assert rows[0]["sp_rms_m"] == rows[1]["sp_rms_m"] == rows[2]["sp_rms_m"] == 0.0
    assert rows[3]["sp_rms_m"] > 0.5
    out = invoke("report", run.path).output
    for text in ("trial", "e/floor", "verdict", "learning step", "sp RMS [m]",
                 "0 (repeat)", "repeat of 0 next", f"e_pos {1e3 * floor:.1f} mm",
                 "after trial 3: model refreshed: north moved"):  # fmt: skip
        assert text in out, text
    moved = run.read_learn_record(3)["decision"]["axes"][0]["refresh"]["moved"]
    assert f"model N {100 * moved:.0f} %" in out


def test_the_epos_figure_draws_the_floor_and_the_html_the_decisions(tmp_path: Path) -> None:
    from synthetic import make_adaptive_run

    run = make_adaptive_run(tmp_path, trials=4, gust_m=0.01)  # the default: two repeats
    floor = run.read_floor()["epos_m"]
    figures = report_figures(run, [0, 1, 3])
    ax = figures["epos"].axes[0]
    levels = [line.get_ydata()[0] for line in ax.get_lines() if len(set(line.get_ydata())) == 1]
    assert any(y == pytest.approx(floor) for y in levels)
    assert [t.get_text() for t in ax.get_xticklabels()] == ["0", "0r", "0r", "1"]
    labels = figures["xy"].axes[0].get_legend_handles_labels()[1]
    assert "trial 1, j = 0 (repeat)" in labels and "trial 3, j = 1" in labels
    path = write_html(run, tmp_path / "r.html")
    text = path.read_text()
    assert "floor (one flight" in text and "learning step" in text and "0 (repeat)" in text


# ------------------------------------------------------------------ what a report says it is

SCHEMA = Path(__file__).resolve().parents[1] / "docs" / "report.schema.json"
_TYPES = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None)}


def _is(value: object, kind: str) -> bool:
    if kind == "integer":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "number":
        return isinstance(value, int | float) and not isinstance(value, bool)
    return isinstance(value, _TYPES[kind])


def _validate(value: object, schema: dict, where: str = "$") -> None:
    """The subset of JSON Schema docs/report.schema.json uses (type, const, enum, required,
    properties, additionalProperties, items)."""
    kinds = schema.get("type")
    if kinds is not None:
        kinds = [kinds] if isinstance(kinds, str) else kinds
        assert any(_is(value, k) for k in kinds), f"{where}: {value!r} is not {kinds}"
    if "const" in schema:
        assert value == schema["const"], f"{where}: {value!r} != {schema['const']!r}"
    if "enum" in schema:
        assert value in schema["enum"], f"{where}: {value!r} not in {schema['enum']}"
    if isinstance(value, dict):
        for key in schema.get("required", []):
            assert key in value, f"{where}: missing {key!r}"
        props = schema.get("properties", {})
        if schema.get("additionalProperties") is False:
            assert set(value) <= set(props), f"{where}: undocumented {set(value) - set(props)}"
        for key, sub in props.items():
            if key in value:
                _validate(value[key], sub, f"{where}.{key}")
    if isinstance(value, list) and "items" in schema:
        for i, item in enumerate(value):
            _validate(item, schema["items"], f"{where}[{i}]")


def _floats(value: object) -> list[float]:
    if isinstance(value, dict):
        return [f for v in value.values() for f in _floats(v)]
    if isinstance(value, list):
        return [f for v in value for f in _floats(v)]
    return [value] if isinstance(value, float) else []


def test_json_is_a_documented_document_with_the_run_and_rounded_numbers(tmp_path: Path) -> None:
    from synthetic import make_adaptive_run

    schema = json.loads(SCHEMA.read_text())
    for run in (make_run(tmp_path / "a", trials=3),
                make_adaptive_run(tmp_path / "b", trials=4, gust_m=0.01)):  # fmt: skip
        doc = json.loads(invoke("report", run.path, "--json").output)
        _validate(doc, schema)
        assert (doc["format"], doc["version"]) == ("gcs-report", 6)
        assert doc["run"]["run_id"] == "run" and doc["run"]["profile"] == run.profile().name
        for value in _floats(doc):
            assert len(repr(value).lstrip("-").replace(".", "").lstrip("0")) <= 13, value
        assert doc["rows"][0]["epos_pct"] == 100.0


def test_every_key_and_column_is_defined_in_the_docs() -> None:
    text = (SCHEMA.parent / "report.md").read_text()
    schema = json.loads(SCHEMA.read_text())
    keys = [*schema["properties"]["run"]["properties"], *schema["properties"]["rows"]["items"]
            ["properties"]]  # fmt: skip
    for key in keys:
        assert f"`{key}`" in text, key
    import tempfile

    from synthetic import make_adaptive_run

    from gcs.app.report_text import table_cells

    with tempfile.TemporaryDirectory() as tmp:
        from gcs.app.report import run_learning, trial_clock_rates

        run = make_adaptive_run(Path(tmp), trials=3, gust_m=0.01)
        rates = {j: 1.0 for j in trial_clock_rates(run)}
        headers, _ = table_cells(run_metrics(run), rates, run_learning(run))
    for header in headers:
        assert f"`{header}`" in text, header


def test_a_report_of_logs_latest_names_the_run_everywhere(tmp_path: Path) -> None:
    make_run(tmp_path, trials=3)
    latest = tmp_path / "latest"
    assert latest.is_symlink()
    out = invoke("report", latest).output
    assert "run (smoother)" in out and "latest" not in out.split("\n", 2)[0]
    doc = json.loads(invoke("report", latest, "--json").output)
    assert doc["run"]["run_id"] == "run" and doc["run"]["path"] == str(latest)
    target = tmp_path / "r.html"
    assert invoke("report", latest, "--html", target).exit_code == 0
    text = target.read_text()
    title = text.split("<title>", 1)[1].split("</title>", 1)[0]
    assert title.startswith("gcs report: run (smoother)") and "profile" in title
    assert "<h1>gcs report: run</h1>" in text
    import matplotlib.pyplot as plt

    from gcs.io.rundir import RunDir

    for name, fig in report_figures(RunDir.open(latest), [0, 2]).items():
        assert fig.get_suptitle().count("run (smoother)") == 1, name
    plt.close("all")


@pytest.mark.parametrize("width", [80, None])
def test_the_table_is_never_cut_at_80_columns_or_in_a_pipe(tmp_path: Path, width) -> None:
    from synthetic import make_adaptive_run

    run = make_adaptive_run(tmp_path, trials=4, gust_m=0.01)
    env = {"COLUMNS": str(width)} if width else {}
    result = gcs_invoke(["report", str(run.path)], env=env)  # CliRunner: not a tty
    assert result.exit_code == 0, result.output
    assert "…" not in result.output
    for header in ("e_pos", "e/e0", "change", "verdict", "learning step"):
        assert header in result.output, header
    assert max(len(line) for line in result.output.splitlines()[:30]) <= 80


def test_the_change_column_is_signed_a_worse_trial_reads_as_worse(tmp_path: Path) -> None:
    from gcs.app.report import change_pct
    from gcs.app.report_text import table_cells

    run = make_run(tmp_path, trials=3)
    rows = run_metrics(run)
    worse = [rows[0], rows[1], replace_epos(rows[2], rows[1].epos_m * 1.5)]
    changes = change_pct(worse)
    assert changes[0] is None and changes[1] < 0 and changes[2] == pytest.approx(50.0)
    _, cells = table_cells(worse, None, None)
    assert cells[2][3] == "+50.00" and cells[1][3].startswith("-")


def replace_epos(row, epos_m):
    from dataclasses import replace

    return replace(row, epos_m=epos_m, delta_pct=abs(epos_m - 1.0))


def test_xy_marks_the_start_and_the_direction_and_d_has_its_2_sigma_band(tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    run = make_run(tmp_path, trials=3)
    figures = report_figures(run, [0, 1])
    assert {"start", "direction of flight"} <= _labels(figures["xy"])
    ax = figures["xy"].axes[0]
    arrows = [c for c in ax.get_children() if type(c).__name__ == "Annotation"]
    assert 2 <= len(arrows) <= 4
    heads = [np.array(a.xy) for a in arrows]  # one arrow per part of the path, none on another
    assert all(np.hypot(*(h - g)) > 0 for i, h in enumerate(heads) for g in heads[:i])
    ref = run.reference().pos_ned_m
    start = [line for line in ax.get_lines() if line.get_label() == "start"][0]
    assert (start.get_xdata()[0], start.get_ydata()[0]) == (ref[0, 1], ref[0, 0])
    # the band is d ± 2 sqrt(p) of the recorded estimate
    d, p = run.read_estimate(0)
    band = figures["disturbance"].axes[0].collections[0]
    top = band.get_paths()[0].vertices[:, 1].max()
    assert top == pytest.approx(float(np.max(d[:, 0] + 2 * np.sqrt(p[:, 0]))))
    plt.close("all")


def test_figures_written_off_a_terminal_say_their_progress_in_plain_lines(tmp_path: Path) -> None:
    run = make_run(tmp_path, trials=2)
    result = invoke("report", run.path, "--plot", tmp_path / "p")
    assert result.exit_code == 0, result.output
    lines = [line for line in result.output.splitlines() if line.startswith("report: figures:")]
    wrote = [line for line in result.output.splitlines() if line.startswith("wrote ")]
    # the first figure at once and the last at the end, each "done/total" of the figures written
    assert lines[0].startswith(f"report: figures: 1/{len(wrote)} figures")
    assert lines[-1].startswith(f"report: figures: {len(wrote)}/{len(wrote)} figures")
    assert "\x1b" not in result.output
