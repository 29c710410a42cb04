"""A study of the user's own set-up: learning settings compared on simulated plants.

The user's profile gives the model(s) the learning uses; the true plants of the study are that
model perturbed as an :class:`Uncertainty` says (natural frequency, damping and gain of every
mode, or every Markov parameter; an extra delay; output noise; a repeatable disturbance). Each
plant then flies the user's reference for ``iterations`` learned trials with every
:class:`StudySetting`, the learning being the step ``gcs fly`` takes: the plants of a chunk
fly one trial loop (:func:`run_trials`, also the loop of :mod:`gcs.core.montecarlo`) and learn
through one :class:`gcs.core.learner.LearnerBatch`, which equals a
:class:`gcs.core.learner.Learner` per plant (the paper's method batched: what depends on the
model once for every plant, a QP only for the plants whose optimum breaks a limit; the
adaptive options batched too, a plant whose model a refresh replaced updated alone). The
plant's simulation is on this side.

Everything is linear in the trial length ``N``: the true plant is simulated as a difference
equation (``scipy.signal.lfilter``) or, for perturbed Markov parameters, by an FFT
convolution, and the learning takes the sparse path of :mod:`gcs.core.update`. No ``N x N``
operator is formed.

Randomness: plant ``i`` of uncertainty level ``l`` draws everything (its parameters, its
disturbance, the noise of every flight) from ``SeedSequence(seed, spawn_key=(l, i))``, so the
plants and their noise are the same for every setting and do not depend on how the plants are
split into chunks, nor on which process simulates them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.fft

from gcs.core.learner import LearnerBatch
from gcs.core.learning import AdaptiveSettings, LearnerSettings
from gcs.core.metrics import epos
from gcs.core.model import DiscreteModel, markov_parameters

__all__ = [
    "PARAMETERS",
    "Uncertainty",
    "StudySetting",
    "StudyPlan",
    "TruePlant",
    "draw_plant",
    "plant_stream",
    "PLANT_DRAW",
    "PLANT_NOISE",
    "run_trials",
    "diverged",
    "fly_plants",
    "fly_plant",
    "PlantResult",
    "run_chunk",
    "chunk_plants",
    "SettingSummary",
    "summarise_setting",
    "steady_window",
    "recommend",
    "check_nominal",
    "noise_floor",
]

#: Parameters an :class:`Uncertainty` can spread: every mode's natural frequency, damping and
#: the static gain (``"modes"``), or every Markov parameter (``"markov"``).
PARAMETERS = ("modes", "markov")

#: A plant is "at the floor" when its e_pos is within this factor of the floor.
FLOOR_FACTOR = 1.15


@dataclass(frozen=True)
class Uncertainty:
    """How the true plants differ from the model the learning uses.

    Parameters
    ----------
    levels : tuple of float
        Relative standard deviations (0.2 = 20 %); the study runs every setting at each.
    parameters : str
        ``"modes"``: each mode's natural frequency and damping and the static gain, each
        ``x (1 + level g)`` with a standard normal ``g``; ``"markov"``: each Markov parameter
        ``f_k (1 + level g_k)`` (for identified high-order models).
    bias : tuple of float
        Relative shift of the centre of the draws of (natural frequency, damping, gain): a
        model known to be off. ``(0, 0, 0)``: centred on the model.
    extra_delay_s : tuple of float
        Range ``(lo, hi)`` of an extra input delay [s], drawn uniformly and rounded to samples.
    noise_std_m : tuple of float
        Standard deviation of the white output noise, (north, east) [m].
    disturbance_rms_m : tuple of float
        RMS of the repeatable output disturbance, (north, east) [m]: low-pass filtered white
        noise, the same in every flight of a plant, different between plants.
    disturbance_bandwidth_hz : float
        Corner of the disturbance's second-order Butterworth filter [Hz].
    floor_source : str or None
        Where the noise level came from (a run's ``floor.json``), None when given as numbers.
    """

    levels: tuple[float, ...] = (0.2,)
    parameters: str = "modes"
    bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    extra_delay_s: tuple[float, float] = (0.0, 0.0)
    noise_std_m: tuple[float, float] = (0.0, 0.0)
    disturbance_rms_m: tuple[float, float] = (0.0, 0.0)
    disturbance_bandwidth_hz: float = 0.5
    floor_source: str | None = None

    def __post_init__(self) -> None:
        if not self.levels or any(not (math.isfinite(v) and v >= 0) for v in self.levels):
            raise ValueError(f"levels must be >= 0, at least one, got {list(self.levels)}")
        if self.parameters not in PARAMETERS:
            raise ValueError(f"parameters must be one of {', '.join(PARAMETERS)}")
        lo, hi = self.extra_delay_s
        if not (0 <= lo <= hi and math.isfinite(hi)):
            raise ValueError(f"extra_delay_s must be 0 <= lo <= hi, got {[lo, hi]}")
        for name in ("noise_std_m", "disturbance_rms_m"):
            if any(not (math.isfinite(v) and v >= 0) for v in getattr(self, name)):
                raise ValueError(f"{name} must be >= 0")
        if not (math.isfinite(self.disturbance_bandwidth_hz) and self.disturbance_bandwidth_hz > 0):
            raise ValueError("disturbance_bandwidth_hz must be > 0")

    def as_dict(self) -> dict:
        """JSON-ready dictionary (SI units)."""
        return {
            "levels": list(self.levels),
            "parameters": self.parameters,
            "bias": dict(zip(("wn", "zeta", "gain"), self.bias, strict=True)),
            "extra_delay_s": list(self.extra_delay_s),
            "noise_std_m": list(self.noise_std_m),
            "disturbance_rms_m": list(self.disturbance_rms_m),
            "disturbance_bandwidth_hz": self.disturbance_bandwidth_hz,
            "floor_source": self.floor_source,
        }


@dataclass(frozen=True)
class StudySetting:
    """One learning setting to compare: everything :func:`plan_next_trial` needs.

    Parameters
    ----------
    name : str
        Label in tables and figures.
    settings : LearnerSettings
        Models, algorithm, weights, Table I settings, arena and limits.
    adaptive : AdaptiveSettings or None
        Options beyond the paper; None: the paper's method.
    repeats : int
        Flights of trial 0's setpoints after the first (they measure the floor for the
        adaptive options; 0 without them).
    source : dict
        What defines the setting (profile name, overrides), for the JSON.
    """

    name: str
    settings: LearnerSettings
    adaptive: AdaptiveSettings | None = None
    repeats: int = 0
    source: dict = field(default_factory=dict)


@dataclass(frozen=True)
class StudyPlan:
    """Everything a chunk of plants needs: reference, nominal models, uncertainty, sizes.

    Parameters
    ----------
    ref_ne_m : ndarray, shape (N+1, 2)
        Reference yd(0..N), absolute north/east [m]; row 0 is the start point.
    models : tuple of DiscreteModel
        (north, east) models the true plants are drawn around.
    uncertainty : Uncertainty
        The draws.
    settings : tuple of StudySetting
        Settings compared.
    plants : int
        Plants per level.
    iterations : int
        Learned trials after trial 0 (and its repeats).
    seed : int
        Seed of every draw.
    chunk_plants : int
        Plants per chunk (the unit of work).
    steady_trials : int
        Last trials averaged for the steady state.
    """

    ref_ne_m: np.ndarray
    models: tuple[DiscreteModel, DiscreteModel]
    uncertainty: Uncertainty
    settings: tuple[StudySetting, ...]
    plants: int
    iterations: int
    seed: int
    chunk_plants: int
    steady_trials: int = 3

    @property
    def n_samples(self) -> int:
        """Trial length N [samples]."""
        return self.ref_ne_m.shape[0] - 1

    @property
    def chunks(self) -> int:
        """Chunks per (setting, level)."""
        return -(-self.plants // self.chunk_plants)


@dataclass(frozen=True)
class TruePlant:
    """One simulated vehicle: a plant per axis, its disturbance and its noise.

    Parameters
    ----------
    b, a : tuple of ndarray
        Per axis, difference-equation coefficients (``lfilter``) of the plant without its
        input delay; for ``"markov"`` plants ``b`` holds the Markov parameters and ``a = [1]``.
    delay_samples : tuple of int
        Per axis input delay (the model's plus the extra one) [samples].
    disturbance_ne_m : ndarray, shape (N, 2)
        Repeatable output disturbance d(1..N) [m].
    noise_std_m : tuple of float
        Output noise standard deviation per axis [m].
    draws : dict
        The drawn relative changes, for the JSON.
    """

    b: tuple[np.ndarray, np.ndarray]
    a: tuple[np.ndarray, np.ndarray]
    delay_samples: tuple[int, int]
    disturbance_ne_m: np.ndarray
    noise_std_m: tuple[float, float]
    draws: dict

    def respond(self, u_ne_m: np.ndarray) -> np.ndarray:
        """Noise-free output y(1..N) for inputs u(0..N-1), learning coordinates.

        Parameters
        ----------
        u_ne_m : ndarray, shape (N, 2)
            Inputs [m] relative to the start point.

        Returns
        -------
        ndarray, shape (N, 2)
            ``plant(u) + disturbance`` [m].
        """
        n = u_ne_m.shape[0]
        y = np.empty_like(u_ne_m)
        from scipy.signal import lfilter  # on first use: a second to import

        for axis in range(2):
            d = self.delay_samples[axis]
            u = np.zeros(n)
            if d < n:
                u[d:] = u_ne_m[: n - d, axis]
            if self.a[axis].size == 1:  # Markov parameters f_1..f_N: y(k) = sum f_i u(k - i)
                f = self.b[axis][:n]
                nfft = scipy.fft.next_fast_len(2 * n, real=True)
                y[:, axis] = np.fft.irfft(np.fft.rfft(f, nfft) * np.fft.rfft(u, nfft), nfft)[:n]
            else:  # strictly proper: b[0] = 0, so b[1:] maps u(k) to y(k + 1)
                y[:, axis] = lfilter(self.b[axis][1:], self.a[axis], u)
        return y + self.disturbance_ne_m


#: The streams of one plant (:func:`plant_stream`): its draw, and its measurement noise.
PLANT_DRAW, PLANT_NOISE = 0, 1


def plant_stream(seed: int, level_index: int, plant: int, stream: int) -> np.random.Generator:
    """The random stream ``stream`` of one plant of a study: :data:`PLANT_DRAW` (the true
    plant, :func:`draw_plant`) or :data:`PLANT_NOISE` (its measurement noise, flight after
    flight). Seeded from the study's seed and the plant's place, so a plant's results do not
    depend on the chunk or the worker that flies it.

    Parameters
    ----------
    seed : int
        The study's seed.
    level_index, plant : int
        The uncertainty level's index and the plant's number.
    stream : int
        Which stream.

    Returns
    -------
    numpy.random.Generator
    """
    return np.random.default_rng(
        np.random.SeedSequence(seed, spawn_key=(level_index, plant, stream))
    )


def _modal_perturb(
    model: DiscreteModel, level: float, bias: tuple[float, float, float], g: np.ndarray
) -> tuple[np.ndarray, np.ndarray, dict]:
    """``(b, a, draws)``: the model with every mode's wn and zeta and its static gain moved.

    Works on the poles of the discrete model mapped to continuous time (``s = ln z / dt``);
    poles at the origin (delay states) and on the negative real axis are kept. The zeros stay;
    the static gain is the model's times ``1 + bias + level g``.
    """
    dt = model.dt_s
    from scipy.signal import ss2tf  # on first use: a second to import

    bnum, aden = ss2tf(model.A, model.B, model.C, np.zeros((1, 1)))
    bnum, aden = np.atleast_1d(bnum[0]), np.atleast_1d(aden)
    f_wn = 1.0 + bias[0] + level * g[0]
    f_zeta = 1.0 + bias[1] + level * g[1]
    f_gain = 1.0 + bias[2] + level * g[2]
    poles = []
    for z in np.roots(aden):
        if abs(z) < 1e-12 or (abs(z.imag) < 1e-12 and z.real <= 0):
            poles.append(z)  # delay states and poles without a continuous-time counterpart
            continue
        s = np.log(complex(z)) / dt
        wn = abs(s)
        zeta = -s.real / wn
        wn2, zeta2 = wn * f_wn, zeta * f_zeta
        if abs(z.imag) < 1e-12:  # a real pole: its frequency moves, it has no damping
            s2 = complex(s.real * f_wn)
        elif zeta2 < 1.0:
            s2 = complex(-zeta2 * wn2, math.copysign(wn2 * math.sqrt(1.0 - zeta2**2), s.imag))
        else:  # the pair became over-damped: two real poles
            s2 = complex(-zeta2 * wn2 + math.copysign(wn2 * math.sqrt(zeta2**2 - 1.0), s.imag))
        poles.append(np.exp(s2 * dt))
    a_new = np.real(np.poly(poles))
    b_new = bnum.copy()
    dc_old, dc_new = _dc(bnum, aden), _dc(bnum, a_new)
    if math.isfinite(dc_old) and math.isfinite(dc_new) and abs(dc_new) > 1e-12:
        b_new = b_new * (dc_old / dc_new)
    draws = {"wn": f_wn - 1.0, "zeta": f_zeta - 1.0, "gain": f_gain - 1.0}
    return b_new * f_gain, a_new, draws


def _dc(b: np.ndarray, a: np.ndarray) -> float:
    den = float(np.sum(a))
    return float(np.sum(b)) / den if abs(den) > 1e-12 else math.inf


def _stable(a: np.ndarray) -> bool:
    return bool(np.all(np.abs(np.roots(a)) < 1.0))


def check_nominal(model: DiscreteModel, uncertainty: Uncertainty) -> None:
    """Refuse an uncertainty whose centre (the model with its bias, no spread) is unstable.

    Parameters
    ----------
    model : DiscreteModel
        A model the plants are drawn around.
    uncertainty : Uncertainty
        The uncertainty.

    Raises
    ------
    ValueError
        The model itself, or the model moved by ``bias``, has a pole on or outside the unit
        circle; or the bias makes a frequency or the gain not positive.
    """
    if not model.is_stable():
        raise ValueError("the model is unstable: a study needs a stable closed loop")
    f = [1.0 + b for b in uncertainty.bias]
    if f[0] <= 0 or f[2] <= 0:
        raise ValueError(
            f"bias {list(uncertainty.bias)} makes the natural frequency or the gain <= 0"
        )
    _, centre, _ = _modal_perturb(model, 0.0, uncertainty.bias, np.zeros(3))
    if not _stable(centre):
        raise ValueError(
            f"bias {list(uncertainty.bias)} makes the nominal plant unstable (damping x {f[1]:g})"
        )


def _axis_plant(
    model: DiscreteModel, u: Uncertainty, level: float, rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray, dict]:
    if u.parameters == "markov":
        f = markov_parameters(model.__class__(model.A, model.B, model.C, model.dt_s, 0), n)
        g = rng.standard_normal(n)
        scale = (1.0 + u.bias[2]) * (1.0 + level * g)
        return f * scale, np.ones(1), {"markov_rms": float(np.sqrt(np.mean((scale - 1) ** 2)))}
    for _ in range(1000):  # resample draws that are not a stable plant
        g = rng.standard_normal(3)
        if 1.0 + u.bias[0] + level * g[0] <= 0 or 1.0 + u.bias[1] + level * g[1] <= 0:
            continue  # not a physical plant (a frequency or a damping <= 0)
        b, a, draws = _modal_perturb(model, level, u.bias, g)
        if _stable(a):
            return b, a, draws
    raise ValueError(f"level {level:g}: 1000 draws in a row gave an unstable plant")


def draw_plant(plan: StudyPlan, level_index: int, plant: int) -> TruePlant:
    """The true plant ``plant`` of level ``level_index`` (the same for every setting).

    Parameters
    ----------
    plan : StudyPlan
        The study.
    level_index : int
        Index into ``plan.uncertainty.levels``.
    plant : int
        Plant number within the level, ``0 .. plants - 1``.

    Returns
    -------
    TruePlant
    """
    u = plan.uncertainty
    level = u.levels[level_index]
    n = plan.n_samples
    rng = plant_stream(plan.seed, level_index, plant, PLANT_DRAW)
    bs, as_, delays, draws = [], [], [], {}
    dt = plan.models[0].dt_s
    for axis, model in enumerate(plan.models):
        b, a, d = _axis_plant(model, u, level, rng, n)
        extra = rng.uniform(*u.extra_delay_s) if u.extra_delay_s[1] > 0 else 0.0
        bs.append(b)
        as_.append(a)
        delays.append(model.delay_samples + int(round(extra / dt)))
        draws[("north", "east")[axis]] = d | {"extra_delay_s": round(extra / dt) * dt}
    dist = np.zeros((n, 2))
    if any(v > 0 for v in u.disturbance_rms_m):
        nyq = 0.5 / dt
        wc = min(u.disturbance_bandwidth_hz / nyq, 0.99)
        from scipy.signal import butter, lfilter  # on first use: a second to import

        bf, af = butter(2, wc)
        white = rng.standard_normal((n + 200, 2))
        shaped = lfilter(bf, af, white, axis=0)[200:]
        rms = np.sqrt(np.mean(shaped**2, axis=0))
        dist = shaped / np.where(rms > 0, rms, 1.0) * np.asarray(u.disturbance_rms_m)
    return TruePlant(
        b=(bs[0], bs[1]),
        a=(as_[0], as_[1]),
        delay_samples=(delays[0], delays[1]),
        disturbance_ne_m=dist,
        noise_std_m=u.noise_std_m,
        draws=draws,
    )


@dataclass(frozen=True)
class PlantResult:
    """One plant learning with one setting.

    Parameters
    ----------
    epos_m : ndarray, shape (flights,)
        e_pos (eq. 10) of every flight, measured (with the noise) [m]; trial 0, its repeats,
        then the learned trials.
    setpoint_rms_m : float
        RMS distance of the last trial's setpoints from the reference [m].
    limit_active : float
        Share of the updates (both axes) where a setpoint limit was active.
    failed : str or None
        Why the learning stopped early (the update had no solution), None when it did not.
    setpoints_m : ndarray, shape (N, 2) or None
        Setpoints of the last flight [m].
    """

    epos_m: np.ndarray
    setpoint_rms_m: float
    limit_active: float
    failed: str | None = None
    setpoints_m: np.ndarray | None = None


def run_trials(
    u0: np.ndarray,
    flights: int,
    fly: Callable[[int, np.ndarray], np.ndarray],
    learn: Callable[[int, np.ndarray, np.ndarray], np.ndarray],
    step: Callable[[], None] | None = None,
) -> np.ndarray:
    """The trial loop of every study: fly, measure, learn, ``flights`` times.

    Parameters
    ----------
    u0 : ndarray, shape (R, N) or (R, N, axes)
        Setpoints of trial 0 [m], one row per run (every plant, every run).
    flights : int
        Trials flown (trial 0 included).
    fly : callable
        ``fly(f, u) -> y``: flight ``f`` with setpoints ``u`` (the shape of ``u0``), measures
        ``y``, shape (R, N) or (R, N, axes) [m], and keeps what the study keeps.
    learn : callable
        ``learn(f, u, y) -> u_next``: the learning step from flight ``f``; ``u_next`` has
        the shape of ``u0`` [m].
    step : callable, optional
        Called after every learning step (progress).

    Returns
    -------
    ndarray, shape of ``u0``
        The setpoints of the last flight [m].
    """
    u = u0
    for f in range(flights):
        y = fly(f, u)
        if f == flights - 1:
            break
        u = learn(f, u, y)
        if step is not None:
            step()
    return u


def diverged(first: np.ndarray, steady: np.ndarray) -> np.ndarray:
    """The divergence rule of every study: the steady state is not below the first trial.

    Parameters
    ----------
    first : ndarray, shape (P,)
        Error of trial 0 per plant (e_pos or error norm) [m].
    steady : ndarray, shape (P,)
        Mean error of the steady-state trials per plant [m].

    Returns
    -------
    ndarray of bool, shape (P,)
        True where ``steady > first`` or either is NaN or inf.
    """
    with np.errstate(invalid="ignore"):
        return ~(np.asarray(steady) <= np.asarray(first))


def fly_plants(
    plan: StudyPlan,
    setting: StudySetting,
    level_index: int,
    plants: Sequence[int],
    *,
    batched: bool = True,
) -> list[PlantResult]:
    """Learn on true plants with one setting: trial 0, its repeats, ``iterations`` more.

    Every plant flies the same trial loop (:func:`run_trials`); the learning is one
    :class:`gcs.core.learner.LearnerBatch` for them all (the paper's method and the adaptive
    options batched). A plant's results do
    not depend on the other plants of the batch (its own plant and noise streams).

    Parameters
    ----------
    plan : StudyPlan
        The study.
    setting : StudySetting
        The learning setting.
    level_index : int
        Uncertainty level.
    plants : sequence of int
        Plant numbers.
    batched : bool
        False: a :class:`gcs.core.learner.Learner` per plant (the reference the batch equals).

    Returns
    -------
    list of PlantResult
        One per plant, in order.
    """
    plants = list(plants)
    count = len(plants)
    true = [draw_plant(plan, level_index, p) for p in plants]
    noise_rng = [plant_stream(plan.seed, level_index, p, PLANT_NOISE) for p in plants]
    ref = plan.ref_ne_m
    start = ref[0]
    n = plan.n_samples
    batch = LearnerBatch(
        setting.settings, ref, count, setting.adaptive, setting.repeats, batched=batched
    )
    flights = 1 + batch.repeats + plan.iterations
    e = np.full((count, flights), np.nan)
    active = np.zeros(count, dtype=int)
    updates = np.zeros(count, dtype=int)
    last = ref[:-1][None].repeat(count, axis=0)

    def fly(f: int, u: np.ndarray) -> np.ndarray:
        y = np.full_like(u, np.nan)
        for k in np.flatnonzero(batch.learning):  # a plant whose learning failed lands
            y[k] = true[k].respond(u[k] - start) + start
            y[k] += np.asarray(true[k].noise_std_m) * noise_rng[k].standard_normal((n, 2))
            e[k, f] = epos(ref[1:], y[k])
            last[k] = u[k]
        return y

    def learn(f: int, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        u_next = batch.step(u, y)
        ok = batch.learning
        if f >= batch.repeats:  # the repeats of trial 0 have no update
            updates[ok] += batch.active_constraints.shape[1]
            active[ok] += (batch.active_constraints[ok] > 0).sum(axis=1)
        return u_next

    run_trials(ref[:-1][None].repeat(count, axis=0), flights, fly, learn)
    out = []
    for k in range(count):
        dev = last[k] - ref[:-1]
        out.append(
            PlantResult(
                epos_m=e[k],
                setpoint_rms_m=float(np.sqrt(np.mean(dev**2))),
                limit_active=active[k] / updates[k] if updates[k] else 0.0,
                failed=batch.failed[k],
                setpoints_m=last[k].copy(),
            )
        )
    return out


def fly_plant(plan: StudyPlan, setting: StudySetting, level_index: int, plant: int) -> PlantResult:
    """One plant of :func:`fly_plants`.

    Parameters
    ----------
    plan : StudyPlan
        The study.
    setting : StudySetting
        The learning setting.
    level_index : int
        Uncertainty level.
    plant : int
        Plant number.

    Returns
    -------
    PlantResult
    """
    return fly_plants(plan, setting, level_index, [plant])[0]


def chunk_plants(plan: StudyPlan, chunk: int) -> range:
    """Plant numbers of one chunk.

    Parameters
    ----------
    plan : StudyPlan
        The study.
    chunk : int
        Chunk index, ``0 .. plan.chunks - 1``.

    Returns
    -------
    range
    """
    return range(chunk * plan.chunk_plants, min((chunk + 1) * plan.chunk_plants, plan.plants))


def run_chunk(plan: StudyPlan, setting_index: int, level_index: int, chunk: int) -> dict:
    """One unit of work: every plant of a chunk with one setting at one level.

    Parameters
    ----------
    plan : StudyPlan
        The study.
    setting_index, level_index, chunk : int
        Which setting, level and chunk.

    Returns
    -------
    dict
        JSON-ready: ``setting``, ``level``, ``chunk``, ``plants`` (numbers) and per plant
        ``epos_m`` (list per flight), ``setpoint_rms_m``, ``limit_active``, ``failed``,
        ``draws``.
    """
    setting = plan.settings[setting_index]
    numbers = chunk_plants(plan, chunk)
    out = []
    for p, r in zip(numbers, fly_plants(plan, setting, level_index, numbers), strict=True):
        out.append(
            {
                "plant": p,
                "epos_m": [None if not math.isfinite(x) else float(x) for x in r.epos_m],
                "setpoint_rms_m": r.setpoint_rms_m,
                "limit_active": r.limit_active,
                "failed": r.failed,
                "draws": draw_plant(plan, level_index, p).draws,
            }
        )
    return {"setting": setting_index, "level": level_index, "chunk": chunk, "plants": out}


@dataclass(frozen=True)
class SettingSummary:
    """What one setting did at one level, over the plants.

    Parameters
    ----------
    setting : str
        Setting name.
    level : float
        Uncertainty level.
    epos_mean_m, epos_std_m : tuple of float
        e_pos of trial 0 and of every learned trial (the repeats of trial 0 left out) over
        the plants that did not diverge [m].
    flights_to_floor : float
        Median, over the plants that reached the floor, of the flights (the repeats included)
        until their e_pos was within 1.15 floors; the plants that never did are left out of
        it and counted apart (``plants - reached_floor``). NaN: no noise (no floor), or no
        plant reached it.
    reached_floor : int
        Plants that reached the floor.
    steady_mean_m, steady_std_m : float
        Mean e_pos of the steady state (the last ``steady_trials`` learned trials, see
        :func:`steady_window`) over the plants that did not diverge.
    diverged : int
        Plants whose steady e_pos exceeds trial 0's, or whose learning failed.
    plants : int
        Plants simulated.
    setpoint_rms_m : float
        Mean RMS distance of the last setpoints from the reference [m].
    limit_active : float
        Share of updates with an active limit.
    floor_m : float
        e_pos of the noise alone (what a learner that leaves nothing repeatable scores) [m].
    steady_trials : int
        Learned trials averaged for the steady state.
    """

    setting: str
    level: float
    epos_mean_m: tuple[float, ...]
    epos_std_m: tuple[float, ...]
    flights_to_floor: float
    reached_floor: int
    steady_mean_m: float
    steady_std_m: float
    diverged: int
    plants: int
    setpoint_rms_m: float
    limit_active: float
    floor_m: float
    steady_trials: int = 1

    @property
    def never_reached_floor(self) -> int | None:
        """Plants that never reached the floor (None without noise: no floor)."""
        return self.plants - self.reached_floor if self.floor_m > 0 else None

    def as_dict(self) -> dict:
        """JSON-ready dictionary (NaN and inf as None and strings)."""

        def j(x: float) -> float | str | None:
            return x if math.isfinite(x) else (None if math.isnan(x) else "inf")

        return {
            "setting": self.setting,
            "level": self.level,
            "epos_mean_m": [j(x) for x in self.epos_mean_m],
            "epos_std_m": [j(x) for x in self.epos_std_m],
            "flights_to_floor": j(self.flights_to_floor),
            "reached_floor": self.reached_floor,
            "never_reached_floor": self.never_reached_floor,
            "steady_mean_m": j(self.steady_mean_m),
            "steady_std_m": j(self.steady_std_m),
            "diverged": self.diverged,
            "plants": self.plants,
            "setpoint_rms_m": self.setpoint_rms_m,
            "limit_active": self.limit_active,
            "floor_m": self.floor_m,
            "steady_trials": self.steady_trials,
        }


def noise_floor(noise_std_m: tuple[float, float]) -> float:
    """Expected e_pos of white noise alone: the mean of a 2-D Gaussian's norm [m].

    Parameters
    ----------
    noise_std_m : tuple of float
        Standard deviation per axis [m].

    Returns
    -------
    float
        Exact for equal axes (``sigma sqrt(pi / 2)``); Monte Carlo free approximation
        ``sqrt(pi / 4 (sn^2 + se^2))`` otherwise.
    """
    sn, se = noise_std_m
    return float(math.sqrt(math.pi / 4.0 * (sn * sn + se * se)))


def steady_window(iterations: int, steady_trials: int) -> int:
    """How many of the last learned trials the steady state averages.

    The last ``steady_trials``, but at most the later half of the learned trials (at least
    one): the first learned trials are the transient, never part of the steady state (with
    3 learned trials and ``steady_trials`` 3, trial j = 3 alone, not j = 1..3).

    Parameters
    ----------
    iterations : int
        Learned trials (after trial 0 and its repeats).
    steady_trials : int
        The study's ``steady_trials``.

    Returns
    -------
    int
        ``min(steady_trials, max(1, iterations // 2))``.
    """
    return min(steady_trials, max(1, iterations // 2))


def summarise_setting(
    plan: StudyPlan, setting_index: int, level_index: int, plants: list[dict]
) -> SettingSummary:
    """Reduce the per-plant results of one setting at one level to a summary.

    Parameters
    ----------
    plan : StudyPlan
        The study.
    setting_index, level_index : int
        Which setting and level.
    plants : list of dict
        The ``plants`` entries of every chunk (:func:`run_chunk`), in plant order.

    Returns
    -------
    SettingSummary
    """
    repeats = plan.settings[setting_index].repeats
    flights = np.array([[np.nan if x is None else x for x in p["epos_m"]] for p in plants])
    e = np.concatenate([flights[:, :1], flights[:, 1 + repeats :]], axis=1)  # trials j
    failed = np.array([p["failed"] is not None for p in plants])
    k = steady_window(e.shape[1] - 1, plan.steady_trials)
    steady = e[:, -k:].mean(axis=1)
    gone = failed | diverged(e[:, 0], steady)
    kept = e[~gone]
    floor = noise_floor(plan.uncertainty.noise_std_m)
    nan = float("nan")
    if floor > 0:
        hit = flights <= FLOOR_FACTOR * floor  # counted in flights, the repeats included
        got_there = hit.any(axis=1)
        first = hit.argmax(axis=1)[got_there] + 1  # "never" is no count: left out, counted
        reached = int(got_there.sum())
        to_floor = float(np.median(first)) if reached else nan
    else:
        reached, to_floor = 0, nan
    with np.errstate(invalid="ignore"):
        mean = kept.mean(axis=0) if kept.size else np.full(e.shape[1], nan)
        std = kept.std(axis=0, ddof=1) if kept.shape[0] > 1 else np.zeros(e.shape[1])
    sk = steady[~gone]
    return SettingSummary(
        setting=plan.settings[setting_index].name,
        level=plan.uncertainty.levels[level_index],
        epos_mean_m=tuple(float(x) for x in mean),
        epos_std_m=tuple(float(x) for x in std),
        flights_to_floor=to_floor,
        reached_floor=reached,
        steady_mean_m=float(sk.mean()) if sk.size else nan,
        steady_std_m=float(sk.std(ddof=1)) if sk.size > 1 else 0.0,
        diverged=int(gone.sum()),
        plants=len(plants),
        setpoint_rms_m=float(np.mean([p["setpoint_rms_m"] for p in plants])),
        limit_active=float(np.mean([p["limit_active"] for p in plants])),
        floor_m=floor,
        steady_trials=k,
    )


def recommend(summaries: list[SettingSummary]) -> tuple[str, str]:
    """The setting to fly, and why.

    Rule: fewest diverged plants over every level; then the lowest steady e_pos averaged
    over the levels; then the fewest plants that never reached the floor; then the fewest
    flights to the floor (the median of the plants that reached it, averaged over the levels).

    Parameters
    ----------
    summaries : list of SettingSummary
        Every setting at every level.

    Returns
    -------
    name : str
        The recommended setting.
    reason : str
        One sentence with the figures behind the choice.
    """
    names = list(dict.fromkeys(s.setting for s in summaries))

    def key(name: str) -> tuple[int, float, int, float]:
        rows = [s for s in summaries if s.setting == name]
        steady = [s.steady_mean_m for s in rows]
        floor = [s.flights_to_floor for s in rows if not math.isnan(s.flights_to_floor)]
        return (
            sum(s.diverged for s in rows),
            float(np.mean(steady)) if all(math.isfinite(x) for x in steady) else math.inf,
            sum(s.never_reached_floor or 0 for s in rows),
            float(np.mean(floor)) if floor else math.inf,
        )

    ranked = sorted(names, key=key)
    best = ranked[0]
    div, steady, _, floor = key(best)
    reason = (
        f"{div} diverged plants over every level, the lowest mean steady e_pos "
        f"({1000 * steady:.1f} mm) among the settings with that few"
    )
    if len(ranked) > 1:
        d2, s2, _, _ = key(ranked[1])
        reason += f"; next: {ranked[1]} ({d2} diverged, {1000 * s2:.1f} mm)"
    rows = [s for s in summaries if s.setting == best and s.floor_m > 0]
    if rows:
        reached = sum(s.reached_floor for s in rows)
        plants = sum(s.plants for s in rows)
        if math.isfinite(floor):
            reason += (
                f"; the floor in {floor:g} flights (median of the {reached} of {plants} "
                "plants that reached it)"
            )
        else:
            reason += f"; none of its {plants} plants reached the floor"
    return best, reason
