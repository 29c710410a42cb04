"""Pre-flight agreement checks: a mirrored axis shows up as a move the wrong way."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.core.frames import FrameMapping, mapping_for
from gcs.flight.mocap.checks import move_direction_problem, pose_agreement_problem

EAST = np.array([0.0, 0.3, 0.0])


def test_move_that_went_the_right_way_passes() -> None:
    est = np.array([0.01, 0.28, -0.01])
    mocap = np.array([-0.01, 0.29, 0.0])
    assert move_direction_problem(EAST, est, mocap) is None


def test_mirrored_mapping_is_caught_on_an_east_move_not_on_a_north_move() -> None:
    # The vehicle really moves; the mocap sees it in Motive axes; gcs maps with a
    # left-handed (mirrored) configuration of the same axes.
    room = mapping_for("optitrack")
    mirrored = FrameMapping(up_axis="+y", north_axis="+x", right_handed=False)
    start = np.array([0.2, -0.1, -1.0])
    for cmd, caught in ((EAST, True), (np.array([0.3, 0.0, 0.0]), False)):
        end = start + cmd
        seen = mirrored.position_to_ned(room.position_from_ned(np.vstack([start, end])))
        reason = move_direction_problem(cmd, cmd, seen[1] - seen[0])
        if caught:
            assert reason is not None
            assert "mocap moved 0.30 m the opposite way" in reason
            assert "frame mapping is wrong" in reason
        else:
            assert reason is None


def test_swapped_axes_are_caught() -> None:
    swapped = np.array([0.3, 0.0, 0.0])  # north and east exchanged
    reason = move_direction_problem(EAST, EAST, swapped)
    assert reason is not None and "mocap moved only 0.00 m" in reason


def test_yaw_offset_off_by_45_deg_is_caught_by_the_angle() -> None:
    off = 0.3 * np.array([np.sin(np.radians(50)), np.cos(np.radians(50)), 0.0])
    reason = move_direction_problem(EAST, EAST, off)
    assert reason is not None and "50 deg off" in reason


def test_estimate_wrong_and_vehicle_not_following() -> None:
    reason = move_direction_problem(EAST, -EAST, EAST)
    assert reason is not None and "vehicle's estimate is wrong" in reason
    reason = move_direction_problem(EAST, np.zeros(3), np.zeros(3))
    assert reason is not None and "did not follow" in reason


def test_bad_inputs() -> None:
    with pytest.raises(ValueError, match="non-zero"):
        move_direction_problem(np.zeros(3), EAST, EAST)
    with pytest.raises(ValueError, match="est_delta_ned_m"):
        move_direction_problem(EAST, np.array([0.0, np.nan, 0.0]), EAST)


def test_pose_agreement() -> None:
    assert pose_agreement_problem([0, 0, -1], [0.05, 0.0, -1.02]) is None
    reason = pose_agreement_problem([0, 0, -1], [0.0, 0.0, 1.0])  # up axis sign wrong
    assert reason is not None and "2.00 m apart (mostly down" in reason
