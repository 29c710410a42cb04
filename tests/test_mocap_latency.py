"""The estimate's lag behind the mocap, recovered from shifted copies (pure)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.flight.mocap.latency import estimate_lag_s


def circle(t: np.ndarray) -> np.ndarray:
    return np.column_stack([np.cos(2 * t), np.sin(2 * t)])


@settings(max_examples=20, deadline=None)
@given(lag_ms=st.integers(-150, 250))
def test_a_known_shift_is_found_to_the_millisecond(lag_ms: int) -> None:
    tm = np.arange(0.0, 6.0, 1 / 120)
    te = np.arange(0.5, 5.5, 1 / 50)
    lag = estimate_lag_s(tm, circle(tm), te, circle(te - lag_ms / 1000))
    assert lag == pytest.approx(lag_ms / 1000, abs=0.0011)


def test_a_still_body_has_no_measurable_lag() -> None:
    t = np.arange(0.0, 3.0, 0.01)
    still = np.zeros((t.size, 2)) + 1e-4 * np.random.default_rng(0).standard_normal((t.size, 2))
    assert estimate_lag_s(t, still, t, still) is None


def test_untracked_rows_are_skipped_and_shapes_are_checked() -> None:
    tm = np.arange(0.0, 6.0, 1 / 120)
    xm = circle(tm)
    xm[100:130] = np.nan
    te = np.arange(0.5, 5.5, 1 / 50)
    assert estimate_lag_s(tm, xm, te, circle(te - 0.04)) == pytest.approx(0.04, abs=0.0011)
    with pytest.raises(ValueError, match="shape"):
        estimate_lag_s(tm, xm.T, te, circle(te))
