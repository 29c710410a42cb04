"""The real-firmware tests' reading of PX4's logs (tests/px4/ulog.py): the line that tells a
failure of PX4 SITL's interval timer from one of gcs.

Here in tests/ rather than beside the module: they need no PX4 build, and tests/px4/ is
collected only when one is there."""

from __future__ import annotations

from px4.ulog import IMU, TIMER_FED, timer_stopped

# A healthy log's ends, as a flight's last log has them (PX4's clock, s): the CPU load comes
# every 0.5 s, the others at 5-50 Hz.
HEALTHY = {
    "vehicle_air_data": 120.27,
    "vehicle_magnetometer": 120.28,
    "vehicle_gps_position": 120.20,
    "battery_status": 120.29,
    "cpuload": 119.85,
    IMU: 120.30,
}


def test_a_log_whose_sensors_went_on_to_its_end_says_nothing() -> None:
    assert timer_stopped(HEALTHY) is None


def test_sensors_that_stopped_while_the_imu_went_on_are_named_from_their_first_end() -> None:
    # as the two failures' logs had it: the simulators at the arming, the CPU load before
    ends = {**HEALTHY, IMU: 160.0}
    ends.update(vehicle_air_data=16.41, vehicle_magnetometer=16.38, vehicle_gps_position=16.36,
                battery_status=16.40, cpuload=16.05)  # fmt: skip
    line = timer_stopped(ends)
    assert line is not None
    assert "16.05 s" in line and "160.00 s" in line
    for name in TIMER_FED:
        assert name in line


def test_one_stream_alone_that_stops_is_not_the_timer() -> None:
    # GPS alone may stop for a reason of its own (a GPS failure injected, say)
    assert timer_stopped({**HEALTHY, "vehicle_gps_position": 30.0}) is None
    line = timer_stopped({**HEALTHY, "vehicle_gps_position": 30.0, "cpuload": 31.5})
    assert line is not None and "vehicle_gps_position, cpuload" in line
    assert "vehicle_air_data" not in line


def test_the_gap_must_exceed_the_bound() -> None:
    ends = {**HEALTHY, IMU: 100.0, "vehicle_air_data": 98.1, "cpuload": 98.1}
    assert timer_stopped(ends) is None  # 1.9 s: within the bound
    line = timer_stopped(ends, min_gap_s=1.5)
    assert line is not None and "98.10 s" in line


def test_topics_a_default_log_lacks_stopped_before_it_and_without_the_imu_nothing_is_judged():
    # a log opened at an arming after the timer stopped (at the disarming before) holds none
    only_imu = {IMU: 40.0, "cpuload": 39.8}
    line = timer_stopped(only_imu)
    assert line is not None and "before this log began" in line
    assert "cpuload" not in line and "vehicle_air_data" in line
    # a log without SIH's IMU (another logging profile) is not judged at all
    assert timer_stopped({"vehicle_air_data": 1.0, "cpuload": 1.0}) is None
