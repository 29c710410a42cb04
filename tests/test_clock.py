"""The vehicle clock: continuous time from raw stamps, and the lower-envelope rate/offset fit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from px4_data import capture

from gcs.flight.clock import (
    BOOT_MS_WRAP_S,
    RATE_TOLERANCE,
    VehicleClock,
    fit_clock,
    lower_hull,
    rate_warning,
    unwrap_vehicle_time,
)


def stream(rate: float, offset_s: float, n: int = 1000, period_s: float = 0.02, seed: int = 0):
    """Vehicle stamps every ``period_s`` and receipts ``offset + v / rate + latency``."""
    rng = np.random.default_rng(seed)
    v = 100.0 + np.arange(n) * period_s
    latency = 0.0005 + rng.exponential(0.002, n)  # never negative, sometimes large
    return v, offset_s + v / rate + latency


@given(
    rate=st.floats(0.5, 2.0),
    offset_s=st.floats(-1e4, 1e4),
    seed=st.integers(0, 1000),
)
@settings(max_examples=40, deadline=None)
def test_fit_recovers_rate_and_offset_and_no_sample_lies_below(rate, offset_s, seed) -> None:
    v, r = stream(rate, offset_s, seed=seed)
    fit = fit_clock(v, r)
    assert fit.rate == pytest.approx(rate, rel=2e-4)
    # the offset includes the smallest latency (0.5 ms here) and no more than a little
    assert 0.0 <= fit.to_local(v[500]) - (offset_s + v[500] / rate) <= 0.0015
    assert fit.latency_p50_s >= 0.0 and fit.latency_max_s >= fit.latency_p50_s
    assert np.all(r - fit.to_local(v) >= -1e-9)
    assert fit.to_vehicle(fit.to_local(123.0)) == pytest.approx(123.0)
    assert fit.n_samples == 1000 and fit.span_s == pytest.approx(v[-1] - v[0])


def test_latency_spikes_do_not_move_the_fit_but_would_bias_least_squares() -> None:
    v, r = stream(0.9, 5.0)
    clean = fit_clock(v, r)
    spiked = r.copy()
    spiked[200:400] += 0.5  # a second of samples held up by half a second (scheduler, link)
    fit = fit_clock(v, spiked)
    # the hull loses at most a vertex or two under the spikes: the line moves by microseconds
    assert fit.rate == pytest.approx(clean.rate, rel=1e-6)
    assert abs(fit.to_local(v) - clean.to_local(v)).max() < 1e-5
    assert fit.latency_max_s == pytest.approx(0.5, abs=0.02)
    ls_rate = 1.0 / np.polyfit(v, spiked, 1)[0]
    assert abs(ls_rate - 0.9) > 50 * abs(fit.rate - 0.9)


def test_fit_on_the_px4_sitl_capture() -> None:
    # PX4 v1.16 SIH in lockstep: its clock ran a little slower than the capture's wall clock
    lpn = capture().lpn
    v = unwrap_vehicle_time(lpn[:, 1], lpn[:, 0])
    np.testing.assert_array_equal(v, lpn[:, 1])  # no wrap, no restart in 193 s
    fit = fit_clock(v, lpn[:, 0])
    assert fit.rate == pytest.approx(0.9934, abs=0.0005)
    assert fit.latency_p50_s < 0.06
    for start in range(0, 180, 20):  # every 15 s window: 0.990-0.997
        inside = (v >= start) & (v < start + 15)
        part = fit_clock(v[inside], lpn[inside, 0])
        assert 0.985 < part.rate < 1.0 and part.latency_p50_s < 0.02
        assert rate_warning(0, part.rate, 15.0, 0.05) is None  # within 2 %: nothing to say


def test_a_wrap_of_time_boot_ms_is_unwrapped_and_fits_as_before() -> None:
    v, r = stream(0.95, 2.0)
    raw_ms = np.floor((v - v[0] + BOOT_MS_WRAP_S - 5.0) * 1000.0) % 2**32  # wraps after 5 s
    t = unwrap_vehicle_time(raw_ms / 1000.0, r)
    assert np.all(np.diff(t) > 0)
    np.testing.assert_allclose(np.diff(t), np.diff(v), atol=1.01e-3)
    assert fit_clock(t, r).rate == pytest.approx(0.95, rel=1e-3)


def test_a_restart_continues_the_time_and_the_fit_recovers() -> None:
    v, r = stream(0.9, 3.0, n=2000)
    raw = v.copy()
    raw[1000:] = 0.3 + (v[1000:] - v[1000])  # the vehicle rebooted: its clock starts again
    clock = VehicleClock(window_s=10.0)
    t = np.array([clock.add(a, b) for a, b in zip(raw, r, strict=True)])
    assert clock.restarts == 1
    assert np.all(np.diff(t) > 0)  # never backwards across the restart
    assert t[1000] - t[999] == pytest.approx(0.02, abs=0.01)  # bridged by the receipt times
    fit = clock.fit()
    assert fit is not None and fit.n_samples == 500  # only the new clock's samples
    assert fit.rate == pytest.approx(0.9, rel=1e-3)


def test_a_reordered_datagram_keeps_its_time_and_stays_out_of_the_fit() -> None:
    clock = VehicleClock()
    assert clock.fit() is None
    for k in range(10):
        clock.add(k * 0.02, 10.0 + k * 0.02)
    assert clock.add(0.15, 10.2) == pytest.approx(0.15)  # arrived after 0.18
    assert clock.latest_s == pytest.approx(0.18)
    assert clock.fit().n_samples == 10


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="two or more"):
        fit_clock([1.0], [2.0])
    with pytest.raises(ValueError, match="two or more"):
        fit_clock([1.0, 1.0], [2.0, 2.1])
    with pytest.raises(ValueError, match="non-decreasing"):
        fit_clock([1.0, 0.5], [2.0, 2.1])
    with pytest.raises(ValueError, match="finite"):
        fit_clock([1.0, np.nan], [2.0, 2.1])
    with pytest.raises(ValueError, match="does not advance"):
        fit_clock([1.0, 2.0], [5.0, 4.0])


def test_lower_hull_of_a_v() -> None:
    x = np.array([0.0, 1.0, 1.0, 2.0, 3.0, 4.0])
    y = np.array([4.0, 3.0, 1.0, 0.0, 1.0, 4.0])
    np.testing.assert_array_equal(lower_hull(x, y), [0, 2, 3, 4, 5])


def test_rate_warning_beyond_two_percent_says_what_it_does_to_the_data() -> None:
    assert rate_warning(3, 1.0, 14.0, 0.05) is None
    assert rate_warning(3, 1.0 - 0.99 * RATE_TOLERANCE, 14.0, 0.05) is None
    assert rate_warning(3, 1.0 + 1.01 * RATE_TOLERANCE, 14.0, 0.05) is not None
    assert rate_warning(3, float("nan"), 14.0, 0.05) is None
    line = rate_warning(3, 0.9, 14.0, 0.05)
    assert line is not None and "\n" not in line
    assert line.startswith("trial 3: the vehicle's clock ran at 0.900x wall time")
    assert "slower than real time" in line and "0.05 s grid in vehicle time" in line
    assert "15.6 s for 14.0 s" in line and "1.11x" in line
    assert "faster than real time" in rate_warning(0, 1.05, 14.0, 0.05)
