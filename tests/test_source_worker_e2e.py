"""End to end: the learning between trials, in its own process, cannot delay the flight.

``gcs fly`` on the indoor mock (no GPS: it navigates on the vision gcs forwards from the mock
arena's NatNet stream) with an adaptive profile whose model is 40 % too strong, so that the
learning step after trial 2 refreshes the model (the heavy one: seconds of numerics), while a
process burning CPU runs beside it. The mock records every vision message and setpoint it
receives on its own clock; what it received between the trials, while gcs learned, is compared
with what it received during the trials (tests/flight_gaps.py).
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml
from flight_gaps import gaps
from synthetic import CI_FLIGHT, CI_MOCAP
from test_mocap_e2e import INDOOR, TIMEOUT_S

from gcs.app.fly import FlyRequest, fly_run, plan_fly, start_run
from gcs.app.fly_view import learning_lines
from gcs.flight.mocap.health import HealthLimits
from gcs.flight.mocap.link import MocapLink
from gcs.io.rundir import RunDir
from gcs.mock.mocap.arena import ArenaOptions
from gcs.mock.process import MockProcess

pytestmark = pytest.mark.e2e
ROOT = Path(__file__).resolve().parents[1]
SHORT = ROOT / "trajectories" / "eight-short.yaml"


def adaptive_mocap_profile(tmp: Path) -> Path:
    data = yaml.safe_load((ROOT / "profiles" / "antx-adaptive.yaml").read_text())
    data["model"]["num"] = [1.4 * v for v in data["model"]["num"]]
    data["flight"] = dict(data.get("flight") or {}, **CI_FLIGHT)
    # one repeat (the profile ships two): trial 2 is learned and the step after it refreshes
    # the model, in three flights
    data["learning"]["adaptive"]["repeats"] = 1
    # no frame check after take-off: it proves the mapping (tests/test_mocap_e2e.py), not the
    # streams during learning, and its five settles cost a minute a flight on the wire
    data["mocap"] = {**CI_MOCAP, "check_move_m": 0.0}
    path = tmp / "antx-adaptive-mocap.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


class VehicleJudged(MocapLink):
    """A mocap link without gcs's stream watch (only a reader that ended stops the flight)."""

    def problem(self) -> str | None:
        return self.client.problem()


@contextmanager
def cpu_burner(seconds: float) -> Iterator[None]:
    """Another process burning one core, for at most ``seconds``: a background job (nice 19),
    taking every cycle the flight leaves, and beside gcs in its scheduling group."""
    code = (
        f"import os, time\nos.nice(19)\nend = time.monotonic() + {seconds}\n"
        "while time.monotonic() < end: pass"
    )
    hog = subprocess.Popen([sys.executable, "-c", code])
    try:
        yield
    finally:
        hog.kill()
        hog.wait()


@pytest.mark.flight_s(63)
def test_learning_between_trials_does_not_delay_the_vision_or_the_setpoints(
    tmp_path: Path,
) -> None:
    run_path, stats_path = tmp_path / "run", tmp_path / "stats.json"
    arena = ArenaOptions(seed=3)
    lines: list[str] = []
    with (
        MockProcess(config_path=INDOOR, seed=3, stats_path=stats_path, arena=arena) as mock,
        cpu_burner(TIMEOUT_S),
    ):
        plan = plan_fly(
            FlyRequest(
                profile=adaptive_mocap_profile(tmp_path), trajectory=SHORT, run=run_path,
                mocap=mock.mocap_url,
            )
        )  # fmt: skip
        assert plan.mocap is not None and plan.mocap.source is not None
        source = plan.mocap.source
        # gcs's own watch judges the stream by the reader's receipt stamps, which this loaded
        # machine delays past its 0.5 s window while the vehicle still receives the vision
        # (seen here: "no mocap frames received" / "stale (0.41 s)" before trial 0, with no
        # gap above 0.13 s at the mock): that watch is left out, and the vehicle's own
        # reception is judged against its limit below instead
        link = VehicleJudged(source, plan.mocap.settings.mapping(source), plan.mocap.settings)
        with link:
            fly_run(
                mock.url, start_run(plan), 3, plan.settings, on_event=lambda e: lines.append(
                    str(e)), on_learn=lambda o: lines.extend(learning_lines(o)), mocap=link,
            )  # fmt: skip
    out = "\n".join(lines)
    assert any("model refreshed: " in line for line in lines), out  # after trial 2, hovering
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1, 2]
    g = gaps(run, json.loads(stats_path.read_text()))
    # the vision kept coming at the arena's rate, in the trials and between them
    assert g.vision_messages > 120 * 3 * 6.5, g
    # while gcs learned, the vehicle kept its vision and its setpoints: no gap that would
    # stop it, judged by the limits that matter there rather than by timing ratios (those are
    # the benchmark's: benchmarks/between_trials.py; on a quiet machine with a burner beside
    # it the largest vision gap was 19 ms in the trials and 158 ms between them)
    assert g.vision_between_s < HealthLimits().max_age_s, g  # gcs's own stale limit
    # PX4 leaves offboard below 2 Hz of setpoints; MAVSDK re-sends the hover one at 20 Hz
    assert g.setpoint_between_s < 0.5, g
