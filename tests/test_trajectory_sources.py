"""Tests of gcs.core.trajectory_sources and the trajectory files of every source."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.core.trajectory import Box, Reference, check_reference
from gcs.core.trajectory_sources import (
    EllipseShape,
    SamplesShape,
    WaypointsShape,
    plane_axes,
    sample_ellipse,
    sample_reference,
    sample_samples,
    sample_waypoints,
    waypoint_times,
)
from gcs.errors import TrajectoryError
from gcs.io.config import load_profile, load_trajectory
from gcs.io.samples_file import PlannerSamples, read_samples, write_samples_csv

ROOT = Path(__file__).resolve().parents[1]
WIDE = Box((-10.0, 10.0), (-10.0, 10.0), (-10.0, 0.0))
EXAMPLES = ("circle", "helix", "inspection", "racetrack", "eight", "eight-short")


def assert_hover_at_start(ref, hover_s: float, atol: float = 1e-9) -> None:
    start = ref.pos_ned_m[0]
    np.testing.assert_allclose(ref.pos_ned_m[-1], start, atol=atol)
    for arr in (ref.vel_ned_m_s, ref.acc_ned_m_s2):
        np.testing.assert_allclose(arr[0], 0.0, atol=1e-9)
        np.testing.assert_allclose(arr[-1], 0.0, atol=1e-9)
    still = ref.t_s <= hover_s + 1e-9
    np.testing.assert_allclose(ref.pos_ned_m[still], np.tile(start, (still.sum(), 1)), atol=atol)


# ------------------------------------------------------------------------ circle and ellipse


def test_circle_cruise_speed_and_curvature_are_those_of_a_circle():
    r, period = 1.2, 5.0
    shape = EllipseShape((0.5, -0.5, -1.5), (r, r), period, loops=2, ramp_s=2.0, hover_s=1.0)
    ref = sample_ellipse(shape, 0.01)
    # cruise: after hover and ramp, before the ramp down
    cruise = (ref.t_s > 1.0 + 2.0 + 1e-9) & (ref.t_s < 1.0 + 2 * period - 1e-9)
    w = 2 * math.pi / period
    speed = np.linalg.norm(ref.vel_ned_m_s[cruise], axis=1)
    np.testing.assert_allclose(speed, r * w, rtol=1e-12)
    # centripetal acceleration v^2 / r towards the centre; curvature |v x a| / |v|^3 = 1 / r
    v, a = ref.vel_ned_m_s[cruise], ref.acc_ned_m_s2[cruise]
    curvature = np.linalg.norm(np.cross(v, a), axis=1) / speed**3
    np.testing.assert_allclose(curvature, 1.0 / r, rtol=1e-9)
    to_centre = np.array(shape.center_ned_m) - ref.pos_ned_m[cruise]
    np.testing.assert_allclose(a, to_centre * w**2, atol=1e-9)
    # every point on the circle, in the horizontal plane of the centre
    dist = np.linalg.norm(ref.pos_ned_m - np.array(shape.center_ned_m), axis=1)
    np.testing.assert_allclose(dist, r, rtol=1e-12)
    # clockwise seen from above: north first towards east
    assert ref.vel_ned_m_s[cruise][0, 1] > 0 and ref.pos_ned_m[0, 0] == pytest.approx(1.7)
    assert_hover_at_start(ref, 1.0)


def test_ellipse_in_a_vertical_plane_and_a_normal_vector():
    shape = EllipseShape((0, 0, -2.0), (1.0, 0.5), 6.0, plane="north-down", loops=1)
    ref = sample_ellipse(shape, 0.02)
    p = ref.pos_ned_m - np.array([0, 0, -2.0])
    np.testing.assert_allclose(p[:, 1], 0.0, atol=1e-12)  # east stays 0
    np.testing.assert_allclose((p[:, 0] / 1.0) ** 2 + (p[:, 2] / 0.5) ** 2, 1.0, atol=1e-12)
    # a normal vector: the plane's axes are orthonormal and normal to it
    for normal in ([0, 0, 1], [1, 0, 0], [1, 1, -1]):
        u, v = plane_axes(tuple(normal))
        n = np.array(normal) / np.linalg.norm(normal)
        assert abs(u @ v) < 1e-12 and abs(u @ n) < 1e-12 and abs(v @ n) < 1e-12
        assert np.linalg.norm(u) == pytest.approx(1) and np.linalg.norm(v) == pytest.approx(1)
    u, v = plane_axes((0, 0, 1))
    np.testing.assert_allclose(u, [1, 0, 0]) and np.testing.assert_allclose(v, [0, 1, 0])


def test_helix_climbs_by_mid_manoeuvre_and_comes_back():
    shape = EllipseShape((0, 0, -1.5), (1.0, 1.0), 6.0, loops=2, climb_m=1.0)
    ref = sample_ellipse(shape, 0.01)
    assert ref.pos_ned_m[:, 2].min() == pytest.approx(-2.5, abs=1e-6)
    mid = np.argmin(ref.pos_ned_m[:, 2])
    assert ref.t_s[mid] == pytest.approx(shape.duration_s / 2, abs=0.02)
    # analytic derivatives agree with the numerical ones (vertical included)
    fd = np.gradient(ref.pos_ned_m, 0.01, axis=0)
    np.testing.assert_allclose(ref.vel_ned_m_s[1:-1], fd[1:-1], atol=2e-3)
    fdd = np.gradient(ref.vel_ned_m_s, 0.01, axis=0)
    np.testing.assert_allclose(ref.acc_ned_m_s2[2:-2], fdd[2:-2], atol=0.05)
    assert_hover_at_start(ref, 1.0)


def test_ellipse_refusals():
    with pytest.raises(TrajectoryError, match="radii_m"):
        EllipseShape((0, 0, -1), (1.0, 0.0), 5.0)
    with pytest.raises(TrajectoryError, match="plane"):
        EllipseShape((0, 0, -1), (1.0, 1.0), 5.0, plane="sideways")
    with pytest.raises(TrajectoryError, match="plane normal"):
        EllipseShape((0, 0, -1), (1.0, 1.0), 5.0, plane=(0.0, 0.0, 0.0))
    with pytest.raises(TrajectoryError, match="ramp_s is too long"):
        EllipseShape((0, 0, -1), (1.0, 1.0), 1.0, ramp_s=2.0)


# ----------------------------------------------------------------------------------- waypoints

SQUARE = ((0, 0, -1.5), (1.5, 0, -1.5), (1.5, 1.5, -2.0), (0, 1.5, -1.5), (0, 0, -1.5))


def test_waypoint_spline_passes_through_the_points_at_their_times_with_zero_end_conditions():
    times = (0.0, 2.5, 5.0, 7.5, 10.0)
    shape = WaypointsShape(SQUARE, times_s=times, hover_s=0.5)
    ref = sample_waypoints(shape, 0.05)
    for point, t in zip(SQUARE, times, strict=True):
        k = int(round((t + 0.5) / 0.05))
        np.testing.assert_allclose(ref.pos_ned_m[k], point, atol=1e-9)
    assert_hover_at_start(ref, 0.5)
    # end conditions of the spline itself, evaluated just inside its ends (quintic: velocity
    # ~ t^2 ... near an end with zero velocity and acceleration, so it is O(h^2))
    fine = sample_waypoints(shape, 0.001)
    k0 = int(round(0.5 / 0.001))
    for h in (1, 2, 4):
        v = np.linalg.norm(fine.vel_ned_m_s[k0 + h])
        a = np.linalg.norm(fine.acc_ned_m_s2[k0 + h])
        assert v < 5e-5 * h**2 and a < 0.05 * h * 1e-3 * 1e3
    # continuous jerk inside the motion: the third difference of a fine grid has no step at
    # the interior waypoints (knots); the motion's start and end, where jerk leaves and
    # returns to the hover's zero, are left out
    k1 = int(round(10.5 / 0.001))
    jerk = np.diff(fine.pos_ned_m[k0 + 5 : k1 - 5], 3, axis=0) / 0.001**3
    steps = np.abs(np.diff(jerk, axis=0)).max()
    assert steps < 0.05 * np.abs(jerk).max()


def test_waypoint_times_from_speed_make_the_peak_speed_the_given_one():
    shape = WaypointsShape(SQUARE, speed_m_s=1.0)
    times = waypoint_times(shape)
    assert times[0] == 0.0 and np.all(np.diff(times) > 0)
    # chord-length: time between waypoints proportional to their distance
    chords = np.linalg.norm(np.diff(np.array(SQUARE, float), axis=0), axis=1)
    np.testing.assert_allclose(np.diff(times) / chords, (times[-1] / chords.sum()), rtol=1e-12)
    fine = sample_waypoints(shape, 0.002)
    assert np.linalg.norm(fine.vel_ned_m_s, axis=1).max() == pytest.approx(1.0, rel=1e-3)
    # twice the speed: half the time, the same path
    fast = WaypointsShape(SQUARE, speed_m_s=2.0)
    np.testing.assert_allclose(waypoint_times(fast), times / 2, rtol=1e-12)


def test_waypoints_refusals():
    with pytest.raises(TrajectoryError, match="last waypoint"):
        WaypointsShape(SQUARE[:-1], speed_m_s=1.0)
    with pytest.raises(TrajectoryError, match="either times_s or speed_m_s"):
        WaypointsShape(SQUARE)
    with pytest.raises(TrajectoryError, match="times_s has 3 entries"):
        WaypointsShape(SQUARE, times_s=(0.0, 1.0, 2.0))
    with pytest.raises(TrajectoryError, match="waypoint 2 at 1 s is not after"):
        WaypointsShape(SQUARE, times_s=(0.0, 2.0, 1.0, 3.0, 4.0))
    with pytest.raises(TrajectoryError, match="waypoints 1 and 2 are the same point"):
        WaypointsShape(((0, 0, -1), (1, 0, -1), (1, 0, -1), (0, 0, -1)), speed_m_s=1.0)
    close = WaypointsShape(SQUARE, times_s=(0.0, 2.0, 2.01, 4.0, 6.0))
    with pytest.raises(TrajectoryError, match="waypoints 1 and 2 are 0.01 s apart"):
        sample_waypoints(close, 0.05)


# ------------------------------------------------------------------------------------- samples


def test_samples_on_the_grid_are_taken_exactly_and_hover_is_added_where_missing():
    dt = 0.05
    t = np.arange(101) * dt  # 5 s, no hover in the file
    pos = np.zeros((101, 3))
    pos[:, 0] = 0.5 * (1 - np.cos(2 * np.pi * t / 5.0))  # out and back, at rest at both ends
    pos[:, 2] = -1.5
    shape = SamplesShape(t, pos, hover_s=1.0)
    assert shape.duration_s == pytest.approx(7.0)  # 1 s added before and after
    ref = sample_samples(shape, dt)
    assert ref.n_samples == 140
    np.testing.assert_allclose(ref.pos_ned_m[20:121], pos, atol=1e-12)
    np.testing.assert_allclose(ref.pos_ned_m[:20], np.tile(pos[0], (20, 1)))
    np.testing.assert_allclose(ref.pos_ned_m[121:], np.tile(pos[-1], (20, 1)))
    # a file that already hovers 1 s at either end gets nothing added
    held = SamplesShape(ref.t_s, ref.pos_ned_m, hover_s=1.0)
    assert held.duration_s == pytest.approx(7.0)
    np.testing.assert_allclose(sample_samples(held, dt).pos_ned_m, ref.pos_ned_m, atol=1e-12)


def test_samples_resampling_is_the_monotone_cubic_interpolant_and_never_overshoots():
    from scipy.interpolate import PchipInterpolator

    t = np.array([0.0, 0.3, 0.5, 1.4, 2.0, 2.2, 3.0])
    pos = np.zeros((7, 3))
    pos[:, 0] = [0.0, 0.0, 1.0, 1.0, 0.2, 0.0, 0.0]  # a step up and down: cubic would overshoot
    pos[:, 2] = -1.0
    ref = sample_samples(SamplesShape(t, pos, hover_s=0.0), 0.01)
    expected = PchipInterpolator(t, pos[:, 0])(np.clip(ref.t_s, 0, 3.0))
    np.testing.assert_allclose(ref.pos_ned_m[:, 0], expected, atol=1e-12)
    assert ref.pos_ned_m[:, 0].max() <= 1.0 + 1e-12 and ref.pos_ned_m[:, 0].min() >= -1e-12


def test_samples_refusals():
    t = np.array([0.0, 1.0, 2.0])
    pos = np.array([[0, 0, -1], [1, 0, -1], [0, 0, -1]], float)
    with pytest.raises(TrajectoryError, match="sample 2: time 1 s is not after"):
        SamplesShape(np.array([0.0, 1.0, 1.0]), pos)
    with pytest.raises(TrajectoryError, match="sample 1: position is NaN"):
        SamplesShape(t, np.where(pos == 1, np.nan, pos))
    with pytest.raises(TrajectoryError, match="end in hover where it began"):
        SamplesShape(t, pos + np.array([[0, 0, 0], [0, 0, 0], [0.1, 0, 0]]))


def test_samples_csv_round_trips_exactly(tmp_path):
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 0.03, 50))
    pos = rng.normal(size=(50, 3))
    yaw = rng.normal(size=50)
    for y in (None, yaw):
        write_samples_csv(tmp_path / "s.csv", PlannerSamples(t, pos, y))
        back = read_samples(tmp_path / "s.csv")
        assert np.array_equal(back.t_s, t) and np.array_equal(back.pos_ned_m, pos)
        assert (back.yaw_deg is None) if y is None else np.array_equal(back.yaw_deg, yaw)
    np.save(tmp_path / "s.npy", np.column_stack([t, pos]))
    assert np.array_equal(read_samples(tmp_path / "s.npy").pos_ned_m, pos)
    np.savez(tmp_path / "s.npz", t_s=t, north_m=pos[:, 0], east_m=pos[:, 1], down_m=pos[:, 2])
    assert np.array_equal(read_samples(tmp_path / "s.npz").pos_ned_m, pos)


@pytest.mark.parametrize(
    ("text", "expect"),
    [
        ("t_s,north_m,east_m,down_m\n0,0,0,-1\n1,nan,0,-1\n", "line 3: column 'north_m' is nan"),
        ("t_s,north_m,east_m,down_m\n0,0,0,-1\n0,1,0,-1\n", "line 3: t_s 0 s repeats"),
        ("t_s,north_m,east_m,down_m\n1,0,0,-1\n0,1,0,-1\n", "line 3: t_s 0 s goes back"),
        ("t_s,north_m,east_m\n0,0,0\n1,1,0\n", "column 'down_m' is missing"),
        ("t_s,north_m,east_m,down_m,speed\n0,0,0,-1,1\n", "column 'speed' is not a known"),
        ("t_s,north_m,east_m,down_m\n0,0,0,-1\n1,x,0,-1\n", "line 3: column 'north_m' is not a"),
        ("t_s,north_m,east_m,down_m\n0,0,0,-1\n1,0,0\n", "line 3: 3 values"),
        ("# only a comment\n", "empty"),
    ],
)
def test_samples_csv_refusals_name_file_and_line(tmp_path, text, expect):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(TrajectoryError) as info:
        read_samples(path)
    assert str(info.value).startswith(str(path)) and expect in str(info.value)


# -------------------------------------------------------------- shipped files and properties


@pytest.mark.parametrize("name", EXAMPLES)
@pytest.mark.parametrize("profile", ["antx", "antx-adaptive"])
def test_shipped_trajectories_pass_the_shipped_profiles_limits_and_arena(name, profile):
    from gcs.app.fly import check_within_limits

    prof = load_profile(ROOT / "profiles" / f"{profile}.yaml")
    spec = load_trajectory(ROOT / "trajectories" / f"{name}.yaml")
    ref = sample_reference(spec.shape, prof.t_ilc_s)
    check_within_limits(ref, prof)
    # a planner's file: its motion may begin within a micrometre at the end of the hover
    assert_hover_at_start(ref, spec.shape.hover_s - 1e-9, 1e-5 if name == "racetrack" else 1e-9)


def test_shipped_samples_file_is_what_the_script_writes():
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "make_samples.py"), "--check"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr


def test_helix_is_three_dimensional_and_within_the_vertical_limits():
    prof = load_profile(ROOT / "profiles" / "antx.yaml")
    ref = sample_reference(load_trajectory(ROOT / "trajectories" / "helix.yaml").shape, 0.05)
    assert np.ptp(ref.pos_ned_m[:, 2]) == pytest.approx(1.0, abs=1e-3)
    vz = np.abs(np.diff(ref.pos_ned_m[:, 2])) / 0.05
    assert 0.2 < vz.max() < prof.max_vertical_speed_m_s


def test_vertical_limits_are_named_when_exceeded():
    ref = sample_reference(load_trajectory(ROOT / "trajectories" / "helix.yaml").shape, 0.05)
    with pytest.raises(TrajectoryError, match=r"vertical speed .*vehicle.max_vertical_speed"):
        check_reference(ref, 10, 10, WIDE, max_vertical_speed_m_s=0.1)
    with pytest.raises(TrajectoryError, match=r"vertical acceleration .* t = "):
        check_reference(ref, 10, 10, WIDE, max_vertical_accel_m_s2=0.05)
    with pytest.raises(TrajectoryError, match=r"vertical jerk on the flown grid"):
        check_reference(ref, 10, 10, WIDE, max_vertical_jerk_m_s3=0.01)
    with pytest.raises(TrajectoryError, match=r"^jerk on the flown grid .*max_jerk_m_s3"):
        check_reference(ref, 10, 10, WIDE, max_jerk_m_s3=0.5)
    with pytest.raises(TrajectoryError, match=r"above the ceiling, arena.down_m is \[-2, 0\]"):
        check_reference(ref, 10, 10, Box((-9, 9), (-9, 9), (-2.0, 0.0)))


shapes = st.one_of(
    st.builds(
        EllipseShape,
        center_ned_m=st.tuples(st.floats(-2, 2), st.floats(-2, 2), st.floats(-3, -0.5)),
        radii_m=st.tuples(st.floats(0.1, 2.0), st.floats(0.1, 2.0)),
        period_s=st.floats(2.0, 10.0),
        plane=st.sampled_from(["horizontal", "north-down", "east-down", (1.0, 2.0, -0.5)]),
        start_angle_deg=st.floats(-180, 180),
        loops=st.integers(1, 3),
        ramp_s=st.floats(0.5, 2.0),
        hover_s=st.floats(0.0, 1.5),
        climb_m=st.floats(-1.0, 1.0),
    ),
    st.builds(
        lambda pts, speed, hover: WaypointsShape((*pts, pts[0]), speed_m_s=speed, hover_s=hover),
        st.lists(
            st.tuples(st.floats(-2, 2), st.floats(-2, 2), st.floats(-3, -0.5)),
            min_size=2,
            max_size=6,
            unique=True,
        ).filter(
            lambda p: all(
                np.linalg.norm(np.subtract(a, b)) > 0.05
                for a, b in zip(p, [*p[1:], p[0]], strict=True)
            )
        ),
        st.floats(0.3, 2.0),
        st.floats(0.0, 1.5),
    ),
)


def _planner_file(shape: EllipseShape, rate_hz: float, hover_s: float) -> SamplesShape:
    """A planner's file: a looped path sampled at its own rate (not the grid), any hover."""
    ref = sample_reference(shape, 1.0 / rate_hz)
    return SamplesShape(ref.t_s + 3.0, ref.pos_ned_m, hover_s=hover_s)


shapes = st.one_of(
    shapes,
    st.builds(
        _planner_file,
        st.builds(
            EllipseShape,
            center_ned_m=st.tuples(st.floats(-2, 2), st.floats(-2, 2), st.floats(-3, -0.5)),
            radii_m=st.tuples(st.floats(0.1, 2.0), st.floats(0.1, 2.0)),
            period_s=st.floats(2.0, 10.0),
            hover_s=st.floats(0.0, 1.5),
            climb_m=st.floats(-1.0, 1.0),
        ),
        st.floats(7.0, 200.0),
        st.floats(0.0, 1.5),
    ),
)


@settings(max_examples=60, deadline=None)
@given(shape=shapes, dt=st.sampled_from([0.02, 0.05, 0.1]))
def test_every_source_starts_and_ends_in_hover_at_its_start_point(shape, dt):
    ref = sample_reference(shape, dt)
    # a file's samples count as still within a micrometre of its first (last) one
    assert_hover_at_start(
        ref, shape.hover_s - 1e-9, 1e-5 if isinstance(shape, SamplesShape) else 1e-9
    )
    assert ref.t_s[-1] >= shape.duration_s - 1e-9 and ref.t_s[-1] < shape.duration_s + dt


@settings(max_examples=40, deadline=None)
@given(shape=shapes, dt=st.sampled_from([0.02, 0.05]))
def test_a_reference_that_passes_the_check_respects_the_limits_on_its_grid(shape, dt):
    """Whatever passes check_reference, the differences of its grid stay within the limits
    it was checked against; and limits just below the grid's own peaks are refused."""
    ref = sample_reference(shape, dt)
    p = ref.pos_ned_m
    v = np.hypot(*(np.diff(p[:, :2], axis=0) / dt).T).max()
    a = np.hypot(*(np.diff(p[:, :2], 2, axis=0) / dt**2).T).max()
    vz = np.abs(np.diff(p[:, 2]) / dt).max()
    box = Box((-20, 20), (-20, 20), (-20, 20))
    vmax = max(v, np.hypot(*ref.vel_ned_m_s[:, :2].T).max())
    amax = max(a, np.hypot(*ref.acc_ned_m_s2[:, :2].T).max())
    vzmax = max(vz, np.abs(ref.vel_ned_m_s[:, 2]).max())
    check_reference(ref, vmax, amax, box, max_vertical_speed_m_s=vzmax)
    if v > 1e-3:
        with pytest.raises(TrajectoryError, match="speed"):
            check_reference(ref, 0.99 * v, 1e9, box)
    if vz > 1e-3:
        with pytest.raises(TrajectoryError, match="vertical speed"):
            check_reference(ref, 1e9, 1e9, box, max_vertical_speed_m_s=0.99 * vz)


# ----------------------------------------------------------------------- planning a flight


def test_a_constant_yaw_is_flown_and_a_varying_one_flown_per_setpoint(tmp_path):
    import yaml

    from gcs.app.fly import FlyRequest, plan_fly, start_run, trial_yaw_deg
    from gcs.io.rundir import RunDir

    profile = ROOT / "profiles" / "antx.yaml"
    data = yaml.safe_load((ROOT / "trajectories" / "circle.yaml").read_text())
    held = tmp_path / "held.yaml"
    held.write_text(yaml.safe_dump(data))
    plan = plan_fly(FlyRequest(profile=profile, trajectory=held, logs=tmp_path / "logs"))
    assert plan.settings.yaw_deg == 0.0 and trial_yaw_deg(plan.reference) is None
    turned = tmp_path / "turned.yaml"
    turned.write_text(yaml.safe_dump(dict(data, yaw_deg=90.0)))
    plan = plan_fly(FlyRequest(profile=profile, trajectory=turned, logs=tmp_path / "logs"))
    assert plan.settings.yaw_deg == pytest.approx(90.0)
    assert np.all(plan.reference.yaw_rad == np.pi / 2)
    np.testing.assert_allclose(trial_yaw_deg(plan.reference), 90.0)
    # a samples file's yaw column: 0 -> 40 deg over 4 s (10 deg/s), one heading per setpoint
    t = np.arange(41) * 0.1
    rows = [f"{a:.1f},{0.2 * np.sin(np.pi * a / 4) ** 2:.6f},0,-1.5,{10 * a:g}" for a in t]
    (tmp_path / "p.csv").write_text("t_s,north_m,east_m,down_m,yaw_deg\n" + "\n".join(rows))
    samples = tmp_path / "s.yaml"
    samples.write_text(yaml.safe_dump({"name": "s", "type": "samples", "file": "p.csv"}))
    plan = plan_fly(
        FlyRequest(
            profile=profile, trajectory=samples, run=tmp_path / "run", logs=tmp_path / "logs"
        )
    )
    yaw = trial_yaw_deg(plan.reference)
    assert yaw.shape == (plan.reference.n_samples,)
    assert plan.settings.yaw_deg == pytest.approx(0.0) and yaw.max() == pytest.approx(40.0)
    # recorded in reference.csv, read back the same (to the file's 9 digits)
    run = RunDir.open(start_run(plan).path)
    np.testing.assert_allclose(run.reference().yaw_rad, plan.reference.yaw_rad, rtol=1e-8)
    # ten times faster: 100 deg/s is beyond the default 90 deg/s, refused naming the limit
    rows = [f"{a:.1f},{0.2 * np.sin(np.pi * a / 4) ** 2:.6f},0,-1.5,{100 * a:g}" for a in t]
    (tmp_path / "p.csv").write_text("t_s,north_m,east_m,down_m,yaw_deg\n" + "\n".join(rows))
    with pytest.raises(TrajectoryError, match=r"yaw rate .* 90 deg/s .*max_yaw_rate_deg_s"):
        plan_fly(FlyRequest(profile=profile, trajectory=samples, logs=tmp_path / "logs"))
    assert not (tmp_path / "logs").exists()


def test_the_yaw_rate_is_checked_on_the_flown_grid_through_a_wrap():
    t = np.arange(5) * 0.1
    pos = np.zeros((5, 3))
    # 170 -> -170 deg is 20 deg the short way round, as np.unwrap records it: 200 deg/s
    yaw = np.unwrap(np.radians([170.0, 170.0, -170.0, -170.0, -170.0]))
    ref = Reference(t, pos, pos, pos, yaw)
    check_reference(ref, 1, 1, WIDE, max_yaw_rate_deg_s=200.0 + 1e-6)
    with pytest.raises(TrajectoryError, match=r"yaw rate on the flown grid 200.00 deg/s .* 0.10"):
        check_reference(ref, 1, 1, WIDE, max_yaw_rate_deg_s=150.0)
    check_reference(Reference(t, pos, pos, pos, None), 1, 1, WIDE, max_yaw_rate_deg_s=1e-9)


def test_a_samples_run_resumes_from_its_recorded_reference(tmp_path):
    import shutil

    from gcs.app.fly import FlyRequest, plan_fly, start_run

    shutil.copy(ROOT / "trajectories" / "racetrack.yaml", tmp_path)
    shutil.copy(ROOT / "trajectories" / "racetrack.csv", tmp_path)
    profile = ROOT / "profiles" / "antx.yaml"
    plan = plan_fly(
        FlyRequest(profile=profile, trajectory=tmp_path / "racetrack.yaml", run=tmp_path / "run")
    )
    run = start_run(plan)
    (tmp_path / "racetrack.csv").unlink()  # the run does not need the planner's file again
    again = plan_fly(FlyRequest(resume=run.path))
    assert again.trajectory.shape is None and again.trajectory.name == "racetrack"
    np.testing.assert_allclose(again.reference.pos_ned_m, plan.reference.pos_ned_m, atol=1e-9)
