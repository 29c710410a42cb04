"""Hover statistics and verdicts on recorded PX4 hovers, the indoor mock and synthetic vehicles."""

from __future__ import annotations

import numpy as np
import pytest
from px4_data import capture_hovers, sitl_hovers

from gcs.flight.hover import (
    SPEED_SPAN_S,
    TOLERANCE_FACTOR,
    hover_stats,
    is_settled,
    judge_hover,
    speeds,
    widened,
)
from gcs.io.settings import FlightSettings
from gcs.mock.config import MockConfig
from gcs.mock.physics import QuadPhysics, Target

SETTINGS = FlightSettings()
TARGET = np.array([0.0, 0.0, -1.5])
T = np.arange(0.0, 10.0, 0.02)  # 10 s at 50 Hz, the default measurement


def synthetic(north_m: np.ndarray, east_m: np.ndarray | float = 0.0, noise_m: float = 0.01):
    rng = np.random.default_rng(1)
    rel = np.column_stack([north_m, np.broadcast_to(east_m, T.shape), np.zeros_like(T)])
    return T, TARGET + rel + rng.normal(0.0, noise_m, (T.size, 3))


def test_px4_sitl_hovers_with_gps_and_vision_are_accepted() -> None:
    # the first second of every trial of shared/data/px4-sitl that started in hover
    hovers = sitl_hovers()
    assert len(hovers) == 13
    distances = {}
    for name, t, pos, target in hovers:
        stats = hover_stats(t, pos, target)
        verdict = judge_hover(stats, SETTINGS)
        assert verdict.ok, (name, verdict.reason)
        assert verdict.tolerance_m == max(SETTINGS.settle_tolerance_m, stats.distance_p50_m)
        assert verdict.speed_tolerance_m_s == pytest.approx(
            max(SETTINGS.settle_speed_m_s, TOLERANCE_FACTOR * stats.speed_p95_m_s)
        )
        assert 0.005 < stats.noise_m < 0.03, name  # 1-2 cm of fast noise
        distances[name] = stats.distance_max_m
    gps = [d for n, d in distances.items() if not n.startswith("vision")]
    vision = [d for n, d in distances.items() if n.startswith("vision")]
    assert max(gps) > 0.8 and max(vision) < 0.2  # GPS sits decimetres off, vision centimetres


def test_px4_capture_hovers_of_eight_seconds_are_accepted() -> None:
    hovers = capture_hovers()
    assert len(hovers) == 11
    for t, pos, target in hovers:
        stats = hover_stats(t, pos, target)
        verdict = judge_hover(stats, SETTINGS)
        assert verdict.ok, verdict.reason
        assert stats.duration_s > 5.5 and stats.oscillation_share < 0.3
        assert stats.drift_m_s < 0.5 * SETTINGS.hover_max_drift_m_s
        assert stats.distance_max_m < 0.75 * SETTINGS.hover_max_offset_m
        # the settle before every trial waits for a typical moment of this hover
        assert stats.distance_p50_m <= verdict.tolerance_m < stats.distance_max_m
        assert verdict.speed_tolerance_m_s > stats.speed_p95_m_s
        # ... and after a timeout allows the 95 % of a hover like it
        tolerance_m, speed_m_s = widened(0.05, 0.1, stats, SETTINGS)
        assert tolerance_m == pytest.approx(stats.distance_p95_m)
        assert speed_m_s == verdict.speed_tolerance_m_s


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_indoor_mock_hover_is_accepted_with_centimetre_tolerances(seed: int) -> None:
    physics = QuadPhysics(MockConfig(), seed, (0.0, 0.0, -1.5))
    physics.command(0.0, Target((0.0, 0.0, -1.5), 0.0))
    t = np.arange(4.0, 14.0, 0.02)
    pos = []
    for tk in t:
        physics.advance_to(float(tk))
        pos.append(physics.measure()[0])
    stats = hover_stats(t, np.array(pos), TARGET)
    verdict = judge_hover(stats, SETTINGS)
    assert verdict.ok and stats.noise_m < 0.006 and stats.speed_p95_m_s < 0.06
    # as still as motion capture allows: the floors, the old fixed 5 cm settle among them
    assert stats.distance_p50_m < 0.08 and stats.distance_max_m < 0.2
    assert verdict.tolerance_m == max(SETTINGS.settle_tolerance_m, stats.distance_p50_m)
    assert verdict.speed_tolerance_m_s == SETTINGS.settle_speed_m_s


def test_a_drifting_vehicle_is_refused() -> None:
    stats = hover_stats(*synthetic(0.4 * T), TARGET)
    assert stats.drift_m_s == pytest.approx(0.4, abs=0.01) and stats.drift_away
    verdict = judge_hover(stats, SETTINGS)
    assert not verdict.ok and verdict.kind == "drifting"
    assert "drifts away at 0.40 m/s" in verdict.reason
    assert "flight.hover_max_drift_m_s" in verdict.reason


def test_a_slower_drift_that_goes_too_far_is_refused_and_approaching_is_not_drifting() -> None:
    verdict = judge_hover(hover_stats(*synthetic(0.2 * T), TARGET), SETTINGS)
    assert verdict.kind == "off" and "flight.hover_max_offset_m 1.5 m" in verdict.reason
    approaching = judge_hover(hover_stats(*synthetic(4.0 - 0.4 * T), TARGET), SETTINGS)
    assert not approaching.ok and approaching.kind == "approaching"


@pytest.mark.parametrize("period_s", [1.0, 2.0, 3.0])
def test_an_oscillating_vehicle_is_refused(period_s: float) -> None:
    phase = 2 * np.pi * T / period_s
    stats = hover_stats(*synthetic(0.2 * np.sin(phase), 0.1 * np.cos(phase)), TARGET)
    assert stats.oscillation_period_s == pytest.approx(period_s, rel=0.03)
    assert stats.oscillation_m == pytest.approx(np.hypot(0.2, 0.1), rel=0.05)
    assert stats.oscillation_share > 0.9
    verdict = judge_hover(stats, SETTINGS)
    assert not verdict.ok and verdict.kind == "oscillating"
    assert f"every {period_s:.1f} s" in verdict.reason


def test_a_small_oscillation_or_a_slow_wander_is_a_hover() -> None:
    small = hover_stats(*synthetic(0.04 * np.sin(2 * np.pi * T / 2.0)), TARGET)
    assert small.oscillation_share > 0.5 and judge_hover(small, SETTINGS).ok
    wander = hover_stats(*synthetic(0.3 * np.sin(2 * np.pi * T / 25.0)), TARGET)
    assert wander.oscillation_share < 0.5 and judge_hover(wander, SETTINGS).ok


def test_statistics_of_known_hovers() -> None:
    t, pos = synthetic(np.full(T.size, 0.3), 0.4, noise_m=0.0)
    stats = hover_stats(t, pos, TARGET)
    assert stats.offset_m == pytest.approx(0.5) and stats.distance_max_m == pytest.approx(0.5)
    assert stats.distance_p50_m == pytest.approx(0.5)
    np.testing.assert_allclose(stats.offset_ned_m, [0.3, 0.4, 0.0], atol=1e-12)
    assert stats.noise_m == pytest.approx(0.0, abs=1e-12) and stats.drift_m_s < 1e-12
    assert stats.n_samples == T.size and stats.duration_s == pytest.approx(T[-1])
    noisy = hover_stats(*synthetic(np.zeros(T.size), noise_m=0.01), TARGET)
    # per-axis noise 1 cm: about sqrt(3) cm in 3-D, less what the 1 s mean keeps
    assert 0.014 < noisy.noise_m < 0.018
    ramp = hover_stats(*synthetic(0.1 * T, noise_m=0.0), TARGET)
    assert ramp.drift_m_s == pytest.approx(0.1) and ramp.speed_p50_m_s == pytest.approx(0.1)
    assert len(hover_stats(*synthetic(0.0 * T), TARGET).describe().splitlines()) == 1


def test_speeds_over_one_second() -> None:
    t = np.arange(0.0, 3.0, 0.1)
    pos = np.column_stack([0.5 * t, 0 * t, 0 * t])
    v = speeds(t, pos)
    assert v.size == np.sum(t + SPEED_SPAN_S <= t[-1] + 1e-9)
    np.testing.assert_allclose(v, 0.5)


def test_is_settled_needs_position_speed_and_the_whole_window() -> None:
    still = np.tile(TARGET + [0.05, 0.0, 0.0], (T.size, 1))
    assert is_settled(T, still, TARGET, 0.1, 0.1, 1.0)
    assert not is_settled(T, still, TARGET, 0.04, 0.1, 1.0)  # outside the position tolerance
    one_out = still.copy()
    one_out[-10] += [0.2, 0.0, 0.0]
    assert not is_settled(T, one_out, TARGET, 0.1, 0.1, 1.0)
    creeping = still + np.outer(T, [0.05, 0.0, 0.0]) - [0.5, 0.0, 0.0]  # at 5 cm/s
    assert is_settled(T, creeping, TARGET, 0.1, 0.06, 1.0)
    assert not is_settled(T, creeping, TARGET, 0.1, 0.04, 1.0)
    short = T < 1.5  # the window and its speed span need 2 s of samples
    assert not is_settled(T[short], still[short], TARGET, 0.1, 0.1, 1.0)


def test_bad_samples_are_refused() -> None:
    with pytest.raises(ValueError, match="at least 10"):
        hover_stats(T[:5], np.zeros((5, 3)), TARGET)
    with pytest.raises(ValueError, match="expected"):
        hover_stats(T, np.zeros((T.size, 2)), TARGET)
    bad = np.zeros((T.size, 3))
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        hover_stats(T, bad, TARGET)
    with pytest.raises(ValueError, match="non-decreasing"):
        hover_stats(T[::-1], np.zeros((T.size, 3)), TARGET)
