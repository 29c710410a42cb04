"""Stream health checks on synthetic streams: each fault found, clean streams left alone."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs.errors import ProfileError
from gcs.flight.mocap.health import (
    HealthLimits,
    frozen_problem,
    jump_problem,
    occlusion_problem,
    stale_problem,
    stream_problem,
)
from gcs.io.mocap_samples import MocapSeries

LIMITS = HealthLimits()


def stream(
    rate_hz: float = 240.0,
    duration_s: float = 1.0,
    speed_m_s: float = 2.0,
    noise_m: float = 2e-4,
    jitter_s: float = 0.0,
    seed: int = 0,
) -> MocapSeries:
    """A body circling at ``speed_m_s`` (radius 1 m), yawing with its heading, noisy."""
    rng = np.random.default_rng(seed)
    n = int(rate_hz * duration_s)
    t = 100.0 + np.arange(n) / rate_hz
    phase = speed_m_s * (t - 100.0)
    pos = np.stack([np.cos(phase), np.sin(phase), np.full(n, -1.0)], 1)
    pos += rng.normal(0, noise_m, pos.shape)
    half = (phase + math.pi / 2) / 2
    quat = np.stack([np.cos(half), np.zeros(n), np.zeros(n), np.sin(half)], 1)
    t_receipt = t + rng.uniform(0, jitter_s, n) if jitter_s else t
    return MocapSeries(
        np.arange(n), np.sort(t_receipt), np.full(n, np.nan), np.ones(n, bool), pos, quat
    )


def edit(series: MocapSeries, **changes) -> MocapSeries:
    fields = {
        "seq": series.seq,
        "t_receipt_s": series.t_receipt_s,
        "t_mocap_s": series.t_mocap_s,
        "tracked": series.tracked,
        "pos_m": series.pos_m,
        "quat_wxyz": series.quat_wxyz,
    }
    fields.update(changes)
    return MocapSeries(**fields)


@pytest.mark.parametrize("rate_hz", [50.0, 100.0, 240.0, 360.0])
@pytest.mark.parametrize("jitter_s", [0.0, 0.003])
def test_clean_fast_noisy_stream_has_no_problem(rate_hz: float, jitter_s: float) -> None:
    s = stream(rate_hz=rate_hz, speed_m_s=4.0, noise_m=5e-4, jitter_s=jitter_s)
    assert stream_problem(s, now_s=float(s.t_receipt_s[-1]) + 0.01) is None


def test_bursty_receipt_does_not_look_like_a_jump() -> None:
    # pairs of frames arriving together (receipt interval ~0) at 5 m/s
    s = stream(rate_hz=240.0, speed_m_s=5.0)
    t = s.t_receipt_s.copy()
    t[1::2] = t[0::2][: t[1::2].size] + 1e-5
    assert jump_problem(edit(s, t_receipt_s=t), LIMITS) is None


def test_stale() -> None:
    s = stream()
    last = float(s.t_receipt_s[-1])
    assert stale_problem(s, last + 0.1, LIMITS) is None
    reason = stale_problem(s, last + 0.5, LIMITS)
    assert reason is not None and "stale" in reason and "0.50 s" in reason
    assert stale_problem(MocapSeries.empty(), last, LIMITS) == "no mocap frames received"


def test_occlusion_after_a_window_of_untracked_frames() -> None:
    s = stream(rate_hz=100.0)
    tracked = s.tracked.copy()
    tracked[-30:] = False  # the last 0.3 s untracked
    pos = s.pos_m.copy()
    pos[~tracked] = np.nan
    occluded = edit(s, tracked=tracked, pos_m=pos)
    now = float(s.t_receipt_s[-1])
    reason = occlusion_problem(occluded, now, LIMITS)
    assert reason is not None and "lost" in reason
    # a short occlusion (0.1 s) is tolerated
    tracked[:-10] = True
    short = edit(s, tracked=tracked)
    assert occlusion_problem(short, now, LIMITS) is None
    assert stream_problem(occluded, now) == reason


def test_never_tracked_body() -> None:
    s = stream(rate_hz=100.0)
    none = edit(s, tracked=np.zeros(len(s), bool))
    reason = occlusion_problem(none, float(s.t_receipt_s[-1]), LIMITS)
    assert reason is not None and "not tracked in any frame" in reason


def test_frozen_stream() -> None:
    s = stream(rate_hz=100.0)
    pos, quat = s.pos_m.copy(), s.quat_wxyz.copy()
    pos[-20:] = pos[-21]
    quat[-20:] = quat[-21]
    frozen = edit(s, pos_m=pos, quat_wxyz=quat)
    reason = frozen_problem(frozen, LIMITS)
    assert reason is not None and "21 identical frames" in reason
    # a single repeated frame (the library re-delivers the old one) is no freeze
    pos, quat = s.pos_m.copy(), s.quat_wxyz.copy()
    pos[-1], quat[-1] = pos[-2], quat[-2]
    assert frozen_problem(edit(s, pos_m=pos, quat_wxyz=quat), LIMITS) is None
    assert frozen_problem(s, LIMITS) is None


def test_position_jump_found_even_small_at_high_rate() -> None:
    s = stream(rate_hz=240.0)
    pos = s.pos_m.copy()
    pos[120:] += [0.1, 0.0, 0.0]  # 10 cm in one frame period (4 ms): 25 m/s
    reason = jump_problem(edit(s, pos_m=pos), LIMITS)
    assert reason is not None and "position jumped" in reason


def test_jump_bound_grows_with_the_gap() -> None:
    # 0.5 m after a 0.2 s occlusion is within physics (10 m/s * 0.2 s = 2 m)
    s = stream(rate_hz=100.0)
    tracked = s.tracked.copy()
    tracked[40:60] = False
    pos = s.pos_m.copy()
    pos[60:] += [0.5, 0.0, 0.0]
    assert jump_problem(edit(s, tracked=tracked, pos_m=pos), LIMITS) is None


def test_attitude_flip() -> None:
    s = stream(rate_hz=100.0)
    quat = s.quat_wxyz.copy()
    w, z = quat[50:, 0].copy(), quat[50:, 3].copy()
    quat[50:, 0], quat[50:, 3] = -z, w  # 180 deg about z: a symmetric marker set flipping
    reason = jump_problem(edit(s, quat_wxyz=quat), LIMITS)
    assert reason is not None and "attitude jumped 179 deg" in reason  # 180 less the yaw of a frame


def test_bad_limits_refused() -> None:
    with pytest.raises(ProfileError, match="max_age_s"):
        HealthLimits(max_age_s=0.0)
