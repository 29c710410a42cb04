"""One learning cycle for both horizontal axes: estimate D from a trial, compute U_(j+1).

This is the single learning step that ``gcs learn`` and ``gcs fly`` both run. It is pure:
arrays in, arrays out.

Learning coordinates: per axis, metres relative to the trajectory's start point (the first
reference sample). Before a trial the vehicle hovers there with that setpoint, so the model
starts from rest with ``u(-1) = 0``, which is what the lifted form assumes; whatever the model
gets wrong about that (its DC gain, the initial state) repeats every trial and is part of D.

Indexing (paper eq. 4): a trial's grid has rows ``k = 0..N``; ``U = u(0..N-1)`` are the
setpoints flown, ``Y = y(1..N)`` the measured positions and ``Yd = yd(1..N)`` the reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gcs.core.estimators import (
    KilcSettings,
    KilcState,
    SmootherSettings,
    kilc_init,
    kilc_update,
    rts_smoother,
)
from gcs.core.model import DiscreteModel, simulate
from gcs.core.trajectory import Box
from gcs.core.update import SetpointLimits, UpdateResult, UpdateWeights, next_input

__all__ = ["LearningInputs", "LearningStep", "learning_step", "axis_limits"]


@dataclass(frozen=True)
class LearningInputs:
    """What one learning step needs, apart from the trial data.

    Parameters
    ----------
    models : tuple of DiscreteModel
        (north, east) closed-loop models.
    algorithm : str
        ``"smoother"`` or ``"kilc"``.
    weights : UpdateWeights
        Weights of eq. (8).
    smoother : SmootherSettings
        Algorithm 1 settings.
    kilc : KilcSettings
        K-ILC settings.
    arena : Box
        Flight volume, local NED [m]; the new setpoints stay inside it.
    max_step_m : float or None
        Bound on the setpoint change per sample [m].
    max_deviation_m : float or None
        Bound on the setpoint distance from the reference [m].
    """

    models: tuple[DiscreteModel, DiscreteModel]
    algorithm: str
    weights: UpdateWeights
    smoother: SmootherSettings
    kilc: KilcSettings
    arena: Box
    max_step_m: float | None = None
    max_deviation_m: float | None = None


@dataclass(frozen=True)
class LearningStep:
    """Result of :func:`learning_step`.

    Parameters
    ----------
    setpoints_ne_m : ndarray, shape (N, 2)
        Next trial's north/east setpoints u(0..N-1), absolute local NED [m].
    d_hat_ne_m : ndarray, shape (N, 2)
        Estimated repetitive disturbance d(1..N) per axis, learning coordinates [m].
    p_ne_m2 : ndarray, shape (N, 2)
        Error variance of the estimate [m^2] (K-ILC: the filter's scalar, repeated).
    kilc_states : tuple of KilcState or None
        Updated K-ILC states (north, east) when the algorithm is K-ILC.
    updates : tuple of UpdateResult
        Solver results per axis.
    """

    setpoints_ne_m: np.ndarray
    d_hat_ne_m: np.ndarray
    p_ne_m2: np.ndarray
    kilc_states: tuple[KilcState, KilcState] | None
    updates: tuple[UpdateResult, UpdateResult]


def axis_limits(
    arena: Box,
    start_ne_m: np.ndarray,
    axis: int,
    max_step_m: float | None,
    max_deviation_m: float | None,
) -> SetpointLimits:
    """Setpoint limits of one horizontal axis in learning coordinates.

    Parameters
    ----------
    arena : Box
        Flight volume, local NED [m].
    start_ne_m : ndarray, shape (2,)
        Start point (north, east) [m], the origin of the learning coordinates.
    axis : int
        0 for north, 1 for east.
    max_step_m, max_deviation_m : float or None
        See :class:`LearningInputs`.

    Returns
    -------
    SetpointLimits
    """
    lo, hi = arena.bounds()[axis]
    return SetpointLimits(
        u_min_m=lo - start_ne_m[axis],
        u_max_m=hi - start_ne_m[axis],
        max_step_m=max_step_m,
        max_deviation_m=max_deviation_m,
    )


def learning_step(
    inputs: LearningInputs,
    ref_ne_m: np.ndarray,
    setpoints_ne_m: np.ndarray,
    pos_ne_m: np.ndarray,
    kilc_states: tuple[KilcState, KilcState] | None = None,
) -> LearningStep:
    """Estimate D from one complete trial and compute the next setpoints, both axes.

    Parameters
    ----------
    inputs : LearningInputs
        Models, algorithm and settings.
    ref_ne_m : ndarray, shape (N+1, 2)
        Reference yd(0..N), absolute north/east [m]; row 0 is the start point.
    setpoints_ne_m : ndarray, shape (N, 2)
        Setpoints flown u(0..N-1), absolute north/east [m].
    pos_ne_m : ndarray, shape (N+1, 2)
        Measured positions y(0..N) on the grid, absolute north/east [m].
    kilc_states : tuple of KilcState, optional
        K-ILC states after the previous trial; None starts from the prior (first trial).

    Returns
    -------
    LearningStep
    """
    ref = np.asarray(ref_ne_m, dtype=float)
    n = ref.shape[0] - 1
    start = ref[0]
    u = np.asarray(setpoints_ne_m, dtype=float) - start
    y = np.asarray(pos_ne_m, dtype=float)[1:] - start
    yd = ref[1:] - start
    if u.shape != (n, 2) or y.shape != (n, 2):
        raise ValueError(f"expected setpoints ({n}, 2) and positions ({n + 1}, 2)")
    u_next = np.empty((n, 2))
    d_hat = np.empty((n, 2))
    p = np.empty((n, 2))
    new_states: list[KilcState] = []
    updates: list[UpdateResult] = []
    for axis, model in enumerate(inputs.models):
        z = y[:, axis] - simulate(model, u[:, axis])
        if inputs.algorithm == "smoother":
            smoothed = rts_smoother(z, inputs.smoother)
            d_hat[:, axis], p[:, axis] = smoothed.d_hat, smoothed.p
        else:
            prior = kilc_init(n, inputs.kilc) if kilc_states is None else kilc_states[axis]
            state = kilc_update(prior, z, inputs.kilc)
            new_states.append(state)
            d_hat[:, axis], p[:, axis] = state.d_hat, state.p
        limits = axis_limits(inputs.arena, start, axis, inputs.max_step_m, inputs.max_deviation_m)
        result = next_input(model, yd[:, axis], d_hat[:, axis], u[:, axis], inputs.weights, limits)
        updates.append(result)
        u_next[:, axis] = result.u_m
    states = tuple(new_states) if new_states else None
    return LearningStep(u_next + start, d_hat, p, states, tuple(updates))  # type: ignore[arg-type]
