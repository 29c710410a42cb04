"""Frame maths: each mocap convention to NED (one test per convention), quaternions, the
invariants (inverse, isometry) as properties, and PX4's map projection."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.core.frames import (
    SYSTEM_FRAMES,
    FrameMapping,
    global_to_ned,
    mapping_for,
    matrix_to_quat,
    ned_to_global,
    quat_angle_rad,
    quat_to_matrix,
)

# A point 1 m north, 2 m east, 3 m up of the origin (NED: 1, 2, -3), written in each
# convention's own axes from the convention's definition (not from the code under test).
POINT_NED = np.array([1.0, 2.0, -3.0])
POINT_IN = {
    # Motive Y-up, north = +X: up = +Y, east = +Z (X cross Y = Z, right-handed)
    "optitrack": [1.0, 3.0, 2.0],
    # Z-up, north = +X (forward-left-up): east = -Y
    "optitrack-zup": [1.0, -2.0, 3.0],
    "vicon": [1.0, -2.0, 3.0],
    "qualisys": [1.0, -2.0, 3.0],
    "vrpn": [1.0, -2.0, 3.0],
    "flu": [1.0, -2.0, 3.0],
    # east-north-up
    "enu": [2.0, 1.0, 3.0],
    "ned": [1.0, 2.0, -3.0],
}


@pytest.mark.parametrize("convention", sorted(SYSTEM_FRAMES))
def test_each_convention_maps_a_known_point_to_ned(convention: str) -> None:
    mapping = mapping_for(convention)
    got = mapping.position_to_ned(np.array(POINT_IN[convention]))
    np.testing.assert_allclose(got, POINT_NED, atol=1e-12)
    np.testing.assert_allclose(mapping.position_from_ned(POINT_NED), POINT_IN[convention])


def test_every_convention_is_tested() -> None:
    assert set(POINT_IN) == set(SYSTEM_FRAMES)


@pytest.mark.parametrize("convention", sorted(SYSTEM_FRAMES))
def test_shipped_conventions_are_right_handed_rotations(convention: str) -> None:
    a = mapping_for(convention).axes()
    np.testing.assert_allclose(a @ a.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(a) == pytest.approx(1.0)


def test_motive_yaw_about_its_up_axis_is_a_yaw_in_ned() -> None:
    # A body turned +30 deg about Motive's +Y (up) turns its nose (+X) towards -Z, i.e. west:
    # seen from above in NED that is a yaw of -30 deg.
    half = math.radians(30.0) / 2
    q_motive = np.array([math.cos(half), 0.0, math.sin(half), 0.0])
    q_ned = mapping_for("optitrack").attitude_to_ned(q_motive)
    half_ned = math.radians(-30.0) / 2
    np.testing.assert_allclose(q_ned, [math.cos(half_ned), 0, 0, math.sin(half_ned)], atol=1e-12)


def test_enu_yaw_zero_faces_east_in_ned() -> None:
    # A body at identity in ENU faces +X = east; the NED heading of east is +90 deg; its body
    # axes (x forward, y left, z up) become FRD after the body-side axis change.
    mapping = mapping_for("enu")
    q = mapping.attitude_to_ned(np.array([1.0, 0.0, 0.0, 0.0]))
    rot = quat_to_matrix(q)
    np.testing.assert_allclose(rot @ [1, 0, 0], [0, 1, 0], atol=1e-12)  # nose east
    np.testing.assert_allclose(rot @ [0, 0, 1], [0, 0, 1], atol=1e-12)  # body down = down


def test_yaw_offset_and_origin() -> None:
    mapping = mapping_for("vicon", yaw_offset_deg=90.0, origin_m=(1.0, 1.0, 0.0))
    # the vicon point (2, 1, 0) is 1 m along vicon +X from the origin; +X heads east (90 deg)
    np.testing.assert_allclose(
        mapping.position_to_ned(np.array([2.0, 1.0, 0.0])), [0, 1, 0], atol=1e-12
    )
    q = mapping.attitude_to_ned(np.array([1.0, 0.0, 0.0, 0.0]))
    np.testing.assert_allclose(quat_to_matrix(q) @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_left_handed_mapping_is_a_mirror() -> None:
    right = mapping_for("optitrack")
    left = FrameMapping(up_axis="+y", north_axis="+x", right_handed=False)
    assert np.linalg.det(left.axes()) == pytest.approx(-1.0)
    p = np.array([0.5, 1.0, 0.7])
    a, b = right.position_to_ned(p), left.position_to_ned(p)
    np.testing.assert_allclose([a[0], a[2]], [b[0], b[2]])  # north and down agree
    assert b[1] == pytest.approx(-a[1])  # east mirrored
    # a mirrored mapping still yields proper rotations
    q_in = np.array([math.cos(0.3), 0.1, math.sin(0.3) * 0.9, 0.0])
    q = left.attitude_to_ned(q_in / np.linalg.norm(q_in))
    assert np.linalg.det(quat_to_matrix(q)) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"up_axis": "y"}, "up_axis"),
        ({"up_axis": "+w"}, "up_axis"),
        ({"north_axis": "+y", "up_axis": "-y"}, "north_axis"),
        ({"origin_m": (0.0, math.nan, 0.0)}, "origin_m"),
        ({"yaw_offset_deg": math.inf}, "yaw_offset_deg"),
    ],
)
def test_bad_mapping_is_refused_naming_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        FrameMapping(**kwargs)


def test_unknown_convention_lists_the_known_ones() -> None:
    with pytest.raises(ValueError, match="optitrack"):
        mapping_for("motive-yup")


def test_wrong_orientation_of_arrays_is_refused() -> None:
    mapping = mapping_for("optitrack")
    with pytest.raises(ValueError, match="shape"):
        mapping.position_to_ned(np.zeros((3, 5)))
    with pytest.raises(ValueError, match="unit"):
        mapping.attitude_to_ned(np.array([2.0, 0.0, 0.0, 0.0]))


# --- properties ------------------------------------------------------------------------------

AXES = ["+x", "-x", "+y", "-y", "+z", "-z"]
finite = st.floats(-50, 50, allow_nan=False)


@st.composite
def mappings(draw) -> FrameMapping:
    up = draw(st.sampled_from(AXES))
    north = draw(st.sampled_from([a for a in AXES if a[1] != up[1]]))
    return FrameMapping(
        up_axis=up,
        north_axis=north,
        right_handed=draw(st.booleans()),
        yaw_offset_deg=draw(st.floats(-360, 360)),
        origin_m=(draw(finite), draw(finite), draw(finite)),
    )


@st.composite
def quaternions(draw) -> np.ndarray:
    q = np.array([draw(st.floats(-1, 1)) for _ in range(4)])
    if np.linalg.norm(q) < 0.1:
        q = np.array([1.0, 0.0, 0.0, 0.0])
    return q / np.linalg.norm(q)


@settings(max_examples=200, deadline=None)
@given(mappings(), st.lists(st.tuples(finite, finite, finite), min_size=2, max_size=5))
def test_position_mapping_then_inverse_is_identity_and_preserves_distances(
    mapping: FrameMapping, points: list
) -> None:
    p = np.array(points)
    ned = mapping.position_to_ned(p)
    np.testing.assert_allclose(mapping.position_from_ned(ned), p, atol=1e-9)
    d_sys = np.linalg.norm(p[:, None] - p[None], axis=-1)
    d_ned = np.linalg.norm(ned[:, None] - ned[None], axis=-1)
    np.testing.assert_allclose(d_ned, d_sys, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(mappings(), quaternions(), quaternions())
def test_attitude_mapping_then_inverse_is_identity_and_preserves_angles(
    mapping: FrameMapping, q1: np.ndarray, q2: np.ndarray
) -> None:
    back = mapping.attitude_from_ned(mapping.attitude_to_ned(q1))
    assert float(quat_angle_rad(back, q1)) < 1e-6
    a1, a2 = mapping.attitude_to_ned(q1), mapping.attitude_to_ned(q2)
    assert float(quat_angle_rad(a1, a2)) == pytest.approx(float(quat_angle_rad(q1, q2)), abs=1e-6)


@settings(max_examples=200, deadline=None)
@given(quaternions())
def test_quaternion_matrix_round_trip(q: np.ndarray) -> None:
    rot = quat_to_matrix(q)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
    back = matrix_to_quat(rot)
    assert back[0] >= 0
    # q and -q are the same rotation (and both have w >= 0 when w = 0)
    assert min(np.abs(back - q).max(), np.abs(back + q).max()) < 1e-9


def test_vectorised_attitudes_match_single_ones() -> None:
    mapping = mapping_for("qualisys", yaw_offset_deg=33.0)
    qs = np.array([[1.0, 0, 0, 0], [0.0, 1, 0, 0], [math.sqrt(0.5), 0, 0, math.sqrt(0.5)]])
    together = mapping.attitude_to_ned(qs)
    for q, got in zip(qs, together, strict=True):
        np.testing.assert_allclose(got, mapping.attitude_to_ned(q), atol=1e-12)


def test_ned_to_global_is_pxs_projection_and_inverts() -> None:
    lat0, lon0 = 47.3977431, 8.5455947
    lat, lon = ned_to_global(lat0, lon0, 1000.0, 0.0)
    assert lat - lat0 == pytest.approx(math.degrees(1000.0 / 6_371_000.0), rel=1e-9)
    assert lon == pytest.approx(lon0, abs=1e-12)
    lat, lon = ned_to_global(lat0, lon0, 0.0, 100.0)
    # east: along the great circle, within a hair of the local parallel's scale
    assert lon - lon0 == pytest.approx(
        math.degrees(100.0 / (6_371_000.0 * math.cos(math.radians(lat0)))), rel=1e-6
    )
    for n, e in ((3.0, -4.5), (-4.5, 4.5), (0.0, 0.0), (250.0, -120.0)):
        back = global_to_ned(lat0, lon0, *ned_to_global(lat0, lon0, n, e))
        np.testing.assert_allclose(back, (n, e), atol=1e-6)
