"""The arithmetic of a learning step: estimate D from the trials, compute U_(j+1), per axis.

:class:`gcs.core.learner.Learner` is the one way in (``gcs learn``, ``gcs fly``, the
benchmarks and a user's script all go through it); this module holds its settings, its
records and the step's arithmetic. It is pure: arrays in, arrays out.

Learning coordinates: per axis, metres relative to the trajectory's start point (the first
reference sample). Before a trial the vehicle hovers there with that setpoint, so the model
starts from rest with ``u(-1) = 0``, which is what the lifted form assumes; whatever the model
gets wrong about that (its DC gain, the initial state) repeats every trial and is part of D.

Indexing (paper eq. 4): a trial's grid has rows ``k = 0..N``; ``U = u(0..N-1)`` are the
setpoints flown, ``Y = y(1..N)`` the measured positions and ``Yd = yd(1..N)`` the reference.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace

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
    floor_flights,
    floor_from_difference,
    floor_from_flights,
    floor_verdicts,
)
from gcs.core.metrics import epos
from gcs.core.model import DiscreteModel, relative_degree, simulate
from gcs.core.noise_model import (
    drift_scale,
    estimate_disturbance,
    fit_iteration_noise,
    fit_time_noise,
)
from gcs.core.refresh import (
    ArNoise,
    RefreshResult,
    RefreshSettings,
    anchor_pairs,
    fit_ar_noise,
    model_change,
    pooled_pairs,
    prediction_loss_z,
    refresh_models,
    transfer_function,
)
from gcs.core.robustness import RobustnessWeight, repeat_cutoff, robustness_weight
from gcs.core.safeguard import (
    SafeguardDecision,
    SafeguardSettings,
    feasible_step,
    minmax_step,
    safeguard,
)
from gcs.core.trajectory import Box
from gcs.core.update import (
    InputUpdate,
    SetpointLimits,
    UpdateResult,
    UpdateWeights,
    reference_for_inputs,
)

__all__ = [
    "AXIS_NAMES",
    "LearnerSettings",
    "newest_step",
    "axis_limits",
    "NOISE_MODELS",
    "AdaptiveSettings",
    "NoiseRecord",
    "AxisRecord",
    "LearningRecord",
    "LearningPlan",
    "plan_next_trial",
    "data_estimates",
    "refresh_axes",
    "takeback_axes",
    "holdout_axes",
    "minmax_steps",
    "converged_with_model",
]


#: Names of the local NED axes, by index.
AXIS_NAMES = ("north", "east", "down")


@dataclass(frozen=True)
class LearnerSettings:
    """What learning needs apart from the reference and the trial data.

    Parameters
    ----------
    models : tuple of DiscreteModel
        One closed-loop model "setpoint -> position" per learned axis, in the order of
        ``axes``.
    algorithm : str
        ``"smoother"`` (Algorithm 1, default) or ``"kilc"``.
    weights : UpdateWeights
        Weights of eq. (8) (default We = 1, Wdu = 0.01, Wu = 0).
    smoother : SmootherSettings
        Algorithm 1 settings (default Table I).
    kilc : KilcSettings
        K-ILC settings (default Table I).
    arena : Box or None
        Flight volume, local NED [m]; the new setpoints stay inside it. None: no bounds
        (the options beyond the paper need one).
    max_step_m : float or None
        Bound on the setpoint change per sample [m].
    max_deviation_m : float or None
        Bound on the setpoint distance from the reference [m].
    axes : tuple of int
        The local NED axis of each model (0 north, 1 east, 2 down): which of the arena's
        bounds limit it. Default (0, 1): north and east.
    max_vertical_step_m, max_vertical_deviation_m : float or None
        The step and deviation bounds of the down axis (index 2) [m]; None: the horizontal
        ones (``max_step_m``, ``max_deviation_m``).
    """

    models: tuple[DiscreteModel, ...]
    algorithm: str = "smoother"
    weights: UpdateWeights = field(default_factory=UpdateWeights)
    smoother: SmootherSettings = field(default_factory=SmootherSettings)
    kilc: KilcSettings = field(default_factory=KilcSettings)
    arena: Box | None = None
    max_step_m: float | None = None
    max_deviation_m: float | None = None
    axes: tuple[int, ...] = (0, 1)
    max_vertical_step_m: float | None = None
    max_vertical_deviation_m: float | None = None

    def limits_of(self, axis: int) -> tuple[float | None, float | None]:
        """The (step, deviation) bounds of a local NED axis [m].

        Parameters
        ----------
        axis : int
            0 north, 1 east, 2 down.

        Returns
        -------
        tuple of float or None
        """
        step, deviation = self.max_step_m, self.max_deviation_m
        if axis == 2:
            if self.max_vertical_step_m is not None:
                step = self.max_vertical_step_m
            if self.max_vertical_deviation_m is not None:
                deviation = self.max_vertical_deviation_m
        return step, deviation

    def __post_init__(self) -> None:
        if self.algorithm not in ("smoother", "kilc"):
            raise ValueError(f"algorithm must be 'smoother' or 'kilc', got {self.algorithm!r}")
        if len(self.models) != len(self.axes) or not self.models:
            raise ValueError(
                f"one model per axis: {len(self.models)} models for axes {tuple(self.axes)}"
            )
        if len(set(self.axes)) != len(self.axes) or not set(self.axes) <= {0, 1, 2}:
            raise ValueError(f"axes must be distinct NED indices 0..2, got {tuple(self.axes)}")


def axis_limits(
    arena: Box | None,
    start_ne_m: np.ndarray,
    axis: int,
    max_step_m: float | None,
    max_deviation_m: float | None,
) -> SetpointLimits:
    """Setpoint limits of one horizontal axis in learning coordinates.

    Parameters
    ----------
    arena : Box or None
        Flight volume, local NED [m]; None for no bounds.
    start_ne_m : float or ndarray, shape (2,) or (3,)
        Start point of this axis [m] (a scalar), the origin of the learning coordinates; an
        array of the NED start point is indexed by ``axis``.
    axis : int
        Local NED index of the axis (0 north, 1 east, 2 down).
    max_step_m, max_deviation_m : float or None
        See :class:`LearnerSettings`.

    Returns
    -------
    SetpointLimits
    """
    lo, hi = (None, None) if arena is None else arena.bounds()[axis]
    start = start_ne_m[axis] if np.ndim(start_ne_m) else start_ne_m
    return SetpointLimits(
        u_min_m=None if lo is None else lo - start,
        u_max_m=None if hi is None else hi - start,
        max_step_m=max_step_m,
        max_deviation_m=max_deviation_m,
    )


def newest_step(
    settings: LearnerSettings,
    updates: Sequence[InputUpdate],
    yd: np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
    kilc_states: tuple[KilcState, ...] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[KilcState, ...] | None, tuple]:
    """The paper's step from the newest trial, every axis (learning coordinates).

    Parameters
    ----------
    settings : LearnerSettings
        Models, algorithm and settings.
    updates : sequence of InputUpdate
        Eq. (8) per axis, built for ``settings.models`` and ``yd``.
    yd : ndarray, shape (N, n_axes)
        Reference yd(1..N) [m].
    u : ndarray, shape (N, n_axes)
        Setpoints flown u(0..N-1) [m].
    y : ndarray, shape (N, n_axes)
        Measured positions y(1..N) [m].
    kilc_states : tuple of KilcState or None
        K-ILC states after the previous trial; None starts from the prior.

    Returns
    -------
    tuple
        ``(u_next, d_hat, p, kilc_states, update_results)``, arrays of shape (N, n_axes).
    """
    n, n_axes = u.shape
    u_next = np.empty((n, n_axes))
    d_hat = np.empty((n, n_axes))
    p = np.empty((n, n_axes))
    new_states: list[KilcState] = []
    results: list[UpdateResult] = []
    for axis, model in enumerate(settings.models):
        z = y[:, axis] - simulate(model, u[:, axis])
        if settings.algorithm == "smoother":
            smoothed = rts_smoother(z, settings.smoother)
            d_hat[:, axis], p[:, axis] = smoothed.d_hat, smoothed.p
        else:
            prior = kilc_init(n, settings.kilc) if kilc_states is None else kilc_states[axis]
            state = kilc_update(prior, z, settings.kilc)
            new_states.append(state)
            d_hat[:, axis], p[:, axis] = state.d_hat, state.p
        result = updates[axis].solve(d_hat[:, axis], u[:, axis])
        results.append(result)
        u_next[:, axis] = result.u_m
    return u_next, d_hat, p, (tuple(new_states) if new_states else None), tuple(results)


# =============================================================================================
# Learning from the whole history of complete trials: the floor, a noise model from the data,
# robustness, a safeguard and model refresh. With AdaptiveSettings() (the default: noise
# "table1", everything else off) plan_next_trial is newest_step on the newest trial, bit for
# bit.
# =============================================================================================

NOISE_MODELS = ("table1", "data")

#: What the refresh assumes of the non-repeatable error (AdaptiveSettings.refresh_noise).
REFRESH_NOISE = ("white", "measured")

#: Largest order of the refresh's autoregressive noise model [samples] (1 s at 0.05 s).
REFRESH_NOISE_MAX_ORDER = 20

#: The take-back's threshold: the one-sided 5 % point of the standard normal (a refreshed model
#: is taken back when the profile's predicted the newest trial better at that level).
TAKEBACK_Z = 1.6448536269514722


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
    refresh_max_move : float or None
        Where the learning has converged with the model in use (its newest trial better than
        trial 0), a refresh that moves the model by more than this where learning acts is
        rejected: such a move contradicts the convergence (``max_move`` of
        :class:`gcs.core.refresh.RefreshSettings`); None: no limit.
    refresh_min_gain_z : float
        How significant a candidate's held-out gain over the model in use must be for the
        refresh to accept it, in standard errors (``min_gain_z`` of
        :class:`gcs.core.refresh.RefreshSettings`): 0 (default), any gain; 1.645, a gain
        significant at the one-sided 5 % level.
    refresh_takeback : bool
        With ``refresh``: judge a refreshed model by the next trial, which it has not seen:
        the model in use and the profile's each predict the newest trial from the trials
        before it; where the profile's predicted significantly better
        (:func:`gcs.core.refresh.prediction_loss_z` above ``TAKEBACK_Z``, the errors'
        correlation taken as ``refresh_block_s``), the axis goes back to the profile's model
        and is not refreshed again in that step (:func:`refresh_axes`).
    refresh_minmax_step : bool
        With ``refresh``: while a refreshed model is in use, take of its update only the
        fraction that minimises the larger of the two models' predicted errors of the next
        trial, the refreshed model's and the profile's (:func:`minmax_steps`): the whole step
        where the profile's model expects it to help as much or more, less where it expects
        the step to overshoot. A refresh is judged on held-out blocks of the pairs it was
        fitted to, and the take-back only after a trial has been flown with it; this keeps
        each step with it within what the profile's model also foresees.
    refresh_holdout : bool
        With ``refresh``: fit the refresh to the trials before the newest, and use the
        candidate only where it predicts the newest trial, which it was not fitted to,
        significantly better than the model in use (:func:`gcs.core.refresh.
        prediction_loss_z` below ``-TAKEBACK_Z``; :func:`holdout_axes`). A refreshed model is
        then never flown before a trial has confirmed it; the cost is one trial's delay.
    refresh_pool_repeats : bool
        With ``refresh``: where consecutive flights share their setpoints (trial 0 and its
        repeats), a pair compares the mean of those flights, not the last of them, with the
        next setpoints' (:func:`gcs.core.refresh.pooled_pairs`): the first refresh after
        ``repeats: 3`` sees the noise ``1.25 r`` instead of ``2 r``.
    refresh_anchor : bool
        With ``refresh``: every pair compares a group of identical setpoints with the first
        (trial 0 and its repeats, their mean), not with the group before it
        (:func:`gcs.core.refresh.anchor_pairs`): each pair carries the whole input change
        from trial 0, large when the steps near the floor are small. Pools the repeats as
        ``refresh_pool_repeats`` does; the first pair is the same.
    refresh_noise : str
        The non-repeatable error the refresh assumes: ``"white"``, of the floor's variance;
        ``"measured"``, an autoregressive model of it fitted to the flights of identical
        setpoints in the history (:func:`gcs.core.refresh.fit_ar_noise`, order up to
        ``REFRESH_NOISE_MAX_ORDER``), with which the pairs are whitened before the fit, the
        cross-validation and the signal-to-noise gate (white until such flights exist).
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
    refresh_noise: str = "white"
    refresh_max_move: float | None = None
    refresh_min_gain_z: float = 0.0
    refresh_takeback: bool = False
    refresh_minmax_step: bool = False
    refresh_holdout: bool = False
    refresh_pool_repeats: bool = False
    refresh_anchor: bool = False
    robustness_cutoff_rad_s: float | str | None = None
    robustness_order: int = 2
    safeguard: bool = False
    safeguard_k_sigma: float = 3.0
    safeguard_step: float = 0.5
    floor_z: float = 2.0

    def __post_init__(self) -> None:
        if self.noise not in NOISE_MODELS:
            raise ValueError(f"noise must be one of {', '.join(NOISE_MODELS)}, got {self.noise!r}")
        if self.refresh_noise not in REFRESH_NOISE:
            raise ValueError(
                f"refresh_noise must be one of {', '.join(REFRESH_NOISE)}, "
                f"got {self.refresh_noise!r}"
            )
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
        return RefreshSettings(
            min_snr=self.refresh_min_snr,
            block_s=self.refresh_block_s,
            max_move=self.refresh_max_move,
            min_gain_z=self.refresh_min_gain_z,
        )

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
        (:func:`gcs.core.safeguard.feasible_step`); times ``minmax_step``.
    minmax_step : float
        With ``refresh_minmax_step``: the fraction of the update that the model in use and
        the profile's both expect to help (:func:`minmax_steps`); 1 otherwise.
    """

    axis: str
    noise: NoiseRecord
    refresh: RefreshResult | None
    robustness: dict | None
    update: UpdateResult
    step: float = 1.0
    minmax_step: float = 1.0

    def as_dict(self) -> dict:
        """JSON-ready dictionary (without the setpoints)."""
        u = self.update
        return {
            "axis": self.axis,
            "step": self.step,
            "minmax_step": self.minmax_step,
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
        One per learned axis.
    """

    trials: int
    epos_m: tuple[float, ...]
    floor: Floor | None
    verdicts: tuple[FloorVerdict, ...]
    safeguard: SafeguardDecision | None
    axes: tuple[AxisRecord, ...]

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
            "verdicts": [asdict(v) for v in self.verdicts],
            "converged": self.converged,
            "safeguard": None if self.safeguard is None else self.safeguard.as_dict(),
            "axes": [a.as_dict() for a in self.axes],
        }


@dataclass(frozen=True)
class LearningPlan:
    """Result of :func:`plan_next_trial` (learning coordinates: relative to the start point).

    Parameters
    ----------
    u_next_m : ndarray, shape (N, n_axes)
        Next trial's setpoints u(0..N-1) [m].
    d_hat_m : ndarray, shape (N, n_axes)
        Estimated repetitive disturbance d(1..N) [m].
    p_m2 : ndarray, shape (N, n_axes)
        Error variance of the estimate [m^2].
    models : tuple of DiscreteModel
        Models after the refresh: the next step's.
    kilc_states : tuple of KilcState or None
        K-ILC states after the newest trial (``noise = "table1"``, algorithm K-ILC).
    record : LearningRecord
        Every decision taken.
    """

    u_next_m: np.ndarray
    d_hat_m: np.ndarray
    p_m2: np.ndarray
    models: tuple[DiscreteModel, ...]
    kilc_states: tuple[KilcState, ...] | None
    record: LearningRecord


#: ``updates(axis, model)``: eq. (8) of one axis for one model (a learner reuses them).
UpdatesFor = Callable[[int, DiscreteModel], InputUpdate]


def _floor_of(sp: np.ndarray, y: np.ndarray, given: Floor | None) -> Floor | None:
    if given is not None:
        return given
    group = floor_flights(sp)
    return floor_from_flights(y[group]) if group else None


def _table1_estimate(
    settings: LearnerSettings, z: np.ndarray
) -> tuple[np.ndarray, np.ndarray, NoiseRecord, KilcState | None]:
    n_trials, n = z.shape
    nan = float("nan")
    if settings.algorithm == "smoother":
        smoothed = rts_smoother(z[-1], settings.smoother)
        weights = (0.0,) * (n_trials - 1) + (1.0,)
        rec = NoiseRecord("table1", nan, nan, settings.smoother.r, False, settings.smoother.q,
                          settings.smoother.r, settings.smoother.r, weights)  # fmt: skip
        return smoothed.d_hat, smoothed.p, rec, None
    state = kilc_init(n, settings.kilc)
    for j in range(n_trials):
        state = kilc_update(state, z[j], settings.kilc)
    rec = NoiseRecord("table1", settings.kilc.q, 0.0, settings.kilc.r, False, nan, nan, nan,
                      (nan,) * n_trials)  # fmt: skip
    return state.d_hat, np.full(n, state.p), rec, state


def model_outputs(models: Sequence[DiscreteModel], u: np.ndarray) -> np.ndarray:
    """``F u`` from rest of every plant with its own model: ``u`` of shape (K, T, N).

    One compiled filter (:func:`gcs.core.model.simulate`) per distinct model, every trial of
    its plants a column: column by column the arithmetic of a plant's own call.
    """
    out = np.empty(u.shape)
    for model, rows in _by_model(models):
        x = u[rows]
        out[rows] = simulate(model, x.reshape(-1, x.shape[-1]).T).T.reshape(x.shape)
    return out


def _residuals(
    models: Sequence[DiscreteModel], u: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The residuals ``y - F u`` (K, T, N) of every trial and the predicted output changes
    ``F (u_j - u_(j-1))`` (K, T-1, N), in one :func:`model_outputs` call."""
    out = model_outputs(models, np.concatenate([u, np.diff(u, axis=1)], axis=1))
    return y - out[:, : u.shape[1]], out[:, u.shape[1] :]


def _by_model(models: Sequence[DiscreteModel]) -> list[tuple[DiscreteModel, np.ndarray]]:
    """The plants of each distinct model (the same object), in order of first appearance."""
    groups: dict[int, tuple[DiscreteModel, list[int]]] = {}
    for k, model in enumerate(models):
        groups.setdefault(id(model), (model, []))[1].append(k)
    return [(model, np.array(rows)) for model, rows in groups.values()]


def data_estimates(
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    models: Sequence[DiscreteModel],
    u: np.ndarray,
    y: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, list[NoiseRecord]]:
    """Data-driven estimate of one axis of K plants from the residuals of every trial.

    Parameters
    ----------
    settings, adaptive
        As :func:`plan_next_trial`.
    models : sequence of DiscreteModel
        Each plant's model of the axis.
    u, y : ndarray, shape (K, T, N)
        Setpoints and positions of every trial, learning coordinates [m].

    Returns
    -------
    tuple
        ``(d_hat, p, records)``: arrays of shape (K, N), one :class:`NoiseRecord` per plant.
    """
    z, change = _residuals(models, u, y)
    est = estimate_disturbance(
        z, drift_scale(change), settings.algorithm == "smoother", adaptive.drift_offset
    )
    it, tn = est.iteration, est.time
    records = [
        NoiseRecord(
            "data",
            float(it.q0_m2[k]),
            float(it.kappa[k]),
            float(it.r_m2[k]),
            bool(it.identified[k]),
            float(tn.q_m2[k]),
            float(tn.r_m2[k]),
            float(est.r_eff_m2[k]),
            tuple(float(w) for w in est.weights[k]),
        )  # fmt: skip
        for k in range(u.shape[0])
    ]
    return est.d_hat_m, est.p_m2, records


def refresh_axes(
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    models: Sequence[DiscreteModel],
    u: np.ndarray,
    y: np.ndarray,
    floors: Sequence[Floor | None],
    axis: int,
    noises: Sequence[ArNoise | None] | None = None,
    converged: Sequence[bool] | None = None,
) -> list[RefreshResult]:
    """The refresh of one axis of K plants from their pairs of trials of different setpoints.

    With ``adaptive.refresh_takeback``, the models in use are judged first
    (:func:`takeback_axes`): a plant whose model is taken back gets the profile's model, and
    no refresh in this step; the others are refreshed, their record carrying the judgement.

    Parameters
    ----------
    settings, adaptive
        As :func:`plan_next_trial`.
    models : sequence of DiscreteModel
        Each plant's model of the axis.
    u, y : ndarray, shape (K, T, N)
        Setpoints and positions of every trial, learning coordinates [m].
    floors : sequence of Floor or None
        Each plant's floor (its noise variance; None: from the residuals).
    axis : int
        Index of the axis in ``settings.axes``.
    noises : sequence of ArNoise or None, optional
        Each plant's measured non-repeatable error (``refresh_noise = "measured"``).
    converged : sequence of bool, optional
        Whether each plant's learning has converged with its model
        (:func:`converged_with_model`; ``refresh_max_move`` applies there).

    Returns
    -------
    list of RefreshResult
        One per plant (:func:`gcs.core.refresh.refresh_models`, or the take-back).
    """
    n_plants = len(models)
    out: list[RefreshResult | None] = [None] * n_plants
    z = np.full(n_plants, np.nan)
    if adaptive.refresh_takeback:
        z, back = takeback_axes(settings, adaptive, models, u, y, axis)
        out = list(back)
    todo = np.array([k for k in range(n_plants) if out[k] is None], dtype=int)
    if todo.size == 0:
        return out  # type: ignore[return-value]
    fit = u.shape[1] - 1 if adaptive.refresh_holdout else u.shape[1]  # the trials fitted to
    du, dy = np.diff(u[:, :fit], axis=1), np.diff(y[:, :fit], axis=1)
    if fit > 1:
        r_m2 = _noise_variances(models, u[:, :fit], y[:, :fit], floors, axis)
    else:  # one trial: no pair, so refresh_models never reads the variance
        r_m2 = np.ones(n_plants)
    moved = np.max(np.abs(du), axis=2) > IDENTICAL_TOL_M  # (K, T-1): repeats left out
    if adaptive.refresh_anchor:
        du, dy = anchor_pairs(u[:, :fit], y[:, :fit], moved)
    elif adaptive.refresh_pool_repeats:
        du, dy = pooled_pairs(u[:, :fit], y[:, :fit], moved)
    for pattern in np.unique(moved[todo], axis=0):  # the plants whose pairs moved alike
        rows = todo[np.all(moved[todo] == pattern, axis=1)]
        results = refresh_models(
            [models[k] for k in rows], du[rows][:, pattern], dy[rows][:, pattern], r_m2[rows],
            adaptive.refresh_settings(), settings.weights.wdu / settings.weights.we,
            None if noises is None else [noises[k] for k in rows],
            None if converged is None else [converged[k] for k in rows],
        )  # fmt: skip
        for k, result in zip(rows, results, strict=True):
            out[k] = result if np.isnan(z[k]) else replace(result, takeback_z=float(z[k]))
    if adaptive.refresh_holdout:
        out = holdout_axes(settings, adaptive, models, out, u, y)  # type: ignore[arg-type]
    return out  # type: ignore[return-value]


def holdout_axes(
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    models: Sequence[DiscreteModel],
    results: Sequence[RefreshResult],
    u: np.ndarray,
    y: np.ndarray,
) -> list[RefreshResult]:
    """Judge each plant's refresh, fitted to the trials before the newest, by the newest.

    The candidate and the model in use each predict the newest trial as the learning step
    does (:func:`prediction_errors`); the candidate is used only where it predicted
    significantly better (:func:`gcs.core.refresh.prediction_loss_z` of its errors against
    the model in use's below ``-TAKEBACK_Z``). A candidate not used is recorded as not
    accepted, its statistic in ``holdout_z``.

    Parameters
    ----------
    settings, adaptive
        As :func:`plan_next_trial`.
    models : sequence of DiscreteModel
        Each plant's model of the axis in use.
    results : sequence of RefreshResult
        Each plant's refresh from the trials before the newest (a take-back stands as it is).
    u, y : ndarray, shape (K, T, N)
        Setpoints and positions of every trial, learning coordinates [m].

    Returns
    -------
    list of RefreshResult
        One per plant: the refresh adopted, or not accepted with the reason.
    """
    out = list(results)
    rows = [
        k for k, r in enumerate(results)
        if r.accepted and not r.reason.startswith("taken back")
    ]  # fmt: skip
    if not rows:
        return out
    errors = prediction_errors(
        settings, adaptive, [[results[k].model for k in rows], [models[k] for k in rows]],
        u[rows], y[rows],
    )  # fmt: skip
    lag = int(round(adaptive.refresh_block_s / models[rows[0]].dt_s))
    stat = prediction_loss_z(errors[0], errors[1], lag)
    newest = u.shape[1] - 1
    for i, k in enumerate(rows):
        r, zk = results[k], float(stat[i])
        if zk < -TAKEBACK_Z:
            why = (
                f"{r.reason}; adopted: predicted trial {newest}, which it was not fitted to, "
                f"better than the model in use (z = {zk:.2f} < {-TAKEBACK_Z:.2f})"
            )
            out[k] = replace(r, reason=why, holdout_z=zk)
        else:
            why = (
                f"fitted to trials 0-{newest - 1}, moved {100 * r.moved:.0f} %, not adopted: "
                f"predicted trial {newest} no better than the model in use "
                f"(z = {zk:.2f} >= {-TAKEBACK_Z:.2f})"
            )
            out[k] = replace(r, model=models[k], accepted=False, reason=why, moved=0.0,
                             holdout_z=zk)  # fmt: skip
    return out


def prediction_errors(
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    model_sets: Sequence[Sequence[DiscreteModel]],
    u: np.ndarray,
    y: np.ndarray,
) -> list[np.ndarray]:
    """Each set of models' error predicting the newest trial of one axis of K plants, as the
    learning step before it did: the estimate ``d_hat`` from the trials before it with that
    model, then ``F u_newest + d_hat - y_newest``.

    Parameters
    ----------
    settings, adaptive
        As :func:`plan_next_trial`.
    model_sets : sequence of sequences of DiscreteModel
        Sets of K models, one per plant.
    u, y : ndarray, shape (K, T, N)
        Setpoints and positions of every trial, learning coordinates [m]; T >= 2.

    Returns
    -------
    list of ndarray, shape (K, N)
        One per set [m].
    """
    errors = []
    for candidates in model_sets:
        d_hat = _estimates(settings, adaptive, candidates, u[:, :-1], y[:, :-1])
        newest = model_outputs(candidates, u[:, -1:])[:, 0]
        errors.append(newest + d_hat - y[:, -1])
    return errors


def takeback_axes(
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    models: Sequence[DiscreteModel],
    u: np.ndarray,
    y: np.ndarray,
    axis: int,
) -> tuple[np.ndarray, list[RefreshResult | None]]:
    """Judge each plant's refreshed model of one axis by the newest trial, which it never saw.

    The refresh accepts a candidate that explains held-out blocks of the pairs it was fitted
    to; the newest trial was flown after it and is new data. The model in use and the
    profile's (``settings.models``) each predict it as the learning step does: the estimate
    ``d_hat`` from the trials before it with that model (:func:`data_estimates`, or Table I's
    estimate), then ``F u_newest + d_hat``. Where the profile's predicted significantly better
    (:func:`gcs.core.refresh.prediction_loss_z` above :data:`TAKEBACK_Z`, the errors'
    correlation taken as ``adaptive.refresh_block_s``, the time the refresh's blocks assume
    independent), the refresh is taken back: the profile's model again, recorded as a
    refresh to it.

    Parameters
    ----------
    settings, adaptive
        As :func:`plan_next_trial`.
    models : sequence of DiscreteModel
        Each plant's model of the axis in use (the one that planned the newest trial).
    u, y : ndarray, shape (K, T, N)
        Setpoints and positions of every trial, learning coordinates [m].
    axis : int
        Index of the axis in ``settings.axes``.

    Returns
    -------
    z : ndarray, shape (K,)
        The statistic per plant; NaN where not judged (the model in use is the profile's, or
        fewer than two trials).
    results : list of RefreshResult or None
        Per plant: the take-back (``accepted``, the profile's model, how far it moved from
        the model in use, the two models' mean square prediction errors as the current's and
        the candidate's held-out losses), or None where the model in use stays.
    """
    prior = settings.models[axis]
    n_plants, n_trials = u.shape[0], u.shape[1]
    z = np.full(n_plants, np.nan)
    out: list[RefreshResult | None] = [None] * n_plants
    rows = [k for k in range(n_plants) if not _same_model(models[k], prior)]
    if n_trials < 2 or not rows:
        return z, out
    in_use = [models[k] for k in rows]
    errors = prediction_errors(settings, adaptive, [in_use, [prior] * len(rows)], u[rows],
                               y[rows])  # fmt: skip
    lag = int(round(adaptive.refresh_block_s / prior.dt_s))
    stat = prediction_loss_z(errors[0], errors[1], lag)
    band = settings.weights.wdu / settings.weights.we
    b1, a1 = transfer_function(prior)
    for i, k in enumerate(rows):
        z[k] = stat[i]
        if not stat[i] > TAKEBACK_Z:
            continue
        b0, a0 = transfer_function(models[k])
        moved = float(
            model_change(b0[None], a0[None], b1[None], a1[None], models[k].delay_samples,
                         prior.dt_s, band, prior.delay_samples)[0]
        )  # fmt: skip
        out[k] = RefreshResult(
            model=prior,
            accepted=True,
            reason=(
                f"taken back: the profile's model predicted trial {n_trials - 1} better "
                f"(z = {stat[i]:.2f} > {TAKEBACK_Z:.2f})"
            ),
            moved=moved,
            candidate_moved=moved,
            cv_loss_current_m2=float(np.mean(errors[0][i] ** 2)),
            cv_loss_candidate_m2=float(np.mean(errors[1][i] ** 2)),
            pairs=0,
            snr=float("nan"),
            takeback_z=float(stat[i]),
        )
    return z, out


def _same_model(a: DiscreteModel, b: DiscreteModel) -> bool:
    """The same model: one object, or equal matrices, sample time and delay."""
    return a is b or (
        a.dt_s == b.dt_s
        and a.delay_samples == b.delay_samples
        and all(np.array_equal(getattr(a, m), getattr(b, m)) for m in "ABC")
    )


def _estimates(
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    models: Sequence[DiscreteModel],
    u: np.ndarray,
    y: np.ndarray,
) -> np.ndarray:
    """The estimate ``d_hat`` (K, N) of one axis of K plants as the learning step makes it."""
    if adaptive.noise == "table1":
        return np.array(
            [table1_estimate_of(settings, m, u[k], y[k])[0] for k, m in enumerate(models)]
        )
    return data_estimates(settings, adaptive, models, u, y)[0]


def minmax_steps(
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    models: Sequence[DiscreteModel],
    axis: int,
    u: np.ndarray,
    y: np.ndarray,
    d_hat: np.ndarray,
    yd: np.ndarray,
    u_anchor: np.ndarray,
    target: np.ndarray,
) -> np.ndarray:
    """How much of each plant's update to take where its model of one axis is not the
    profile's (``refresh_minmax_step``).

    The model in use and the profile's (``settings.models``) each predict the next trial's
    error as the learning step does, from its own estimate ``d_hat`` of the trials so far:
    ``yd - F (U_anchor + s (U* - U_anchor)) - d_hat``. The step ``s`` in ``[0, 1]`` minimises
    the larger of the two (:func:`gcs.core.safeguard.minmax_step`).

    Parameters
    ----------
    settings, adaptive
        As :func:`plan_next_trial`.
    models : sequence of DiscreteModel
        Each plant's model of the axis in use (after this step's refresh).
    axis : int
        Index of the axis in ``settings.axes``.
    u, y : ndarray, shape (K, T, N)
        Setpoints and positions of every trial, learning coordinates [m].
    d_hat : ndarray, shape (K, N)
        Each plant's estimate with the model in use [m].
    yd : ndarray, shape (N,)
        The reference yd(1..N), learning coordinates [m].
    u_anchor, target : ndarray, shape (K, N)
        The anchor's setpoints and eq. (8)'s [m].

    Returns
    -------
    ndarray, shape (K,)
        The fraction per plant; 1 where the model in use is the profile's.
    """
    prior = settings.models[axis]
    out = np.ones(len(models))
    rows = [k for k in range(len(models)) if not _same_model(models[k], prior)]
    if not rows:
        return out
    moves = np.stack([u_anchor[rows], target[rows] - u_anchor[rows]], axis=1)  # (R, 2, N)
    priors = [prior] * len(rows)
    d_prior = _estimates(settings, adaptive, priors, u[rows], y[rows])
    # per model (in use, profile's): the response to the anchor and to the whole step
    f = np.stack([model_outputs([models[k] for k in rows], moves), model_outputs(priors, moves)])
    error0 = yd - f[:, :, 0] - np.stack([d_hat[rows], d_prior])  # (2, R, N)
    for i, k in enumerate(rows):
        out[k] = minmax_step(error0[:, i], f[:, i, 1])
    return out


def converged_with_model(epos_m: np.ndarray) -> bool:
    """Whether learning has converged with the model in use: its newest trial came out better
    than trial 0. Where it has, the vehicle is within the model's convergence region, and
    ``refresh_max_move`` applies.

    Parameters
    ----------
    epos_m : ndarray, shape (T,)
        e_pos of every trial so far, oldest first [m].

    Returns
    -------
    bool
        True when there are two trials or more and the newest is better than trial 0.
    """
    return bool(epos_m.size > 1 and epos_m[-1] < epos_m[0])


def refresh_noise_of(sp: np.ndarray, y: np.ndarray) -> ArNoise | None:
    """The non-repeatable error of one axis from the flights of identical setpoints in the
    history (``sp``: (T, N, 2) setpoints, ``y``: (T, N) that axis's positions), or None."""
    group = floor_flights(sp)
    if not group:
        return None
    k = len(group)
    delta = np.sqrt(k / (k - 1)) * (y[group] - y[group].mean(axis=0))
    # two flights give one series (the other is its negative)
    return fit_ar_noise(delta[:1] if k == 2 else delta, REFRESH_NOISE_MAX_ORDER)


def plan_next_trial(
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    updates: UpdatesFor,
    ref_m: np.ndarray,
    sp_m: np.ndarray,
    y_m: np.ndarray,
    models: tuple[DiscreteModel, ...],
    floor: Floor | None = None,
) -> LearningPlan:
    """The next setpoints from every complete trial so far, and a record of every decision.

    Horizontal only: e_pos (eq. 10), the floor and the safeguard are defined on north and
    east, so ``settings.axes`` must be (0, 1).

    Parameters
    ----------
    settings : LearnerSettings
        Models, algorithm, weights, Table I settings, arena and limits.
    adaptive : AdaptiveSettings
        The options beyond the paper; ``AdaptiveSettings()`` is the paper's method.
    updates : callable
        ``updates(axis, model)`` gives eq. (8) of that axis for that model.
    ref_m : ndarray, shape (N+1, 2)
        Reference yd(0..N), absolute [m]; row 0 is the start point.
    sp_m : ndarray, shape (T, N, 2)
        Setpoints u(0..N-1) of the complete trials, oldest first, absolute [m]. Trials flown
        with identical setpoints (a repeat) measure the floor.
    y_m : ndarray, shape (T, N, 2)
        Measured positions y(1..N) of the same trials, absolute [m].
    models : tuple of DiscreteModel
        Models in use (the previous plan's).
    floor : Floor, optional
        The floor, when measured elsewhere; default: from trials of identical setpoints in the
        history, if any.

    Returns
    -------
    LearningPlan
    """
    ref, sp, y = ref_m, sp_m, y_m
    epos_all, the_floor, verdicts, decision = history_decisions(
        settings, adaptive, ref, sp, y, models, floor
    )
    anchor = sp.shape[0] - 1 if decision is None else decision.anchor_trial
    step = 1.0 if decision is None else decision.step
    converged = converged_with_model(epos_all)
    common = (settings, adaptive, updates)
    axes = [
        _plan_axis(*common, models[a], a, ref, sp, y, the_floor, anchor, step, converged)
        for a in range(len(models))
    ]
    states = [ax.kilc_state for ax in axes if ax.kilc_state is not None]
    record = LearningRecord(
        trials=sp.shape[0],
        epos_m=tuple(float(e) for e in epos_all),
        floor=the_floor,
        verdicts=verdicts,
        safeguard=decision,
        axes=tuple(ax.record for ax in axes),
    )
    return LearningPlan(
        u_next_m=np.column_stack([ax.u_next for ax in axes]),
        d_hat_m=np.column_stack([ax.d_hat for ax in axes]),
        p_m2=np.column_stack([ax.p for ax in axes]),
        models=tuple(ax.model for ax in axes),
        kilc_states=tuple(states) if states else None,
        record=record,
    )


def history_decisions(
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    ref_m: np.ndarray,
    sp_m: np.ndarray,
    y_m: np.ndarray,
    models: tuple[DiscreteModel, ...],
    floor: Floor | None = None,
) -> tuple[np.ndarray, Floor | None, tuple[FloorVerdict, ...], SafeguardDecision | None]:
    """What :func:`plan_next_trial` decides from one plant's whole history before any axis:
    e_pos of every trial, the floor, the verdicts and the safeguard's decision (None when
    off or after one trial). Arguments as :func:`plan_next_trial`.

    Returns
    -------
    tuple
        ``(epos_m, floor, verdicts, safeguard)``.
    """
    ref, sp, y = ref_m, sp_m, y_m
    start = ref[0]
    n_trials = sp.shape[0]
    epos_all = np.array([epos(ref[1:], y[j]) for j in range(n_trials)])
    the_floor = _floor_of(sp, y, floor)
    verdicts = floor_verdicts(epos_all, the_floor, adaptive.floor_z, sp) if the_floor else ()
    decision = None
    if adaptive.safeguard and n_trials > 1:
        scatter = _scatter(the_floor, models, sp - start, y - start)
        decision = safeguard(epos_all, sp, scatter, settings.arena, adaptive.safeguard_settings())
    return epos_all, the_floor, verdicts, decision


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
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    updates: UpdatesFor,
    model: DiscreteModel,
    axis: int,
    ref: np.ndarray,
    sp: np.ndarray,
    y_abs: np.ndarray,
    the_floor: Floor | None,
    anchor: int,
    step: float,
    converged: bool = False,
) -> _AxisPlan:
    """Refresh, estimate and update one axis from the whole history."""
    start = ref[0]
    u, y = sp[:, :, axis] - start[axis], y_abs[:, :, axis] - start[axis]
    yd = ref[1:, axis] - start[axis]
    refresh = None
    if adaptive.refresh and u.shape[0] > 1:
        noise = refresh_noise_of(sp, y) if adaptive.refresh_noise == "measured" else None
        refresh = refresh_axes(settings, adaptive, [model], u[None], y[None], [the_floor], axis,
                               [noise], [converged])[0]  # fmt: skip
        model = refresh.model
    state = None
    if adaptive.noise == "table1":
        d_hat, p, noise_rec, state = table1_estimate_of(settings, model, u, y)
    else:
        d_hat, p, records = data_estimates(settings, adaptive, [model], u[None], y[None])
        d_hat, p, noise_rec = d_hat[0], p[0], records[0]
    robust, robust_rec = robustness_of(settings, adaptive, model, axis, ref, sp, y_abs, u[0])
    update = updates(axis, model)
    result = update.solve(d_hat, u[anchor], robust)
    minmax = 1.0
    if adaptive.refresh_minmax_step:
        one = (u[None], y[None], d_hat[None], yd, u[anchor][None], result.u_m[None])
        minmax = float(minmax_steps(settings, adaptive, [model], axis, *one)[0])
    u_next, step = step_from_anchor(model, yd, update.limits, u[anchor], result.u_m, step * minmax)
    name = AXIS_NAMES[settings.axes[axis]]
    record = AxisRecord(name, noise_rec, refresh, robust_rec, result, step, minmax)
    return _AxisPlan(u_next, d_hat, p, model, state, record)


def step_from_anchor(
    model: DiscreteModel,
    yd: np.ndarray,
    limits: SetpointLimits | None,
    anchor: np.ndarray,
    target: np.ndarray,
    step: float,
) -> tuple[np.ndarray, float]:
    """The next setpoints of one axis, ``step`` of the way from the anchor's to eq. (8)'s
    ``target`` (all of it when ``step`` is 1); after a safeguard revert no further from the
    best trial than its limits allow (:func:`gcs.core.safeguard.feasible_step`).

    Returns
    -------
    tuple
        ``(u_next, step)``: setpoints (N,) and the step taken.
    """
    if step >= 1.0:
        return target, 1.0
    yd_u = reference_for_inputs(yd, relative_degree(model))
    step = feasible_step(anchor, target, yd_u, limits, step)
    return (target if step >= 1.0 else anchor + step * (target - anchor)), step


def table1_estimate_of(
    settings: LearnerSettings, model: DiscreteModel, u: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray, NoiseRecord, KilcState | None]:
    """Table I's estimate of one axis from its trials ``u``, ``y`` (T, N)."""
    # one trial at a time: the same arithmetic as newest_step, bit for bit
    z = np.array([y[j] - simulate(model, u[j]) for j in range(u.shape[0])])
    return _table1_estimate(settings, z)


def robustness_of(
    settings: LearnerSettings,
    adaptive: AdaptiveSettings,
    model: DiscreteModel,
    axis: int,
    ref: np.ndarray,
    sp: np.ndarray,
    y: np.ndarray,
    anchor_m: np.ndarray,
) -> tuple[RobustnessWeight | None, dict | None]:
    """The robustness weight of one axis (None when off) and its record."""
    cutoff, source = adaptive.robustness_cutoff_rad_s, "profile"
    if cutoff == "auto":
        cutoff, source = _auto_cutoff(sp, y, ref, axis, model.dt_s), "auto"
    if cutoff is None:
        return None, None
    weight = robustness_weight(
        model, float(cutoff), adaptive.robustness_order, anchor_m, settings.weights.we
    )
    rec = {"cutoff_rad_s": weight.cutoff_rad_s, "lam": weight.lam, "order": weight.order,
           "source": source}  # fmt: skip
    return weight, rec


def _noise_variances(
    models: Sequence[DiscreteModel],
    u: np.ndarray,
    y: np.ndarray,
    floors: Sequence[Floor | None],
    axis: int,
) -> np.ndarray:
    """One flight's non-repeatable variance per sample of one axis of K plants, for the
    refresh's SNR: the floor's, else fitted to the residuals (u, y: (K, T, N))."""
    r_m2 = np.array([np.nan if f is None else f.axis_rms_m[axis] ** 2 for f in floors])
    rest = np.flatnonzero([f is None for f in floors])
    if rest.size:
        z, change = _residuals([models[k] for k in rest], u[rest], y[rest])
        white = fit_time_noise(z).r_m2
        m = drift_scale(change)
        r_m2[rest] = fit_iteration_noise(z, m, white, drift_offset=False).r_m2
    return r_m2


def _scatter(
    the_floor: Floor | None,
    models: tuple[DiscreteModel, ...],
    u: np.ndarray,
    y: np.ndarray,
) -> float:
    """Scatter of one trial's e_pos: the floor's, else from the newest pair, model-corrected."""
    if the_floor is not None:
        return the_floor.scatter_m
    diff = np.column_stack(
        [
            (y[-1, :, a] - y[-2, :, a]) - simulate(models[a], u[-1, :, a] - u[-2, :, a])
            for a in range(len(models))
        ]
    )
    return floor_from_difference(diff, "model-corrected pair").scatter_m


def _auto_cutoff(
    sp: np.ndarray, y: np.ndarray, ref: np.ndarray, axis: int, dt_s: float
) -> float | None:
    """The data's cutoff for one axis from the flights of the floor, or None."""
    group = floor_flights(sp)
    if not group:
        return None
    errors = ref[None, 1:, axis] - y[group, :, axis]
    cutoff = repeat_cutoff(errors, dt_s)
    return cutoff if cutoff < 0.9 * np.pi / dt_s else None
