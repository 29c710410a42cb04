"""The live error per trial segment: a line every few seconds of a trial in flight."""

from __future__ import annotations

import io

import numpy as np
import pytest
from rich.console import Console

from gcs.app.fly_view import SEGMENT_S, SegmentError, live_progress
from gcs.flight.campaign import TrialProgress, TrialStarted


def test_a_line_per_segment_with_its_mean_and_largest_error() -> None:
    n, dt = 300, 0.05  # a 15 s trial: three segments of 5 s
    seg = SegmentError(4, n, n * dt)
    rng = np.random.default_rng(1)
    err = rng.uniform(0.0, 0.2, n + 1)
    ks = range(0, n + 1, 2)  # the campaign reports now and then, not every sample
    lines = {k: line for k in ks if (line := seg.add(k, err[k])) is not None}
    assert sorted(lines) == [100, 200, 300]
    for (k0, k1), line in zip([(0, 100), (100, 200), (200, 300)], lines.values(), strict=True):
        # a boundary report closes its segment: (k0, k1], the very first report k = 0 too
        taken = [k for k in ks if (k0 < k <= k1) or (k0 == 0 and k == 0)]
        mean, top = np.mean(err[taken]), np.max(err[taken])
        assert line.startswith(f"trial 4 {k0 * dt:.1f}-{k1 * dt:.1f} s: ")
        assert f"mean {mean:.3f} m, largest {top:.3f} m from the setpoint in force" in line


def test_the_live_view_prints_the_segments_while_the_trial_flies() -> None:
    out = io.StringIO()
    console = Console(file=out, force_terminal=False, width=200)
    progress, on_event = live_progress(console)
    n, dt = 240, 0.05
    with progress:
        on_event(TrialStarted(2, 1, 3, n, n * dt))
        for k in range(0, n + 1, 5):
            on_event(TrialProgress(2, k, n, 0.01 * (1 + k // 100)))
    text = out.getvalue()
    segments = [line for line in text.splitlines() if "from the setpoint in force" in line]
    assert len(segments) == int(np.ceil(n * dt / SEGMENT_S)) == 3
    assert segments[0].startswith("trial 2 0.0-5.0 s:") and "largest 0.020 m" in segments[0]
    assert segments[-1].startswith("trial 2 10.0-12.0 s:")
    assert "mean 0.030 m" in segments[-1]


def test_a_trial_shorter_than_a_segment_still_gets_its_line() -> None:
    seg = SegmentError(0, 20, 1.0)
    assert seg.add(0, 0.1) is None
    line = seg.add(20, 0.3)
    assert line is not None and "0.0-1.0 s" in line and "mean 0.200 m" in line
    # the final hover reports k = N again and again: no second line for it
    assert seg.add(20, 0.5) is None and seg.add(20, 0.5) is None


@pytest.mark.parametrize("segment_s", [1.0, 2.5])
def test_the_segment_length_is_in_trial_time(segment_s: float) -> None:
    seg = SegmentError(0, 200, 10.0, segment_s)
    done = [k for k in range(201) if seg.add(k, 0.0) is not None]
    assert done == list(range(round(segment_s / 0.05), 201, round(segment_s / 0.05)))
