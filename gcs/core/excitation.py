"""Excitation signals for identification experiments (pure functions, no I/O).

Both signals are position-setpoint perturbations in metres, to be added to a hover (or slow
reference) setpoint along one horizontal axis, one value per sample of ``dt_s`` seconds:

* :func:`prbs` -- a maximum-length pseudo-random binary sequence (+/- amplitude), held for
  several samples so that its power sits below ``bandwidth_hz``. Rich (persistently exciting of
  high order) but made of steps.
* :func:`multisine` -- a sum of cosines on the record's frequency grid between ``f_min_hz`` and
  ``f_max_hz`` with Schroeder phases (low crest factor), zero mean, raised-cosine taper at both
  ends so the setpoint starts and ends at zero with zero slope.

The identification caveat of the prior art applies (SIPPY issue #8): a single sinusoid is not
enough; use either of these.
"""

from __future__ import annotations

import numpy as np

from gcs.errors import IdentificationError

__all__ = ["prbs", "multisine"]

_TAPER_FRACTION = 0.1


def _check_common(n_samples: int, dt_s: float, amplitude_m: float) -> None:
    if int(n_samples) != n_samples or n_samples < 2:
        raise IdentificationError(f"n_samples must be an integer >= 2, got {n_samples}")
    if not (np.isfinite(dt_s) and dt_s > 0):
        raise IdentificationError(f"dt_s must be positive and finite, got {dt_s}")
    if not (np.isfinite(amplitude_m) and amplitude_m > 0):
        raise IdentificationError(f"amplitude_m must be positive and finite, got {amplitude_m}")


def prbs(
    n_samples: int, dt_s: float, amplitude_m: float, bandwidth_hz: float, seed: int
) -> np.ndarray:
    """Maximum-length pseudo-random binary sequence of +/- ``amplitude_m``.

    The binary sequence is clocked every ``hold = max(1, round(1 / (2.5 * bandwidth_hz *
    dt_s)))`` samples: the power spectrum of a PRBS with clock frequency ``f_c`` is flat to
    within 3 dB up to about ``0.4 f_c``, so a clock of ``2.5 * bandwidth_hz`` covers the band.
    The register length is the smallest (>= 5 bits) whose period covers the record, so no
    period repeats within it.

    Parameters
    ----------
    n_samples : int
        Number of samples N.
    dt_s : float
        Sample time [s].
    amplitude_m : float
        Level of the sequence [m]; every sample is ``+amplitude_m`` or ``-amplitude_m``.
    bandwidth_hz : float
        Upper end of the excited band [Hz], ``0 < bandwidth_hz <= 1 / (2 dt_s)``.
    seed : int
        Selects the (non-zero) initial state of the shift register.

    Returns
    -------
    ndarray, shape (N,)
        Setpoint perturbation [m].
    """
    _check_common(n_samples, dt_s, amplitude_m)
    nyquist = 0.5 / dt_s
    if not (np.isfinite(bandwidth_hz) and 0 < bandwidth_hz <= nyquist):
        raise IdentificationError(
            f"bandwidth_hz must be in (0, {nyquist:g}] (Nyquist for dt_s={dt_s:g}), "
            f"got {bandwidth_hz}"
        )
    hold = max(1, int(round(1.0 / (2.5 * bandwidth_hz * dt_s))))
    n_clock = -(-int(n_samples) // hold)
    nbits = max(5, int(np.ceil(np.log2(n_clock + 1))))
    rng = np.random.default_rng(seed)
    state = rng.integers(0, 2, size=nbits)
    if not state.any():
        state[rng.integers(0, nbits)] = 1
    from scipy.signal import max_len_seq  # on first use: a second to import

    bits, _ = max_len_seq(nbits, state=state, length=n_clock)
    levels = np.where(bits > 0, amplitude_m, -amplitude_m).astype(float)
    return np.repeat(levels, hold)[: int(n_samples)]


def multisine(
    n_samples: int, dt_s: float, amplitude_m: float, f_min_hz: float, f_max_hz: float, seed: int
) -> np.ndarray:
    """Schroeder-phased multisine, zero mean, tapered, peak ``amplitude_m``.

    Lines are the record's frequency grid ``k / (N dt_s)`` that lie in ``[f_min_hz, f_max_hz]``
    (at least one must), all of equal amplitude with Schroeder phases
    ``phi_k = -pi k (k - 1) / M`` (low crest factor for a flat spectrum). ``seed`` applies a
    circular time shift, which changes the waveform but not its spectrum or crest factor. The
    first and last 10 % of the record are multiplied by raised-cosine ramps (value and slope
    zero at both ends), an offset is removed so the tapered signal has zero mean exactly, and
    the result is scaled so its largest absolute value equals ``amplitude_m``.

    Parameters
    ----------
    n_samples : int
        Number of samples N.
    dt_s : float
        Sample time [s].
    amplitude_m : float
        Peak absolute value of the result [m].
    f_min_hz, f_max_hz : float
        Excited band [Hz], ``0 <= f_min_hz <= f_max_hz < 1 / (2 dt_s)``.
    seed : int
        Selects the circular time shift.

    Returns
    -------
    ndarray, shape (N,)
        Setpoint perturbation [m]; ``out[0] == out[-1] == 0``.
    """
    _check_common(n_samples, dt_s, amplitude_m)
    n = int(n_samples)
    nyquist = 0.5 / dt_s
    if not (np.isfinite(f_min_hz) and np.isfinite(f_max_hz) and 0 <= f_min_hz <= f_max_hz):
        raise IdentificationError(
            f"need 0 <= f_min_hz <= f_max_hz, got f_min_hz={f_min_hz}, f_max_hz={f_max_hz}"
        )
    if f_max_hz >= nyquist:
        raise IdentificationError(
            f"f_max_hz={f_max_hz:g} must be below Nyquist {nyquist:g} Hz for dt_s={dt_s:g}"
        )
    df = 1.0 / (n * dt_s)
    k_lo = max(1, int(np.ceil(f_min_hz / df - 1e-9)))
    k_hi = int(np.floor(f_max_hz / df + 1e-9))
    if k_hi < k_lo:
        raise IdentificationError(
            f"no frequency line of the {n * dt_s:g} s record (spacing {df:g} Hz) lies in "
            f"[{f_min_hz:g}, {f_max_hz:g}] Hz: widen the band or lengthen the record"
        )
    lines = np.arange(k_lo, k_hi + 1)
    m = lines.size
    idx = np.arange(1, m + 1)
    phases = -np.pi * idx * (idx - 1) / m
    t = np.arange(n)
    s = np.cos(2 * np.pi * np.outer(t, lines) / n + phases).sum(axis=1)
    shift = int(np.random.default_rng(seed).integers(0, n))
    s = np.roll(s, shift)
    w = np.ones(n)
    n_taper = max(1, int(round(_TAPER_FRACTION * n)))
    if 2 * n_taper >= n:
        n_taper = max(1, (n - 1) // 2)
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(n_taper) / n_taper)
    w[:n_taper] = ramp
    w[n - n_taper :] = ramp[::-1]
    w[-1] = 0.0
    offset = float(np.sum(w * s) / np.sum(w))
    out = w * (s - offset)
    peak = float(np.max(np.abs(out)))
    if peak == 0.0:
        raise IdentificationError("multisine degenerated to zero: lengthen the record")
    return out * (amplitude_m / peak)
