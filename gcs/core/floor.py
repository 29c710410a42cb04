"""Repeatability of the vehicle and the floor of learning (pure numerics).

No ILC removes what does not repeat. Flights of identical setpoints differ only by their
non-repeatable parts ``v_i`` (gusts, estimator wander, measurement noise):
``Y_i - Y_l = v_i - v_l``. For independent, identically distributed zero-mean Gaussian
``v_i`` (any covariance, isotropic or not, correlated in time or not), the scaled deviation
from the mean of ``K`` flights,

    delta_i = sqrt(K / (K - 1)) (Y_i - mean_l Y_l),

has exactly the distribution of one flight's ``v``; for two flights ``delta = (Y_1 - Y_2) /
sqrt(2)``. So the floor in the terms of eq. (10), the expected e_pos of a flight whose
repeatable error is zero, is the mean over samples (and flights) of ``|delta(k)|`` (the
horizontal distance), and its RMS version ``sqrt(mean |delta|^2)``.

The floor's scatter is the standard deviation of one trial's e_pos at the floor. Within one
trial it is the standard error of a time average of the correlated series
``a(k) = |delta(k)|``, i.e. ``sd(a) sqrt(tau / N)`` with ``tau`` the integrated
autocorrelation time of ``a`` (Geyer's initial positive sequence). That cannot see a wander
slower than the trial, nor a flight that goes worse as a whole: on PX4 firmware in a lab it
came out 2-4 times below the spread of e_pos between flights. With ``K >= 3`` flights the
spread between them is measured too, and the larger of the two is the scatter. Why these
statistics decide "reached" and "converged" is in ``docs/learning-floor.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "Floor",
    "FloorVerdict",
    "floor_from_flights",
    "prediction_noise_ratio",
    "floor_from_difference",
    "floor_flights",
    "first_flights",
    "integrated_autocorrelation",
    "floor_verdicts",
    "FloorDrift",
    "floor_drift",
    "DRIFT_TRIALS",
]

#: Trials in a row above the floor, after one at it, that make a drift (:func:`floor_drift`).
DRIFT_TRIALS = 2

#: Setpoints closer than this count as identical [m].
IDENTICAL_TOL_M = 1e-9


@dataclass(frozen=True)
class Floor:
    """One flight's non-repeatable error, in e_pos terms, with its sampling scatter.

    Parameters
    ----------
    epos_m : float
        Expected e_pos (eq. 10) of a trial with no repeatable error left [m].
    rms_m : float
        RMS horizontal non-repeatable error of one flight [m].
    axis_rms_m : tuple of float
        RMS per axis (north, east) [m].
    axis_mean_abs_m : tuple of float
        Mean absolute non-repeatable error per axis (north, east) [m].
    scatter_m : float
        Standard deviation of one trial's e_pos at the floor [m].
    effective_samples : float
        ``N / tau``: independent samples a trial is worth for the time average.
    flights : int
        Flights the floor is measured from (``K``); 2 for a difference.
    source : str
        ``"repeat"`` (identical setpoints) or ``"model-corrected pair"`` (two trials of
        different setpoints, the model's predicted change removed: an upper bound).
    scatter_within_m : float or None
        The scatter estimated within the trials (from the time series) [m].
    scatter_between_m : float or None
        The scatter measured between flights (``K >= 3``; None for two) [m]. ``scatter_m``
        is the larger of the two.
    """

    epos_m: float
    rms_m: float
    axis_rms_m: tuple[float, float]
    axis_mean_abs_m: tuple[float, float]
    scatter_m: float
    effective_samples: float
    flights: int
    source: str = "repeat"
    scatter_within_m: float | None = None
    scatter_between_m: float | None = None

    @property
    def floor_scatter_m(self) -> float:
        """Standard deviation of the floor estimate itself [m] (``K - 1`` degrees of freedom)."""
        return self.scatter_m / np.sqrt(max(self.flights - 1, 1))

    def as_dict(self) -> dict:
        """JSON-ready dictionary of the fields (SI units)."""
        return {
            "epos_m": self.epos_m,
            "rms_m": self.rms_m,
            "axis_rms_m": list(self.axis_rms_m),
            "axis_mean_abs_m": list(self.axis_mean_abs_m),
            "scatter_m": self.scatter_m,
            "floor_scatter_m": self.floor_scatter_m,
            "effective_samples": self.effective_samples,
            "flights": self.flights,
            "source": self.source,
            "scatter_within_m": self.scatter_within_m,
            "scatter_between_m": self.scatter_between_m,
        }


def _check_ne(name: str, arr: np.ndarray, ndim: int) -> np.ndarray:
    arr = np.asarray(arr, dtype=float)
    if arr.ndim != ndim or arr.shape[-1] != 2:
        want = "(K, N, 2)" if ndim == 3 else "(N, 2)"
        raise ValueError(f"{name} must have shape {want} (north, east last), got {arr.shape}")
    if arr.shape[-2] < 4:
        raise ValueError(f"{name} needs at least 4 samples per flight, got {arr.shape[-2]}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return arr


def integrated_autocorrelation(x: np.ndarray) -> float:
    """Integrated autocorrelation time ``tau = 1 + 2 sum_k rho(k)`` of a series.

    The sum runs over Geyer's initial positive sequence: pairs ``rho(2m) + rho(2m+1)`` are
    added while they stay positive, which bounds the noise of the long lags.

    Parameters
    ----------
    x : ndarray, shape (N,)
        The series.

    Returns
    -------
    float
        ``tau`` in samples, between 1 and ``N``.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"x must be one-dimensional, got shape {x.shape}")
    n = x.size
    xc = x - x.mean()
    var = float(xc @ xc) / n
    if var == 0.0 or n < 4:
        return 1.0
    spec = np.fft.rfft(xc, 2 * n)
    acov = np.fft.irfft(spec * np.conj(spec), 2 * n)[:n] / n
    rho = acov / var
    tau = -1.0  # rho(0) = 1 enters the first pair: tau = -1 + 2 sum of pairs
    for m in range(n // 2):
        pair = rho[2 * m] + (rho[2 * m + 1] if 2 * m + 1 < n else 0.0)
        if pair <= 0:
            break
        tau += 2.0 * pair
    return float(min(max(tau, 1.0), n))


def _floor(delta: np.ndarray, flights: int, source: str) -> Floor:
    """Floor statistics from deviations ``delta`` of shape (K', N, 2) distributed like v."""
    dist = np.hypot(delta[..., 0], delta[..., 1])  # (K', N)
    n = dist.shape[-1]
    taus = [integrated_autocorrelation(a) for a in dist]
    tau = float(np.mean(taus))
    # s^2 tau / (N - tau): the demeaned sample variance underestimates the variance by the
    # variance of the mean itself, sigma^2 tau / N
    within = float(np.mean([np.std(a) for a in dist])) * np.sqrt(tau / max(n - tau, 1.0))
    between = _between_flights(dist.mean(axis=1)) if dist.shape[0] >= 3 else None
    scatter = within if between is None else max(within, between)
    return Floor(
        epos_m=float(dist.mean()),
        rms_m=float(np.sqrt(np.mean(dist**2))),
        axis_rms_m=tuple(float(x) for x in np.sqrt(np.mean(delta**2, axis=(0, 1)))),  # type: ignore[arg-type]
        axis_mean_abs_m=tuple(float(x) for x in np.mean(np.abs(delta), axis=(0, 1))),  # type: ignore[arg-type]
        scatter_m=float(scatter),
        effective_samples=float(n / tau),
        flights=flights,
        source=source,
        scatter_within_m=within,
        scatter_between_m=between,
    )


def _between_flights(epos_m: np.ndarray) -> float:
    """The standard deviation of one flight's e_pos at the floor from the e_pos ``a_i`` of
    ``K >= 3`` deviations ``delta_i`` from the flights' mean.

    The ``delta_i`` share the mean they are taken from: their correlation is ``rho =
    -1 / (K - 1)``, and that of their distances about ``rho^2`` (for Gaussian pairs,
    ``corr(|X|, |Y|)`` is close to ``rho^2``), so the sample variance of the ``a_i`` is
    ``1 - rho^2`` times a single flight's, on average; that factor is taken out (checked by
    simulation in tests/test_floor.py).
    """
    k = epos_m.size
    return float(np.sqrt(np.var(epos_m, ddof=1) / (1.0 - 1.0 / (k - 1) ** 2)))


def floor_from_flights(pos_ne_m: np.ndarray) -> Floor:
    """The floor from ``K >= 2`` flights of identical setpoints.

    Parameters
    ----------
    pos_ne_m : ndarray, shape (K, N, 2)
        Measured north/east positions y(1..N) of each flight on the trial grid [m] (absolute
        or learning coordinates: only differences enter).

    Returns
    -------
    Floor
    """
    pos = _check_ne("pos_ne_m", pos_ne_m, 3)
    k = pos.shape[0]
    if k < 2:
        raise ValueError(f"the floor needs at least 2 flights, got {k}")
    delta = np.sqrt(k / (k - 1)) * (pos - pos.mean(axis=0))
    # two flights give one series (delta_2 = -delta_1): keep one so tau is not counted twice
    return _floor(delta[:1] if k == 2 else delta, k, "repeat")


def prediction_noise_ratio(weights: np.ndarray) -> float:
    """How far a flight comes out from a learning step's prediction of it, in floors, when the
    model is right: its own noise and the estimate's.

    The estimate of the disturbance is a weighted mean of the trials' residuals, so it carries
    ``sum_i w_i v_i`` of their non-repeatable parts; the flight adds its own ``v``. For
    independent flights of one Gaussian process the difference is that process scaled by
    ``sqrt(1 + sum_i w_i^2)``, and so is its e_pos: the floor times that factor (1 for an
    estimate without noise, ``sqrt(2)`` for the newest trial alone).

    Parameters
    ----------
    weights : ndarray, shape (T,)
        Weight of each trial in the estimate (``NoiseRecord.weights``).

    Returns
    -------
    float
        The factor, >= 1.
    """
    w = np.asarray(weights, dtype=float)
    if w.ndim != 1 or not np.all(np.isfinite(w)):
        raise ValueError(f"weights must be a finite (T,) array, got shape {w.shape}")
    return float(np.sqrt(1.0 + np.sum(w**2)))


def floor_from_difference(diff_ne_m: np.ndarray, source: str = "repeat") -> Floor:
    """The floor from the difference of two flights' non-repeatable parts ``v_1 - v_2``.

    Parameters
    ----------
    diff_ne_m : ndarray, shape (N, 2)
        ``Y_1 - Y_2`` for identical setpoints, or ``Y_1 - Y_2 - F (U_1 - U_2)`` (the model's
        predicted change removed) for different ones [m].
    source : str
        ``"repeat"`` or ``"model-corrected pair"`` (recorded in the result).

    Returns
    -------
    Floor
    """
    diff = _check_ne("diff_ne_m", diff_ne_m, 2)
    return _floor(diff[None] / np.sqrt(2.0), 2, source)


def floor_flights(setpoints_ne_m: np.ndarray, tol_m: float = IDENTICAL_TOL_M) -> list[int]:
    """The flights that measure the floor: trial 0 and the trials right after it flown with
    its setpoints (the repeats), when there are two or more.

    A later flight of setpoints flown before (``gcs fly --again``) does not join them: the
    floor is measured once, before learning starts, and the verdicts of every later trial
    are taken against that one floor.

    Parameters
    ----------
    setpoints_ne_m : ndarray, shape (T, N, 2)
        Setpoints of every trial, in trial order [m].
    tol_m : float
        Largest difference that counts as identical [m].

    Returns
    -------
    list of int
        ``[0, 1, .., r]`` (``r >= 1``), or empty when trial 1 does not repeat trial 0.
    """
    first = first_flights(setpoints_ne_m, tol_m)
    r = 0
    while r + 1 < len(first) and first[r + 1] == 0:
        r += 1
    return list(range(r + 1)) if r >= 1 else []


@dataclass(frozen=True)
class FloorVerdict:
    """How one trial's e_pos compares with the floor.

    Parameters
    ----------
    trial : int
        Trial index j.
    epos_m : float
        The trial's e_pos [m].
    ratio : float
        ``epos_m / floor.epos_m``.
    z : float
        ``(epos_m - floor) / sigma_d``, ``sigma_d`` the scatter of a trial's e_pos minus the
        floor estimate.
    at_floor : bool
        ``z <= z_max``: the trial is indistinguishable from a flight with nothing repeatable
        left.
    converged : bool
        This learned trial and the learned one before it are at the floor and their mean lies
        within one single-flight scatter of the floor: further trials cannot show an
        improvement. Trial 0 and flights of setpoints flown before (its repeats,
        ``gcs fly --again``) are never part of the pair: they say how the same setpoints
        scatter, not where learning went.
    repeat_of : int or None
        The earliest trial flown with this trial's setpoints when this one flew them again (a
        repeat, ``gcs fly --again``); None for a trial of setpoints new to the run.
    """

    trial: int
    epos_m: float
    ratio: float
    z: float
    at_floor: bool
    converged: bool
    repeat_of: int | None = None


def first_flights(setpoints_ne_m: np.ndarray, tol_m: float = IDENTICAL_TOL_M) -> tuple[int, ...]:
    """For every trial, the earliest trial flown with its setpoints (itself if none).

    Parameters
    ----------
    setpoints_ne_m : ndarray, shape (T, N, 2)
        Setpoints of every trial, in trial order [m].
    tol_m : float
        Largest difference that counts as identical [m].

    Returns
    -------
    tuple of int, length T
        ``first[j] <= j``; ``first[j] < j`` when trial j flew trial ``first[j]``'s setpoints
        again.
    """
    sp = np.asarray(setpoints_ne_m, dtype=float)
    if sp.ndim != 3 or sp.shape[-1] != 2:
        raise ValueError(f"setpoints_ne_m must have shape (T, N, 2), got {sp.shape}")
    first: list[int] = []
    for j in range(sp.shape[0]):
        own = [i for i in range(j) if first[i] == i]  # trials of setpoints new when flown
        same = np.max(np.abs(sp[j] - sp[own]), axis=(1, 2)) <= tol_m if own else []
        first.append(own[int(np.argmax(same))] if np.any(same) else j)
    return tuple(first)


def floor_verdicts(
    epos_m: np.ndarray,
    floor: Floor,
    z_max: float = 2.0,
    setpoints_ne_m: np.ndarray | None = None,
) -> tuple[FloorVerdict, ...]:
    """Verdicts "at the floor" and "converged" for every trial.

    Parameters
    ----------
    epos_m : ndarray, shape (T,)
        e_pos of trials j = 0..T-1 [m].
    floor : Floor
        The measured floor.
    z_max : float
        One-sided threshold of the z statistic (2: a trial at the floor is called so with
        probability 0.977 under a Gaussian e_pos).
    setpoints_ne_m : ndarray, shape (T, N, 2), optional
        The trials' setpoints [m]: marks the flights of setpoints flown before
        (``FloorVerdict.repeat_of``). Default: every trial counts as new.

    Returns
    -------
    tuple of FloorVerdict
    """
    e = np.asarray(epos_m, dtype=float)
    if e.ndim != 1 or not np.all(np.isfinite(e)):
        raise ValueError(f"epos_m must be a finite 1-D array, got shape {e.shape}")
    first = tuple(range(e.size)) if setpoints_ne_m is None else first_flights(setpoints_ne_m)
    if len(first) != e.size:
        raise ValueError(f"setpoints_ne_m has {len(first)} trials, epos_m {e.size}")
    sigma = floor.scatter_m
    sigma_d = float(np.hypot(sigma, floor.floor_scatter_m))
    out: list[FloorVerdict] = []
    learned: int | None = None  # the newest learned trial before j
    for j, ej in enumerate(e):
        gap = ej - floor.epos_m
        z = gap / sigma_d if sigma_d > 0 else (0.0 if gap <= 0 else np.inf)
        at = bool(z <= z_max)
        new = j >= 1 and first[j] == j  # learned: neither trial 0 nor a flight flown before
        conv = (
            new
            and at
            and learned is not None
            and out[learned].at_floor
            and 0.5 * (e[j] + e[learned]) - floor.epos_m <= sigma
        )
        ratio = float(ej / floor.epos_m) if floor.epos_m > 0 else float("inf")
        again = None if first[j] == j else first[j]
        out.append(FloorVerdict(j, float(ej), ratio, float(z), at, bool(conv), again))
        if new:
            learned = j
    return tuple(out)


@dataclass(frozen=True)
class FloorDrift:
    """Learning that left the floor it had reached.

    Parameters
    ----------
    reached_trial : int
        The first trial at the floor.
    best_trial : int
        The trial at the floor with the smallest e_pos: the setpoints worth flying again.
    above : tuple of int
        The newest trials of new setpoints, all after ``reached_trial``, each above the floor.
    """

    reached_trial: int
    best_trial: int
    above: tuple[int, ...]


def floor_drift(
    verdicts: tuple[FloorVerdict, ...], newest: int = DRIFT_TRIALS
) -> FloorDrift | None:
    """Whether learning has left the floor it reached.

    A drift is the ``newest`` newest trials of new setpoints (learned ones; not repeats)
    all above the floor (``z > z_max``), after an earlier trial was at it. One trial at the
    floor is called above it by chance with probability 1 - 0.977 under a Gaussian e_pos
    (``z_max = 2``), so two in a row by chance about 5e-4 when the trials are independent: a
    rise, not the scatter. A flight of setpoints flown before (``repeat_of`` set: the repeat
    that measures the floor, ``gcs fly --again``) says how much the same setpoints scatter,
    not where learning went: it can be the trial that reached the floor, never one above it.

    Parameters
    ----------
    verdicts : tuple of FloorVerdict
        One per trial, in trial order (:func:`floor_verdicts`).
    newest : int
        Trials in a row above the floor that make a drift (>= 1).

    Returns
    -------
    FloorDrift or None
        None while no trial reached the floor, or while one of the newest is at it.
    """
    if newest < 1:
        raise ValueError(f"newest must be >= 1, got {newest}")
    new = [i for i, v in enumerate(verdicts) if v.repeat_of is None][-newest:]
    tail = [verdicts[i] for i in new]
    if len(tail) < newest or any(v.at_floor for v in tail):
        return None
    earlier = [v for v in verdicts[: new[0]] if v.at_floor]
    if not earlier:
        return None
    best = min(earlier, key=lambda v: (v.epos_m, v.trial))
    return FloorDrift(earlier[0].trial, best.trial, tuple(v.trial for v in tail))
