"""Batched Monte Carlo study of the paper's Sec. IV (Tables II and III).

Every run of a level learns through one :class:`gcs.core.learner.LearnerBatch`, the engine of
``gcs fly``, ``gcs learn`` and ``gcs study``: the learning always uses the nominal model, so
the smoother of Algorithm 1 and the unconstrained minimiser of eq. (8) are fixed linear
operators, folded once into two dense matrices (``U_(j+1) = c - Y_j A_y + U_j A_u`` for the
smoother; K-ILC's scalar gains and ``M (Y_d - D_hat_j) + L U_j``). The only plant-dependent
step is the true plant's response ``F_p U``, a causal convolution with the plant's Markov
parameters, done here with a zero-padded FFT. One iteration of the whole batch
(``plants x repeats`` trials) therefore costs a few ``(M, N) @ (N, N)`` products and one
batched FFT: ``O(N^2)`` per trial, no Python loop over plants, repeats or samples.

Conventions (as in :mod:`gcs.core.model`): ``Y = [y(1) .. y(N)] = F U + D``,
``U = [u(0) .. u(N-1)]``, trial ``j = 0`` flies ``U_0`` before any learning, trial ``j >= 1``
flies the input computed from the data of trial ``j - 1``. The readings of the details the
paper leaves open are explicit fields of :class:`MontecarloSettings`; ``docs/montecarlo.md``
gives the evidence for each default.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import scipy.fft
import scipy.linalg

from gcs.core.estimators import KilcSettings, SmootherSettings
from gcs.core.learner import LearnerBatch
from gcs.core.learning import AdaptiveSettings, LearnerSettings
from gcs.core.model import DiscreteModel, from_transfer_function
from gcs.core.study import diverged, run_trials
from gcs.core.update import UpdateWeights

__all__ = [
    "ALGORITHMS",
    "PAPER_TABLES",
    "MontecarloSettings",
    "StudyRow",
    "PlantSample",
    "sample_plants",
    "noise_generator",
    "error_norms",
    "run_study",
    "summarise",
    "ComparisonRow",
    "adaptive_error_norms",
    "compare_study",
    "check_adaptive_size",
    "check_study_size",
]

ALGORITHMS = ("smoother", "kilc")

#: The paper's Tables II (5 %) and III (10, 20, 40 %): ``(algorithm, level) ->
#: (first_mean, first_std, steady_mean, steady_std)``, error 2-norms [m].
PAPER_TABLES: dict[tuple[str, float], tuple[float, float, float, float]] = {
    ("smoother", 0.05): (0.84, 0.10, 0.23, 0.01),
    ("smoother", 0.10): (1.30, 0.32, 0.23, 0.01),
    ("smoother", 0.20): (2.39, 0.65, 0.23, 0.01),
    ("smoother", 0.40): (4.33, 2.53, 0.38, 0.25),
    ("kilc", 0.05): (1.46, 0.21, 0.23, 0.01),
    ("kilc", 0.10): (1.99, 0.42, 0.23, 0.01),
    ("kilc", 0.20): (2.74, 0.66, 0.23, 0.01),
    ("kilc", 0.40): (4.10, 2.16, 0.28, 0.18),
}

_RULES = ("resample", "exclude")
_SIGNALS = ("true", "measured")
_U0 = ("reference", "zero")
_DIVERGED = ("include", "exclude")


@dataclass(frozen=True)
class MontecarloSettings:
    """Configuration of the Monte Carlo study (defaults: the paper's Sec. IV and Table I).

    Parameters
    ----------
    levels : tuple of float
        Uncertainty levels: standard deviation of ``wn`` and ``zeta`` as a fraction of the
        nominal value (0.05 = 5 %).
    plants : int
        Plants drawn per level (paper: 100).
    repeats : int
        Noise realisations per plant (paper: 10); a plant's statistic is the mean over them.
    iterations : int
        Learning updates; trials ``j = 0 .. iterations`` are flown (paper: 30).
    seed : int
        Seed of every random draw; plants and noise of a level depend only on ``seed`` and
        the level, and both algorithms see the same plants and the same noise.
    n_samples : int
        Trial length N [samples]. Default 200 (2 s); see ``docs/montecarlo.md``.
    t_ilc_s : float
        Sample time of the learning [s] (paper: 0.01 s).
    noise_std : float
        Standard deviation of the Gaussian output noise [m]. Default 0.1: "N(0, 0.01)" read
        as a variance (see ``docs/montecarlo.md``).
    error_signal : str
        Which output the error norm ``||Yd - Y_j||_2`` uses: ``"true"`` (noise-free plant
        output, default) or ``"measured"`` (with the noise).
    first_iteration : int
        Trial reported as "first iteration" (default 1, the first learned trial; trial 0
        flies ``U_0`` and is the same for both algorithms).
    steady_from, steady_to : int
        Trials averaged for "steady state", inclusive (paper's footnote 4: 20 to 30).
    u0 : str
        First input: ``"reference"`` (``u(k) = yd(k t_ilc_s)``, default) or ``"zero"``.
    invalid_plant_rule : str
        What to do with a draw where ``wn <= 0`` or ``zeta <= 0`` (non-physical; with
        ``zeta < 0`` the plant is unstable): ``"resample"`` it (default, so every level has
        exactly ``plants`` plants) or ``"exclude"`` it. Either way it counts in
        ``StudyRow.excluded``.
    wn_rad_s, zeta : float
        Nominal natural frequency [rad/s] and damping ratio (paper: 1.8, 0.8).
    disturbance_amp_m, disturbance_omega_rad_s : float
        Output disturbance ``d(t) = amp sin^2(omega t)`` [m] (paper: 0.5, 1).
    reference_amp_m, reference_omega_rad_s : float
        Desired output ``yd(t) = amp sin(omega t)`` [m] (paper: 1, 0.5 pi).
    we, wdu, wu : float
        Weights of eq. (8), each times the identity (Table I: 1, 0.01, 0).
    smoother : SmootherSettings
        Algorithm 1 (Table I "Proposed": P(0) = 0.1, R = 0.01, Q = 0.1).
    kilc : KilcSettings
        K-ILC filter (Table I: P(0) = 0.1 I, R = 0.01 I, Q = 0.1 I).
    algorithms : tuple of str
        Which of ``"smoother"``, ``"kilc"`` to run.
    diverged_rule : str
        A plant whose learning diverged (mean error norm of the steady-state trials above
        that of trial 0) is counted in ``StudyRow.diverged`` and either kept in the
        statistics (``"include"``, default: the study as specified) or left out of them
        (``"exclude"``).
    """

    levels: tuple[float, ...] = (0.05, 0.10, 0.20, 0.40)
    plants: int = 100
    repeats: int = 10
    iterations: int = 30
    seed: int = 20240601
    n_samples: int = 200
    t_ilc_s: float = 0.01
    noise_std: float = 0.1
    error_signal: str = "true"
    first_iteration: int = 1
    steady_from: int = 20
    steady_to: int = 30
    u0: str = "reference"
    invalid_plant_rule: str = "resample"
    wn_rad_s: float = 1.8
    zeta: float = 0.8
    disturbance_amp_m: float = 0.5
    disturbance_omega_rad_s: float = 1.0
    reference_amp_m: float = 1.0
    reference_omega_rad_s: float = 0.5 * np.pi
    we: float = 1.0
    wdu: float = 0.01
    wu: float = 0.0
    smoother: SmootherSettings = field(default_factory=SmootherSettings)
    kilc: KilcSettings = field(default_factory=KilcSettings)
    algorithms: tuple[str, ...] = ALGORITHMS
    diverged_rule: str = "include"

    def __post_init__(self) -> None:
        object.__setattr__(self, "levels", tuple(float(x) for x in self.levels))
        object.__setattr__(self, "algorithms", tuple(self.algorithms))
        for name in ("plants", "repeats", "iterations", "n_samples"):
            if int(getattr(self, name)) < 1:
                raise ValueError(
                    f"MontecarloSettings.{name} must be >= 1, got {getattr(self, name)}"
                )
        if any(not np.isfinite(x) or x < 0 for x in self.levels):
            raise ValueError(
                f"MontecarloSettings.levels must be finite and >= 0, got {self.levels}"
            )
        if not self.t_ilc_s > 0:
            raise ValueError(f"MontecarloSettings.t_ilc_s must be > 0, got {self.t_ilc_s}")
        if not self.noise_std >= 0:
            raise ValueError(f"MontecarloSettings.noise_std must be >= 0, got {self.noise_std}")
        if self.error_signal not in _SIGNALS:
            raise ValueError(f"MontecarloSettings.error_signal must be one of {_SIGNALS}")
        if self.u0 not in _U0:
            raise ValueError(f"MontecarloSettings.u0 must be one of {_U0}")
        if self.diverged_rule not in _DIVERGED:
            raise ValueError(f"MontecarloSettings.diverged_rule must be one of {_DIVERGED}")
        if self.invalid_plant_rule not in _RULES:
            raise ValueError(f"MontecarloSettings.invalid_plant_rule must be one of {_RULES}")
        if not 0 <= self.first_iteration <= self.iterations:
            raise ValueError("MontecarloSettings.first_iteration must lie in 0 .. iterations")
        if not 0 <= self.steady_from <= self.steady_to <= self.iterations:
            raise ValueError("MontecarloSettings.steady_from/steady_to must lie in 0 .. iterations")
        bad = [a for a in self.algorithms if a not in ALGORITHMS]
        if bad or not self.algorithms:
            raise ValueError(f"MontecarloSettings.algorithms must be a subset of {ALGORITHMS}")
        if not (self.we > 0 and self.wdu >= 0 and self.wu >= 0):
            raise ValueError("MontecarloSettings weights need we > 0, wdu >= 0, wu >= 0")
        if not (self.wn_rad_s > 0 and self.zeta > 0):
            raise ValueError("MontecarloSettings.wn_rad_s and zeta must be > 0")

    @property
    def duration_s(self) -> float:
        """Trial length ``n_samples * t_ilc_s`` [s]."""
        return self.n_samples * self.t_ilc_s


@dataclass(frozen=True)
class StudyRow:
    """One row of Tables II/III: one algorithm at one uncertainty level.

    Parameters
    ----------
    algorithm : str
        ``"smoother"`` (the paper's "Proposed") or ``"kilc"``.
    uncertainty : float
        Uncertainty level (fraction of the nominal values).
    first_mean, first_std : float
        Mean and standard deviation over plants of the error 2-norm [m] of trial
        ``first_iteration``, each plant averaged over its repeats.
    steady_mean, steady_std : float
        The same for the mean error 2-norm of trials ``steady_from .. steady_to`` [m].
    excluded : int
        Plant draws rejected by the invalid-plant rule at this level.
    excluded_rule : str
        The rule, in words.
    plants : int
        Plants the statistics are over.
    diverged : int
        Plants whose learning diverged (steady-state error norm above the trial-0 one),
        included in or excluded from the statistics by ``MontecarloSettings.diverged_rule``.
    """

    algorithm: str
    uncertainty: float
    first_mean: float
    first_std: float
    steady_mean: float
    steady_std: float
    excluded: int
    excluded_rule: str
    plants: int
    diverged: int = 0


@dataclass(frozen=True)
class PlantSample:
    """The plants of one uncertainty level.

    Parameters
    ----------
    wn_rad_s : ndarray, shape (P,)
        Natural frequencies [rad/s] of the plants kept.
    zeta : ndarray, shape (P,)
        Damping ratios of the plants kept.
    excluded : int
        Draws rejected by ``invalid_plant_rule``.
    """

    wn_rad_s: np.ndarray
    zeta: np.ndarray
    excluded: int


def _level_key(level: float) -> int:
    return int(round(level * 1_000_000))


def _rng(settings: MontecarloSettings, level: float, stream: int) -> np.random.Generator:
    return np.random.default_rng([settings.seed, _level_key(level), stream])


def sample_plants(settings: MontecarloSettings, level: float) -> PlantSample:
    """Draw the plants of one uncertainty level.

    ``wn = wn_nom (1 + level g1)``, ``zeta = zeta_nom (1 + level g2)`` with independent
    standard normal ``g1, g2``. A draw with ``wn <= 0`` or ``zeta <= 0`` is not a
    mass-spring-damper (``zeta < 0``: unstable) and is resampled or dropped according to
    ``settings.invalid_plant_rule``.

    Parameters
    ----------
    settings : MontecarloSettings
        Seed, plant count, nominal values and rule.
    level : float
        Relative standard deviation of both parameters.

    Returns
    -------
    PlantSample
    """
    rng = _rng(settings, level, 0)
    wn_nom, z_nom = settings.wn_rad_s, settings.zeta
    g = rng.standard_normal((settings.plants, 2))
    wn = wn_nom * (1.0 + level * g[:, 0])
    zeta = z_nom * (1.0 + level * g[:, 1])
    ok = (wn > 0) & (zeta > 0)
    excluded = int(np.count_nonzero(~ok))
    if settings.invalid_plant_rule == "exclude":
        return PlantSample(wn[ok], zeta[ok], excluded)
    while not np.all(ok):
        bad = np.flatnonzero(~ok)
        g = rng.standard_normal((bad.size, 2))
        wn[bad] = wn_nom * (1.0 + level * g[:, 0])
        zeta[bad] = z_nom * (1.0 + level * g[:, 1])
        ok = (wn > 0) & (zeta > 0)
        excluded += int(np.count_nonzero(~ok))
    return PlantSample(wn, zeta, excluded)


def noise_generator(settings: MontecarloSettings, level: float) -> np.random.Generator:
    """The generator of the output noise of one uncertainty level.

    Every trial ``j = 0 .. iterations`` of the level, in order, draws
    ``standard_normal((P * repeats, N))`` from it: row ``i * repeats + k`` is the noise of
    plant ``i`` (of :func:`sample_plants`), repeat ``k``, and the measured output is
    ``y = y_true + noise_std * draw``. Seeded by ``settings.seed`` and ``level`` only (a
    stream apart from the plants'), so both algorithms, and :func:`adaptive_error_norms`,
    see the same noise; a trial-by-trial rerun that draws the same way sees it too.

    Parameters
    ----------
    settings : MontecarloSettings
        The seed (the draws' shapes follow from ``plants``, ``repeats`` and ``n_samples``).
    level : float
        Uncertainty level (fraction of the nominal values).

    Returns
    -------
    numpy.random.Generator
        A new generator at the start of the level's noise: unit standard deviation,
        dimensionless (scaled by ``noise_std`` [m]).
    """
    return _rng(settings, level, 1)


def _msd_model(wn: float, zeta: float, dt_s: float) -> DiscreteModel:
    return from_transfer_function([wn * wn], [1.0, 2.0 * zeta * wn, wn * wn], 0.0, dt_s)


def _markov_batch(wn: np.ndarray, zeta: np.ndarray, n: int, dt_s: float) -> np.ndarray:
    """Markov parameters ``f_1 .. f_N`` of every plant, shape (P, N).

    ZOH of the controllable canonical form of ``wn^2 / (s^2 + 2 zeta wn s + wn^2)`` (one
    batched matrix exponential), then ``f_k = C A^(k-1) B`` advanced for all plants at once.
    Markov parameters do not depend on the realisation, so this equals
    ``markov_parameters(from_transfer_function(...))`` (a test checks it).
    """
    p = wn.size
    m = np.zeros((p, 3, 3))
    m[:, 0, 0] = -2.0 * zeta * wn * dt_s
    m[:, 0, 1] = -wn * wn * dt_s
    m[:, 1, 0] = dt_s
    m[:, 0, 2] = dt_s
    e = scipy.linalg.expm(m)
    a, x = e[:, :2, :2], e[:, :2, 2]
    c = np.zeros((p, 2))
    c[:, 1] = wn * wn
    f = np.empty((p, n))
    for k in range(n):
        f[:, k] = np.einsum("pi,pi->p", c, x)
        x = np.einsum("pij,pj->pi", a, x)
    return f


def _signals(settings: MontecarloSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reference ``yd(1..N)``, disturbance ``d(1..N)`` and ``U_0``, each shape (N,)."""
    n, dt = settings.n_samples, settings.t_ilc_s
    t_out = dt * np.arange(1, n + 1)
    t_in = dt * np.arange(n)
    yd = settings.reference_amp_m * np.sin(settings.reference_omega_rad_s * t_out)
    d = settings.disturbance_amp_m * np.sin(settings.disturbance_omega_rad_s * t_out) ** 2
    if settings.u0 == "reference":
        u0 = settings.reference_amp_m * np.sin(settings.reference_omega_rad_s * t_in)
    else:
        u0 = np.zeros(n)
    return yd, d, u0


def _simulate(
    settings: MontecarloSettings,
    plants: PlantSample,
    level: float,
    algorithm: str,
    step: Callable[[], None] | None = None,
    adaptive: AdaptiveSettings | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Error norms of every trial (P, R, iterations + 1), and the runs whose model a refresh
    replaced (P, R) (``adaptive`` only; else every False)."""
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {algorithm!r}")
    n, dt = settings.n_samples, settings.t_ilc_s
    p, r = plants.wn_rad_s.size, settings.repeats
    norms = np.zeros((p, r, settings.iterations + 1))
    refreshed = np.zeros((p, r), dtype=bool)
    if p == 0:
        return norms, refreshed
    runs = p * r
    # the paper's method: a run is a plant of one axis. The adaptive options are defined on
    # north and east, which they learn apart (without a repeat, which the study does not
    # fly): two runs are then the two axes of one vehicle, the last one twice when odd
    axes = 1 if adaptive is None else 2
    vehicles = -(-runs // axes)
    yd, d, u0 = _signals(settings)
    model = _msd_model(settings.wn_rad_s, settings.zeta, dt)
    learner = LearnerBatch(
        LearnerSettings(
            models=(model,) * axes,
            algorithm=algorithm,
            weights=UpdateWeights(settings.we, settings.wdu, settings.wu),
            smoother=settings.smoother,
            kilc=settings.kilc,
            axes=tuple(range(axes)),
        ),
        np.repeat(np.concatenate([[0.0], yd])[:, None], axes, axis=1),  # at rest at 0 first
        vehicles,
        adaptive,
    )
    f_true = _markov_batch(plants.wn_rad_s, plants.zeta, n, dt)
    noise_rng = noise_generator(settings, level)  # same stream for both algorithms
    fly = _flights(settings, f_true, yd, d, noise_rng, norms)

    def as_vehicles(x: np.ndarray) -> np.ndarray:  # (runs, N) -> (vehicles, N, axes)
        x = np.concatenate([x, x[runs - 1 :].repeat(vehicles * axes - runs, axis=0)])
        return x.reshape(vehicles, axes, n).transpose(0, 2, 1)

    def learn(j: int, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        u_next = learner.step(as_vehicles(u), as_vehicles(y))
        return u_next.transpose(0, 2, 1).reshape(vehicles * axes, n)[:runs]

    run_trials(np.broadcast_to(u0, (runs, n)).copy(), settings.iterations + 1, fly, learn, step)
    if adaptive is not None:
        replaced = [m is not model for models in learner.models for m in models]
        refreshed = np.array(replaced[:runs]).reshape(p, r)
    return norms, refreshed


def _flights(
    settings: MontecarloSettings,
    f_true: np.ndarray,
    yd: np.ndarray,
    d: np.ndarray,
    noise_rng: np.random.Generator,
    norms: np.ndarray,
) -> Callable[[int, np.ndarray], np.ndarray]:
    """The flights of every run (P plants x R repeats, plant Markov parameters ``f_true``):
    ``fly(j, u) -> y`` measured, the error norm of trial ``j`` kept in ``norms[:, :, j]``."""
    p, r, _ = norms.shape
    n = yd.size
    nfft = scipy.fft.next_fast_len(2 * n - 1, real=True)  # linear, not circular
    f_true_fft = np.fft.rfft(f_true, nfft, axis=-1)[:, None, :]
    measured = settings.error_signal == "measured"

    def fly(j: int, u: np.ndarray) -> np.ndarray:
        u_fft = np.fft.rfft(u.reshape(p, r, n), nfft, axis=-1)
        y_true = np.fft.irfft(f_true_fft * u_fft, nfft, axis=-1)[..., :n].reshape(p * r, n) + d
        y = y_true + settings.noise_std * noise_rng.standard_normal((p * r, n))
        e = yd - (y if measured else y_true)
        norms[:, :, j] = np.sqrt(np.einsum("ij,ij->i", e, e)).reshape(p, r)
        return y

    return fly


def error_norms(settings: MontecarloSettings, level: float, algorithm: str) -> np.ndarray:
    """Error 2-norms ``||Yd - Y_j||_2`` of every trial of one level and algorithm.

    The plants and the noise are those :func:`run_study` uses for the same ``settings`` and
    ``level`` (``level`` need not be in ``settings.levels``).

    Parameters
    ----------
    settings : MontecarloSettings
        The study.
    level : float
        Uncertainty level.
    algorithm : str
        ``"smoother"`` or ``"kilc"``.

    Returns
    -------
    ndarray, shape (P, repeats, iterations + 1)
        ``[plant, repeat, j]`` [m]; ``P`` is ``settings.plants`` minus excluded plants.
    """
    return _simulate(settings, sample_plants(settings, level), level, algorithm)[0]


def _rule_text(settings: MontecarloSettings) -> str:
    action = "resampled" if settings.invalid_plant_rule == "resample" else "excluded"
    return f"draws with wn <= 0 or zeta <= 0 {action}"


def summarise(
    settings: MontecarloSettings, norms: np.ndarray, level: float, algorithm: str, excluded: int
) -> StudyRow:
    """Reduce an :func:`error_norms` array to one table row.

    Parameters
    ----------
    settings : MontecarloSettings
        Gives ``first_iteration``, ``steady_from`` and ``steady_to``.
    norms : ndarray, shape (P, R, iterations + 1)
        Error norms [m].
    level : float
        Uncertainty level of the row.
    algorithm : str
        Algorithm of the row.
    excluded : int
        Rejected plant draws.

    Returns
    -------
    StudyRow
    """
    per_plant = norms.mean(axis=1)  # (P, J): average over repeats first
    first = per_plant[:, settings.first_iteration]
    steady = per_plant[:, settings.steady_from : settings.steady_to + 1].mean(axis=1)
    gone = diverged(per_plant[:, 0], steady)  # NaN/inf count as diverged
    if settings.diverged_rule == "exclude":
        first, steady = first[~gone], steady[~gone]
    nan = float("nan")

    def stats(x: np.ndarray) -> tuple[float, float]:
        if x.size == 0:
            return nan, nan
        return float(x.mean()), float(x.std(ddof=1)) if x.size > 1 else 0.0

    fm, fs = stats(first)
    sm, ss = stats(steady)
    return StudyRow(
        algorithm=algorithm,
        uncertainty=float(level),
        first_mean=fm,
        first_std=fs,
        steady_mean=sm,
        steady_std=ss,
        excluded=int(excluded),
        excluded_rule=_rule_text(settings),
        plants=int(first.size),
        diverged=int(np.count_nonzero(gone)),
    )


def _counter(total: int, progress: Callable[[int, int], None] | None) -> Callable[[], None]:
    """A step callback that reports ``progress(done, total)`` after every call."""
    done = 0

    def step() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    return step


def run_study(
    settings: MontecarloSettings,
    progress: Callable[[int, int], None] | None = None,
    threads: int = 1,
) -> list[StudyRow]:
    """Run the Monte Carlo study: one row per (level, algorithm), levels in order.

    Every (level, algorithm) batch is independent: it draws its plants and its noise from
    generators of its own, seeded by ``settings.seed`` and its level alone, so the rows are the
    same, bit for bit, whatever the number of threads that run the batches.

    Parameters
    ----------
    settings : MontecarloSettings
        The study.
    progress : callable, optional
        ``progress(done, total)`` after every learning iteration of every (level, algorithm)
        batch; ``total = len(levels) * len(algorithms) * iterations``. Called from the thread
        that ran the iteration, one call at a time.
    threads : int
        Threads of this process that run the batches (1: one after the other). numpy's matrix
        products and FFTs release the GIL, so the batches share the cores; with more than one
        thread, give BLAS one thread (``OPENBLAS_NUM_THREADS=1`` before numpy is imported),
        or its own threads contend for the same cores.

    Returns
    -------
    list of StudyRow
    """
    if threads < 1:
        raise ValueError(f"threads must be at least 1, got {threads}")
    step = _counter(len(settings.levels) * len(settings.algorithms) * settings.iterations, progress)
    if threads > 1:
        lock = threading.Lock()
        counted = step

        def step() -> None:
            with lock:
                counted()

    def batch(level: float, algorithm: str) -> StudyRow:
        plants = sample_plants(settings, level)
        norms = _simulate(settings, plants, level, algorithm, step)[0]
        return summarise(settings, norms, level, algorithm, plants.excluded)

    jobs = [(level, algorithm) for level in settings.levels for algorithm in settings.algorithms]
    if threads == 1 or len(jobs) == 1:
        return [batch(*job) for job in jobs]
    with ThreadPoolExecutor(min(threads, len(jobs))) as pool:
        futures = [pool.submit(batch, *job) for job in jobs]
        try:
            return [f.result() for f in futures]
        finally:
            for f in futures:
                f.cancel()


# =============================================================================================
# Memory, and the study with the options beyond the paper (data-driven noise model, model
# refresh): the same trial loop, the runs learning through LearnerBatch with those options
# (each run's model and estimator then follow its own data; see _simulate).
# =============================================================================================


def _physical_memory() -> float:
    """This machine's memory [bytes] (16 GB when the system does not say)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return 16e9


def check_study_size(settings: MontecarloSettings, memory_bytes: float | None = None) -> None:
    """Refuse a study whose fixed operators and batch would not fit in memory.

    The paper's study keeps about ten ``N x N`` operators (the lifted model, the update and the
    smoother) and a few ``(plants x repeats, N)`` arrays per (level, algorithm) task.

    Parameters
    ----------
    settings : MontecarloSettings
        The study.
    memory_bytes : float, optional
        The memory it may use; default half of this machine's.

    Raises
    ------
    ValueError
        ``"MontecarloSettings.n_samples ..."`` naming the size and the memory.
    """
    n = float(settings.n_samples)
    runs = float(settings.plants * settings.repeats)
    need = 8.0 * (10.0 * n * n + 8.0 * runs * n)
    limit = 0.5 * _physical_memory() if memory_bytes is None else memory_bytes
    if need > limit:
        raise ValueError(
            f"MontecarloSettings.n_samples {settings.n_samples} with {settings.plants} x "
            f"{settings.repeats} runs needs about {need / 1e9:.3g} GB (N x N operators), more "
            f"than the {limit / 1e9:.3g} GB it may use on this machine; use fewer samples"
        )


@dataclass(frozen=True)
class ComparisonRow:
    """The paper's method against the new options at one uncertainty level (same plants, noise).

    Parameters
    ----------
    uncertainty : float
        Uncertainty level.
    algorithm : str
        Estimator of both (``"smoother"`` or ``"kilc"``).
    paper_mean_2_5 : float
        Mean error 2-norm over trials j = 2..5, plants and repeats, the paper's method [m].
    new_mean_2_5 : float
        The same with the new options [m].
    change_pct : float
        ``100 (new / paper - 1)``: negative is better.
    paper_diverged, new_diverged : int
        Plants whose learning diverged (steady-state norm above trial 0's).
    plants : int
        Plants at this level.
    paper_kept_2_5, new_kept_2_5 : float
        Mean error 2-norm over trials j = 2..5 over the plants that diverged under neither
        method [m].
    paper_steady, new_steady : float
        Mean steady-state norm (trials ``steady_from..steady_to``) over the plants that did not
        diverge under either method [m].
    refreshed_pct : float
        Share of runs whose model a refresh changed at least once [%].
    seconds : float
        Wall time of the new options' simulation at this level [s].
    """

    uncertainty: float
    algorithm: str
    paper_mean_2_5: float
    new_mean_2_5: float
    change_pct: float
    paper_diverged: int
    new_diverged: int
    plants: int
    paper_kept_2_5: float
    new_kept_2_5: float
    paper_steady: float
    new_steady: float
    refreshed_pct: float
    seconds: float


def adaptive_error_norms(
    settings: MontecarloSettings, level: float, algorithm: str, adaptive: AdaptiveSettings
) -> tuple[np.ndarray, np.ndarray]:
    """Error 2-norms of every trial with the new options, on the paper's plants and noise.

    The runs learn through :class:`gcs.core.learner.LearnerBatch` with ``adaptive``, as a
    flight's learner does: two runs are the north and east axes of one vehicle, which the
    options learn apart (no repeat is flown, so no floor couples them).

    Parameters
    ----------
    settings : MontecarloSettings
        The study (the plants and noise of ``level`` are :func:`error_norms`'s).
    level : float
        Uncertainty level.
    algorithm : str
        ``"smoother"`` or ``"kilc"``.
    adaptive : AdaptiveSettings
        The options. Without a repeat flight, ``robustness_cutoff_rad_s = "auto"`` and
        ``refresh_noise = "measured"`` find no floor (off, white); the safeguard needs an
        arena, which the study has not (refused).

    Returns
    -------
    norms : ndarray, shape (P, repeats, iterations + 1)
        ``[plant, repeat, j]`` [m].
    refreshed : ndarray of bool, shape (P, repeats)
        Runs whose model a refresh replaced.
    """
    plants = sample_plants(settings, level)
    return _simulate(settings, plants, level, algorithm, None, adaptive)


def _diverged(settings: MontecarloSettings, norms: np.ndarray) -> np.ndarray:
    per_plant = norms.mean(axis=1)
    steady = per_plant[:, settings.steady_from : settings.steady_to + 1].mean(axis=1)
    return diverged(per_plant[:, 0], steady)


def check_adaptive_size(settings: MontecarloSettings, memory_bytes: float | None = None) -> None:
    """Refuse an adaptive study whose trials would not fit in memory.

    The new options learn from every trial so far: each level keeps the setpoints and
    positions of every trial of every run, and each step stacks them and their residuals.

    Parameters
    ----------
    settings : MontecarloSettings
        The study.
    memory_bytes : float, optional
        The memory it may use; default half of this machine's.

    Raises
    ------
    ValueError
        The trials of one level would take more than that.
    """
    runs = float(settings.plants * settings.repeats)
    need = 8.0 * 6.0 * runs * (settings.iterations + 1) * settings.n_samples
    limit = 0.5 * _physical_memory() if memory_bytes is None else memory_bytes
    if need > limit:
        raise ValueError(
            f"the adaptive study keeps every trial of its {settings.plants} x "
            f"{settings.repeats} runs ({settings.iterations + 1} trials of "
            f"{settings.n_samples} samples): about {need / 1e9:.3g} GB, more than the "
            f"{limit / 1e9:.3g} GB it may use on this machine; use fewer plants, repeats or "
            "samples"
        )


def compare_study(
    settings: MontecarloSettings,
    adaptive: AdaptiveSettings,
    algorithm: str = "smoother",
    progress: Callable[[int, int], None] | None = None,
) -> tuple[list[StudyRow], list[ComparisonRow]]:
    """The paper's method and the new options on the same plants and noise, every level.

    Parameters
    ----------
    settings : MontecarloSettings
        The study.
    adaptive : AdaptiveSettings
        The new options (``noise = "data"``).
    algorithm : str
        Estimator of both.
    progress : callable, optional
        ``progress(done, total)`` after every learning iteration of the new options.

    Returns
    -------
    rows : list of StudyRow
        Tables II/III rows of the new options (algorithm ``"<algorithm>+adaptive"``).
    comparison : list of ComparisonRow
        One per level.

    Raises
    ------
    ValueError
        The trials would not fit in memory (:func:`check_adaptive_size`).
    """
    import time

    check_adaptive_size(settings)
    step = _counter(len(settings.levels) * settings.iterations, progress)
    rows, comparison = [], []
    for level in settings.levels:
        plants = sample_plants(settings, level)
        paper = _simulate(settings, plants, level, algorithm)[0]
        start = time.perf_counter()
        new, refreshed = _simulate(settings, plants, level, algorithm, step, adaptive)
        seconds = time.perf_counter() - start
        rows.append(summarise(settings, new, level, f"{algorithm}+adaptive", plants.excluded))
        div_p, div_n = _diverged(settings, paper), _diverged(settings, new)
        keep = ~(div_p | div_n)
        window = slice(2, min(5, settings.iterations) + 1)
        pm, nm = float(paper[:, :, window].mean()), float(new[:, :, window].mean())
        steady = slice(settings.steady_from, settings.steady_to + 1)
        comparison.append(
            ComparisonRow(
                uncertainty=float(level),
                algorithm=algorithm,
                paper_mean_2_5=pm,
                new_mean_2_5=nm,
                change_pct=100.0 * (nm / pm - 1.0),
                paper_diverged=int(div_p.sum()),
                new_diverged=int(div_n.sum()),
                plants=int(plants.wn_rad_s.size),
                paper_kept_2_5=float(paper[keep][:, :, window].mean()) if keep.any() else np.nan,
                new_kept_2_5=float(new[keep][:, :, window].mean()) if keep.any() else np.nan,
                paper_steady=float(paper[keep][:, :, steady].mean()) if keep.any() else np.nan,
                new_steady=float(new[keep][:, :, steady].mean()) if keep.any() else np.nan,
                refreshed_pct=100.0 * float(refreshed.mean()),
                seconds=seconds,
            )
        )
    return rows, comparison
