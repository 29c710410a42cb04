"""The real-firmware tests' vehicle (tests/px4/sitl.py) without firmware: the parameters every
vehicle starts with, and a second start refused while PX4 runs.

Here in tests/ rather than beside the module: they need no PX4 build, and tests/px4/ is
collected only when one is there."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from px4.sitl import SITL_PARAMS, Px4Build, Px4BuildError, Px4Sitl


def test_every_vehicle_starts_with_the_sitl_parameters_and_a_tests_own_win(tmp_path: Path) -> None:
    build = Px4Build(tmp_path / "no-build")
    assert SITL_PARAMS == {"IMU_GYRO_CAL_EN": 0}
    plain = Px4Sitl(build, tmp_path / "a")
    assert plain.params == SITL_PARAMS
    own = Px4Sitl(build, tmp_path / "b", {"EKF2_EV_DELAY": 30.0, "IMU_GYRO_CAL_EN": 1})
    assert own.params == {"IMU_GYRO_CAL_EN": 1, "EKF2_EV_DELAY": 30.0}


def test_a_second_start_while_px4_runs_is_refused_before_anything_starts(tmp_path: Path) -> None:
    vehicle = Px4Sitl(Px4Build(tmp_path / "no-build"), tmp_path / "wd")
    # a process standing in for the running PX4 (the build is never reached: it does not exist)
    vehicle.proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    vehicle.instance = 7
    try:
        with pytest.raises(RuntimeError, match="instance 7 already started"):
            vehicle.start()
        assert vehicle.proc.poll() is None  # the running one untouched
    finally:
        vehicle.proc.kill()
        vehicle.proc.wait()
    with pytest.raises(Px4BuildError):  # once it has ended, start goes on to the build
        vehicle.start()
