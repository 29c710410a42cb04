"""Helpers of the real-firmware flights: the gcs CLI run to its end, its report, the profiles."""

from __future__ import annotations

import json
import shutil
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import yaml
from synthetic import CI_MOCAP
from test_fly_e2e import ROOT
from test_fly_e2e import gcs as _gcs

from gcs.app.report import (
    report_document,
    run_learning,
    run_metrics,
    trial_clock_rates,
    trial_overview,
)
from gcs.io.rundir import RunDir

FLIGHT_TIMEOUT_S = 420  # an upper bound for a whole session on a loaded machine, not a wait
# The watchdog limits of the mock's end-to-end flights (tests/synthetic.py's CI_FLIGHT), and
# for the same reason: PX4 SITL runs in lockstep with its simulator, so when the machine
# starves PX4 of CPU its clock stops, and gcs, whose stream goes on on the wall clock, sees no
# telemetry. Measured on a 2-core machine at load 14: 0.5 s without a position sample while
# PX4's own log shows its estimate every 8 ms of its time without a gap. The shipped 0.5 s and
# 0.2 s are for a real vehicle, whose clock never stops.
SITL_LIMITS = {"max_telemetry_age_s": 1.0, "max_setpoint_late_s": 0.4}
ON_GROUND, IN_AIR = 1, 2  # MAV_LANDED_STATE


_started: list[subprocess.Popen] = []
#: what each gcs process of the running test said: (its arguments, its output so far)
_transcripts: list[tuple[str, Callable[[], str]]] = []


class _Recorded:
    """A process's stdout that keeps every line a test reads from it (the rest of the output,
    read by ``communicate``, is added by :func:`finish` and :func:`kill_leftovers`)."""

    def __init__(self, stream) -> None:
        self._stream = stream
        self.parts: list[str] = []

    def __iter__(self) -> Iterator[str]:
        for line in self._stream:
            self.parts.append(line)
            yield line

    def readline(self, *args) -> str:
        line = self._stream.readline(*args)
        self.parts.append(line)
        return line

    def read(self, *args) -> str:
        text = self._stream.read(*args)
        self.parts.append(text)
        return text

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def gcs(*args: object) -> subprocess.Popen:
    """``python -m gcs *args`` started (output on a pipe), remembered for :func:`kill_leftovers`
    and its output for :func:`keep_transcripts`."""
    proc = _gcs(*args)
    proc.stdout = recorded = _Recorded(proc.stdout)
    _started.append(proc)
    remember(" ".join(map(str, args)), lambda: "".join(recorded.parts))
    return proc


def remember(command: str, output: Callable[[], str]) -> None:
    """Keep ``output()`` (a gcs process's output so far) if the running test fails."""
    _transcripts.append((command, output))


def keep_transcripts(dest: Path, tmp: Path) -> list[Path]:
    """Write what every gcs process of the test said to ``dest/gcs-<k>.txt`` and copy its files
    (run directories, profiles: everything under ``tmp`` but the vehicles' working directories,
    kept by their fixture) to ``dest/files``; then forget them. The files written."""
    written = []
    dest.mkdir(parents=True, exist_ok=True)
    for k, (command, output) in enumerate(_transcripts):
        path = dest / f"gcs-{k}.txt"
        path.write_text(f"$ gcs {command}\n{output()}")
        written.append(path)
    _transcripts.clear()
    for item in sorted(tmp.iterdir()):
        if not item.name.startswith("px4-"):
            target = dest / "files" / item.name
            if item.is_dir():
                shutil.copytree(item, target, symlinks=True, dirs_exist_ok=True)
            else:
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(item, target)
            written.append(target)
    return written


def forget_transcripts() -> None:
    """The test passed: nothing of its gcs processes to keep."""
    _transcripts.clear()


def kill_leftovers() -> list[int]:
    """SIGKILL every gcs process a test started and left running (a test that failed mid-flight);
    the pids killed."""
    killed = []
    while _started:
        proc = _started.pop()
        if proc.poll() is None:
            proc.kill()
            out, _ = proc.communicate(timeout=10)
            proc.stdout.parts.append(out or "")
            killed.append(proc.pid)
    return killed


def finish(proc: subprocess.Popen, before: list[str] = ()) -> tuple[int, str]:
    """Run ``proc`` to its end; its exit code and whole output (``before``: lines read already)."""
    out, _ = proc.communicate(timeout=FLIGHT_TIMEOUT_S)
    if isinstance(proc.stdout, _Recorded):
        proc.stdout.parts.append(out)
    return proc.returncode, "".join(before) + out


def report_rows(run: Path) -> list[dict]:
    """The rows of ``gcs report --json`` of a run: one per trial (docs/report.md), made in this
    process by the functions the command calls (a gcs process costs its start-up, tens of
    seconds on a loaded machine; the command itself is tested on the mock's runs)."""
    rd = RunDir.open(run)
    learning = run_learning(rd) if rd.kind == "learning" else None
    rows = run_metrics(rd)
    document = report_document(rd, rows, trial_clock_rates(rd), trial_overview(rd), learning)
    return json.loads(json.dumps(document, allow_nan=False))["rows"]


def sitl_profile(
    tmp: Path,
    name: str = "antx",
    *,
    limits: dict | None = None,
    mocap: dict | None = None,
    fields: dict[str, object] | None = None,
    **sections: dict,
) -> Path:
    """The shipped profile ``name`` for a firmware flight, written to ``tmp``: the watchdog
    limits ``limits`` (default :data:`SITL_LIMITS`; the lab flights give the mock's
    ``CI_FLIGHT``), a ``mocap`` section when given (a lab; with ``CI_MOCAP`` unless it says
    otherwise), any ``sections`` updated, and
    ``fields`` set by their dotted names (``{"learning.adaptive.repeats": 1}``)."""
    data = yaml.safe_load((ROOT / "profiles" / f"{name}.yaml").read_text())
    data["flight"] = dict(data.get("flight") or {}, **(SITL_LIMITS if limits is None else limits))
    if mocap is not None:
        data["mocap"] = {**CI_MOCAP, **mocap}
    for key, values in sections.items():
        data[key] = dict(data.get(key) or {}, **values)
    for dotted, value in (fields or {}).items():
        *parents, last = dotted.split(".")
        section = data
        for key in parents:
            section = section.setdefault(key, {})
        section[last] = value
    path = tmp / f"{name}-sitl.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def since(t0: float, t: float) -> float:
    """Seconds from the monotonic time ``t0`` to ``t``, to 0.1 s."""
    return round(t - t0, 1)


def first(events: list[tuple[float, str]], what: str) -> float:
    """When ``what`` first happened in a monitor's events [s after their start]."""
    return next(t for t, said in events if said == what)
