"""Safeguard of the learning: fall back to the best trial when a trial comes out worse.

A pure decision on the e_pos history. Trial ``j`` is *worse* when

    e_j - e_best > k sqrt(2) sigma,

``e_best`` the smallest e_pos of the earlier trials and ``sigma`` the scatter of one trial's
e_pos at the floor (:class:`gcs.core.floor.Floor`): the difference of two trials' e_pos
scatters by ``sqrt(2) sigma`` when nothing but the vehicle's non-repeatability separates them,
so with ``k = 2`` a trial is called worse by chance with probability 2.3 % (more when
``e_best`` is the smallest of several trials at the floor, which sits below their mean).
A trial that flew the best trial's setpoints again (a repeat measuring the floor) is never
called worse: identical setpoints differ by the vehicle's non-repeatability alone, and a fall
back to the same setpoints would only shorten the next step. Otherwise, when worse, the next
update starts from the best trial's setpoints and takes only a fraction ``step`` of the QP's
step from there:
``U_next = U_best + step (U* - U_best)``. ``U*`` satisfies the arena and every setpoint
limit of the model in use; ``U_best`` satisfied those of the model it was learned with. When a
model refresh changed the relative degree since, the deviation bound is aligned differently
and ``U_best`` may break today's bound: :func:`feasible_step` then takes the smallest step at
least ``step`` that keeps every limit (the limits are linear in the step, so the feasible
steps are an interval that contains 1, ``U*`` itself).

Where two models disagree on what the next step does (a refreshed model and the profile's),
:func:`minmax_step` takes the fraction of the step that minimises the larger of their
predicted errors: the step both models expect to help.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gcs.core.trajectory import Box
from gcs.core.update import SetpointLimits

__all__ = [
    "SafeguardSettings",
    "SafeguardDecision",
    "safeguard",
    "feasible_step",
    "minmax_step",
]


@dataclass(frozen=True)
class SafeguardSettings:
    """Thresholds of the safeguard.

    Parameters
    ----------
    k_sigma : float
        Trigger when ``e_j - e_best > k_sigma sqrt(2) sigma``.
    step : float
        Fraction of the update taken from the best trial's setpoints after a trigger, in
        ``(0, 1]``.
    """

    k_sigma: float = 3.0
    step: float = 0.5

    def __post_init__(self) -> None:
        if not (np.isfinite(self.k_sigma) and self.k_sigma >= 0):
            raise ValueError(f"k_sigma must be finite and >= 0, got {self.k_sigma}")
        if not 0 < self.step <= 1:
            raise ValueError(f"step must lie in (0, 1], got {self.step}")


@dataclass(frozen=True)
class SafeguardDecision:
    """What the next update starts from.

    Parameters
    ----------
    action : str
        ``"continue"`` (from the newest trial, full step) or ``"revert"`` (from the best
        trial, reduced step).
    anchor_trial : int
        Trial whose setpoints the update starts from.
    step : float
        Fraction of the QP's step taken.
    anchor_ne_m : ndarray, shape (N, 2)
        The anchor's north/east setpoints, absolute local NED, inside the arena [m].
    epos_m : float
        e_pos of the newest trial [m].
    best_trial : int
        The trial with the smallest e_pos so far, the newest included (the earlier one on a
        tie).
    best_epos_m : float
        Its e_pos [m].
    compared_trial : int
        The earlier trial with the smallest e_pos, which the newest is compared with (the
        newest itself when it is the only one); the anchor after a revert.
    compared_epos_m : float
        Its e_pos [m].
    threshold_m : float
        ``e_best + k sqrt(2) sigma`` [m].
    reason : str
        The decision in words.
    """

    action: str
    anchor_trial: int
    step: float
    anchor_ne_m: np.ndarray
    epos_m: float
    best_trial: int
    best_epos_m: float
    threshold_m: float
    reason: str
    compared_trial: int = 0
    compared_epos_m: float = float("nan")

    def as_dict(self) -> dict:
        """JSON-ready dictionary (without the anchor's setpoints)."""
        return {
            "action": self.action,
            "anchor_trial": self.anchor_trial,
            "step": self.step,
            "epos_m": self.epos_m,
            "best_trial": self.best_trial,
            "best_epos_m": self.best_epos_m,
            "compared_trial": self.compared_trial,
            "compared_epos_m": self.compared_epos_m,
            "threshold_m": self.threshold_m,
            "reason": self.reason,
        }


def safeguard(
    epos_m: np.ndarray,
    setpoints_ne_m: np.ndarray,
    scatter_m: float,
    arena: Box,
    settings: SafeguardSettings,
) -> SafeguardDecision:
    """Decide where the next update starts from.

    Parameters
    ----------
    epos_m : ndarray, shape (T,)
        e_pos of trials j = 0..T-1 [m] (eq. 10).
    setpoints_ne_m : ndarray, shape (T, N, 2)
        Their north/east setpoints, absolute local NED [m].
    scatter_m : float
        Scatter of one trial's e_pos at the floor [m] (``Floor.scatter_m``).
    arena : Box
        Flight volume, local NED [m].
    settings : SafeguardSettings
        Thresholds.

    Returns
    -------
    SafeguardDecision
    """
    e = np.asarray(epos_m, dtype=float)
    sp = np.asarray(setpoints_ne_m, dtype=float)
    if e.ndim != 1 or e.size == 0 or not np.all(np.isfinite(e)):
        raise ValueError(f"epos_m must be a non-empty finite 1-D array, got shape {e.shape}")
    if sp.ndim != 3 or sp.shape[0] != e.size or sp.shape[-1] != 2:
        raise ValueError(f"setpoints_ne_m must have shape ({e.size}, N, 2), got {sp.shape}")
    if not (np.isfinite(scatter_m) and scatter_m >= 0):
        raise ValueError(f"scatter_m must be finite and >= 0, got {scatter_m}")
    newest = e.size - 1
    best = int(np.argmin(e[:-1])) if e.size > 1 else newest
    threshold = float(e[best] + settings.k_sigma * np.sqrt(2.0) * scatter_m)
    above = e.size > 1 and e[newest] > threshold
    repeat = above and np.array_equal(sp[newest], sp[best])
    worse = above and not repeat
    anchor = best if worse else newest
    overall = int(np.argmin(e))
    (n_lo, n_hi), (e_lo, e_hi), _ = arena.bounds()
    anchor_ne = np.column_stack(
        [np.clip(sp[anchor, :, 0], n_lo, n_hi), np.clip(sp[anchor, :, 1], e_lo, e_hi)]
    )
    if worse:
        reason = (
            f"trial {newest} e_pos {e[newest]:.4f} m is above the best trial {best} "
            f"({e[best]:.4f} m) by more than {settings.k_sigma:g} sqrt(2) x scatter "
            f"({scatter_m:.4f} m): start from trial {best} with step {settings.step:g}"
        )
    elif repeat:
        reason = (
            f"trial {newest} e_pos {e[newest]:.4f} m is above {threshold:.4f} m, but it flew "
            f"the setpoints of trial {best} again: nothing but noise to fall back from: continue"
        )
    else:
        reason = f"trial {newest} e_pos {e[newest]:.4f} m within {threshold:.4f} m: continue"
    return SafeguardDecision(
        action="revert" if worse else "continue",
        anchor_trial=anchor,
        step=settings.step if worse else 1.0,
        anchor_ne_m=anchor_ne,
        epos_m=float(e[newest]),
        best_trial=overall,
        best_epos_m=float(e[overall]),
        threshold_m=threshold,
        reason=reason,
        compared_trial=best,
        compared_epos_m=float(e[best]),
    )


def feasible_step(
    anchor_m: np.ndarray,
    target_m: np.ndarray,
    yd_u_m: np.ndarray,
    limits: SetpointLimits,
    step: float,
    tol_m: float = 1e-9,
) -> float:
    """The smallest step ``s >= step`` for which ``anchor + s (target - anchor)`` keeps the limits.

    The limits of one axis, in learning coordinates (the start point at 0): the arena box
    ``u_min <= u(k) <= u_max``, the deviation ``|u(k) - yd_u(k)| <= max_deviation`` from the
    reference aligned with the inputs, and the step ``|u(k) - u(k-1)| <= max_step`` with
    ``u(-1) = 0``. Each is linear in ``s``, so the feasible steps form an interval; ``target``
    (the QP's solution) satisfies them, so it contains 1.

    Parameters
    ----------
    anchor_m, target_m : ndarray, shape (N,)
        The best trial's inputs and the QP's solution [m].
    yd_u_m : ndarray, shape (N,)
        The reference aligned with the inputs of the model in use [m]
        (:func:`gcs.core.update.reference_for_inputs`).
    limits : SetpointLimits
        The axis's limits.
    step : float
        The step asked for, in ``(0, 1]``.
    tol_m : float
        Slack of every bound [m] (the solver keeps them to about 1e-9 m).

    Returns
    -------
    float
        In ``[step, 1]``.
    """
    a, t, yd = (np.asarray(v, dtype=float) for v in (anchor_m, target_m, yd_u_m))
    if a.ndim != 1 or a.shape != t.shape or a.shape != yd.shape:
        raise ValueError(f"anchor, target and yd_u must be 1-D of one length: {a.shape}, "
                         f"{t.shape}, {yd.shape}")  # fmt: skip
    rows = [(a, t - a, limits.u_min_m, limits.u_max_m)]
    if limits.max_deviation_m is not None:
        dev = limits.max_deviation_m
        rows.append((a - yd, t - a, -dev, dev))
    if limits.max_step_m is not None:
        da = np.diff(np.concatenate([[0.0], a]))
        dd = np.diff(np.concatenate([[0.0], t - a]))
        rows.append((da, dd, -limits.max_step_m, limits.max_step_m))
    lowest = step
    for v, w, lo, hi in rows:
        # lo - tol <= v + s w <= hi + tol, for the rows that move with s
        moving = np.abs(w) > 0.0
        v, w = v[moving], w[moving]
        bound = np.where(w > 0, lo - tol_m - v, hi + tol_m - v) / w
        if bound.size:
            lowest = max(lowest, float(np.max(bound)))
    return min(lowest, 1.0)


def minmax_step(error0_m: np.ndarray, change_m: np.ndarray) -> float:
    """The fraction ``s`` of a step that minimises the larger of several models' predicted
    errors, ``max_m || e0_m - s g_m ||^2`` over ``s`` in ``[0, 1]``.

    Model ``m`` predicts the next trial's tracking error ``e0_m`` at the anchor's setpoints
    and ``e0_m - s g_m`` a fraction ``s`` of the way to the update's (``g_m = F_m (U* -
    U_anchor)``). Each is a convex quadratic in ``s``, so their maximum is convex and its
    minimum lies at an end of the interval, at one model's own minimum, or where two of them
    cross; every such point is tried. Among equal values the largest step wins: with one
    model, or models that agree, the whole step (``s = 1`` where each model's error falls all
    the way).

    Parameters
    ----------
    error0_m : ndarray, shape (M, N)
        Each model's predicted error at the anchor's setpoints [m].
    change_m : ndarray, shape (M, N)
        Each model's predicted output change of the whole step [m].

    Returns
    -------
    float
        ``s`` in ``[0, 1]``.
    """
    e0, g = np.asarray(error0_m, dtype=float), np.asarray(change_m, dtype=float)
    if e0.ndim != 2 or e0.shape != g.shape:
        raise ValueError(f"error0_m and change_m must be (M, N) of one shape: {e0.shape}, "
                         f"{g.shape}")  # fmt: skip
    # || e0 - s g ||^2 = c - 2 b s + a s^2 per model
    a, b, c = np.sum(g * g, axis=1), np.sum(e0 * g, axis=1), np.sum(e0 * e0, axis=1)
    points = [0.0, 1.0]
    with np.errstate(all="ignore"):  # a vanishing a or b: an infinite point, dropped below
        points += list(b / a)
        for m in range(a.size):
            for n in range(m + 1, a.size):
                # where models m and n predict the same error
                points += _roots(a[m] - a[n], b[m] - b[n], c[m] - c[n])
    candidates = np.unique(np.clip([p for p in points if np.isfinite(p)], 0.0, 1.0))
    worst = np.max(c[:, None] - 2.0 * b[:, None] * candidates + a[:, None] * candidates**2,
                   axis=0)  # fmt: skip
    # the largest step among those within rounding of the smallest worst case
    best = np.flatnonzero(worst <= np.min(worst) * (1.0 + 1e-12) + 1e-300)
    return float(candidates[best[-1]])


def _roots(a: float, b: float, c: float) -> list[float]:
    """The real roots of ``a s^2 - 2 b s + c = 0`` (linear where ``a`` vanishes against the
    others), in the form that loses no digits to cancellation."""
    scale = max(abs(a), abs(b), abs(c))
    if not scale > 0:
        return []
    a, b, c = a / scale, b / scale, c / scale
    if abs(a) < 1e-12:
        return [c / (2.0 * b)] if b != 0 else []
    disc = b * b - a * c
    if disc < 0:
        return []
    q = b + np.copysign(np.sqrt(disc), b)
    return [q / a, c / q] if q != 0 else [b / a]
