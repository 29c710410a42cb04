"""End to end on the indoor mock: NatNet -> gcs -> MAVSDK (vision forwarded) -> the mock.

The mock (``profiles/mock-mocap.yaml``) has no GPS: its position estimate exists only while the
vision gcs forwards arrives, so every flight here flies on the mocap path or not at all.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from synthetic import CI_FLIGHT, CI_MOCAP, SHORT

from gcs.io.mocap_samples import read_mocap_csv
from gcs.io.records import MOCAP_GRID_COLUMNS
from gcs.io.rundir import RunDir
from gcs.io.settings import FlightSettings
from gcs.mock.mocap.arena import ArenaFault, ArenaOptions
from gcs.mock.process import MockProcess

pytestmark = pytest.mark.e2e
ROOT = Path(__file__).resolve().parents[1]
INDOOR = ROOT / "profiles" / "mock-mocap.yaml"
TIMEOUT_S = 240


def gcs(*args: object) -> tuple[int, str]:
    proc = subprocess.run(
        [sys.executable, "-m", "gcs", *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, "COLUMNS": "200", "PYTHONUNBUFFERED": "1"},
        timeout=TIMEOUT_S,
    )
    return proc.returncode, proc.stdout + proc.stderr


#: The test's settle tolerance where a flight flies the frame check: the indoor mock hovers
#: about 5 cm from its setpoint, at antx's 5 cm tolerance, so each of the check's five settles
#: took 8-16 s on the wire (a minute a flight); within 10 cm they took 2-7 s, and the check
#: judged the same moves (its windows are the 1.5 s hovers after each settle).
QUICK_SETTLE = {"settle_tolerance_m": 0.1}


def profile(tmp: Path, flight: dict | None = None, **mocap: object) -> Path:
    """antx.yaml with :data:`CI_FLIGHT` (and ``flight``) and the section ``mocap`` (with
    :data:`CI_MOCAP` unless it says otherwise)."""
    data = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    data["flight"] = dict(data.get("flight") or {}, **CI_FLIGHT, **(flight or {}))
    data["mocap"] = {**CI_MOCAP, **mocap}
    path = tmp / "antx-mocap.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(SHORT))
    return path


@pytest.mark.flight_s(80)
def test_indoor_flight_on_mocap_only_forwards_vision_logs_it_and_learns(
    tmp_path: Path, tiny: Path
) -> None:
    run_path = tmp_path / "run"
    code, out = gcs(
        "fly", "--mock", "--mocap", "mock", "--iter", 2, "--trajectory", tiny,
        "--profile", profile(tmp_path, QUICK_SETTLE), "--run", run_path,
    )  # fmt: skip
    assert code == 0, out
    assert "EKF2: EV_CTRL 11, HGT_REF 3, GPS_CTRL 0" in out, out
    assert "the mapping is not judged in the air" in out, out  # forwarded: (2) alone
    assert "mocap check: the estimate followed +0.30 m north and +0.30 m east" in out, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1]
    for j in (0, 1):
        header = (run_path / f"trial-{j:03d}.csv").read_text().splitlines()[0].split(",")
        assert tuple(header[-3:]) == MOCAP_GRID_COLUMNS
        record = run.read_trial(j)
        assert np.all(np.isfinite(record.mocap_ned_m))
        # the estimate is the fused vision: it follows the mocap within centimetres
        assert np.max(np.abs(record.mocap_ned_m - record.pos_ned_m)[:, :2]) < 0.1
        samples = read_mocap_csv(run_path / f"mocap-{j:03d}.csv")
        duration_s = run.n_samples * run.t_ilc_s
        assert len(samples) > 100 * duration_s  # the arena streams at 120 Hz
        assert samples.tracked.all()
        extra = run.read_status(j).extra
        assert extra["measurement"] == "mocap" and extra["mocap_samples"] == len(samples)
        # the estimate leads by about EKF2_EV_DELAY (5 ms) less the loopback chain (docs/mocap.md)
        assert -0.02 <= extra["mocap_lag_s"] <= 0.02
    statuses = [run.read_status(j) for j in (0, 1)]
    assert statuses[1].epos_m < statuses[0].epos_m  # learning on the mocap: e_pos falls
    session = json.loads((run_path / "session-001.json").read_text())
    mocap = session["mocap"]
    assert mocap["forward"] and mocap["forwarded"] > 1000 and mocap["forward_failed"] == 0
    assert mocap["ekf2"]["EKF2_EV_CTRL"] == 11 and mocap["agreement_m"] < 0.05
    check = mocap["moves"][-1]
    assert [m["problem"] for m in mocap["moves"]] == [None] and check["following"] == "ok"
    # the estimate is the fused mocap: it moves with the mocap, along each axis
    for seen in check["mapping"]:
        assert 0.9 < seen["gain"] < 1.1 and seen["angle_deg"] < 10, check
    code, report = gcs("report", run_path)
    assert code == 0 and "e_pos by mocap" in report and "the mocap by" in report


@pytest.mark.flight_s(69)
def test_occlusion_mid_trial_aborts_lands_keeps_logs_and_resume_completes(
    tmp_path: Path, tiny: Path
) -> None:
    run_path = tmp_path / "run"
    stats = tmp_path / "stats.json"
    prof = profile(tmp_path, check_move_m=0.0)  # no checks: the trial's start is predictable
    # as the link-loss test: after the first OFFBOARD the hold and hover measurement, the
    # shortest settle and the hold before trial 0, then 1 s into the trial
    s = FlightSettings(**CI_FLIGHT)
    at_s = 4.0 + 2 * s.hover_before_trial_s + s.hover_measure_s + s.settle_time_s + 1.0
    arena = ArenaOptions(faults=(ArenaFault("occlusion", at_s, 1.0),))
    with MockProcess(config_path=INDOOR, seed=3, stats_path=stats, arena=arena) as mock:
        vehicle = ("--connect", mock.url, "--mocap", mock.mocap_url)
        code, out = gcs(
            "fly", *vehicle, "--iter", 2, "--trajectory", tiny, "--profile", prof,
            "--run", run_path,
        )  # fmt: skip
        assert code == 2, out
        assert "landed and disarmed" in out, out
        run = RunDir.open(run_path)
        status = run.read_status(0)
        assert not status.complete and "mocap" in status.reason and "lost" in status.reason
        raw = read_mocap_csv(run_path / "mocap-000.csv")  # the raw stream of the aborted trial
        assert (~raw.tracked).any() and raw.tracked.any()
        code, out = gcs("fly", *vehicle, "--resume", run_path, "--iter", 1)
        assert code == 0, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0]
    assert (run_path / "aborted" / "mocap-000-attempt-1.csv").exists()
    final = json.loads(stats.read_text())["modes"][-1]
    assert final["armed"] is False


def test_a_mirrored_mapping_is_refused_before_anything_starts(tmp_path: Path, tiny: Path) -> None:
    run_path = tmp_path / "run"
    code, out = gcs(
        "fly", "--mock", "--mocap", "mock", "--trajectory", tiny,
        "--profile", profile(tmp_path, right_handed=False), "--run", run_path,
    )  # fmt: skip
    assert code == 2
    lines = [ln for ln in out.splitlines() if ln.strip()]
    assert len(lines) == 1 and "mocap.right_handed" in lines[0] and "mirrors" in lines[0]
    assert not run_path.exists()  # nothing created, nothing started, nothing flown


#: The default mock (its own estimate, GPS-like wander) with an indoor PX4's EKF2 parameters:
#: a vehicle whose vision another bridge feeds (``mocap.forward: false``).
OWN_ESTIMATE = {
    "px4": {"ekf2_gps_ctrl": 0, "ekf2_ev_ctrl": 11, "ekf2_hgt_ref": 3, "ekf2_ev_delay_ms": 5.0}
}


@pytest.mark.flight_s(40)  # each case: 29-45 s
@pytest.mark.parametrize(
    ("case", "room_yaw_deg", "mocap", "refusal", "flight"),
    [
        # gcs reads the mocap 180 deg off the frame the vehicle flies in: the frame check
        ("another bridge, room 180 deg", 180.0, {"forward": False},
         r"pre-flight frame check: the mocap saw the vehicle's north motion 1[78]\d deg off "
         r"\(gain -1\.0\d, rotated [+-]1[78]\d deg\)", QUICK_SETTLE),
        # Motive's Y-up read as Z-up: the vehicle's east motion shows vertical in the mocap
        ("another bridge, wrong up axis", 0.0, {"forward": False, "up_axis": "+z"},
         r"pre-flight frame check: the mocap saw the vehicle's east motion (8\d|9\d) deg off "
         r"\(gain -?0\.\d\d, out of the horizontal plane\)", QUICK_SETTLE),
        # gcs forwards the mocap 90 deg off to a vehicle with its own heading: the position
        # loop turns and the vehicle spirals out faster and faster while settling. Two watches
        # see it, each rightly, and whichever sees it first ends the flight: the fence's (the
        # estimate runs against the velocity) or the mocap's (the body moved faster between
        # two frames than a multirotor can; about 5 mm over its limit in one CI run)
        ("forwarded, room 90 deg", 90.0, {},
         r"(the estimate contradicts itself|mocap position jumped \d\.\d+ m in [\d.]+ ms "
         r"\(more than \d\.\d+ m possible\)) while waiting for settling", {}),
    ],
)  # fmt: skip
def test_a_wrong_mapping_is_refused_after_take_off_before_the_first_trial(
    tmp_path: Path,
    tiny: Path,
    case: str,
    room_yaw_deg: float,
    mocap: dict,
    refusal: str,
    flight: dict,
) -> None:
    run_path = tmp_path / "run"
    stats = tmp_path / "stats.json"
    config = INDOOR
    if mocap.get("forward") is False:
        config = tmp_path / "mock-own-estimate.yaml"
        config.write_text(yaml.safe_dump(OWN_ESTIMATE))
    arena = ArenaOptions(yaw_offset_deg=room_yaw_deg)
    with MockProcess(config_path=config, seed=3, stats_path=stats, arena=arena) as mock:
        code, out = gcs(
            "fly", "--connect", mock.url, "--mocap", mock.mocap_url, "--trajectory", tiny,
            "--profile", profile(tmp_path, flight, **mocap), "--run", run_path,
        )  # fmt: skip
    assert code == 2, out
    assert re.search(refusal, out.splitlines()[-1]), out
    assert "trial 0 started" not in out and "landed and disarmed" in out, out
    assert RunDir.open(run_path).complete_trials() == []
    final = json.loads(stats.read_text())["modes"][-1]
    assert final["armed"] is False
    if "frame check" in refusal:  # the figures that refused it were said
        assert "mocap check: 0.30 m moves; gain/angle N, E: estimate on command" in out, out
