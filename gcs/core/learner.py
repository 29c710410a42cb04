"""The learner: a reference and settings, then one call per trial::

    learner = Learner(settings, reference_m)    # structure built once
    u = reference_m[:-1]                         # trial 0: the reference itself
    for j in range(5):
        y = fly(u)                               # your vehicle, simulator or log
        u = learner.step(u, y)                   # the next trial's setpoints

Problem, algorithm and workspace as in IterativeLearningControl2.jl: the problem is the
reference and the models (:class:`LearnerSettings`), the algorithm the paper's smoother-based
ILC or K-ILC with, optionally, the options of :class:`AdaptiveSettings`; the workspace, kept
inside the learner, is what does not change between trials (per axis: the QP's banded
structure and its KKT factorisation, the Markov parameters, the setpoint limits' rows) and the
state that does (K-ILC's states, the refreshed models, the history of trials, the floor).

Units and frames: metres, in any fixed frame shared by the reference, the setpoints and the
measurements (gcs uses local NED). Learning coordinates are relative to the reference's first
row, the start point where the vehicle rests before each trial (``u(-1) = y(0) = yd(0)``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gcs.core.estimators import (
    KilcState,
    kilc_init,
    kilc_update,
    rts_smoother,
    smoother_operator,
)
from gcs.core.floor import Floor
from gcs.core.learning import (
    AdaptiveSettings,
    LearnerSettings,
    LearningRecord,
    axis_limits,
    converged_with_model,
    data_estimates,
    history_decisions,
    minmax_steps,
    newest_step,
    plan_next_trial,
    refresh_axes,
    refresh_noise_of,
    robustness_of,
    step_from_anchor,
    table1_estimate_of,
)
from gcs.core.model import DiscreteModel, lifted_matrix, simulate
from gcs.core.update import InputUpdate, UpdateResult

__all__ = ["FOLD_MAX_SAMPLES", "FOLD_MIN_PLANTS", "Learner", "LearnerBatch", "LearnerStep", "Trial"]


@dataclass(frozen=True)
class Trial:
    """One complete trial the learner has seen.

    Parameters
    ----------
    u_m : ndarray, shape (N, n_axes)
        Setpoints flown u(0..N-1) [m].
    y_m : ndarray, shape (N, n_axes)
        Measured positions y(1..N) [m].
    """

    u_m: np.ndarray
    y_m: np.ndarray


@dataclass(frozen=True)
class LearnerStep:
    """What one :meth:`Learner.step` computed.

    Parameters
    ----------
    setpoints_m : ndarray, shape (N, n_axes)
        The next trial's setpoints u(0..N-1) [m], the reference's frame.
    d_hat_m : ndarray, shape (N, n_axes) or None
        Estimated repetitive disturbance d(1..N), learning coordinates [m]; None for a repeat.
    p_m2 : ndarray, shape (N, n_axes) or None
        Error variance of the estimate [m^2] (K-ILC: the filter's scalar, repeated).
    updates : tuple of UpdateResult
        Eq. (8)'s solution per axis (solver path, active limits, objective); empty for a
        repeat.
    models : tuple of DiscreteModel
        The models after this step (a refresh may have replaced one).
    kilc_states : tuple of KilcState or None
        K-ILC states after this step (algorithm K-ILC, Table I noise).
    record : LearningRecord or None
        Every decision of the options beyond the paper (``adaptive`` given, not a repeat).
    repeat_of : int or None
        0 when the next trial repeats trial 0 (the floor's flights), else None.
    """

    setpoints_m: np.ndarray
    d_hat_m: np.ndarray | None
    p_m2: np.ndarray | None
    updates: tuple[UpdateResult, ...]
    models: tuple[DiscreteModel, ...]
    kilc_states: tuple[KilcState, ...] | None
    record: LearningRecord | None
    repeat_of: int | None = None

    @property
    def methods(self) -> tuple[str, ...]:
        """Solver path per axis: ``"direct"``, ``"clarabel"`` or ``"active-set"`` (``"-"`` for a
        repeat)."""
        return tuple(u.method for u in self.updates) or ("-",) * len(self.models)

    @property
    def active_constraints(self) -> int:
        """Setpoint limits holding with equality, every axis."""
        return sum(u.active_constraints for u in self.updates)


class Learner:
    """Iterative learning of a repeated trajectory, one call per trial.

    Parameters
    ----------
    settings : LearnerSettings
        One model per axis, the algorithm (``"smoother"``: Algorithm 1; ``"kilc"``), the
        weights of eq. (8), Table I's variances, the arena and the setpoint limits.
    reference_m : ndarray, shape (N+1, n_axes)
        Reference yd(0..N) [m]; row 0 is the start point (learning coordinates' origin).
    adaptive : AdaptiveSettings, optional
        Learn from every trial with the options beyond the paper (floor, noise model from the
        data, refresh, robustness, safeguard) and record every decision; None (default): the
        paper's method on the newest trial. Needs the axes (north, east).
    repeats : int
        With ``adaptive``: trial 0 is flown ``repeats`` more times with identical setpoints
        (they measure the floor) before the first update.
    floor : Floor, optional
        With ``adaptive``: the floor when measured elsewhere (default: from trials of
        identical setpoints in the history).
    models : tuple of DiscreteModel, optional
        The models to start from (e.g. refreshed ones recorded by an earlier run); default
        ``settings.models``.
    kilc_states : tuple of KilcState, optional
        K-ILC states to start from (e.g. a resumed run's); default the prior.
    history : sequence of Trial, optional
        Trials already flown, oldest first (a resumed run's); :meth:`step` adds the next.

    Raises
    ------
    ValueError
        A shape, a NaN, or ``adaptive`` on axes other than (north, east).
    TrajectoryError, ModelError
        The reference is too short for a model.
    """

    def __init__(
        self,
        settings: LearnerSettings,
        reference_m: np.ndarray,
        adaptive: AdaptiveSettings | None = None,
        repeats: int = 0,
        floor: Floor | None = None,
        *,
        models: tuple[DiscreteModel, ...] | None = None,
        kilc_states: tuple[KilcState, ...] | None = None,
        history: tuple[Trial, ...] | list[Trial] = (),
    ) -> None:
        ref = np.asarray(reference_m, dtype=float)
        n_axes = len(settings.models)
        if ref.ndim != 2 or ref.shape[1] != n_axes or ref.shape[0] < 2:
            raise ValueError(f"reference_m must have shape (N+1, {n_axes}), got {ref.shape}")
        if not np.all(np.isfinite(ref)):
            raise ValueError("reference_m contains NaN or inf")
        if adaptive is not None and tuple(settings.axes) != (0, 1):
            raise ValueError(
                "learning with adaptive options is defined on north and east (e_pos, floor, "
                f"safeguard); got axes {tuple(settings.axes)}"
            )
        if adaptive is not None and adaptive.safeguard and settings.arena is None:
            raise ValueError("the safeguard of the adaptive options needs settings.arena")
        if int(repeats) != repeats or repeats < 0:
            raise ValueError(f"repeats must be an integer >= 0, got {repeats}")
        self.settings = settings
        self.adaptive = adaptive
        self.repeats = int(repeats) if adaptive is not None else 0
        self._floor_given = floor
        self._ref = ref
        self._start = ref[0]
        self._yd = ref[1:] - ref[0]
        self._models = tuple(models) if models is not None else tuple(settings.models)
        if len(self._models) != n_axes:
            raise ValueError(f"one model per axis: {len(self._models)} for {n_axes} axes")
        self._kilc = tuple(kilc_states) if kilc_states is not None else None
        self._history: list[Trial] = []
        for trial in history:
            self._history.append(self._trial(trial.u_m, trial.y_m))
        self._updates: list[InputUpdate | None] = [None] * n_axes
        self.last: LearnerStep | None = None
        zeros = np.zeros((1, self.n_samples))
        for axis, model in enumerate(self._models):  # the structure, once; checks the lengths
            # and the KKT factorisation, here rather than in the first step (one unconstrained
            # solve factorises it; its answer is not kept)
            self._update(axis, model).solve_unconstrained(zeros, zeros)

    # ------------------------------------------------------------------ state, read-only

    @property
    def n_samples(self) -> int:
        """Trial length N [samples]."""
        return self._ref.shape[0] - 1

    @property
    def n_axes(self) -> int:
        """Number of learned axes."""
        return self._ref.shape[1]

    @property
    def reference_m(self) -> np.ndarray:
        """Reference yd(0..N), shape (N+1, n_axes) [m] (a copy)."""
        return self._ref.copy()

    @property
    def models(self) -> tuple[DiscreteModel, ...]:
        """The models the next step starts from (refreshed ones included)."""
        return self._models

    @property
    def kilc_states(self) -> tuple[KilcState, ...] | None:
        """K-ILC states after the newest trial, or None."""
        return self._kilc

    @property
    def history(self) -> tuple[Trial, ...]:
        """Every trial seen, oldest first."""
        return tuple(self._history)

    @property
    def floor(self) -> Floor | None:
        """The floor of the newest step (given, or measured from repeats), or None."""
        if self.last is not None and self.last.record is not None:
            return self.last.record.floor
        return self._floor_given

    @property
    def decisions(self) -> LearningRecord | None:
        """Every decision of the newest step (``adaptive`` only), or None."""
        return None if self.last is None else self.last.record

    @property
    def iteration(self) -> int:
        """The paper's j of the next trial: learning updates so far (repeats are j = 0)."""
        return max(0, len(self._history) - self.repeats)

    # ------------------------------------------------------------------------- learning

    def step(self, u_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Learn from one complete trial; return the next trial's setpoints.

        Parameters
        ----------
        u_m : ndarray, shape (N, n_axes)
            Setpoints flown u(0..N-1) [m], the reference's frame.
        y_m : ndarray, shape (N, n_axes)
            Measured positions y(1..N) on the trial grid [m].

        Returns
        -------
        ndarray, shape (N, n_axes)
            The next trial's setpoints u(0..N-1) [m]; :attr:`last` has the estimate, the
            solver results and the decisions.

        Raises
        ------
        ValueError
            A shape or a NaN.
        UpdateInfeasible
            The setpoint limits admit no sequence.
        """
        trial = self._trial(u_m, y_m)
        self._history.append(trial)
        if self.adaptive is None:
            result = self._paper(trial)
        elif len(self._history) <= self.repeats:
            first = self._history[0].u_m.copy()
            result = LearnerStep(first, None, None, (), self._models, self._kilc, None, 0)
        else:
            result = self._plan()
        self._models, self._kilc = result.models, result.kilc_states
        self.last = result
        return result.setpoints_m.copy()

    def _paper(self, trial: Trial) -> LearnerStep:
        start = self._start
        updates = [self._update(a, m) for a, m in enumerate(self._models)]
        u_next, d_hat, p, states, results = newest_step(
            self.settings, updates, self._yd, trial.u_m - start, trial.y_m - start, self._kilc
        )
        return LearnerStep(u_next + start, d_hat, p, results, self._models, states, None)

    def _plan(self) -> LearnerStep:
        sp = np.array([t.u_m for t in self._history])
        y = np.array([t.y_m for t in self._history])
        plan = plan_next_trial(
            self.settings, self.adaptive or AdaptiveSettings(), self._update, self._ref, sp, y,
            self._models, self._floor_given,
        )  # fmt: skip
        updates = tuple(a.update for a in plan.record.axes)
        return LearnerStep(
            plan.u_next_m + self._start, plan.d_hat_m, plan.p_m2, updates, plan.models,
            plan.kilc_states, plan.record,
        )  # fmt: skip

    def _update(self, axis: int, model: DiscreteModel) -> InputUpdate:
        """Eq. (8) of one axis for ``model``: built once per model, then reused."""
        cached = self._updates[axis]
        if cached is not None and cached.model is model:
            return cached
        s = self.settings
        limits = axis_limits(s.arena, self._start[axis], s.axes[axis], *s.limits_of(s.axes[axis]))
        update = InputUpdate(model, self._yd[:, axis], s.weights, limits)
        if cached is not None:  # a refreshed model: its limits first guessed from the old one's
            update.start_from(cached)
        self._updates[axis] = update
        return update

    def _trial(self, u_m: np.ndarray, y_m: np.ndarray) -> Trial:
        shape = (self.n_samples, self.n_axes)
        u = np.array(u_m, dtype=float)
        y = np.array(y_m, dtype=float)
        for name, arr in (("u_m", u), ("y_m", y)):
            if arr.shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} contains NaN or inf")
        return Trial(u, y)


#: Plants from which :class:`LearnerBatch` folds the paper's step into dense matrices.
FOLD_MIN_PLANTS = 16
#: Longest trial it folds [samples]: four ``N x N`` matrices per axis (128 MB at 2 000).
FOLD_MAX_SAMPLES = 2000


@dataclass(frozen=True)
class _Fold:
    """The paper's step of one axis as dense matrices, for many plants at once (rows).

    ``z = y - u F'``; the update ``u_next = c + (yd - d_hat) M' + u L'``; with the smoother
    (``d_hat = z S' + d0 s0``) the two fold into ``u_next = c_s - y A_y + u A_u``.
    """

    yd: np.ndarray  # yd(1..N), (N,)
    f_t: np.ndarray  # F', (N, N)
    m_t: np.ndarray  # M', (N, N)
    l_t: np.ndarray  # L', (N, N)
    c: np.ndarray  # the pinned tail, (N,)
    a_y: np.ndarray | None  # (M S)', smoother only
    a_u: np.ndarray | None  # (M S F)' + L', smoother only
    c_s: np.ndarray | None  # (yd - d0 s0) M' + c, smoother only

    @classmethod
    def build(cls, update: InputUpdate, yd: np.ndarray, settings: LearnerSettings) -> _Fold:
        n = yd.size
        M, L, c = update.unconstrained_map()
        f_t = lifted_matrix(update.model, n).T.copy()
        m_t, l_t = M.T.copy(), L.T.copy()
        if settings.algorithm != "smoother":
            return cls(yd, f_t, m_t, l_t, c, None, None, None)
        S, s0 = smoother_operator(n, settings.smoother)
        a_y = S.T @ m_t
        a_u = f_t @ a_y + l_t
        c_s = (yd - settings.smoother.d0 * s0) @ m_t + c
        return cls(yd, f_t, m_t, l_t, c, a_y, a_u, c_s)

    def update(self, d_hat: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Eq. (8)'s unconstrained optimum of every row: ``d_hat``, ``u`` of shape (P, N)."""
        return (self.yd - d_hat) @ self.m_t + u @ self.l_t + self.c

    def smoothed(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The smoother and the update at once: ``y``, ``u`` of shape (P, N)."""
        return self.c_s - y @ self.a_y + u @ self.a_u


class LearnerBatch:
    """Many plants learning one reference with one set of settings: :class:`Learner` per
    plant, with what depends only on the model computed once for them all.

    The plants share the learner's model; only their data differ. The paper's method
    (``adaptive`` None) therefore runs batched: for every plant at once the residual, the
    smoother or K-ILC update and the unconstrained optimum of eq. (8), and the QP with the
    setpoint limits only for the plants whose optimum breaks a limit, each from its own last
    active set, as its own :class:`Learner` would. From :data:`FOLD_MIN_PLANTS` plants (trials
    up to :data:`FOLD_MAX_SAMPLES` samples) the smoother and the unconstrained optimum are
    folded into two dense matrices per axis, computed once (two matrix products per trial);
    fewer plants take one banded solve of the KKT system per trial.

    With ``adaptive`` (:func:`gcs.core.learning.plan_next_trial` per plant) the plants' models
    and estimators change with their own data, but most of the arithmetic still batches: the
    residuals (one compiled filter per distinct model), the noise model from the data and its
    filters (:func:`gcs.core.learning.data_estimates`), the refresh's noise variance and its
    fits (:func:`gcs.core.learning.refresh_axes`, the plants of one delay together), and the
    update of every plant still on the nominal model without a robustness weight (one banded
    solve, the QP only for the plants that break a limit). Per plant: the floor, e_pos, the
    safeguard's decision and step, the robustness weight, ``noise = "table1"``'s estimate,
    and the update of a plant whose model a refresh replaced (its own :class:`InputUpdate`).

    Every plant's setpoints equal its own :class:`Learner`'s to rounding (``batched=False``
    runs exactly those).

    Parameters
    ----------
    settings : LearnerSettings
        As :class:`Learner`.
    reference_m : ndarray, shape (N+1, n_axes)
        As :class:`Learner`.
    plants : int
        Number of plants ``P``.
    adaptive : AdaptiveSettings, optional
        As :class:`Learner`.
    repeats : int
        As :class:`Learner`.
    batched : bool
        False: a :class:`Learner` per plant (the reference).

    Raises
    ------
    ValueError
        As :class:`Learner`; ``plants < 1``.
    """

    def __init__(
        self,
        settings: LearnerSettings,
        reference_m: np.ndarray,
        plants: int,
        adaptive: AdaptiveSettings | None = None,
        repeats: int = 0,
        *,
        batched: bool = True,
    ) -> None:
        if int(plants) != plants or plants < 1:
            raise ValueError(f"plants must be an integer >= 1, got {plants}")
        template = Learner(settings, reference_m, adaptive, repeats)
        self.settings = settings
        self.plants = int(plants)
        self.repeats = template.repeats
        self._ref = template.reference_m
        self._yd = template._yd
        self.adaptive = adaptive
        self._each: list[Learner] | None = None
        self._folds: list[_Fold] | None = None
        if not batched:
            self._each = [template] + [
                Learner(settings, reference_m, adaptive, repeats) for _ in range(self.plants - 1)
            ]
        else:
            updates = [template._update(a, m) for a, m in enumerate(settings.models)]
            self._updates = [[u.fork() for u in updates] for _ in range(self.plants)]
            self._shared = updates
            self._kilc: list[KilcState] | None = None
            self._models = [tuple(settings.models)] * self.plants
            self._sp: list[np.ndarray] = []  # setpoints and positions of every trial (adaptive)
            self._y: list[np.ndarray] = []
            if adaptive is None and (
                self.plants >= FOLD_MIN_PLANTS and self._yd.shape[0] <= FOLD_MAX_SAMPLES
            ):
                self._folds = [
                    _Fold.build(u, self._yd[:, a], settings) for a, u in enumerate(updates)
                ]
        self.failed: list[str | None] = [None] * self.plants
        #: Per plant and axis: limits holding with equality after the newest step.
        self.active_constraints = np.zeros((self.plants, len(settings.models)), dtype=int)

    @property
    def learning(self) -> np.ndarray:
        """Plants still learning (their update has not failed), shape (P,) of bool."""
        return np.array([f is None for f in self.failed])

    @property
    def models(self) -> list[tuple[DiscreteModel, ...]]:
        """Each plant's models after the newest step (a refresh may have replaced some)."""
        if self._each is not None:
            return [learner.models for learner in self._each]
        return list(self._models)

    def step(self, u_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Learn from one complete trial of every plant still learning.

        Parameters
        ----------
        u_m : ndarray, shape (P, N, n_axes)
            Setpoints flown [m], the reference's frame.
        y_m : ndarray, shape (P, N, n_axes)
            Measured positions [m].

        Returns
        -------
        ndarray, shape (P, N, n_axes)
            The next setpoints; NaN for a plant that is not learning. A plant whose update
            raises ``ValueError`` (no setpoints within the limits) or gives non-finite
            setpoints stops learning: :attr:`failed` says why.
        """
        u = np.asarray(u_m, dtype=float)
        y = np.asarray(y_m, dtype=float)
        shape = (self.plants, *self._ref[1:].shape)
        for name, arr in (("u_m", u), ("y_m", y)):
            if arr.shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
        out = np.full(u.shape, np.nan)
        self.active_constraints[:] = 0
        if self._each is not None:
            for k, learner in enumerate(self._each):
                if self.failed[k] is not None:
                    continue
                try:
                    out[k] = learner.step(u[k], y[k])
                except ValueError as exc:  # no next input within the limits
                    self.failed[k] = str(exc)
                    continue
                for a, update in enumerate(learner.last.updates):
                    self.active_constraints[k, a] = update.active_constraints
        elif self.adaptive is not None:
            self._plan(u, y, out)
        else:
            self._paper(u, y, out)
        for k in np.flatnonzero(self.learning & ~np.all(np.isfinite(out), axis=(1, 2))):
            self.failed[k] = "non-finite setpoints"
            out[k] = np.nan
        return out

    def _paper(self, u_m: np.ndarray, y_m: np.ndarray, out: np.ndarray) -> None:
        """The paper's step (:func:`gcs.core.learning.newest_step`) for every plant learning."""
        s = self.settings
        self._refuse_non_finite(u_m, y_m)
        live = np.flatnonzero(self.learning)
        if live.size == 0:
            return
        every = live.size == self.plants
        start = self._ref[0]
        u = (u_m if every else u_m[live]) - start
        y = (y_m if every else y_m[live]) - start
        states = []
        for a, model in enumerate(s.models):
            fold = None if self._folds is None else self._folds[a]
            ua, ya = u[:, :, a], y[:, :, a]
            if fold is not None and fold.a_y is not None:  # the smoother, folded
                u_next = fold.smoothed(ya, ua)
            else:
                z = ya - ua @ fold.f_t if fold is not None else (ya.T - simulate(model, ua.T)).T
                d_hat, state = self._estimate(a, z, live)
                if state is not None:
                    states.append(state)
                if fold is not None:
                    u_next = fold.update(d_hat, ua)
                else:
                    u_next = self._shared[a].solve_unconstrained(d_hat, ua)[0]
            within, active = self._shared[a].check_limits(u_next)
            self.active_constraints[live[within], a] = active[within]
            out[live[within], :, a] = u_next[within]
            for i in np.flatnonzero(~within):
                k = live[i]
                if fold is not None and fold.a_y is not None:
                    d_i = rts_smoother(ya[i] - ua[i] @ fold.f_t, s.smoother).d_hat
                else:
                    d_i = d_hat[i]
                try:
                    result = self._updates[k][a].solve(d_i, ua[i])
                except ValueError as exc:  # no next input within the limits
                    self.failed[k] = str(exc)
                    continue
                out[k, :, a] = result.u_m
                self.active_constraints[k, a] = result.active_constraints
        if s.algorithm != "smoother":
            self._kilc = states
        out += start
        out[~self.learning] = np.nan

    def _refuse_non_finite(self, u_m: np.ndarray, y_m: np.ndarray) -> None:
        """Stop the plants whose trial has a NaN or inf, as :meth:`Learner.step` refuses it."""
        for name, arr in (("u_m", u_m), ("y_m", y_m)):
            bad = self.learning & ~np.all(np.isfinite(arr), axis=(1, 2))
            for k in np.flatnonzero(bad):
                self.failed[k] = f"{name} contains NaN or inf"

    def _plan(self, u_m: np.ndarray, y_m: np.ndarray, out: np.ndarray) -> None:
        """:func:`gcs.core.learning.plan_next_trial` for every plant learning, batched where
        the plants' arithmetic is shared (see the class)."""
        s, adaptive = self.settings, self.adaptive or AdaptiveSettings()
        self._refuse_non_finite(u_m, y_m)
        self._sp.append(u_m.copy())
        self._y.append(y_m.copy())
        live = np.flatnonzero(self.learning)
        if len(self._sp) <= self.repeats:  # trial 0 once more: the floor's flights
            out[live] = self._sp[0][live]
            return
        ref, start = self._ref, self._ref[0]
        sp, y = np.stack(self._sp, axis=1)[live], np.stack(self._y, axis=1)[live]  # (K, T, N, 2)
        n_trials = sp.shape[1]
        floors, anchors, steps, converged = [], [], [], []
        for i, k in enumerate(live):
            epos_all, floor, _, decision = history_decisions(
                s, adaptive, ref, sp[i], y[i], self._models[k]
            )
            converged.append(converged_with_model(epos_all))
            floors.append(floor)
            anchors.append(n_trials - 1 if decision is None else decision.anchor_trial)
            steps.append(1.0 if decision is None else decision.step)
        at_anchor = (np.arange(live.size), np.array(anchors))
        new_models = [list(self._models[k]) for k in live]
        for a in range(self.n_axes):
            u, ya = sp[..., a] - start[a], y[..., a] - start[a]  # (K, T, N)
            models = [m[a] for m in new_models]
            if adaptive.refresh and n_trials > 1:
                noises = None
                if adaptive.refresh_noise == "measured":
                    noises = [refresh_noise_of(sp[i], ya[i]) for i in range(live.size)]
                results = refresh_axes(s, adaptive, models, u, ya, floors, a, noises, converged)
                models = [r.model for r in results]
            if adaptive.noise == "table1":
                d_hat = np.array(
                    [table1_estimate_of(s, m, u[i], ya[i])[0] for i, m in enumerate(models)]
                )
            else:
                d_hat = data_estimates(s, adaptive, models, u, ya)[0]
            u_anchor = u[at_anchor]
            target = np.empty_like(u_anchor)
            solo = np.ones(live.size, dtype=bool)  # plants solved alone
            if adaptive.robustness_cutoff_rad_s is None:
                shared = np.array([m is s.models[a] for m in models], dtype=bool)
                if shared.any():
                    target[shared], within, active = self._shared[a].solve_unconstrained(
                        d_hat[shared], u_anchor[shared]
                    )
                    self.active_constraints[live[shared], a] = active
                    solo[np.flatnonzero(shared)[within]] = False
            for i in np.flatnonzero(solo):
                k = live[i]
                robust = robustness_of(s, adaptive, models[i], a, ref, sp[i], y[i], u[i, 0])[0]
                try:
                    result = self._update_of(k, a, models[i]).solve(d_hat[i], u_anchor[i], robust)
                except ValueError as exc:  # no next input within the limits
                    self.failed[k] = str(exc)
                    continue
                target[i] = result.u_m
                self.active_constraints[k, a] = result.active_constraints
            minmax = np.ones(live.size)
            ok = np.array([self.failed[k] is None for k in live], dtype=bool)
            if adaptive.refresh_minmax_step and ok.any():
                kept = [models[i] for i in np.flatnonzero(ok)]
                minmax[ok] = minmax_steps(s, adaptive, kept, a, u[ok], ya[ok], d_hat[ok],
                                          self._yd[:, a], u_anchor[ok], target[ok])  # fmt: skip
            for i, k in enumerate(live):
                if self.failed[k] is not None:
                    continue
                limits = self._shared[a].limits  # every model's, the same arena and bounds
                out[k, :, a] = step_from_anchor(
                    models[i], self._yd[:, a], limits, u_anchor[i], target[i],
                    steps[i] * minmax[i],
                )[0]  # fmt: skip
                new_models[i][a] = models[i]
        for i, k in enumerate(live):
            self._models[k] = tuple(new_models[i])
        out[live] += start
        out[~self.learning] = np.nan

    def _update_of(self, plant: int, axis: int, model: DiscreteModel) -> InputUpdate:
        """Eq. (8) of one plant's axis for ``model``, as :meth:`Learner._update` keeps it."""
        cached = self._updates[plant][axis]
        if cached.model is model:
            return cached
        update = InputUpdate(model, self._yd[:, axis], self.settings.weights, cached.limits)
        update.start_from(cached)
        self._updates[plant][axis] = update
        return update

    @property
    def n_axes(self) -> int:
        """Number of learned axes."""
        return self._ref.shape[1]

    def _estimate(
        self, axis: int, z: np.ndarray, live: np.ndarray
    ) -> tuple[np.ndarray, KilcState | None]:
        """The disturbance estimate (P, N) of the plants ``live`` from their residuals ``z``
        (P, N): Algorithm 1's smoother, or a K-ILC update and its new state (every plant's,
        the others unchanged)."""
        s = self.settings
        if s.algorithm == "smoother":
            return rts_smoother(z.T, s.smoother).d_hat.T, None
        n = z.shape[1]
        prior = kilc_init(n, s.kilc) if self._kilc is None else self._kilc[axis]
        d_all = prior.d_hat
        if d_all.ndim == 1:  # the prior, every plant alike
            d_all = np.repeat(d_all[:, None], self.plants, axis=1)
        state = kilc_update(KilcState(d_all[:, live], prior.p, prior.trials), z.T, s.kilc)
        full = d_all.copy()
        full[:, live] = state.d_hat
        return state.d_hat.T, KilcState(full, state.p, state.trials)
