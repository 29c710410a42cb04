"""Helpers of the real-firmware flights: the gcs CLI run to its end, its report, the profiles."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import yaml
from test_fly_e2e import ROOT
from test_fly_e2e import gcs as _gcs

FLIGHT_TIMEOUT_S = 420  # an upper bound for a whole session on a loaded machine, not a wait
# The watchdog limits of the mock's end-to-end flights (tests/synthetic.py's CI_FLIGHT), and
# for the same reason: PX4 SITL runs in lockstep with its simulator, so when the machine
# starves PX4 of CPU its clock stops, and gcs, whose stream goes on on the wall clock, sees no
# telemetry. Measured on a 2-core machine at load 14: 0.5 s without a position sample while
# PX4's own log shows its estimate every 8 ms of its time without a gap. The shipped 0.5 s and
# 0.2 s are for a real vehicle, whose clock never stops.
SITL_LIMITS = {"max_telemetry_age_s": 1.0, "max_setpoint_late_s": 0.4}


_started: list[subprocess.Popen] = []


def gcs(*args: object) -> subprocess.Popen:
    """``python -m gcs *args`` started (output on a pipe), remembered for :func:`kill_leftovers`."""
    proc = _gcs(*args)
    _started.append(proc)
    return proc


def kill_leftovers() -> list[int]:
    """SIGKILL every gcs process a test started and left running (a test that failed mid-flight);
    the pids killed."""
    killed = []
    while _started:
        proc = _started.pop()
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=10)
            killed.append(proc.pid)
    return killed


def finish(proc: subprocess.Popen, before: list[str] = ()) -> tuple[int, str]:
    """Run ``proc`` to its end; its exit code and whole output (``before``: lines read already)."""
    out, _ = proc.communicate(timeout=FLIGHT_TIMEOUT_S)
    return proc.returncode, "".join(before) + out


def report_rows(run: Path) -> list[dict]:
    """The rows of ``gcs report --json`` of a run: one per trial (docs/report.md)."""
    code, out = finish(gcs("report", run, "--json"))
    assert code == 0, out
    return json.loads(out)["rows"]


def sitl_profile(tmp: Path, name: str = "antx", **sections: dict) -> Path:
    """The shipped profile ``name`` with :data:`SITL_LIMITS` (and any ``sections`` updated),
    written to ``tmp``."""
    data = yaml.safe_load((ROOT / "profiles" / f"{name}.yaml").read_text())
    data["flight"] = dict(data.get("flight") or {}, **SITL_LIMITS)
    for key, values in sections.items():
        data[key] = dict(data.get(key) or {}, **values)
    path = tmp / f"{name}-sitl.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path
