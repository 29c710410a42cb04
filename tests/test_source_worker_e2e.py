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
from synthetic import CI_FLIGHT
from test_mocap_e2e import INDOOR, TIMEOUT_S, gcs

from gcs.flight.mocap.health import HealthLimits
from gcs.io.rundir import RunDir
from gcs.mock.mocap.arena import ArenaOptions
from gcs.mock.process import MockProcess

pytestmark = pytest.mark.e2e
ROOT = Path(__file__).resolve().parents[1]
SHORT = ROOT / "trajectories" / "eight-short.yaml"
RATIO = 2.0
"""Between trials the largest vision gap at the vehicle is at most this times the largest
during a trial: the flight process does less then than while it streams a trial."""


def adaptive_mocap_profile(tmp: Path) -> Path:
    data = yaml.safe_load((ROOT / "profiles" / "antx-adaptive.yaml").read_text())
    data["model"]["num"] = [1.4 * v for v in data["model"]["num"]]
    data["flight"] = dict(data.get("flight") or {}, **CI_FLIGHT)
    data["mocap"] = {}
    path = tmp / "antx-adaptive-mocap.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@contextmanager
def cpu_burner(seconds: float) -> Iterator[None]:
    """Another process burning one core, for at most ``seconds``."""
    code = f"import time\nend = time.monotonic() + {seconds}\nwhile time.monotonic() < end: pass"
    hog = subprocess.Popen([sys.executable, "-c", code])
    try:
        yield
    finally:
        hog.kill()
        hog.wait()


def test_learning_between_trials_does_not_delay_the_vision_or_the_setpoints(
    tmp_path: Path,
) -> None:
    run_path, stats_path = tmp_path / "run", tmp_path / "stats.json"
    arena = ArenaOptions(seed=3)
    with (
        MockProcess(config_path=INDOOR, seed=3, stats_path=stats_path, arena=arena) as mock,
        cpu_burner(TIMEOUT_S),
    ):
        code, out = gcs(
            "fly", "--connect", mock.url, "--mocap", mock.mocap_url, "--iter", 3,
            "--trajectory", SHORT, "--profile", adaptive_mocap_profile(tmp_path),
            "--run", run_path,
        )  # fmt: skip
    assert code == 0, out
    assert "model refreshed: " in out, out  # the heavy step ran, in the hover after trial 2
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1, 2]
    g = gaps(run, json.loads(stats_path.read_text()))
    # the vision kept coming at the arena's rate, in the trials and between them
    assert g.vision_messages > 120 * 3 * 6.5, g
    assert g.vision_between_s < HealthLimits().max_age_s, g  # EKF2 would stop fusing beyond
    assert g.vision_between_s <= RATIO * g.vision_trial_s, g
    # between trials MAVSDK re-sends the hover setpoint at 20 Hz on its own: no gap beyond
    # what the trials saw or that period, whichever is longer, times the ratio
    assert g.setpoint_between_s <= RATIO * max(g.setpoint_trial_s, 1 / 20), g
