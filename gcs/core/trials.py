"""Arithmetic of a run's trials: the paper's iteration of a trial, repeats, errors, deviation.

Pure functions shared by flying, learning, identification and the report.

Indexing: trials are numbered in the order they are flown (``trial-JJJ``); the paper's
iteration j counts learning updates, so with ``repeats`` flights of trial 0's setpoints after
it (they measure the floor), trial t is iteration ``max(0, t - repeats)``.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from gcs.core.metrics import axis_rms, epos, epos_3d, max_error

__all__ = [
    "iteration_of",
    "repeat_of",
    "setpoint_deviation",
    "trial_errors",
    "trial_errors_3d",
    "GridTrial",
]


class GridTrial(Protocol):
    """A trial on the learning grid (e.g. :class:`gcs.io.records.TrialRecord`)."""

    @property
    def ref_ned_m(self) -> np.ndarray:
        """Reference yd(0..N), shape (N+1, 3), local NED [m]."""

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Measured position y(0..N), shape (N+1, 3), local NED [m]."""


def iteration_of(trial: int, repeats: int) -> int:
    """The paper's iteration j of a trial: learning updates before it (a repeat is j = 0).

    Parameters
    ----------
    trial : int
        Trial number (order of flight).
    repeats : int
        Repeats of trial 0 the run flies (``learning.adaptive.repeats``).

    Returns
    -------
    int
    """
    return max(0, trial - repeats)


def repeat_of(trial: int, repeats: int) -> int | None:
    """The trial that ``trial`` repeats (0 for trials 1..repeats), or None.

    Parameters
    ----------
    trial : int
        Trial number.
    repeats : int
        Repeats of trial 0 the run flies.

    Returns
    -------
    int or None
    """
    return 0 if 1 <= trial <= repeats else None


def setpoint_deviation(sp_ned_m: np.ndarray, ref_ned_m: np.ndarray) -> tuple[float, float]:
    """RMS and largest horizontal distance of the setpoints from the reference [m].

    What learning adds to the reference, sample by sample (u(k) - yd(k), not aligned by the
    delay): it shows the setpoints growing, with noise or with a model the vehicle does not
    follow.

    Parameters
    ----------
    sp_ned_m : ndarray, shape (N, 3)
        Setpoints u(0..N-1), local NED [m].
    ref_ned_m : ndarray, shape (N+1, 3)
        Reference yd(0..N) [m].

    Returns
    -------
    tuple of float
        ``(rms_m, max_m)``.
    """
    dev = np.hypot(*(np.asarray(sp_ned_m)[:, :2] - np.asarray(ref_ned_m)[:-1, :2]).T)
    return float(np.sqrt(np.mean(dev**2))), float(np.max(dev))


def trial_errors_3d(record: GridTrial) -> tuple[float, float, float, float]:
    """The 3-D e_pos and the RMS error per axis of a trial, over k = 1..N [m].

    Parameters
    ----------
    record : GridTrial
        A complete trial: its ``ref_ned_m`` and ``pos_ned_m``, shape (N+1, 3) [m].

    Returns
    -------
    tuple of float
        ``(epos_3d, rms_north, rms_east, rms_down)`` (:func:`gcs.core.metrics.epos_3d`,
        :func:`gcs.core.metrics.axis_rms`).
    """
    ref, pos = record.ref_ned_m[1:], record.pos_ned_m[1:]
    return (epos_3d(ref, pos), *axis_rms(ref, pos))


def trial_errors(record: GridTrial) -> tuple[float, float]:
    """e_pos (eq. 10) and the maximum horizontal error of a trial, over k = 1..N [m].

    Parameters
    ----------
    record : GridTrial
        A complete trial: its ``ref_ned_m`` and ``pos_ned_m``, shape (N+1, 3) [m].

    Returns
    -------
    tuple of float
    """
    ref, pos = record.ref_ned_m[1:, :2], record.pos_ned_m[1:, :2]
    return epos(ref, pos), max_error(ref, pos)
