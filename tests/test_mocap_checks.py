"""Pre-flight agreement checks: a mirrored axis shows up as a move the wrong way."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.core.frames import FrameMapping, mapping_for
from gcs.flight.mocap.checks import (
    WANDER_FACTOR,
    move_direction_problem,
    move_length,
    pose_agreement_problem,
    window_mean,
)

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


def test_window_mean_and_wander_against_a_direct_computation() -> None:
    rng = np.random.default_rng(3)
    pos = rng.normal(0.0, 0.1, (200, 3)) + [1.0, -2.0, -1.5]
    pos[7] = np.nan
    mean, wander = window_mean(pos)
    ok = pos[np.isfinite(pos).all(axis=1)]
    np.testing.assert_allclose(mean, ok.mean(axis=0))
    d = ok[:, :2] - ok[:, :2].mean(axis=0)
    assert wander == pytest.approx(np.sqrt((d**2).sum(axis=1).mean()))
    with pytest.raises(ValueError, match="no finite"):
        window_mean(np.full((3, 3), np.nan))


def test_a_wandering_hover_lengthens_the_move_within_the_cap() -> None:
    assert move_length(0.3, 0.01) == 0.3
    assert move_length(0.3, 0.15) == pytest.approx(WANDER_FACTOR * 0.15)
    assert move_length(0.3, 2.0) == 1.0
    assert move_length(1.5, 2.0) == 1.5


def test_averaged_windows_see_a_move_that_a_mid_swing_snapshot_hides() -> None:
    # hover swinging +-0.25 m east; a 0.3 m east move: snapshots at opposite swings see 0.05 m
    t = np.linspace(0.0, 1.5, 150)
    swing = 0.25 * np.sin(2 * np.pi * t / 1.5)
    before = np.column_stack([np.zeros_like(t), swing, np.full_like(t, -1.5)])
    after = before + [0.0, 0.3, 0.0]
    cmd = np.array([0.0, 0.3, 0.0])
    snap = after[112] - before[37]  # +0.25 before, -0.25 after: seen as 0.3 - 0.5
    assert move_direction_problem(cmd, snap, snap) is not None
    (m0, _), (m1, _) = window_mean(before), window_mean(after)
    assert move_direction_problem(cmd, m1 - m0, m1 - m0) is None
