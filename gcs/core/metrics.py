"""Tracking metrics of the paper's Sec. V-A (eq. 10 and the Table IV columns)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "IterationMetrics", "axis_rms", "epos", "epos_3d", "iteration_table", "max_error",
    "start_offset",
]  # fmt: skip


@dataclass(frozen=True)
class IterationMetrics:
    """One row of the learning table (Table IV).

    Parameters
    ----------
    iteration : int
        Trial index j.
    epos_m : float
        Average horizontal position error e_pos,j of eq. (10) [m].
    epos_pct : float
        ``100 e_pos,j / e_pos,0`` [%].
    delta_pct : float or None
        ``100 |e_pos,j - e_pos,j-1| / e_pos,j-1`` [%]; None for the first trial.
    max_err_m : float
        Largest horizontal error of the trial [m].
    epos_3d_m : float or None
        Average 3-D position error (:func:`epos_3d`) [m]; None where not computed.
    rms_north_m, rms_east_m, rms_down_m : float or None
        RMS error per axis (:func:`axis_rms`) [m]; None where not computed.
    start_offset_m : float or None
        How far from the start point the trial began (:func:`start_offset`) [m]; None where
        not computed.
    """

    iteration: int
    epos_m: float
    epos_pct: float
    delta_pct: float | None
    max_err_m: float
    epos_3d_m: float | None = None
    rms_north_m: float | None = None
    rms_east_m: float | None = None
    rms_down_m: float | None = None
    start_offset_m: float | None = None


def _horizontal_errors(ref_ne_m: np.ndarray, pos_ne_m: np.ndarray) -> np.ndarray:
    ref = np.asarray(ref_ne_m, dtype=float)
    pos = np.asarray(pos_ne_m, dtype=float)
    if ref.shape != pos.shape or ref.ndim != 2 or ref.shape[1] != 2:
        raise ValueError(f"expected two (N, 2) arrays, got {ref.shape} and {pos.shape}")
    return np.hypot(pos[:, 0] - ref[:, 0], pos[:, 1] - ref[:, 1])


def epos(ref_ne_m: np.ndarray, pos_ne_m: np.ndarray) -> float:
    """Average horizontal position error, eq. (10).

    Parameters
    ----------
    ref_ne_m : ndarray, shape (N, 2)
        Desired north and east positions ``x_d(k), y_d(k)``, k = 1..N [m].
    pos_ne_m : ndarray, shape (N, 2)
        Measured north and east positions ``x_m(k), y_m(k)`` [m].

    Returns
    -------
    float
        ``(1/N) sum_k sqrt((x_m - x_d)^2 + (y_m - y_d)^2)`` [m].
    """
    return float(np.mean(_horizontal_errors(ref_ne_m, pos_ne_m)))


def max_error(ref_ne_m: np.ndarray, pos_ne_m: np.ndarray) -> float:
    """Largest horizontal position error over the trial [m].

    Parameters
    ----------
    ref_ne_m : ndarray, shape (N, 2)
        Desired north and east positions [m].
    pos_ne_m : ndarray, shape (N, 2)
        Measured north and east positions [m].

    Returns
    -------
    float
    """
    return float(np.max(_horizontal_errors(ref_ne_m, pos_ne_m)))


def start_offset(ref_ne_m: np.ndarray, pos_ne_m: np.ndarray) -> float:
    """Horizontal distance of the measured position at k = 0 from the reference's [m].

    Learning assumes every trial starts at rest at the start point (the initial reset, the
    paper's eq. 1); a trial that began elsewhere carries a disturbance that does not repeat.

    Parameters
    ----------
    ref_ne_m : ndarray, shape (N+1, 2)
        Desired north and east positions, k = 0..N [m]; row 0 is the start point.
    pos_ne_m : ndarray, shape (N+1, 2)
        Measured north and east positions, k = 0..N [m].

    Returns
    -------
    float
        ``sqrt((x_m(0) - x_d(0))^2 + (y_m(0) - y_d(0))^2)`` [m].
    """
    return float(_horizontal_errors(ref_ne_m, pos_ne_m)[0])


def _ned_pair(ref_ned_m: np.ndarray, pos_ned_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ref = np.asarray(ref_ned_m, dtype=float)
    pos = np.asarray(pos_ned_m, dtype=float)
    if ref.shape != pos.shape or ref.ndim != 2 or ref.shape[1] != 3:
        raise ValueError(f"expected two (N, 3) arrays, got {ref.shape} and {pos.shape}")
    return ref, pos


def epos_3d(ref_ned_m: np.ndarray, pos_ned_m: np.ndarray) -> float:
    """Average 3-D position error: eq. (10) with the down error under the root.

    Parameters
    ----------
    ref_ned_m : ndarray, shape (N, 3)
        Desired positions, k = 1..N, local NED [m].
    pos_ned_m : ndarray, shape (N, 3)
        Measured positions [m].

    Returns
    -------
    float
        ``(1/N) sum_k |p_m(k) - p_d(k)|`` (Euclidean norm over north, east, down) [m].
    """
    ref, pos = _ned_pair(ref_ned_m, pos_ned_m)
    return float(np.mean(np.linalg.norm(pos - ref, axis=1)))


def axis_rms(ref_ned_m: np.ndarray, pos_ned_m: np.ndarray) -> tuple[float, float, float]:
    """RMS position error per axis.

    Parameters
    ----------
    ref_ned_m : ndarray, shape (N, 3)
        Desired positions, k = 1..N, local NED [m].
    pos_ned_m : ndarray, shape (N, 3)
        Measured positions [m].

    Returns
    -------
    tuple of float
        ``sqrt((1/N) sum_k (p_m(k) - p_d(k))^2)`` for north, east and down [m].
    """
    ref, pos = _ned_pair(ref_ned_m, pos_ned_m)
    rms = np.sqrt(np.mean((pos - ref) ** 2, axis=0))
    return float(rms[0]), float(rms[1]), float(rms[2])


def iteration_table(
    epos_m: list[float], max_err_m: list[float], iterations: list[int] | None = None
) -> list[IterationMetrics]:
    """Rows of Table IV from the per-trial e_pos and maximum errors.

    Parameters
    ----------
    epos_m : list of float
        e_pos,j for consecutive trials j = 0, 1, ... [m].
    max_err_m : list of float
        Maximum horizontal error of the same trials [m].
    iterations : list of int, optional
        Trial indices (default ``0 .. len - 1``).

    Returns
    -------
    list of IterationMetrics
    """
    if len(epos_m) != len(max_err_m):
        raise ValueError("epos_m and max_err_m differ in length")
    iterations = list(range(len(epos_m))) if iterations is None else list(iterations)
    rows: list[IterationMetrics] = []
    for i, (e, m) in enumerate(zip(epos_m, max_err_m, strict=True)):
        delta = None if i == 0 else 100.0 * abs(e - epos_m[i - 1]) / epos_m[i - 1]
        rows.append(IterationMetrics(iterations[i], float(e), 100.0 * e / epos_m[0], delta, m))
    return rows
