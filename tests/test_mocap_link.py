"""A trial's raw mocap on its grid (through the trial's clock fit) and the estimate's lag."""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np
import pytest

from gcs.core.frames import mapping_for
from gcs.flight.clock import fit_clock
from gcs.flight.mocap.campaign import with_mocap
from gcs.flight.mocap.health import HealthLimits
from gcs.flight.mocap.link import HEALTH_WINDOW_S, MocapLink, trial_mocap
from gcs.flight.mocap.reader import SAMPLE
from gcs.flight.trial import TrialRecording
from gcs.io.mocap_samples import MocapSeries
from gcs.io.mocap_source import parse_mocap_url
from gcs.io.settings import MocapSettings

MOTIVE = mapping_for("optitrack")
OFFSET_S = 1000.0  # local monotonic time = vehicle time + 1000 s


def circle_ned(t: np.ndarray) -> np.ndarray:
    return np.column_stack([np.cos(t), np.sin(t), np.full(t.size, -1.5)])


def recording(lag_s: float) -> TrialRecording:
    """A 4 s trial whose estimate is the circle ``lag_s`` late, at 50 Hz."""
    n, t_ilc = 80, 0.05
    v0 = 20.0
    raw_v = v0 - 0.5 + np.arange(0, 5.0, 0.02)
    clock = fit_clock(raw_v, raw_v + OFFSET_S + 0.001)
    return TrialRecording(
        t_s=np.arange(n + 1) * t_ilc, pos_ned_m=np.zeros((n + 1, 3)),
        vel_ned_m_s=np.zeros((n + 1, 3)), sent_s=np.zeros(n),
        interpolated=np.zeros(n + 1, bool), complete=True, abort_reason=None,
        setpoints_ned_m=np.zeros((n, 3)), t_ilc_s=t_ilc, raw_t_s=raw_v - v0,
        raw_pos_ned_m=circle_ned(raw_v - v0 - lag_s), t0_vehicle_s=v0, clock=clock,
    )  # fmt: skip


def mocap(gap: tuple[float, float] | None = None) -> MocapSeries:
    """120 Hz of the circle as Motive streams it, received 1 ms after the vehicle time."""
    v = 20.0 - 0.5 + np.arange(0, 5.0, 1 / 120)
    tracked = np.ones(v.size, bool)
    if gap is not None:
        tracked &= ~((v - 20.0 >= gap[0]) & (v - 20.0 < gap[1]))
    pos = MOTIVE.position_from_ned(circle_ned(v - 20.0))
    pos[~tracked] = np.nan
    quat = np.tile([1.0, 0, 0, 0], (v.size, 1))
    quat[~tracked] = np.nan
    n = v.size
    return MocapSeries(np.arange(n), v + OFFSET_S + 0.001, np.full(n, math.nan), tracked, pos,
                       quat)  # fmt: skip


def test_the_mocap_lands_on_the_grid_in_ned_and_the_lag_is_found() -> None:
    rec = recording(0.030)
    result = trial_mocap(mocap(), MOTIVE, rec)
    np.testing.assert_allclose(result.pos_ned_m, circle_ned(rec.t_s), atol=2e-4)
    assert result.lag_s == pytest.approx(0.030, abs=0.0015)
    assert len(result.series) == mocap().seq.size


def test_an_occlusion_longer_than_the_grid_gap_leaves_nan_there_only() -> None:
    result = trial_mocap(mocap(gap=(1.0, 1.5)), MOTIVE, recording(0.0))
    t = recording(0.0).t_s
    inside = (t > 1.0 + 1 / 120) & (t < 1.5 - 1 / 120)
    assert np.all(np.isnan(result.pos_ned_m[inside]))
    assert np.all(np.isfinite(result.pos_ned_m[~((t >= 1.0 - 0.01) & (t <= 1.5 + 0.01))]))


def test_without_a_clock_fit_nothing_is_placed() -> None:
    from dataclasses import replace

    result = trial_mocap(mocap(), MOTIVE, replace(recording(0.0), clock=None))
    assert np.all(np.isnan(result.pos_ned_m)) and result.lag_s is None


def test_a_gap_the_watch_lets_a_trial_fly_through_is_interpolated_across() -> None:
    """0.3 s untracked: NaN with the grid's own 0.1 s, on the grid (linear across the gap, within
    the circle's sag over 0.3 s) with the 0.4 s a stale-stream watch allows."""
    series, rec = mocap(gap=(1.0, 1.3)), recording(0.0)
    assert np.isnan(trial_mocap(series, MOTIVE, rec).pos_ned_m).any()
    result = trial_mocap(series, MOTIVE, rec, max_gap_s=0.4)
    assert np.all(np.isfinite(result.pos_ned_m))
    t = rec.t_s
    inside = (t > 1.0) & (t < 1.3)
    outside = (t < 1.0 - 0.01) | (t > 1.3 + 0.01)
    np.testing.assert_allclose(result.pos_ned_m[outside], circle_ned(t[outside]), atol=2e-4)
    error = np.abs(result.pos_ned_m[inside] - circle_ned(t[inside])).max()
    assert 1e-3 < error < 0.05, error  # the chord across the gap, not the circle


def test_a_stream_pausing_across_k0_still_puts_k0_on_the_grid() -> None:
    """The stream pauses 0.22 s across the trial's start (a mock Motive stalled on a loaded
    machine), and the trial's journal opens inside the pause, two stream periods before k = 0.
    Begun there, it held no sample before k = 0: k = 0, 1, 2 were left without mocap ("no mocap
    position at k = 0 (3 grid points)") and the trial was refused by learning. Begun with the
    last max_gap_s of the stream, it has the sample before the pause, and k = 0 is on the grid
    like any point of a gap the watch let the trial fly through."""
    rec = recording(0.0)
    stream = mocap()  # 120 Hz from 0.5 s before k = 0, received 1 ms after the vehicle time
    t = stream.t_receipt_s - OFFSET_S - 0.001 - 20.0  # vehicle time from k = 0 [s]
    journal_start_s = OFFSET_S + 0.001 + 20.0 - 2 / 60  # two 60 Hz stream periods before k = 0

    def flown(pre_roll: bool) -> np.ndarray:
        link = MocapLink(parse_mocap_url("optitrack://127.0.0.1/drone"), MOTIVE, MocapSettings())
        feed = link.client._record  # as the client's thread takes the reader's records
        for i in np.flatnonzero(t < -0.1):  # up to the pause
            feed(b"S", SAMPLE.pack(i, stream.t_receipt_s[i], True, *stream.pos_m[i], 1, 0, 0, 0))
        if pre_roll:
            link.start_journal(now_s=journal_start_s)
        else:  # the journal of the trial alone
            link.client.start_journal(now_s=journal_start_s)
        for i in np.flatnonzero(t >= 0.12):  # after the pause
            feed(b"S", SAMPLE.pack(i, stream.t_receipt_s[i], True, *stream.pos_m[i], 1, 0, 0, 0))
        recording_with = with_mocap(rec, link)
        assert recording_with.mocap is not None
        return recording_with.mocap.pos_ned_m

    missing = np.flatnonzero(~np.all(np.isfinite(flown(pre_roll=False)), axis=1))
    np.testing.assert_array_equal(missing, [0, 1, 2])
    on_grid = flown(pre_roll=True)
    assert np.all(np.isfinite(on_grid))
    # k = 0..2 on the chord across the pause, the rest on the circle
    np.testing.assert_allclose(on_grid[3:], circle_ned(rec.t_s[3:]), atol=2e-4)
    np.testing.assert_allclose(on_grid[:3], circle_ned(rec.t_s[:3]), atol=0.01)


def test_the_profiles_stale_limit_is_the_watchs_and_the_gap_it_flies_through() -> None:
    source = parse_mocap_url("optitrack://127.0.0.1/drone")
    default = MocapLink(source, MOTIVE, MocapSettings())
    assert default.limits == HealthLimits() and default.max_gap_s == HealthLimits().max_age_s
    wider = MocapLink(source, MOTIVE, MocapSettings(max_age_s=0.8))
    assert wider.limits == replace(HealthLimits(), max_age_s=0.8) and wider.max_gap_s == 0.8
    given = HealthLimits(max_age_s=0.3)
    assert MocapLink(source, MOTIVE, MocapSettings(max_age_s=0.8), limits=given).limits is given


def test_a_gap_longer_than_the_window_is_judged_by_the_profiles_stale_limit() -> None:
    """A lab-floor flight on real PX4 (2026-12-06, two test suites on 2 cores) stopped in the
    hold before a trial on "no mocap frames received", half a second into a pause of the stream,
    though the test profile's stale limit was 0.8 s: the watch judged only the frames of its
    last 0.5 s. Frames had come, so such a pause is judged by the newest frame's age against
    ``max_age_s``: flown through under a limit of 2 s (far above the pause, so that a loaded
    machine cannot make it stale before the check), stale (with its age) under 0.4 s, and "no
    mocap frames received" only where none ever came."""
    source = parse_mocap_url("optitrack://127.0.0.1/drone")
    silent_s = HEALTH_WINDOW_S + 0.1  # since the newest frame, at least, at the check

    def after_a_pause(max_age_s: float) -> str | None:
        link = MocapLink(source, MOTIVE, MocapSettings(max_age_s=max_age_s))
        newest_s = time.monotonic() - silent_s
        for i, t_s in enumerate(newest_s - np.arange(60)[::-1] / 120):  # 0.5 s of 120 Hz
            link.client._record(b"S", SAMPLE.pack(i, t_s, True, 0.01 * i, 0, 1.5, 1, 0, 0, 0))
        return link.problem()

    assert after_a_pause(2.0) is None
    stale = after_a_pause(0.4)
    assert stale is not None and stale.startswith("mocap stream stale ("), stale
    assert float(stale.split("(")[1].split(" s")[0]) >= silent_s - 0.005
    never = MocapLink(source, MOTIVE, MocapSettings(max_age_s=2.0))
    assert never.problem() == "no mocap frames received"
