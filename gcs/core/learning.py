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
from gcs.core.floor import (
    IDENTICAL_TOL_M,
    Floor,
    FloorVerdict,
    floor_from_difference,
    floor_from_flights,
    floor_verdicts,
    identical_groups,
)
from gcs.core.metrics import epos
from gcs.core.model import DiscreteModel, relative_degree, simulate
from gcs.core.noise_model import (
    drift_scale,
    estimate_disturbance,
    fit_iteration_noise,
    fit_time_noise,
)
from gcs.core.refresh import RefreshResult, RefreshSettings, refresh_model
from gcs.core.robustness import RobustnessWeight, repeat_cutoff, robustness_weight
from gcs.core.safeguard import SafeguardDecision, SafeguardSettings, feasible_step, safeguard
from gcs.core.trajectory import Box
from gcs.core.update import (
    SetpointLimits,
    UpdateResult,
    UpdateWeights,
    next_input,
    reference_for_inputs,
)

__all__ = [
    "LearningInputs",
    "LearningStep",
    "learning_step",
    "axis_limits",
    "NOISE_MODELS",
    "AdaptiveSettings",
    "NoiseRecord",
    "AxisRecord",
    "LearningRecord",
    "LearningPlan",
    "plan_next_trial",
]


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


# =============================================================================================
# Learning from the whole history of complete trials: the floor, a noise model from
# the data, robustness, a safeguard and model refresh. With AdaptiveSettings() (the default:
# noise "table1", everything else off) plan_next_trial is learning_step on the newest trial,
# bit for bit.
# =============================================================================================

NOISE_MODELS = ("table1", "data")


@dataclass(frozen=True)
class AdaptiveSettings:
    """Options beyond the paper; the defaults are the paper's method with Table I.

    Parameters
    ----------
    noise : str
        ``"table1"``: the estimator of the profile's algorithm with its fixed Table I
        variances, fed with the newest trial (smoother) or every trial in turn (K-ILC).
        ``"data"``: variances estimated from the recorded trials by maximum likelihood, and an
        iteration-domain Kalman filter over every trial so far, followed (smoother) by the
        RTS smoother in time (:mod:`gcs.core.noise_model`).
    drift_offset : bool
        ``"data"`` only: the drift between trials whose input changed has a part ``q0`` that
        does not scale with the predicted output change (nonlinear, path-dependent effects);
        False lets it scale with the change alone (``q0 = 0``).
    refresh : bool
        Correct the model between trials from trials of different setpoints
        (:mod:`gcs.core.refresh`), accepted only when it explains held-out data better.
    refresh_min_snr : float
        A pair of trials is informative when its predicted output change exceeds this
        multiple of the noise of a difference of two flights.
    refresh_block_s : float
        Cross-validation block length of the refresh [s].
    robustness_cutoff_rad_s : float, "auto" or None
        Cutoff of the zero-phase robustness weight (Q-filter) in the QP [rad/s]; ``"auto"``:
        from the flights of identical setpoints in the history, where the repeatable error
        stops outweighing the non-repeatable one
        (:func:`gcs.core.robustness.repeat_cutoff`), off until such flights exist and when
        the answer lies above 0.9 Nyquist; None: off.
    robustness_order : int
        Order of the weight's difference operator (roll-off ``w^(2p)``).
    safeguard : bool
        Start the next update from the best trial, with a smaller step, when the newest trial
        is worse than it by more than the floor's scatter (:mod:`gcs.core.safeguard`).
    safeguard_k_sigma : float
        Trigger threshold in units of ``sqrt(2)`` scatters.
    safeguard_step : float
        Fraction of the update taken after a trigger, in ``(0, 1]``.
    floor_z : float
        Threshold of the "at the floor" statistic (:func:`gcs.core.floor.floor_verdicts`).
    """

    noise: str = "table1"
    drift_offset: bool = True
    refresh: bool = False
    refresh_min_snr: float = 1.0
    refresh_block_s: float = 1.0
    robustness_cutoff_rad_s: float | str | None = None
    robustness_order: int = 2
    safeguard: bool = False
    safeguard_k_sigma: float = 3.0
    safeguard_step: float = 0.5
    floor_z: float = 2.0

    def __post_init__(self) -> None:
        if self.noise not in NOISE_MODELS:
            raise ValueError(f"noise must be one of {', '.join(NOISE_MODELS)}, got {self.noise!r}")
        cutoff = self.robustness_cutoff_rad_s
        if (
            cutoff is not None
            and cutoff != "auto"
            and not (isinstance(cutoff, (int, float)) and np.isfinite(cutoff) and cutoff > 0)
        ):
            raise ValueError(f"robustness_cutoff_rad_s must be > 0, 'auto' or None, got {cutoff}")
        if int(self.robustness_order) != self.robustness_order or self.robustness_order < 1:
            raise ValueError(
                f"robustness_order must be an integer >= 1, got {self.robustness_order}"
            )
        if not (np.isfinite(self.floor_z) and self.floor_z > 0):
            raise ValueError(f"floor_z must be > 0, got {self.floor_z}")
        self.refresh_settings()  # validates the refresh fields
        self.safeguard_settings()  # validates the safeguard fields

    def refresh_settings(self) -> RefreshSettings:
        """The refresh fields as :class:`gcs.core.refresh.RefreshSettings`."""
        return RefreshSettings(min_snr=self.refresh_min_snr, block_s=self.refresh_block_s)

    def safeguard_settings(self) -> SafeguardSettings:
        """The safeguard fields as :class:`gcs.core.safeguard.SafeguardSettings`."""
        return SafeguardSettings(k_sigma=self.safeguard_k_sigma, step=self.safeguard_step)

    @property
    def is_paper(self) -> bool:
        """True when every option is off: the paper's method with the profile's variances."""
        return (
            self.noise == "table1"
            and not self.refresh
            and self.robustness_cutoff_rad_s is None
            and not self.safeguard
        )


@dataclass(frozen=True)
class NoiseRecord:
    """The noise model one axis's estimate was computed with.

    Parameters
    ----------
    method : str
        ``"table1"`` or ``"data"``.
    q0_m2, kappa, r_m2 : float
        Iteration-domain variances (``"data"``): drift per trial, drift per unit of
        predicted output change, one flight's non-repeatable variance [m^2, -, m^2]; NaN for
        ``"table1"``.
    identified : bool
        False when fewer than two residual differences were available (``r`` at its bound).
    q_time_m2, r_white_m2 : float
        Time-domain random walk and white noise variances [m^2] (``"data"``).
    r_eff_m2 : float
        White-noise variance left in the iteration estimate, given to the smoother [m^2].
    weights : tuple of float
        Weight of each trial in the estimate (``"table1"`` smoother: the newest trial only).
    """

    method: str
    q0_m2: float
    kappa: float
    r_m2: float
    identified: bool
    q_time_m2: float
    r_white_m2: float
    r_eff_m2: float
    weights: tuple[float, ...]

    def as_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__} | {
            "weights": list(self.weights)
        }


@dataclass(frozen=True)
class AxisRecord:
    """Every decision taken for one axis.

    Parameters
    ----------
    axis : str
        ``"north"`` or ``"east"``.
    noise : NoiseRecord
        Noise model and trial weights.
    refresh : RefreshResult or None
        Model refresh decision (None when refresh is off or only one trial exists).
    robustness : dict or None
        ``{"cutoff_rad_s", "lam", "order"}`` of the weight used, None when off.
    update : UpdateResult
        Solver result.
    step : float
        Fraction of the update taken from the anchor's setpoints: 1, or after a safeguard
        revert its step, raised as far as the limits need
        (:func:`gcs.core.safeguard.feasible_step`).
    """

    axis: str
    noise: NoiseRecord
    refresh: RefreshResult | None
    robustness: dict | None
    update: UpdateResult
    step: float = 1.0

    def as_dict(self) -> dict:
        """JSON-ready dictionary (without the setpoints)."""
        u = self.update
        return {
            "axis": self.axis,
            "step": self.step,
            "noise": self.noise.as_dict(),
            "refresh": None if self.refresh is None else self.refresh.as_dict(),
            "robustness": self.robustness,
            "update": {
                "status": u.status,
                "method": u.method,
                "objective": u.objective,
                "active_constraints": u.active_constraints,
            },
        }


@dataclass(frozen=True)
class LearningRecord:
    """A record of every decision of one :func:`plan_next_trial` call.

    Parameters
    ----------
    trials : int
        Number of complete trials learned from (``T``).
    epos_m : tuple of float
        e_pos (eq. 10) of every trial [m].
    floor : Floor or None
        The floor used (from flights of identical setpoints, or given).
    verdicts : tuple of FloorVerdict
        "At the floor" / "converged" per trial (empty without a floor).
    safeguard : SafeguardDecision or None
        The safeguard's decision (None when off).
    axes : tuple of AxisRecord
        North and east.
    """

    trials: int
    epos_m: tuple[float, ...]
    floor: Floor | None
    verdicts: tuple[FloorVerdict, ...]
    safeguard: SafeguardDecision | None
    axes: tuple[AxisRecord, AxisRecord]

    @property
    def converged(self) -> bool:
        """True when the newest trial's verdict says further trials cannot help."""
        return bool(self.verdicts) and self.verdicts[-1].converged

    def as_dict(self) -> dict:
        """JSON-ready dictionary of every decision (SI units)."""
        return {
            "trials": self.trials,
            "epos_m": list(self.epos_m),
            "floor": None if self.floor is None else self.floor.as_dict(),
            "verdicts": [
                {
                    "trial": v.trial,
                    "epos_m": v.epos_m,
                    "ratio": v.ratio,
                    "z": v.z,
                    "at_floor": v.at_floor,
                    "converged": v.converged,
                }
                for v in self.verdicts
            ],
            "converged": self.converged,
            "safeguard": None if self.safeguard is None else self.safeguard.as_dict(),
            "axes": [a.as_dict() for a in self.axes],
        }


@dataclass(frozen=True)
class LearningPlan:
    """Result of :func:`plan_next_trial`.

    Parameters
    ----------
    setpoints_ne_m : ndarray, shape (N, 2)
        Next trial's north/east setpoints u(0..N-1), absolute local NED [m].
    d_hat_ne_m : ndarray, shape (N, 2)
        Estimated repetitive disturbance d(1..N) per axis, learning coordinates [m].
    p_ne_m2 : ndarray, shape (N, 2)
        Error variance of the estimate [m^2].
    models : tuple of DiscreteModel
        (north, east) models after the refresh: pass them to the next call.
    kilc_states : tuple of KilcState or None
        K-ILC states after the newest trial (``noise = "table1"``, algorithm K-ILC).
    record : LearningRecord
        Every decision taken.
    """

    setpoints_ne_m: np.ndarray
    d_hat_ne_m: np.ndarray
    p_ne_m2: np.ndarray
    models: tuple[DiscreteModel, DiscreteModel]
    kilc_states: tuple[KilcState, KilcState] | None
    record: LearningRecord


def _history(
    ref_ne_m: np.ndarray, setpoints_ne_m: np.ndarray, pos_ne_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validate the history; return ref, setpoints (T, N, 2), positions (T, N+1, 2), start."""
    ref = np.asarray(ref_ne_m, dtype=float)
    sp = np.asarray(setpoints_ne_m, dtype=float)
    pos = np.asarray(pos_ne_m, dtype=float)
    if ref.ndim != 2 or ref.shape[1] != 2 or ref.shape[0] < 2:
        raise ValueError(f"ref_ne_m must have shape (N+1, 2), got {ref.shape}")
    n = ref.shape[0] - 1
    if sp.ndim != 3 or sp.shape[1:] != (n, 2) or sp.shape[0] < 1:
        raise ValueError(f"setpoints_ne_m must have shape (T, {n}, 2), got {sp.shape}")
    if pos.shape != (sp.shape[0], n + 1, 2):
        raise ValueError(f"pos_ne_m must have shape ({sp.shape[0]}, {n + 1}, 2), got {pos.shape}")
    for name, arr in (("ref_ne_m", ref), ("setpoints_ne_m", sp), ("pos_ne_m", pos)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} contains NaN or inf")
    return ref, sp, pos, ref[0]


def _floor_of(sp: np.ndarray, pos: np.ndarray, given: Floor | None) -> Floor | None:
    if given is not None:
        return given
    groups = identical_groups(sp)
    if not groups:
        return None
    group = max(groups, key=len)
    return floor_from_flights(pos[group, 1:])


def _table1_estimate(
    inputs: LearningInputs, z: np.ndarray
) -> tuple[np.ndarray, np.ndarray, NoiseRecord, KilcState | None]:
    n_trials, n = z.shape
    nan = float("nan")
    if inputs.algorithm == "smoother":
        smoothed = rts_smoother(z[-1], inputs.smoother)
        weights = (0.0,) * (n_trials - 1) + (1.0,)
        rec = NoiseRecord("table1", nan, nan, inputs.smoother.r, False, inputs.smoother.q,
                          inputs.smoother.r, inputs.smoother.r, weights)  # fmt: skip
        return smoothed.d_hat, smoothed.p, rec, None
    state = kilc_init(n, inputs.kilc)
    for j in range(n_trials):
        state = kilc_update(state, z[j], inputs.kilc)
    rec = NoiseRecord("table1", inputs.kilc.q, 0.0, inputs.kilc.r, False, nan, nan, nan,
                      (nan,) * n_trials)  # fmt: skip
    return state.d_hat, np.full(n, state.p), rec, state


def _data_estimate(
    inputs: LearningInputs,
    adaptive: AdaptiveSettings,
    model: DiscreteModel,
    u: np.ndarray,
    y: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, NoiseRecord]:
    """Data-driven estimate of one axis from residuals of every trial (u, y: (T, N))."""
    z = y - simulate(model, u.T).T
    change = simulate(model, np.diff(u, axis=0).T).T.reshape(u.shape[0] - 1, u.shape[1])
    est = estimate_disturbance(
        z, drift_scale(change), inputs.algorithm == "smoother", adaptive.drift_offset
    )
    it, tn = est.iteration, est.time
    rec = NoiseRecord(
        "data", float(it.q0_m2), float(it.kappa), float(it.r_m2), bool(it.identified),
        float(tn.q_m2), float(tn.r_m2), float(est.r_eff_m2),
        tuple(float(w) for w in est.weights),
    )  # fmt: skip
    return est.d_hat_m, est.p_m2, rec


def _refresh_axis(
    model: DiscreteModel,
    u: np.ndarray,
    y: np.ndarray,
    r_m2: float,
    adaptive: AdaptiveSettings,
    weights: UpdateWeights,
) -> RefreshResult:
    du, dy = np.diff(u, axis=0), np.diff(y, axis=0)
    moved = np.max(np.abs(du), axis=1) > IDENTICAL_TOL_M
    return refresh_model(
        model, du[moved], dy[moved], r_m2, adaptive.refresh_settings(), weights.wdu / weights.we
    )


def plan_next_trial(
    inputs: LearningInputs,
    adaptive: AdaptiveSettings,
    ref_ne_m: np.ndarray,
    setpoints_ne_m: np.ndarray,
    pos_ne_m: np.ndarray,
    models: tuple[DiscreteModel, DiscreteModel] | None = None,
    floor: Floor | None = None,
) -> LearningPlan:
    """The next setpoints from every complete trial so far, and a record of every decision.

    Parameters
    ----------
    inputs : LearningInputs
        Models, algorithm, weights, Table I settings, arena and limits (as for
        :func:`learning_step`).
    adaptive : AdaptiveSettings
        The options beyond the paper; ``AdaptiveSettings()`` is the paper's method.
    ref_ne_m : ndarray, shape (N+1, 2)
        Reference yd(0..N), absolute north/east [m]; row 0 is the start point.
    setpoints_ne_m : ndarray, shape (T, N, 2)
        Setpoints u(0..N-1) of the complete trials, oldest first, absolute [m]. Trials flown
        with identical setpoints (a repeat) measure the floor.
    pos_ne_m : ndarray, shape (T, N+1, 2)
        Measured positions y(0..N) of the same trials, absolute [m].
    models : tuple of DiscreteModel, optional
        (north, east) models in use, e.g. the ``models`` of the previous plan; default the
        profile's (``inputs.models``).
    floor : Floor, optional
        The floor, when measured elsewhere; default: from trials of identical setpoints in the
        history, if any.

    Returns
    -------
    LearningPlan
    """
    ref, sp, pos, start = _history(ref_ne_m, setpoints_ne_m, pos_ne_m)
    n_trials = sp.shape[0]
    u_all = sp - start
    y_all = pos[:, 1:] - start
    epos_all = np.array([epos(ref[1:], pos[j, 1:]) for j in range(n_trials)])
    current = tuple(models) if models is not None else tuple(inputs.models)
    the_floor = _floor_of(sp, pos, floor)
    verdicts = floor_verdicts(epos_all, the_floor, adaptive.floor_z) if the_floor else ()
    decision = None
    if adaptive.safeguard and n_trials > 1:
        scatter = _scatter(the_floor, current, u_all, y_all)
        decision = safeguard(epos_all, sp, scatter, inputs.arena, adaptive.safeguard_settings())
    anchor = n_trials - 1 if decision is None else decision.anchor_trial
    step = 1.0 if decision is None else decision.step
    axes = [
        _plan_axis(inputs, adaptive, current[a], a, ref, sp, pos, the_floor, anchor, step)
        for a in range(2)
    ]
    states = [ax.kilc_state for ax in axes if ax.kilc_state is not None]
    record = LearningRecord(
        trials=n_trials,
        epos_m=tuple(float(e) for e in epos_all),
        floor=the_floor,
        verdicts=verdicts,
        safeguard=decision,
        axes=(axes[0].record, axes[1].record),
    )
    return LearningPlan(
        setpoints_ne_m=np.column_stack([ax.u_next for ax in axes]) + start,
        d_hat_ne_m=np.column_stack([ax.d_hat for ax in axes]),
        p_ne_m2=np.column_stack([ax.p for ax in axes]),
        models=(axes[0].model, axes[1].model),
        kilc_states=(states[0], states[1]) if states else None,
        record=record,
    )


@dataclass(frozen=True)
class _AxisPlan:
    """What :func:`_plan_axis` returns for one axis (learning coordinates)."""

    u_next: np.ndarray
    d_hat: np.ndarray
    p: np.ndarray
    model: DiscreteModel
    kilc_state: KilcState | None
    record: AxisRecord


def _plan_axis(
    inputs: LearningInputs,
    adaptive: AdaptiveSettings,
    model: DiscreteModel,
    axis: int,
    ref: np.ndarray,
    sp: np.ndarray,
    pos: np.ndarray,
    the_floor: Floor | None,
    anchor: int,
    step: float,
) -> _AxisPlan:
    """Refresh, estimate and update one axis from the whole history."""
    start = ref[0]
    u, y = sp[:, :, axis] - start[axis], pos[:, 1:, axis] - start[axis]
    yd = ref[1:, axis] - start[axis]
    refresh = None
    if adaptive.refresh and u.shape[0] > 1:
        r_m2 = _noise_variance(model, u, y, the_floor, axis)
        refresh = _refresh_axis(model, u, y, r_m2, adaptive, inputs.weights)
        model = refresh.model
    state = None
    if adaptive.noise == "table1":
        # one trial at a time: the same arithmetic as learning_step, bit for bit
        z = np.array([y[j] - simulate(model, u[j]) for j in range(u.shape[0])])
        d_hat, p, noise_rec, state = _table1_estimate(inputs, z)
    else:
        d_hat, p, noise_rec = _data_estimate(inputs, adaptive, model, u, y)
    robust, robust_rec = _robustness(inputs, adaptive, model, axis, ref, sp, pos, u[0])
    limits = axis_limits(inputs.arena, start, axis, inputs.max_step_m, inputs.max_deviation_m)
    result = next_input(model, yd, d_hat, u[anchor], inputs.weights, limits, robust)
    if step < 1.0:  # after a safeguard revert: no further from the best trial than its limits allow
        yd_u = reference_for_inputs(yd, relative_degree(model))
        step = feasible_step(u[anchor], result.u_m, yd_u, limits, step)
    u_next = result.u_m if step >= 1.0 else u[anchor] + step * (result.u_m - u[anchor])
    record = AxisRecord(("north", "east")[axis], noise_rec, refresh, robust_rec, result, step)
    return _AxisPlan(u_next, d_hat, p, model, state, record)


def _robustness(
    inputs: LearningInputs,
    adaptive: AdaptiveSettings,
    model: DiscreteModel,
    axis: int,
    ref: np.ndarray,
    sp: np.ndarray,
    pos: np.ndarray,
    anchor_m: np.ndarray,
) -> tuple[RobustnessWeight | None, dict | None]:
    """The robustness weight of one axis (None when off) and its record."""
    cutoff, source = adaptive.robustness_cutoff_rad_s, "profile"
    if cutoff == "auto":
        cutoff, source = _auto_cutoff(sp, pos, ref, axis, model.dt_s), "auto"
    if cutoff is None:
        return None, None
    weight = robustness_weight(
        model, float(cutoff), adaptive.robustness_order, anchor_m, inputs.weights.we
    )
    rec = {"cutoff_rad_s": weight.cutoff_rad_s, "lam": weight.lam, "order": weight.order,
           "source": source}  # fmt: skip
    return weight, rec


def _noise_variance(
    model: DiscreteModel,
    u: np.ndarray,
    y: np.ndarray,
    the_floor: Floor | None,
    axis: int,
) -> float:
    """One flight's non-repeatable variance per sample of one axis, for the refresh's SNR."""
    if the_floor is not None:
        return float(the_floor.axis_rms_m[axis] ** 2)
    z = y - simulate(model, u.T).T
    white = float(fit_time_noise(z).r_m2)
    m = drift_scale(simulate(model, np.diff(u, axis=0).T).T)
    return float(fit_iteration_noise(z, m, white, drift_offset=False).r_m2)


def _scatter(
    the_floor: Floor | None,
    models: tuple[DiscreteModel, DiscreteModel],
    u: np.ndarray,
    y: np.ndarray,
) -> float:
    """Scatter of one trial's e_pos: the floor's, else from the newest pair, model-corrected."""
    if the_floor is not None:
        return the_floor.scatter_m
    diff = np.column_stack(
        [
            (y[-1, :, a] - y[-2, :, a]) - simulate(models[a], u[-1, :, a] - u[-2, :, a])
            for a in range(2)
        ]
    )
    return floor_from_difference(diff, "model-corrected pair").scatter_m


def _auto_cutoff(
    sp: np.ndarray, pos: np.ndarray, ref: np.ndarray, axis: int, dt_s: float
) -> float | None:
    """The data's cutoff for one axis from the largest group of identical trials, or None."""
    groups = identical_groups(sp)
    if not groups:
        return None
    group = max(groups, key=len)
    errors = ref[None, 1:, axis] - pos[group, 1:, axis]
    cutoff = repeat_cutoff(errors, dt_s)
    return cutoff if cutoff < 0.9 * np.pi / dt_s else None
