"""Tests of gcs.core.trajectory: the eight-shape of the paper's Sec. V-D and its checks."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from gcs.core.trajectory import (
    Box,
    EightShape,
    Reference,
    check_reference,
    loop_phase,
    points_outside,
    sample_eight,
)
from gcs.errors import TrajectoryError
from gcs.io.config import load_trajectory

ROOT = Path(__file__).resolve().parents[1]
WIDE = Box((-10.0, 10.0), (-10.0, 10.0), (-10.0, 0.0))


def eight() -> EightShape:
    return load_trajectory(ROOT / "trajectories" / "eight.yaml").shape


def horizontal_norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(v[:, 0] ** 2 + v[:, 1] ** 2)


def test_default_eight_speed_and_acceleration_as_in_the_paper():
    ref = sample_eight(eight(), 0.05)
    assert ref.t_ilc_s == pytest.approx(0.05)
    assert ref.n_samples == round((2 * 1.0 + 2.0 + 2 * 5.0) / 0.05)
    assert np.max(horizontal_norm(ref.vel_ned_m_s)) == pytest.approx(2.1, rel=0.05)
    assert np.max(horizontal_norm(ref.acc_ned_m_s2)) == pytest.approx(4.0, rel=0.05)
    # also from the position alone (finite differences on a fine grid)
    fine = sample_eight(eight(), 0.001)
    v = np.diff(fine.pos_ned_m, axis=0) / 0.001
    a = np.diff(fine.pos_ned_m, 2, axis=0) / 0.001**2
    assert np.max(horizontal_norm(v)) == pytest.approx(2.1, rel=0.05)
    assert np.max(horizontal_norm(a)) == pytest.approx(4.0, rel=0.05)


def test_default_eight_starts_and_ends_at_rest_at_the_same_point():
    shape = eight()
    ref = sample_eight(shape, 0.05)
    np.testing.assert_allclose(ref.pos_ned_m[0], shape.center_ned_m, atol=1e-12)
    np.testing.assert_allclose(ref.pos_ned_m[-1], shape.center_ned_m, atol=1e-12)
    for arr in (ref.vel_ned_m_s, ref.acc_ned_m_s2):
        np.testing.assert_allclose(arr[0], 0.0, atol=1e-12)
        np.testing.assert_allclose(arr[-1], 0.0, atol=1e-12)
    # hover phases: the first and last hover_s seconds stay at the centre
    hover = ref.t_s <= shape.hover_s
    np.testing.assert_allclose(ref.pos_ned_m[hover], np.tile(shape.center_ned_m, (hover.sum(), 1)))
    # altitude constant, horizontal only
    np.testing.assert_array_equal(ref.pos_ned_m[:, 2], -1.5)
    np.testing.assert_array_equal(ref.vel_ned_m_s[:, 2], 0.0)
    # the motion does go somewhere: the north excursion reaches the amplitude
    assert np.max(np.abs(ref.pos_ned_m[:, 0])) == pytest.approx(shape.amplitude_north_m, rel=1e-2)
    assert np.max(np.abs(ref.pos_ned_m[:, 1])) == pytest.approx(
        shape.amplitude_east_m / 2, rel=1e-2
    )


def test_velocity_and_acceleration_match_numerical_derivatives():
    h = 0.002
    ref = sample_eight(eight(), h)
    v_num = np.gradient(ref.pos_ned_m, h, axis=0)
    a_num = np.gradient(ref.vel_ned_m_s, h, axis=0)
    # central differences: error O(h^2 * jerk), jerk of the eight is tens of m/s^3
    np.testing.assert_allclose(ref.vel_ned_m_s[1:-1], v_num[1:-1], atol=2e-3)
    np.testing.assert_allclose(ref.acc_ned_m_s2[1:-1], a_num[1:-1], atol=2e-2)
    # and on the ILC grid itself, more loosely
    ref = sample_eight(eight(), 0.05)
    v_num = np.gradient(ref.pos_ned_m, 0.05, axis=0)
    np.testing.assert_allclose(ref.vel_ned_m_s[1:-1], v_num[1:-1], atol=0.05)


def _first_time_over(values: np.ndarray, t: np.ndarray, limit: float) -> float:
    for k in range(len(values)):
        if values[k] > limit:
            return float(t[k])
    raise AssertionError("never over")


def _message_time(message: str) -> float:
    match = re.search(r"t = ([0-9.]+) s", message)
    assert match, message
    return float(match.group(1))


def test_check_reference_accepts_the_default_eight_within_profile_limits():
    ref = sample_eight(eight(), 0.05)
    check_reference(ref, 3.0, 5.0, Box((-3.0, 3.0), (-3.0, 3.0), (-3.0, 0.0)))


def test_check_reference_refuses_excessive_speed_naming_limit_and_time():
    ref = sample_eight(eight(), 0.05)
    speed = horizontal_norm(ref.vel_ned_m_s)
    with pytest.raises(TrajectoryError) as info:
        check_reference(ref, 1.5, 100.0, WIDE)
    msg = str(info.value)
    assert "speed" in msg and "1.5 m/s" in msg
    assert f"{speed.max():.2f}" in msg
    assert _message_time(msg) == pytest.approx(_first_time_over(speed, ref.t_s, 1.5), abs=0.006)


def test_check_reference_refuses_excessive_acceleration_naming_limit_and_time():
    ref = sample_eight(eight(), 0.05)
    accel = horizontal_norm(ref.acc_ned_m_s2)
    with pytest.raises(TrajectoryError) as info:
        check_reference(ref, 100.0, 3.0, WIDE)
    msg = str(info.value)
    assert "acceleration" in msg and "3 m/s^2" in msg
    assert _message_time(msg) == pytest.approx(_first_time_over(accel, ref.t_s, 3.0), abs=0.006)


def test_check_reference_refuses_leaving_the_arena_naming_time():
    ref = sample_eight(eight(), 0.05)
    arena = Box((-1.0, 3.0), (-3.0, 3.0), (-3.0, 0.0))  # the eight reaches north -1.2
    with pytest.raises(TrajectoryError) as info:
        check_reference(ref, 100.0, 100.0, arena)
    msg = str(info.value)
    assert "arena" in msg
    first = float(ref.t_s[np.flatnonzero(ref.pos_ned_m[:, 0] < -1.0)[0]])
    assert _message_time(msg) == pytest.approx(first, abs=0.006)
    # altitude: an arena whose floor is above the flight altitude
    with pytest.raises(TrajectoryError, match=r"t = 0.00 s"):
        check_reference(ref, 100.0, 100.0, Box((-3.0, 3.0), (-3.0, 3.0), (-1.0, 0.0)))


def test_points_outside_by_hand():
    box = Box((0.0, 1.0), (0.0, 1.0), (-1.0, 0.0))
    pts = np.array([[0.5, 0.5, -0.5], [1.1, 0.5, -0.5], [0.5, 0.5, 0.2], [1.0, 0.0, -1.0]])
    np.testing.assert_array_equal(points_outside(pts, box), [1, 2])
    np.testing.assert_array_equal(points_outside(pts, box, tol_m=0.15), [2])


@pytest.mark.parametrize(
    "kwargs",
    [
        {"amplitude_north_m": 0.0},
        {"amplitude_east_m": -1.0},
        {"period_s": 0.0},
        {"loops": 0},
        {"ramp_s": -0.5},
        {"hover_s": -1.0},
        {"center_ned_m": (0.0, 0.0)},
    ],
)
def test_bad_shapes_refused(kwargs):
    with pytest.raises(TrajectoryError):
        EightShape(**kwargs)


def test_ramp_too_long_and_bad_sample_time_refused():
    with pytest.raises(TrajectoryError):
        sample_eight(EightShape(period_s=1.0, loops=1, ramp_s=2.0), 0.05)
    with pytest.raises(TrajectoryError):
        sample_eight(EightShape(), 0.0)


shapes = st.builds(
    EightShape,
    center_ned_m=st.tuples(st.floats(-2, 2), st.floats(-2, 2), st.floats(-3, -0.5)),
    amplitude_north_m=st.floats(0.1, 3.0),
    amplitude_east_m=st.floats(0.1, 3.0),
    period_s=st.floats(1.0, 10.0),
    loops=st.integers(1, 3),
    ramp_s=st.floats(0.0, 3.0),
    hover_s=st.floats(0.0, 2.0),
)


@settings(max_examples=60, deadline=None)
@given(shape=shapes, dt=st.sampled_from([0.01, 0.02, 0.05, 0.1]))
def test_random_eights_start_and_end_at_rest_at_the_centre(shape, dt):
    assume(shape.ramp_s <= shape.loops * shape.period_s)
    ref = sample_eight(shape, dt)
    assert isinstance(ref, Reference)
    np.testing.assert_allclose(ref.t_s, np.arange(ref.n_samples + 1) * dt)
    np.testing.assert_allclose(ref.pos_ned_m[0], shape.center_ned_m, atol=1e-9)
    np.testing.assert_allclose(ref.pos_ned_m[-1], shape.center_ned_m, atol=1e-9)
    # ramp_s = 0 is a deliberate velocity step; ramps and hovers shorter than a sample are
    # not resolved by the grid
    if shape.ramp_s >= dt and shape.hover_s >= dt:
        np.testing.assert_allclose(ref.vel_ned_m_s[[0, -1]], 0.0, atol=1e-9)
    # the grid covers the whole manoeuvre
    duration = 2 * shape.hover_s + shape.ramp_s + shape.loops * shape.period_s
    assert ref.t_s[-1] >= duration - shape.hover_s - 1e-9


@settings(max_examples=60, deadline=None)
@given(shape=shapes)
def test_random_eights_phase_is_monotone_and_makes_whole_loops(shape):
    assume(shape.ramp_s <= shape.loops * shape.period_s)
    duration = 2 * shape.hover_s + shape.ramp_s + shape.loops * shape.period_s
    t = np.linspace(-0.5, duration + 0.5, 4001)
    s, sd, sdd = loop_phase(t, shape.period_s, shape.loops, shape.ramp_s, shape.hover_s)
    assert np.all(np.diff(s) >= -1e-12)
    assert np.all(sd >= 0)
    assert np.all(sd <= 2 * np.pi / shape.period_s + 1e-12)
    assert s[0] == 0.0
    assert s[-1] == pytest.approx(2 * np.pi * shape.loops, rel=1e-12)
    # rate is the derivative of the phase (trapezoid integration of sd); with a ramp shorter
    # than the step (ramp_s = 0, or hypothesis's 5e-324) the rate jumps by 2 pi / period at the
    # start and at the end of the loops, and a trapezoid across each jump is off by at most
    # half the jump times the step
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (sd[1:] + sd[:-1]) * np.diff(t))])
    step = t[1] - t[0]
    jumps = 2 * np.pi / shape.period_s * step if shape.ramp_s < step else 0.0
    np.testing.assert_allclose(s, integral, atol=1e-3 * (1 + s[-1]) + jumps)


# ------------------------------------------------------------------- limits on the flown grid


def test_a_phase_rate_that_jumps_in_one_sample_is_refused_on_the_grid():
    """ramp_s: 0 passes the analytic check but asks for 2.13 m/s within one 0.05 s sample."""
    from dataclasses import replace

    shape = replace(eight(), ramp_s=0.0)
    ref = sample_eight(shape, 0.05)
    analytic = horizontal_norm(ref.acc_ned_m_s2).max()
    assert analytic < 5.0  # what the analytic derivatives alone would have let through
    # at rest, then at full phase rate: the speed a w (north) and b w (east) at s = 0
    w = 2 * np.pi / shape.period_s
    jump = np.hypot(shape.amplitude_north_m * w, shape.amplitude_east_m * w)
    with pytest.raises(TrajectoryError, match="acceleration on the flown grid") as info:
        check_reference(ref, 3.0, 5.0, WIDE)
    value = float(re.search(r"grid ([0-9.]+) m/s\^2", str(info.value)).group(1))
    # the first difference of the position, differenced once more, over dt^2
    assert value == pytest.approx(jump / 0.05, rel=0.05)
    assert _message_time(str(info.value)) == pytest.approx(shape.hover_s, abs=0.051)


def test_grid_differences_of_the_default_eight_stay_within_its_limits():
    ref = sample_eight(eight(), 0.05)
    p = ref.pos_ned_m[:, :2]
    speed = horizontal_norm(np.diff(p, axis=0) / 0.05)
    accel = horizontal_norm(np.diff(p, 2, axis=0) / 0.05**2)
    assert 2.0 < speed.max() < 2.2 and 3.8 < accel.max() < 4.2  # the paper's 2.1 m/s, 4 m/s^2
    # a smooth reference: the grid's differences and the derivatives agree to a few percent
    assert speed.max() == pytest.approx(horizontal_norm(ref.vel_ned_m_s).max(), rel=0.01)
    assert accel.max() == pytest.approx(horizontal_norm(ref.acc_ned_m_s2).max(), rel=0.02)
    check_reference(ref, 2.2, 4.2, WIDE)


def _line_reference(n: int = 40, dt: float = 0.05, speed: float = 1.0) -> Reference:
    t = np.arange(n + 1) * dt
    pos = np.zeros((n + 1, 3))
    pos[:, 0] = speed * t
    pos[:, 1] = -0.5 * speed * t
    pos[:, 2] = -1.5
    zero = np.zeros_like(pos)
    return Reference(t, pos, zero, zero)


def test_check_setpoints_accepts_the_aligned_reference_and_names_each_limit():
    from gcs.core.trajectory import check_setpoints

    ref = _line_reference()
    r = (3, 2)  # relative degrees, north and east
    yd = ref.pos_ned_m
    aligned = np.column_stack(
        [np.concatenate([yd[r[a] :, a], np.full(r[a] - 1, yd[-1, a])]) for a in (0, 1)]
        + [yd[:-1, 2]]
    )
    # u(k) = yd(k + r): deviation 0, steps of the reference's own (0.05 and 0.025 m); the
    # first step from the hover point yd(0) is r samples of motion at once
    check_setpoints(aligned, ref, WIDE, 0.15, 0.0, r)
    with pytest.raises(TrajectoryError, match=r"k = 0 steps 0.150 m on north"):
        check_setpoints(aligned, ref, WIDE, 0.149, None, r)
    late = yd[:-1].copy()  # u(k) = yd(k): 3 samples behind on north, 2 on east
    with pytest.raises(TrajectoryError, match=r"k = 0 is 0.150 m from the reference on north"):
        check_setpoints(late, ref, WIDE, None, 0.1, r)
    bumped = aligned.copy()
    bumped[17, 1] += 0.4
    with pytest.raises(TrajectoryError, match=r"k = 17 steps 0.375 m on east"):
        check_setpoints(bumped, ref, WIDE, 0.2, None, r)
    with pytest.raises(TrajectoryError, match=r"k = 17 is 0.400 m from the reference on east"):
        check_setpoints(bumped, ref, WIDE, None, 0.3, r)
    far = aligned.copy()
    far[17, 0] += 2.0  # north 3.0 m: the only point beyond 2.5 m
    with pytest.raises(TrajectoryError, match=r"k = 17 \[3.0, .* outside the arena"):
        check_setpoints(far, ref, Box((-3.0, 2.5), (-3.0, 3.0), (-3.0, 0.0)), None, None, r)
    bumped[5, 0] = np.nan
    with pytest.raises(TrajectoryError, match="k = 5 is NaN"):
        check_setpoints(bumped, ref, WIDE)
    with pytest.raises(TrajectoryError, match="shape"):
        check_setpoints(aligned[:-1], ref, WIDE)


def test_setpoint_array_is_a_finite_n_by_3_copy_or_a_refusal():
    from gcs.core.trajectory import setpoint_array

    given = [[0, 0, -1]]
    sp = setpoint_array(given)
    assert sp.dtype == float and sp.shape == (1, 3) and sp.base is None
    assert setpoint_array(np.zeros((4, 3)), 4).shape == (4, 3)
    for bad, n, match in (
        (np.zeros((4, 2)), None, r"shape \(4, 2\), expected \(N, 3\)"),
        (np.zeros((0, 3)), None, "N >= 1"),
        (np.zeros((4, 3)), 5, r"expected \(5, 3\)"),
        ([[0, 0, -1], [0, np.nan, -1]], None, "k = 1 is NaN"),
    ):
        with pytest.raises(TrajectoryError, match=match):
            setpoint_array(bad, n)
