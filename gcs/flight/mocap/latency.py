"""How late the vehicle's estimate follows the motion capture (pure).

Both series are on one clock (seconds); the lag is the shift ``tau`` that brings the
estimate closest to the mocap: ``est(t) ~ mocap(t - tau)``, minimising the mean squared
horizontal distance over a grid of shifts (1 ms steps). It needs motion: in a still hover
every shift fits equally and the answer is meaningless (``None`` when the mocap moved less
than ``min_motion_m``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["estimate_lag_s"]


def estimate_lag_s(
    mocap_t_s: np.ndarray,
    mocap_ne_m: np.ndarray,
    est_t_s: np.ndarray,
    est_ne_m: np.ndarray,
    max_lag_s: float = 0.3,
    step_s: float = 0.001,
    min_motion_m: float = 0.2,
) -> float | None:
    """Lag of the estimate behind the mocap [s] (negative: the estimate leads).

    Parameters
    ----------
    mocap_t_s : numpy.ndarray
        Mocap times, shape (M,), increasing [s].
    mocap_ne_m : numpy.ndarray
        Mocap north and east, shape (M, 2) [m].
    est_t_s : numpy.ndarray
        Estimate times on the same clock, shape (K,), increasing [s].
    est_ne_m : numpy.ndarray
        Estimate north and east, shape (K, 2) [m].
    max_lag_s : float
        Shifts searched: ``-max_lag_s .. max_lag_s`` [s].
    step_s : float
        Grid step of the shifts [s].
    min_motion_m : float
        Smallest extent of the mocap's path for a meaningful answer [m].

    Returns
    -------
    float or None
        The lag [s], or None (too little motion or overlap).
    """
    tm, xm = np.asarray(mocap_t_s, float), np.asarray(mocap_ne_m, float)
    te, xe = np.asarray(est_t_s, float), np.asarray(est_ne_m, float)
    if xm.shape != (tm.size, 2) or xe.shape != (te.size, 2):
        raise ValueError("positions must have shape (N, 2) matching their times")
    keep = np.all(np.isfinite(xm), axis=1) & np.isfinite(tm)
    tm, xm = tm[keep], xm[keep]
    if tm.size < 10 or te.size < 10:
        return None
    if float(np.max(np.ptp(xm, axis=0))) < min_motion_m:
        return None
    shifts = np.arange(-max_lag_s, max_lag_s + step_s / 2, step_s)
    cost = np.full(shifts.size, np.inf)
    for i, tau in enumerate(shifts):
        t = te - tau  # the mocap time the estimate at te shows
        inside = (t >= tm[0]) & (t <= tm[-1])
        if inside.sum() < 10:
            continue
        ref = np.column_stack([np.interp(t[inside], tm, xm[:, c]) for c in range(2)])
        cost[i] = float(np.mean(np.sum((xe[inside] - ref) ** 2, axis=1)))
    if not np.isfinite(cost).any():
        return None
    return float(shifts[int(np.argmin(cost))])
