"""A synthetic run directory: trials 'flown' by a simulated closed loop (no vehicle)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gcs.core.model import DiscreteModel, from_transfer_function, simulate
from gcs.core.trials import trial_errors
from gcs.io.config import (
    Profile,
    load_profile,
    load_trajectory,
    profile_from_dict,
    trajectory_from_dict,
)
from gcs.io.records import TrialRecord, TrialStatus
from gcs.io.rundir import RunDir

ROOT = Path(__file__).resolve().parents[1]
SHORT = {
    "name": "tiny",
    "type": "eight",
    "center_ned_m": [0.0, 0.0, -1.5],
    "amplitude_north_m": 0.6,
    "amplitude_east_m": 0.6,
    "period_s": 4.0,
    "loops": 1,
    "ramp_s": 1.0,
    "hover_s": 0.5,
}


def profile() -> Profile:
    return load_profile(ROOT / "profiles" / "antx.yaml")


def true_plants() -> tuple[DiscreteModel, DiscreteModel]:
    """A 'vehicle' that the profile's eq. (11) describes imperfectly."""
    return (
        from_transfer_function([0.09, 2.2], [1, 1.6, 2.3], 0.25, 0.05),
        from_transfer_function([0.07, 1.8], [1, 1.9, 1.85], 0.25, 0.05),
    )


def synthetic_positions(
    run: RunDir,
    sp: np.ndarray,
    seed: int,
    plants: tuple[DiscreteModel, DiscreteModel] | None = None,
    gust_m: float = 0.0,
) -> np.ndarray:
    """Positions y(0..N) of the synthetic vehicle flying setpoints ``sp`` (N, 3).

    ``plants`` default :func:`true_plants`; a repeatable disturbance, 2 mm white noise, and
    with ``gust_m`` a non-repeatable error correlated in time (white noise averaged over
    0.75 s, scaled to this standard deviation [m]).
    """
    ref = run.reference()
    start = ref.pos_ned_m[0]
    rng = np.random.default_rng(seed)
    pos = np.tile(start, (run.n_samples + 1, 1))
    for a, plant in enumerate(plants or true_plants()):
        drift = 0.05 * np.sin(0.7 * ref.t_s[1:]) ** 2  # repeatable disturbance
        pos[1:, a] = start[a] + simulate(plant, sp[:, a] - start[a]) + drift
        pos[1:, a] += rng.normal(0.0, 0.002, run.n_samples)
        if gust_m > 0:
            gust = np.convolve(rng.standard_normal(run.n_samples), np.ones(15), mode="same")
            pos[1:, a] += gust_m * gust / np.sqrt(15)
    return pos


def fly_synthetic(
    run: RunDir,
    j: int,
    seed: int = 0,
    plants: tuple[DiscreteModel, DiscreteModel] | None = None,
    gust_m: float = 0.0,
) -> TrialRecord:
    """Simulate trial j from its setpoints file and record it as complete (see
    :func:`synthetic_positions`; the noise is seeded with ``seed + j``)."""
    ref = run.reference()
    sp = run.read_setpoints(j)
    pos = synthetic_positions(run, sp, seed + j, plants, gust_m)
    vel = np.gradient(pos, run.t_ilc_s, axis=0)
    record = TrialRecord(
        t_s=ref.t_s,
        ref_ned_m=ref.pos_ned_m,
        sp_ned_m=np.vstack([sp, sp[-1]]),
        pos_ned_m=pos,
        vel_ned_m_s=vel,
        sp_sent_s=np.append(ref.t_s[:-1], np.nan),
        interpolated=np.zeros(run.n_samples + 1, dtype=bool),
    )
    e, m = trial_errors(record)
    run.write_trial(j, record, TrialStatus(j, True, epos_m=e, max_err_m=m))
    return record


def make_run(tmp: Path, algorithm: str = "smoother", trials: int = 1) -> RunDir:
    """A run of the tiny eight with ``trials`` simulated complete trials and learning between."""
    from gcs.app.learn import learn_run

    run = RunDir.create(tmp, profile(), trajectory_from_dict(SHORT), algorithm, run_id="run")
    for j in range(trials):
        fly_synthetic(run, j)
        if j < trials - 1:
            learn_run(run)
    return run


def adaptive_profile(repeats: int | None = None) -> Profile:
    """profiles/antx-adaptive.yaml; with ``repeats``, its ``learning.adaptive.repeats`` set to
    that (1: the trial plan of a test about something else than the floor, trial 2 the first
    learned one, whatever the shipped default)."""
    path = ROOT / "profiles" / "antx-adaptive.yaml"
    if repeats is None:
        return load_profile(path)
    import yaml

    data = yaml.safe_load(path.read_text())
    data["learning"]["adaptive"]["repeats"] = repeats
    return profile_from_dict(data, str(path))


def make_adaptive_run(
    tmp: Path,
    trials: int,
    seed: int = 0,
    plants: tuple[DiscreteModel, DiscreteModel] | None = None,
    gust_m: float = 0.0,
    prof: Profile | None = None,
    repeats: int | None = None,
) -> RunDir:
    """A run of the tiny eight with antx-adaptive.yaml (``repeats`` as :func:`adaptive_profile`
    says) or ``prof``: ``trials`` simulated trials (trials 1..repeats repeat trial 0),
    learning with history after each, the last too."""
    from gcs.app.learn import learn_run

    prof = prof or adaptive_profile(repeats)
    run = RunDir.create(tmp, prof, trajectory_from_dict(SHORT), "smoother", run_id="run")
    for j in range(trials):
        fly_synthetic(run, j, seed, plants, gust_m)
        learn_run(run)
    return run


def eight_trajectory():
    return load_trajectory(ROOT / "trajectories" / "eight.yaml")


#: Watchdog limits for end-to-end flights on a loaded 2-core CI machine, where other test
#: workers can starve the flight process for more than the default 0.1 s. The watchdog itself
#: is tested with its defaults in tests/test_flight_trial.py. The hover measurement before the
#: first trial is 2 s instead of 10 s: the indoor mock's hover (gusts of 1.5 s correlation)
#: shows in 2 s, and every e2e flight would otherwise take 8 s longer.
CI_FLIGHT = {
    "stream_rate_hz": 60,
    "max_setpoint_late_s": 0.4,
    "max_telemetry_age_s": 1.0,
    "hover_measure_s": 2.0,
}


#: The motion-capture stream's stale limit for the flights of the tests (``mocap.max_age_s``;
#: gcs's default 0.4 s is for a lab, where Motive runs on a machine of its own). Here one
#: machine runs the vehicle, Motive and gcs, and when it pauses (a CI machine left a
#: real-time thread unscheduled for 0.5 s, two flights at once: tests/pause_watch.py) all
#: three stop together: the stream has a gap no lab's has, while the vehicle, stopped too,
#: never flew blind. 0.8 s stays within what EKF2 rides through on its inertial prediction
#: (it stops fusing vision after 0.4 s, and holds its local position valid for
#: ``EKF2_NOAID_TOUT``, 5 s).
CI_MOCAP = {"max_age_s": 0.8}


def ci_profile(tmp: Path) -> Path:
    """profiles/antx.yaml with :data:`CI_FLIGHT` limits, written to ``tmp``."""
    import yaml

    data = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    data["flight"] = dict(data.get("flight") or {}, **CI_FLIGHT)
    path = tmp / "antx-ci.yaml"
    path.write_text(yaml.safe_dump(data))
    return path
