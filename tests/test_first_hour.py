"""A researcher's first hour: the resume command, the mock's seed per session, and friends."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np

from gcs.app.fly import FlyRequest, mock_session_seed, resume_command
from gcs.io.paths import packaged_dir


def test_a_session_flies_its_seed_unless_an_earlier_session_flew_it() -> None:
    assert mock_session_seed(0, 1) == 0  # a new run: --seed itself
    assert mock_session_seed(4, 2, {3}) == 4  # a resume given a seed of its own
    again = mock_session_seed(0, 2, {0})
    assert again != 0 and again == mock_session_seed(0, 2, {0})  # derived, reproducibly
    third = mock_session_seed(0, 3, {0, again})
    assert third not in {0, again}
    assert 0 <= again < 2**31 and 0 <= third < 2**31


def test_the_resume_command_names_the_vehicle_as_the_session_did() -> None:
    run = Path("logs/run 1")
    gps = packaged_dir("profile") / "mock-gps.yaml"
    mock = resume_command(run, FlyRequest(use_mock=True, mock_config=gps, seed=5), 2)
    assert shlex.split(mock) == [
        "gcs", "fly", "--resume", "logs/run 1", "--mock", "--mock-config", "mock-gps",
        "--seed", "5", "--iter", "2",
    ]  # fmt: skip
    request = FlyRequest(
        connect="udpin://0.0.0.0:14540", mocap="optitrack://10.0.0.2/drone", until_converged=True
    )
    real = resume_command(run, request, 3, again=4)
    assert shlex.split(real) == [
        "gcs", "fly", "--resume", "logs/run 1", "--connect", "udpin://0.0.0.0:14540",
        "--mocap", "optitrack://10.0.0.2/drone", "--iter", "3", "--until-converged",
        "--again", "4",
    ]  # fmt: skip


def test_a_samples_file_is_a_trajectory_of_its_own(tmp_path: Path) -> None:
    from gcs.app.fly import plan_fly

    root = Path(__file__).resolve().parents[1] / "trajectories"
    csv = tmp_path / "my racetrack.csv"
    csv.write_bytes((root / "racetrack.csv").read_bytes())
    direct = plan_fly(
        FlyRequest(profile=packaged_dir("profile") / "antx.yaml", trajectory=csv, logs=tmp_path)
    )
    wrapped = plan_fly(
        FlyRequest(
            profile=packaged_dir("profile") / "antx.yaml", trajectory=root / "racetrack.yaml"
        )
    )
    assert direct.trajectory.name == "my-racetrack"
    assert direct.trajectory.source == {
        "name": "my-racetrack", "type": "samples", "file": "my racetrack.csv"
    }  # fmt: skip
    np.testing.assert_array_equal(direct.reference.pos_ned_m, wrapped.reference.pos_ned_m)


def test_did_you_mean_names_the_closest_known_name_or_nothing() -> None:
    from gcs.io.suggest import did_you_mean

    assert did_you_mean("antz", ["antx", "antx-3d", "mock"]) == "; did you mean 'antx'?"
    assert did_you_mean("Stream_Rate", ["stream_rate_hz", "yaw_deg"]) == (
        "; did you mean 'stream_rate_hz'?"
    )
    assert did_you_mean("colour", ["frame", "url"]) == ""
    assert did_you_mean("x", []) == ""


def test_mavsdks_harmless_warning_is_logged_at_debug_and_others_as_they_come(caplog) -> None:
    import logging

    from mavsdk import LogLevel

    from gcs.flight.mavsdk_link import route_mavsdk_log

    with caplog.at_level(logging.DEBUG, logger="gcs.flight.mavsdk"):
        route_mavsdk_log(LogLevel.WARN, "Unexpected component ID 0", None, 0)
        route_mavsdk_log(LogLevel.WARN, "Unexpected component ID 1", None, 0)
    assert [(r.levelno, r.getMessage()) for r in caplog.records] == [
        (logging.DEBUG, "Unexpected component ID 0"),
        (logging.WARNING, "Unexpected component ID 1"),
    ]


def test_the_connect_hint_says_what_to_check_for_each_kind_of_url() -> None:
    from gcs.flight.link import connect_hint

    assert "UDP port 14540: is PX4 SITL running" in connect_hint("udpin://0.0.0.0:14540")
    assert "listening at 10.0.0.2:14550" in connect_hint("udpout://10.0.0.2:14550")
    assert "on /dev/ttyUSB0, powered" in connect_hint("serial:///dev/ttyUSB0:57600")
