"""Excitation signals: levels, bounds, spectra, reproducibility, bad arguments."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.core.excitation import multisine, prbs
from gcs.errors import IdentificationError

DT = 0.05


def _band_power_fraction(x: np.ndarray, dt: float, f_lo: float, f_hi: float) -> float:
    spec = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(x.size, dt)
    inside = (f >= f_lo) & (f <= f_hi)
    return float(spec[inside].sum() / spec[1:].sum())


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(50, 3000),
    amp=st.floats(0.01, 2.0),
    bw=st.floats(0.05, 10.0),
    seed=st.integers(0, 2**31 - 1),
)
def test_prbs_is_binary_with_the_requested_level(n: int, amp: float, bw: float, seed: int) -> None:
    x = prbs(n, DT, amp, bw, seed)
    assert x.shape == (n,)
    assert np.all(np.isin(x, [amp, -amp]))


def test_prbs_hold_and_balance() -> None:
    x = prbs(4000, DT, 0.5, 2.0, seed=3)
    hold = round(1 / (2.5 * 2.0 * DT))  # 4 samples
    runs = np.diff(np.flatnonzero(np.diff(x) != 0))
    assert np.all(runs % hold == 0)
    assert abs(x.mean()) < 0.05 * 0.5  # maximum-length sequences are nearly balanced
    # sinc^2 spectrum of a clock at 2.5 x bandwidth: about 2/3 of the power below bandwidth,
    # against 0.4 for a white sequence (clocked every sample)
    assert _band_power_fraction(x, DT, 0.0, 2.0) > 0.6
    assert _band_power_fraction(prbs(4000, DT, 0.5, 10.0, seed=3), DT, 0.0, 2.0) < 0.5


def test_prbs_reproducible_and_seed_dependent() -> None:
    a = prbs(500, DT, 1.0, 10.0, seed=1)
    assert np.array_equal(a, prbs(500, DT, 1.0, 10.0, seed=1))
    assert not np.array_equal(a, prbs(500, DT, 1.0, 10.0, seed=2))


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(100, 4000),
    amp=st.floats(0.01, 2.0),
    f_lo=st.floats(0.0, 3.0),
    width=st.floats(0.3, 6.0),
    seed=st.integers(0, 2**31 - 1),
)
def test_multisine_bounded_zero_mean_tapered(
    n: int, amp: float, f_lo: float, width: float, seed: int
) -> None:
    f_hi = min(f_lo + width, 9.5)
    x = multisine(n, DT, amp, f_lo, f_hi, seed)
    assert x.shape == (n,)
    assert np.max(np.abs(x)) == pytest.approx(amp, rel=1e-12)
    assert abs(x.mean()) < 1e-12 * amp
    assert x[0] == 0.0 and x[-1] == 0.0
    assert abs(x[1]) < 0.2 * amp and abs(x[-2]) < 0.2 * amp  # smooth start and end


def test_multisine_power_lies_in_band_and_crest_is_low() -> None:
    x = multisine(2000, DT, 1.0, 0.1, 2.0, seed=4)
    assert _band_power_fraction(x, DT, 0.05, 2.1) > 0.97
    core = x[300:-300]  # away from the tapers
    crest = np.max(np.abs(core)) / np.sqrt(np.mean(core**2))
    assert crest < 2.2  # Schroeder phases; random phases give about 3-4
    assert np.array_equal(x, multisine(2000, DT, 1.0, 0.1, 2.0, seed=4))


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: prbs(1, DT, 1.0, 1.0, 0), "n_samples"),
        (lambda: prbs(100, 0.0, 1.0, 1.0, 0), "dt_s"),
        (lambda: prbs(100, DT, -1.0, 1.0, 0), "amplitude_m"),
        (lambda: prbs(100, DT, 1.0, 11.0, 0), "Nyquist"),
        (lambda: multisine(100, DT, 1.0, 2.0, 1.0, 0), "f_min_hz <= f_max_hz"),
        (lambda: multisine(100, DT, 1.0, 1.0, 10.0, 0), "below Nyquist"),
        (lambda: multisine(100, DT, 1.0, 0.01, 0.1, 0), "no frequency line"),
        (lambda: multisine(100, DT, np.nan, 0.5, 1.0, 0), "amplitude_m"),
    ],
)
def test_bad_arguments_raise(call, match: str) -> None:
    with pytest.raises(IdentificationError, match=match):
        call()
