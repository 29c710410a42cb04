"""The mock-gps profile against the shared PX4 v1.16 SITL data (GPS + EKF2), side by side.

Computes the same statistics on the shared run directories (the recorded PX4 v1.16 SITL runs, read
only) and on the mock drone's physics flown offline (no network, ``gcs.mock.physics``), and,
with ``--run DIR``, on a live run directory of the repeat experiment flown on the mock:

- **repeat**: the same setpoints flown four times in one session (``repeat/``, profile
  ``profile-repeat.yaml``): pairwise horizontal RMS differences between the flights and each
  flight's RMS deviation from the four-flight mean (reported positions, all 281 samples);
- **hover**: the first second of every trial that starts in hover (the start point after the
  settle and the 4 s hold): distance from the point, speed over it, fast noise
  (``gcs.flight.hover.hover_stats``);
- **velocity disagreement**: the reported velocity against the derivative of the reported
  position, ``d(pos)/dt - vel`` [m/s], averaged over 5 s (one north period of the eight, two
  east ones, so that the manoeuvre's own harmonics cancel) and its RMS per axis, over the
  eight flights and over the identification runs. A GPS-aided estimator's velocity error
  shows here (``gcs.mock.estimator``); an estimate that agrees with itself gives 0;
- **identification residual**: what a linear model of the loop cannot explain in the two
  60 s PRBS experiments of ``identify/`` (the mock flies the same setpoints): per axis, the
  residual of a least-squares FIR model (3 s of taps plus a constant), its RMS and the share
  of its power below 0.1 Hz, 0.1-0.5 Hz and above 0.5 Hz;
- **steps**: eight steps of +-1 m on x, 12 s each from hover, as in the notes of the recorded PX4
  data (its figures: wn about 1.0 rad/s, zeta 0.5-0.85, gain 0.91, no measurable dead time); the
  mock's mean response of the eight fitted with ``gcs.mock.physics.fit_step_response``, per
  seed: median (range over the seeds);
- **truth** (mock only): the estimator error against the true position during the trials
  (the notes of the recorded PX4 data: 0.1-0.2 m RMS horizontally, up to 0.6 m).

The mock offline follows the campaign of ``gcs fly`` as it matters here: take-off hover at the
start point, hold 4 s, measure 10 s (tolerances from ``gcs.flight.hover.judge_hover`` with the
profile's ``flight`` settings), then per trial: settle (``is_settled``), hold 4 s, fly the
setpoints (setpoint k from k t_ilc, sampled at k t_ilc), move back (minimum-jerk, 1 m/s).
Telemetry is sampled on the 0.05 s grid directly (gcs interpolates 50 Hz samples onto it).

Usage::

    .venv/bin/python benchmarks/mock_gps_calibration.py [--mock-config profiles/mock-gps.yaml]
        [--seeds 0-9] [--run logs/<repeat run>] [--json]
"""

from __future__ import annotations

import argparse
import glob
import itertools
import json
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from px4_data import shared  # noqa: E402

from gcs.flight.hover import hover_stats, is_settled, judge_hover  # noqa: E402
from gcs.io.config import load_profile  # noqa: E402
from gcs.io.settings import FlightSettings  # noqa: E402
from gcs.mock.config import MockConfig, load_mock_config  # noqa: E402
from gcs.mock.physics import QuadPhysics, Target, fit_step_response  # noqa: E402

SITL = shared() / "data" / "px4-sitl"
T_ILC_S = 0.05
SLOW_S = 5.0  # averaging span of the velocity disagreement [s]
FIR_TAPS = 60  # 3 s at 0.05 s
BANDS_HZ = ((0.0, 0.1), (0.1, 0.5), (0.5, 10.0))
STEP_FIGURES = {"wn_rad_s": "about 1.0", "zeta": "0.5-0.85", "gain": "0.91", "delay_s": "none"}
README_TRUTH = {"rms_m": "0.1-0.2", "max_m": "up to 0.6"}


# -- statistics (the same code for the shared data and the mock) ------------------------------


def repeat_stats(flights: list[np.ndarray]) -> dict[str, list[float]]:
    """Pairwise RMS differences and per-flight RMS deviations from the mean.

    ``flights``: (N, 2) reported north/east positions of identical setpoints, each [m].
    """
    pos = np.array(flights)
    pairwise = [
        float(np.sqrt(np.mean(np.sum((pos[a] - pos[b]) ** 2, axis=1))))
        for a, b in itertools.combinations(range(len(pos)), 2)
    ]
    mean = pos.mean(axis=0)
    deviation = [float(np.sqrt(np.mean(np.sum((p - mean) ** 2, axis=1)))) for p in pos]
    return {"pairwise_m": pairwise, "deviation_m": deviation}


def velocity_disagreement(t_s: np.ndarray, pos: np.ndarray, vel: np.ndarray) -> np.ndarray:
    """RMS per axis (north, east, down) of ``d(pos)/dt - vel`` averaged over SLOW_S [m/s]."""
    dt = np.diff(t_s)[:, None]
    r = np.diff(pos, axis=0) / dt - 0.5 * (vel[1:] + vel[:-1])
    n = int(round(SLOW_S / T_ILC_S))
    if len(r) < n:
        return np.full(3, math.nan)
    kernel = np.ones(n) / n
    slow = np.column_stack([np.convolve(r[:, i], kernel, mode="valid") for i in range(3)])
    return np.sqrt(np.mean(slow**2, axis=0))


def fir_residual(u: np.ndarray, y: np.ndarray, taps: int = FIR_TAPS) -> np.ndarray:
    """Residual of the least-squares FIR model ``y(k) = c + sum_i h_i u(k - i)``, i < taps."""
    n = len(y)
    rows = np.column_stack([np.ones(n - taps)] + [u[taps - i : n - i] for i in range(taps)])
    target = y[taps:]
    coef, *_ = np.linalg.lstsq(rows, target, rcond=None)
    return target - rows @ coef


def band_shares(x: np.ndarray, dt_s: float = T_ILC_S) -> list[float]:
    """Share of the power of ``x`` (demeaned) in each of BANDS_HZ."""
    spec = np.abs(np.fft.rfft(x - x.mean())) ** 2
    f = np.fft.rfftfreq(len(x), dt_s)
    total = spec[1:].sum()
    return [float(spec[(f >= lo) & (f < hi) & (f > 0)].sum() / total) for lo, hi in BANDS_HZ]


def residual_stats(flights: list[tuple[np.ndarray, np.ndarray]]) -> dict[str, list[float]]:
    """Per axis: RMS of the FIR residual [m] and its band shares, averaged over the flights.

    ``flights``: (setpoints (N, 2), reported positions (N, 2)) per experiment.
    """
    rms, shares = [], []
    for u, y in flights:
        for axis in range(2):
            res = fir_residual(u[:, axis], y[:, axis])
            rms.append(float(np.sqrt(np.mean(res**2))))
            shares.append(band_shares(res))
    r = np.array(rms).reshape(-1, 2)
    s = np.array(shares).reshape(-1, 2, len(BANDS_HZ))
    return {
        "rms_x_m": r[:, 0].tolist(),
        "rms_y_m": r[:, 1].tolist(),
        "share_x": s[:, 0].mean(axis=0).tolist(),
        "share_y": s[:, 1].mean(axis=0).tolist(),
    }


@dataclass(frozen=True)
class Flight:
    """One recorded trial on the 0.05 s grid: times [s], reported position and velocity (N, 3),
    setpoints (N, 3); truth and estimator error (N, 3) for the mock only."""

    t_s: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    sp: np.ndarray
    true_pos: np.ndarray | None = None


def _columns(t: np.ndarray, prefix: str, unit: str) -> np.ndarray:
    return np.column_stack([t[f"{prefix}_{axis}_{unit}"] for axis in ("north", "east", "down")])


def read_trial(path: Path) -> Flight:
    """A trial CSV of a gcs run directory."""
    t = np.genfromtxt(path, delimiter=",", names=True)
    return Flight(
        t["t_s"], _columns(t, "pos", "m"), _columns(t, "vel", "m_s"), _columns(t, "sp", "m")
    )


def read_trials(run_dir: Path) -> list[Flight]:
    """Every trial CSV of a run directory, in order (complete or not: the JSON is not read)."""
    return [read_trial(Path(p)) for p in sorted(glob.glob(str(run_dir / "trial-*.csv")))]


def starts_in_hover(f: Flight) -> bool:
    """The first second holds the start point (learned setpoints may move at once)."""
    return bool(np.allclose(f.sp[:21], f.sp[0], atol=1e-3))


def hover_rows(flights: list[Flight]) -> list[dict[str, float]]:
    """Hover statistics of the first second of the flights that start in hover."""
    rows = []
    for f in flights:
        if not starts_in_hover(f):
            continue
        s = hover_stats(f.t_s[:21], f.pos[:21], f.sp[0])
        rows.append(
            {"offset_m": s.offset_m, "speed_m_s": s.speed_p50_m_s, "noise_cm": 100 * s.noise_m}
        )
    return rows


def summary(flights: list[Flight], repeats: list[list[Flight]], identify: list[Flight]) -> dict:
    """Every statistic of one source (shared data, mock offline, live run)."""
    out: dict = {}
    rep = [repeat_stats([f.pos[:, :2] for f in group]) for group in repeats]
    out["pairwise_m"] = [x for r in rep for x in r["pairwise_m"]]
    out["deviation_m"] = [x for r in rep for x in r["deviation_m"]]
    out["session_pairwise_m"] = [float(np.mean(r["pairwise_m"])) for r in rep]
    out["session_deviation_m"] = [float(np.mean(r["deviation_m"])) for r in rep]
    out["hover"] = hover_rows(flights)
    eight = [velocity_disagreement(f.t_s, f.pos, f.vel) for f in flights]
    out["vel_disagreement_eight_m_s"] = np.array(eight).T.tolist() if eight else []
    if identify:
        ident = [velocity_disagreement(f.t_s, f.pos, f.vel) for f in identify]
        out["vel_disagreement_identify_m_s"] = np.array(ident).T.tolist()
        out["residual"] = residual_stats([(f.sp[:, :2], f.pos[:, :2]) for f in identify])
    truth = [f for f in flights if f.true_pos is not None]
    if truth:
        err = np.concatenate(
            [np.linalg.norm(f.pos[:, :2] - f.true_pos[:, :2], axis=1) for f in truth]
        )
        per = [
            float(np.sqrt(np.mean(np.sum((f.pos[:, :2] - f.true_pos[:, :2]) ** 2, axis=1))))
            for f in truth
        ]
        out["truth"] = {"rms_m": per, "max_m": float(err.max())}
    return out


# -- the shared data ----------------------------------------------------------------------------


def shared_summary(vision: bool = False) -> dict:
    """Statistics of the shared GPS (or vision) run directories."""
    prefix = "vision-" if vision else ""
    dirs = [
        p
        for p in sorted(SITL.glob(f"{prefix}*"))
        if p.is_dir() and (vision or not p.name.startswith("vision-"))
    ]
    flights, identify = [], []
    for d in dirs:
        trials = read_trials(d)
        (identify if d.name.endswith("identify") else flights).extend(trials)
    repeat = read_trials(SITL / f"{prefix}repeat")
    return summary(flights, [repeat], identify)


# -- the calibration (--fit): every parameter from the shared data -----------------------------

FIT_LAGS_S = (0.5, 8.0)  # lags of the autocovariance fit [s]: above the manoeuvre's artefacts
GUST_GRID = {"gust_sigma_m_s2": (0.2, 0.25, 0.3, 0.35, 0.4), "gust_tau_s": (0.1, 0.2, 0.3, 0.5)}
TRUTH_RMS_M = 0.15  # the middle of the recorded PX4 data's 0.1-0.2 m (estimate - truth, horizontal)


def disagreement_autocovariance(flights: list[Flight], max_lag: int = 200) -> np.ndarray:
    """Pooled autocovariance (max_lag + 1, 3) of ``d(pos)/dt - vel`` over the flights."""
    num, count = np.zeros((max_lag + 1, 3)), np.zeros(max_lag + 1)
    for f in flights:
        r = np.diff(f.pos, axis=0) / np.diff(f.t_s)[:, None] - 0.5 * (f.vel[1:] + f.vel[:-1])
        for lag in range(min(max_lag + 1, len(r))):
            num[lag] += np.sum(r[: len(r) - lag] * r[lag:], axis=0)
            count[lag] += len(r) - lag
    return num / count[:, None]


def fit_velocity_error() -> dict[str, list[float] | float]:
    """The estimator's velocity error and aiding time constant from the shared flights.

    ``d(pos)/dt - vel`` of the GPS flights less that of the vision flights (the manoeuvre's own
    artefacts, the same in both), fitted per axis by ``sigma^2 exp(-lag / tau)`` over
    FIT_LAGS_S: in the model it is ``-(p_err - g) / T``, the velocity error low-passed by T.
    With no aiding error the position error is ``T`` times it, so T sets the README's
    estimate-to-truth RMS; the velocity error's own sigma is then ``sigma sqrt((tau + T) / tau)``.
    """
    import scipy.optimize

    def flights(vision: bool) -> list[Flight]:
        dirs = [d for d in sorted(SITL.iterdir()) if d.is_dir()]
        return [f for d in dirs if d.name.startswith("vision-") == vision for f in read_trials(d)]

    cov = disagreement_autocovariance(flights(False)) - disagreement_autocovariance(flights(True))
    lags = np.arange(cov.shape[0]) * T_ILC_S
    sel = (lags >= FIT_LAGS_S[0]) & (lags <= FIT_LAGS_S[1])
    sigma_r, tau = [], []
    for axis in range(3):
        (var, t), _ = scipy.optimize.curve_fit(
            lambda lag, var, t: var * np.exp(-lag / t), lags[sel], cov[sel, axis], p0=(0.05, 3.0)
        )
        sigma_r.append(float(np.sqrt(var)))
        tau.append(float(t))
    t_aid = TRUTH_RMS_M / math.hypot(sigma_r[0], sigma_r[1])
    sigma_v = [s * math.sqrt((t + t_aid) / t) for s, t in zip(sigma_r, tau, strict=True)]
    return {
        "disagreement_sigma_ned_m_s": sigma_r,
        "vel_sigma_ned_m_s": sigma_v,
        "vel_tau_ned_s": tau,
        "aid_time_constant_s": t_aid,
    }


def largest_jump() -> tuple[float, float]:
    """Largest one-sample step of the reported position beyond its velocity [m] in the shared
    GPS flights (against a 1 s running median), and their total duration [s]."""
    from scipy.ndimage import median_filter

    jump, duration = 0.0, 0.0
    for d in sorted(SITL.iterdir()):
        if not d.is_dir() or d.name.startswith("vision-"):
            continue
        for f in read_trials(d):
            dt = np.diff(f.t_s)[:, None]
            r = np.diff(f.pos[:, :2], axis=0) / dt - 0.5 * (f.vel[1:, :2] + f.vel[:-1, :2])
            fast = (r - median_filter(r, size=(21, 1))) * dt
            jump = max(jump, float(np.abs(fast).max()))
            duration += float(f.t_s[-1] - f.t_s[0])
    return jump, duration


def _mean_noise(stats: dict) -> float:
    return float(np.mean([row["noise_cm"] for row in stats["hover"]]))


def fit_gusts(cfg: MockConfig, settings: FlightSettings, seeds: list[int]) -> list[dict]:
    """The vehicle's own jitter: gusts that give the vision repeat experiment's figures.

    The mock with its estimator off (the truth is known, as with a perfect motion-capture
    feed) flies ``vision-repeat/``'s setpoints; the grid point whose mean pairwise difference,
    mean per-flight deviation and mean fast noise of the hovers are nearest (in log ratio) to
    the shared ones comes first. The two repeat figures alone fix only the gusts' low-frequency
    power (sigma^2 tau); the hovers' fast noise separates sigma from tau.
    """
    target = summary([], [read_trials(SITL / "vision-repeat")], [])
    shared_vision = shared_summary(vision=True)
    sp = read_trial(SITL / "vision-repeat" / "trial-000.csv").sp[:-1]
    off = replace(cfg, estimator=replace(cfg.estimator, enabled=False))
    rows = []
    for sigma, tau in itertools.product(*GUST_GRID.values()):
        c = replace(
            off, disturbance=replace(off.disturbance, gust_sigma_m_s2=sigma, gust_tau_s=tau)
        )
        groups = [mock_session(c, seed, [sp] * 4, settings) for seed in seeds]
        got = summary([f for g in groups for f in g], groups, [])
        r = ratios(target, got)
        r["noise"] = _mean_noise(got) / _mean_noise(shared_vision)
        cost = sum(math.log(x) ** 2 for x in r.values())
        rows.append({"gust_sigma_m_s2": sigma, "gust_tau_s": tau, **r, "cost": cost})
    return sorted(rows, key=lambda row: row["cost"])


# -- the mock, offline --------------------------------------------------------------------------


class OfflineVehicle:
    """The mock's physics flown like ``gcs fly`` flies it, without the network.

    Parameters
    ----------
    cfg : MockConfig
        Mock profile.
    seed : int
        The mock's seed.
    start_ned_m : array_like, shape (3,)
        Where it hovers after take-off.
    """

    def __init__(self, cfg: MockConfig, seed: int, start_ned_m: np.ndarray) -> None:
        self.sim = QuadPhysics(cfg, seed=seed, pos_ned_m=tuple(float(x) for x in start_ned_m))
        self.target = np.asarray(start_ned_m, dtype=float)
        self.sim.command(0.0, Target(tuple(self.target)))

    def _sample(self) -> tuple[np.ndarray, np.ndarray]:
        pos, vel = self.sim.measure()
        return np.array(pos), np.array(vel)

    def hold(self, duration_s: float, dt_s: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
        """Hold the current target; samples (t, pos) at 50 Hz."""
        t0 = self.sim.t_s
        ts, ps = [], []
        for k in range(1, int(round(duration_s / dt_s)) + 1):
            self.sim.advance_to(t0 + k * dt_s)
            ts.append(self.sim.t_s)
            ps.append(self._sample()[0])
        return np.array(ts), np.array(ps)

    def goto(self, ned_m: np.ndarray, speed_m_s: float = 1.0) -> None:
        """Minimum-jerk move at 60 Hz, as ``gcs.flight.manoeuvres.Manoeuvres.goto``."""
        start, target = self.target, np.asarray(ned_m, dtype=float)
        n = max(1, math.ceil(1.875 * np.linalg.norm(target - start) / speed_m_s * 60))
        t0 = self.sim.t_s
        for i in range(1, n + 1):
            s = i / n
            p = start + (10 * s**3 - 15 * s**4 + 6 * s**5) * (target - start)
            self.sim.advance_to(t0 + i / 60)
            self.sim.command(self.sim.t_s, Target(tuple(p)))
        self.target = target

    def settle(self, tolerance_m: float, speed_m_s: float, settings: FlightSettings) -> bool:
        """Wait until ``is_settled`` over ``settle_time_s``; False after ``settle_timeout_s``."""
        window = settings.settle_time_s + 1.0
        ts, ps = self.hold(window)
        t_end = self.sim.t_s + settings.settle_timeout_s - window
        while not is_settled(ts, ps, self.target, tolerance_m, speed_m_s, settings.settle_time_s):
            if self.sim.t_s >= t_end:
                return False
            t, p = self.hold(0.1)
            ts, ps = np.concatenate([ts, t])[-150:], np.concatenate([ps, p])[-150:]
        return True

    def fly(self, setpoints: np.ndarray) -> Flight:
        """Setpoint k from k t_ilc; samples k = 0..N on the grid (the trial's N + 1 rows)."""
        t0 = self.sim.t_s
        n = len(setpoints)
        rows = []
        for k in range(n + 1):
            self.sim.advance_to(t0 + k * T_ILC_S)
            pos, vel = self._sample()
            rows.append((pos, vel, np.array(self.sim.pos)))
            if k < n:
                self.sim.command(self.sim.t_s, Target(tuple(setpoints[k])))
        self.target = setpoints[-1]
        pos, vel, true = (np.array(c) for c in zip(*rows, strict=True))
        sp = np.vstack([setpoints, setpoints[-1:]])
        return Flight(np.arange(n + 1) * T_ILC_S, pos, vel, sp, true)


def mock_session(
    cfg: MockConfig, seed: int, setpoints: list[np.ndarray], settings: FlightSettings
) -> list[Flight]:
    """One ``gcs fly`` session offline: hover measurement, then settle, hold, fly per trial."""
    start = setpoints[0][0]
    v = OfflineVehicle(cfg, seed, start)
    v.hold(settings.hover_before_trial_s)
    t, p = v.hold(settings.hover_measure_s)
    verdict = judge_hover(hover_stats(t, p, start), settings)
    flights = []
    for sp in setpoints:
        v.goto(sp[0])
        v.settle(verdict.tolerance_m, verdict.speed_tolerance_m_s, settings)
        v.hold(settings.hover_before_trial_s)
        flights.append(v.fly(sp))
    return flights


def mock_steps(cfg: MockConfig, seed: int) -> tuple[np.ndarray, np.ndarray, list]:
    """Eight +-1 m steps on x from hover at 2 m, 12 s each: mean unit response and fits."""
    v = OfflineVehicle(cfg, seed, np.array([0.0, 0.0, -2.0]))
    v.hold(12.0)
    responses, fits, level = [], [], 0.0
    for _ in range(8):
        new = 1.0 - level
        before = v.sim.measure()[0][0]
        v.sim.command(v.sim.t_s, Target((new, 0.0, -2.0)))
        t, p = v.hold(12.0, dt_s=T_ILC_S)
        t = np.concatenate([[0.0], t - t[0] + T_ILC_S])
        y = (np.concatenate([[before], p[:, 0]]) - level) / (new - level)
        responses.append(y)
        fits.append(fit_step_response(t, y))
        level = new
    mean = np.mean(responses, axis=0)
    return t, mean, fits


def mock_summary(cfg: MockConfig, seeds: list[int], settings: FlightSettings) -> dict:
    """Statistics of the mock offline: the repeat session per seed, identify, steps."""
    repeat_sp = read_trial(SITL / "repeat" / "trial-000.csv").sp[:-1]
    ident_sp = [f.sp[:-1] for f in read_trials(SITL / "identify")]
    flights, repeats, identify = [], [], []
    for seed in seeds:
        group = mock_session(cfg, seed, [repeat_sp] * 4, settings)
        repeats.append(group)
        flights.extend(group)
        identify.extend(mock_session(cfg, seed, ident_sp, settings))
    out = summary(flights, repeats, identify)
    fits = []
    for seed in seeds:
        t, mean, _ = mock_steps(cfg, seed)
        fits.append(fit_step_response(t, mean))
    out["steps"] = {
        key: [getattr(f, key) for f in fits] for key in ("wn_rad_s", "zeta", "gain", "delay_s")
    }
    return out


def run_trials(run_dir: Path) -> list[Flight]:
    """The complete trials of a live repeat run directory (at least two)."""
    from gcs.io.rundir import RunDir

    done = RunDir.open(run_dir).complete_trials()
    if len(done) < 2:
        raise SystemExit(f"{run_dir}: {len(done)} complete trial(s), the repeat needs two or more")
    return [read_trial(run_dir / f"trial-{j:03d}.csv") for j in done]


# -- output -------------------------------------------------------------------------------------


def _range(values: list[float], fmt: str = "{:.2f}") -> str:
    if not values:
        return "-"
    a = np.asarray(values, dtype=float)
    return f"{fmt.format(a.min())}-{fmt.format(a.max())} (mean {fmt.format(a.mean())})"


def _shares(shares: list[float]) -> str:
    return " / ".join(f"{s:.2f}" for s in shares)


def _hover(rows: list[dict[str, float]], key: str, fmt: str = "{:.2f}") -> str:
    return _range([r[key] for r in rows], fmt)


def table(columns: dict[str, dict]) -> str:
    """Markdown table, one column per source."""
    lines = ["| statistic | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]

    def row(name: str, cell) -> None:  # type: ignore[no-untyped-def]
        cells = []
        for c in columns.values():
            try:
                cells.append(cell(c))
            except (KeyError, IndexError, ValueError):
                cells.append("-")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")

    row("repeat: pairwise RMS difference [m]", lambda c: _range(c["pairwise_m"]))
    row("repeat: per-flight RMS deviation from the mean [m]", lambda c: _range(c["deviation_m"]))
    row(
        "repeat: a session's mean pairwise difference [m]",
        lambda c: _range(c["session_pairwise_m"]),
    )
    row("repeat: a session's mean deviation [m]", lambda c: _range(c["session_deviation_m"]))
    row(
        "hover (first s of a trial): distance from the point [m]",
        lambda c: _hover(c["hover"], "offset_m"),
    )
    row("hover: speed [m/s]", lambda c: _hover(c["hover"], "speed_m_s"))
    row("hover: fast noise [cm]", lambda c: _hover(c["hover"], "noise_cm", "{:.1f}"))
    for i, axis in enumerate(("north", "east", "down")):
        row(
            f"velocity disagreement, eight flights, {axis} [m/s]",
            lambda c, i=i: _range(c["vel_disagreement_eight_m_s"][i], "{:.3f}"),
        )
    for i, axis in enumerate(("north", "east")):
        row(
            f"velocity disagreement, identify runs, {axis} [m/s]",
            lambda c, i=i: _range(c["vel_disagreement_identify_m_s"][i], "{:.3f}"),
        )
    for axis in ("x", "y"):
        row(
            f"identify residual RMS, {axis} [m]",
            lambda c, a=axis: _range(c["residual"][f"rms_{a}_m"], "{:.3f}"),
        )
        row(
            f"identify residual power <0.1 / 0.1-0.5 / >0.5 Hz, {axis}",
            lambda c, a=axis: _shares(c["residual"][f"share_{a}"]),
        )
    row("steps: wn [rad/s]", lambda c: c["steps_text"]["wn_rad_s"])
    row("steps: zeta", lambda c: c["steps_text"]["zeta"])
    row("steps: gain", lambda c: c["steps_text"]["gain"])
    row("steps: dead time [s]", lambda c: c["steps_text"]["delay_s"])
    row("estimate - truth, horizontal RMS per flight [m]", lambda c: c["truth_text"]["rms_m"])
    row("estimate - truth, largest [m]", lambda c: c["truth_text"]["max_m"])
    return "\n".join(lines)


def _steps_text(steps: dict) -> dict[str, str]:
    """Median and range over the sessions of the eight steps' mean-response fits."""
    return {key: f"{np.median(v):.2f} ({min(v):.2f}-{max(v):.2f})" for key, v in steps.items()}


def ratios(shared_stats: dict, other: dict) -> dict[str, float]:
    """Mean pairwise and mean deviation of ``other`` over the shared ones' (1 = equal)."""
    return {
        key: float(np.mean(other[key]) / np.mean(shared_stats[key]))
        for key in ("pairwise_m", "deviation_m")
    }


def print_fit(cfg: MockConfig, settings: FlightSettings, seeds: list[int]) -> None:
    """The estimator's and the gusts' parameters from the shared data (``--fit``)."""
    fit = fit_velocity_error()
    print(
        f"estimator (d(pos)/dt - vel, GPS less vision, lags {FIT_LAGS_S[0]:g}-{FIT_LAGS_S[1]:g} s):"
    )
    for key, value in fit.items():
        shown = [round(v, 3) for v in value] if isinstance(value, list) else round(value, 3)
        print(f"  {key}: {shown}")
    jump, duration = largest_jump()
    print(
        f"  largest one-sample jump in the GPS flights: {100 * jump:.1f} cm in {duration:.0f} s "
        "(reset_rate_1_s: 0 unless a jump stands out)"
    )
    print(f"gusts (estimator off, vision-repeat/, seeds {seeds[0]}-{seeds[-1]}), best first:")
    for row in fit_gusts(cfg, settings, seeds)[:5]:
        print("  " + ", ".join(f"{k} {v:.3g}" for k, v in row.items()))


def parse_seeds(text: str) -> list[int]:
    """``0-9`` or ``0,3,5``."""
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mock-config", type=Path, default=ROOT / "profiles" / "mock-gps.yaml")
    parser.add_argument(
        "--profile",
        type=Path,
        default=SITL / "profile-repeat.yaml",
        help="gcs profile: the flight settings of the offline campaign",
    )
    parser.add_argument("--seeds", default="0-9")
    parser.add_argument(
        "--run",
        type=Path,
        action="append",
        default=[],
        help="a live repeat run directory, one session (may repeat: one column for all)",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")
    parser.add_argument("--fit", action="store_true", help="fit the profile's noise parameters")
    args = parser.parse_args()

    cfg = load_mock_config(args.mock_config)
    profile = load_profile(args.profile)
    settings = profile.flight
    if args.fit:
        print_fit(cfg, settings, parse_seeds(args.seeds))
        return
    gps = shared_summary()
    gps["steps_text"] = STEP_FIGURES
    gps["truth_text"] = README_TRUTH
    mock = mock_summary(cfg, parse_seeds(args.seeds), settings)
    mock["steps_text"] = _steps_text(mock["steps"])
    mock["truth_text"] = {
        "rms_m": _range(mock["truth"]["rms_m"]),
        "max_m": f"{mock['truth']['max_m']:.2f}",
    }
    columns = {"PX4 SITL, GPS (shared)": gps, f"mock offline, seeds {args.seeds}": mock}
    sessions = [run_trials(run) for run in args.run]
    if sessions:  # one column, each run a session of its own
        flights = [f for group in sessions for f in group]
        columns[f"mock live, {len(sessions)} session(s)"] = summary(flights, sessions, [])
    if args.json:
        print(json.dumps({name: c for name, c in columns.items()}, default=float))
        return
    print(table(columns))
    print()
    for name, c in columns.items():
        if c is not gps:
            r = ratios(gps, c)
            per = ", ".join(
                f"{p / np.mean(gps['pairwise_m']):.2f} / {d / np.mean(gps['deviation_m']):.2f}"
                for p, d in zip(c["session_pairwise_m"], c["session_deviation_m"], strict=True)
            )
            print(
                f"{name}: mean pairwise / shared {r['pairwise_m']:.2f}, mean deviation / shared "
                f"{r['deviation_m']:.2f}; per session (pairwise / deviation): {per}"
            )


if __name__ == "__main__":
    main()
