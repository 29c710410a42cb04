"""gcs fly --check against the mock drone: the real-vehicle checklist, per parameter."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

# gcs processes against the mock drone over MAVSDK: with the wire's flights, out of test-fast
pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[1]


def check(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gcs", "fly", "--mock", "--check", "--logs", str(tmp_path / "logs"),
         *args],
        capture_output=True, text=True, timeout=120, env={**os.environ, "COLUMNS": "250"},
    )  # fmt: skip


def rows(stdout: str) -> dict[str, str]:
    found = re.findall(r"^(ok|warn|refuse) +([A-Z0-9_]+): found", stdout, flags=re.M)
    return {param: level for level, param in found}


def test_the_gps_and_the_mocap_checklists_judge_every_parameter(tmp_path: Path) -> None:
    gps = check(tmp_path, "--mock-config", "mock-gps")
    assert gps.returncode == 0, gps.stdout + gps.stderr
    levels = rows(gps.stdout)
    assert levels["EKF2_GPS_CTRL"] == levels["EKF2_HGT_REF"] == levels["EKF2_EV_CTRL"] == "ok"
    assert levels["NAV_DLL_ACT"] == "warn"  # the mock keeps PX4's default 0
    assert levels["GF_ACTION"] == "ok" and "COM_RC_OVERRIDE" in levels
    assert set(levels.values()) <= {"ok", "warn"}
    mocap = check(tmp_path, "--mocap", "mock")
    assert mocap.returncode == 0, mocap.stdout + mocap.stderr
    levels = rows(mocap.stdout)
    # the mock serves a lab's vision settings: the barometer kept, EKF2_EVP_NOISE 0.01 m
    for param in ("EKF2_EV_CTRL", "EKF2_HGT_REF", "EKF2_GPS_CTRL", "EKF2_EV_DELAY",
                  "EKF2_BARO_CTRL", "EKF2_EVP_NOISE"):  # fmt: skip
        assert levels[param] == "ok", (param, mocap.stdout)
    assert {"EKF2_MAG_TYPE", "COM_OBL_RC_ACT"} <= set(levels)
    assert not (tmp_path / "logs").exists()  # a check creates nothing


def test_vision_not_fused_with_mocap_is_refused_naming_the_fix(tmp_path: Path) -> None:
    text = (ROOT / "profiles" / "mock-mocap.yaml").read_text()
    bad = tmp_path / "bad.yaml"
    bad.write_text(re.sub(r"ekf2_ev_ctrl: \d+", "ekf2_ev_ctrl: 0", text))
    result = check(tmp_path, "--mocap", "mock", "--mock-config", str(bad))
    assert result.returncode == 2, result.stdout + result.stderr
    assert rows(result.stdout)["EKF2_EV_CTRL"] == "refuse"
    error = result.stderr.strip().splitlines()
    assert len(error) == 1 and "set EKF2_EV_CTRL to 15" in error[0], result.stderr
