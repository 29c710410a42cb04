"""What PX4 is sent for a mocap sample: mapping, time stamp, covariance, message kind."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs.core.frames import mapping_for
from gcs.flight.mocap.client import MocapSample
from gcs.flight.mocap.forward import VisionForwarder, pose_covariance, vision_pose

MOTIVE = mapping_for("optitrack")


def sample(pos=(1.0, 2.0, 3.0), quat=(1.0, 0.0, 0.0, 0.0), tracked=True) -> MocapSample:
    return MocapSample(7, 123.4567891, math.nan, tracked, pos, quat)


def test_a_motive_pose_becomes_ned_with_its_receipt_time() -> None:
    cov = pose_covariance(0.005, math.radians(1.0))
    pose = vision_pose(sample(), MOTIVE, cov)
    assert pose is not None
    # Motive: X north, Y up, Z east (right-handed, Y up)
    np.testing.assert_allclose(pose.pos_ned_m, (1.0, 3.0, -2.0))
    np.testing.assert_allclose(pose.quat_wxyz, (1, 0, 0, 0), atol=1e-12)
    assert pose.time_usec == 123456789
    diag = [cov[k] for k in (0, 6, 11, 15, 18, 20)]
    np.testing.assert_allclose(diag, [0.005**2] * 3 + [math.radians(1.0) ** 2] * 3)
    assert sum(cov) == pytest.approx(sum(diag))


def test_a_turn_about_motives_up_axis_is_a_yaw_in_ned() -> None:
    # +30 deg about Motive's +Y (up) turns X (north) towards -Z (west): yaw -30 deg in NED
    half = math.radians(30) / 2
    pose = vision_pose(sample(quat=(math.cos(half), 0, math.sin(half), 0)), MOTIVE, (0.0,) * 21)
    assert pose is not None
    roll, pitch, yaw = pose.euler_rad
    assert (roll, pitch) == pytest.approx((0.0, 0.0), abs=1e-9)
    assert yaw == pytest.approx(math.radians(-30), abs=1e-9)


def test_an_untracked_sample_is_not_sent() -> None:
    nan = (math.nan,) * 3
    assert vision_pose(sample(pos=nan, quat=(math.nan,) * 4, tracked=False), MOTIVE, ()) is None


class Recorder:
    """Stands in for MAVSDK's blocking plugin: records what it is given."""

    def __init__(self, fail: bool = False) -> None:
        self.calls: list[tuple[str, object]] = []
        self.fail = fail

    def set_odometry(self, odometry: object) -> None:
        if self.fail:
            raise RuntimeError("link down")
        self.calls.append(("odometry", odometry))

    def set_vision_position_estimate(self, estimate: object) -> None:
        self.calls.append(("vpe", estimate))


def test_odometry_is_local_frd_vision_with_the_pose_and_unknown_velocity() -> None:
    from mavsdk.plugins.mocap import Odometry

    plugin = Recorder()
    fwd = VisionForwarder(plugin, MOTIVE, "odometry", 0.005, 0.02)
    fwd.send(sample())
    fwd.send(sample(pos=(math.nan,) * 3, quat=(math.nan,) * 4, tracked=False))
    ((kind, odo),) = plugin.calls
    assert kind == "odometry"
    assert odo.frame_id == Odometry.MavFrame.LOCAL_FRD  # what PX4's receiver passes to EKF2
    assert odo.estimator_type == Odometry.MavEstimatorType.VISION
    assert (odo.position_body.x_m, odo.position_body.y_m, odo.position_body.z_m) == (1, 3, -2)
    assert math.isnan(odo.speed_body.x_m_s) and odo.quality_percent == 100
    assert len(odo.pose_covariance.covariance_matrix) == 21
    stats = fwd.stats()
    assert (stats.sent, stats.skipped, stats.failed) == (1, 1, 0)


def test_vision_position_estimate_carries_the_angles() -> None:
    plugin = Recorder()
    VisionForwarder(plugin, MOTIVE, "vision_position_estimate", 0.005, 0.02).send(sample())
    ((kind, vpe),) = plugin.calls
    assert kind == "vpe" and vpe.time_usec == 123456789
    assert vpe.angle_body.yaw_rad == pytest.approx(0.0)


def test_a_failing_send_is_counted_not_raised_and_stop_ends_sending() -> None:
    fwd = VisionForwarder(Recorder(fail=True), MOTIVE, "odometry", 0.005, 0.02)
    fwd.send(sample())
    assert fwd.stats().failed == 1 and "link down" in fwd.stats().last_error
    plugin = Recorder()
    fwd = VisionForwarder(plugin, MOTIVE, "odometry", 0.005, 0.02)
    fwd.stop()
    fwd.send(sample())
    assert plugin.calls == []
