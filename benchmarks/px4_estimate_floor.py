"""What the floor on firmware is made of: the mocap, PX4's estimate, or how PX4 flew.

A lab flight on real PX4 v1.16 SIH (the lab rig of ``tests/px4/lab_rig.py``; a flight of
``tests/px4/test_px4_lab_floor.py`` or of ``benchmarks/lab_floor_px4.py``) logs, in PX4's own
flight log, the simulated vehicle's truth (``vehicle_local_position_groundtruth``, NED), every
vision pose PX4 took from gcs (``vehicle_visual_odometry``, in the room's axes), PX4's own
estimate of its position and velocity (``vehicle_local_position``, the room's axes: on vision
only PX4 flies in them) and EKF2's vision innovations (``estimator_innovations``). The truth is
what the mocap measures and e_pos scores, so the floor (``gcs.core.floor``: drawn from the
flights of identical setpoints) is made of how much the truth differs between such flights.

Per flight: the room's turn and the mocap's delay, fitted once (the rotation and offset taking
the truth, as it was the delay earlier, onto the vision poses, by least squares, the delay on a
2 ms grid). Per trial (``t0_vehicle_s`` of its record, on PX4's clock), in the room's axes
(north, east):

- ``mocap``: the vision poses PX4 received against the truth the delay earlier, RMS [mm];
- ``estimate``: PX4's position estimate against the truth at the same instant, RMS per axis
  [mm], and its velocity estimate against the true velocity [mm/s];
- ``innovation``: EKF2's vision-position innovations, RMS per axis [mm];
- ``tilt``: PX4's attitude estimate against the true attitude, as the horizontal components of
  the body's thrust axis (the room's north, east) [deg], RMS: the accelerometer's specific force
  goes to the room through that attitude, so a tilt error of x deg puts about g x pi / 180 of
  horizontal acceleration [m/s^2] into the estimate where the vision does not pull it back;
- ``accel bias``: EKF2's estimate of the accelerometer's horizontal bias (body x and y:
  ``estimator_states`` states 13 and 14, covariances 12 and 13), as the standard deviation
  EKF2 grants it (the median over the trial) [mm/s^2] and how far the estimate moved within
  the trial (the RMS of its distance from its mean over the trial) [mm/s^2]. A bias estimate
  that moves is a horizontal acceleration the estimate integrates until the vision pulls it
  back;
- ``arming``: which arming since PX4 started the trial was flown in (0: the vehicle's first
  flight after PX4 started). PX4 logs each arming in a file of its own; a PX4 that started again
  begins its clock again, which is how the logs of one directory are told apart by start.

Per pair of flights of identical setpoints (trial 0 and its repeats, a trial and its
``--again`` flights), the RMS per axis of the difference between their tracks: of the truth
(what makes the floor), of the estimate (what PX4 flew on) and of the estimate's error. Then
the medians over every trial and every pair of the flights given.

A flight is a directory holding the run (``run/``, or the directory itself) and PX4's logs
below it (the test's temporary directory: ``run/`` and ``px4-0/log/``), or a run of
``benchmarks/lab_floor_px4.py --out OUT`` (``OUT/NAME``, its PX4's logs in ``OUT/.NAME-px4``).
PX4 logs each arming in a file of its own; each trial is taken from the one log whose span on
PX4's clock holds it (a run resumed on a restarted PX4 can have two: it is refused).

    .venv/bin/python benchmarks/px4_estimate_floor.py logs/lab-floor/NAME [...] [--json]

Nothing is asserted.
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from pyulog import ULog

from gcs.io.rundir import RunDir

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lab_floor_px4 import identical_groups  # noqa: E402

TOPICS = (
    "vehicle_local_position",
    "vehicle_local_position_groundtruth",
    "vehicle_visual_odometry",
    "estimator_innovations",
    "vehicle_attitude",
    "vehicle_attitude_groundtruth",
    "estimator_states",
)
#: EKF2's indices of the accelerometer's x and y bias in PX4 v1.16's ``estimator_states``: in
#: ``states`` (25: the attitude quaternion's four first) and in ``covariances`` (the 24 variances
#: of the error state: the attitude's three first), one apart
ACCEL_BIAS_STATES_XY = (13, 14)
ACCEL_BIAS_COVARIANCES_XY = (12, 13)
#: the delays tried for the mocap [s]: the rig's latency is 0-50 ms
DELAYS_S = np.arange(0.0, 0.1001, 0.002)
#: the grid the tracks are compared on [s]
STEP_S = 0.02
#: vision poses from this height up (NED down [m]) fit the room: the vehicle is flying
AIRBORNE_DOWN_M = -0.5


@dataclass(frozen=True)
class Trial:
    """One trial's errors, in the room's axes (north, east) [mm, mm/s, deg]."""

    trial: int
    epos_mm: float
    mocap_mm: float
    estimate_mm: tuple[float, float]
    velocity_mm_s: tuple[float, float]
    innovation_mm: tuple[float, float]
    tilt_deg: tuple[float, float]
    arming: int
    accel_bias_sd_mm_s2: float
    accel_bias_moved_mm_s2: float


@dataclass(frozen=True)
class Pair:
    """Two flights of identical setpoints: RMS per axis (north, east) of their difference [mm]."""

    trials: tuple[int, int]
    truth_mm: tuple[float, float]
    estimate_mm: tuple[float, float]
    error_mm: tuple[float, float]


@dataclass(frozen=True)
class Flight:
    """One flight's room and delay, trials and pairs."""

    name: str
    turn_deg: float
    delay_ms: float
    trials: list[Trial]
    pairs: list[Pair]


class Log:
    """The topics of :data:`TOPICS` from one PX4 log, on PX4's clock [s]."""

    def __init__(self, path: Path) -> None:
        ulog = ULog(str(path), list(TOPICS))
        self.data = {d.name: d.data for d in ulog.data_list if d.multi_id == 0}
        missing = [t for t in TOPICS if t not in self.data]
        if missing:
            raise ValueError(f"{path}: no {', '.join(missing)} in the log")

    def at(self, topic: str, fields: tuple[str, ...], t_s: np.ndarray) -> np.ndarray:
        """``fields`` of ``topic`` at the times ``t_s`` [s], interpolated: (n, len(fields))."""
        data = self.data[topic]
        stamps = data["timestamp"] * 1e-6
        return np.column_stack([np.interp(t_s, stamps, data[f]) for f in fields])


def fit_room(log: Log) -> tuple[np.ndarray, np.ndarray, float]:
    """The rotation (2, 2), offset (2,) [m] and delay [s] taking the truth onto the vision poses."""
    vision = log.data["vehicle_visual_odometry"]
    t_s = vision["timestamp"] * 1e-6
    air = vision["position[2]"] < AIRBORNE_DOWN_M
    seen = np.column_stack([vision["position[0]"], vision["position[1]"]])[air]
    best = None
    for delay in DELAYS_S:
        truth = log.at("vehicle_local_position_groundtruth", ("x", "y"), t_s[air] - delay)
        a, b = truth - truth.mean(0), seen - seen.mean(0)
        u, _, vt = np.linalg.svd(a.T @ b)
        rot = (u @ vt).T
        rms = float(np.sqrt(np.mean(np.sum((a @ rot.T - b) ** 2, axis=1))))
        if best is None or rms < best[0]:
            best = (rms, rot, seen.mean(0) - rot @ truth.mean(0), float(delay))
    assert best is not None
    return best[1], best[2], best[3]


def accel_bias(log: Log, t_s: np.ndarray) -> tuple[float, float]:
    """EKF2's horizontal accelerometer bias over ``t_s`` [s]: the median of the standard
    deviation it grants the estimate (the larger of x and y) [mm/s^2], and how far the estimate
    moved: the RMS of its distance (x and y together) from its mean over ``t_s`` [mm/s^2]."""
    states = log.data["estimator_states"]
    stamps = states["timestamp"] * 1e-6
    inside = (stamps >= t_s[0]) & (stamps <= t_s[-1])
    sd = np.sqrt(
        np.column_stack([states[f"covariances[{i}]"][inside] for i in ACCEL_BIAS_COVARIANCES_XY])
    )
    bias = np.column_stack([states[f"states[{i}]"][inside] for i in ACCEL_BIAS_STATES_XY])
    moved = np.sqrt(np.mean(np.sum((bias - bias.mean(axis=0)) ** 2, axis=1)))
    return float(np.median(sd.max(axis=1))) * 1e3, float(moved) * 1e3


def up_axis(q: np.ndarray) -> np.ndarray:
    """The body's z axis in the world frame of quaternions ``q`` (n, 4; w, x, y, z; interpolated,
    so normalised here): (n, 3)."""
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.column_stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


def thrust_axis(log: Log, t_s: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """PX4's estimated minus the true body z axis, horizontal components in the room (n, 2)."""
    fields = tuple(f"q[{i}]" for i in range(4))
    estimated = up_axis(log.at("vehicle_attitude", fields, t_s))
    true = up_axis(log.at("vehicle_attitude_groundtruth", fields, t_s))
    return estimated[:, :2] - true[:, :2] @ rot.T


def rms(x: np.ndarray) -> np.ndarray:
    """RMS of each column of ``x`` (n, k): (k,)."""
    return np.sqrt(np.mean(x**2, axis=0))


def rms_axes(x: np.ndarray) -> tuple[float, float]:
    """RMS of each column of ``x`` (n, 2) [m], in millimetres."""
    return tuple(round(float(v) * 1e3, 1) for v in rms(x))


def flight_of(path: Path) -> tuple[RunDir, list[Path]]:
    """The run and PX4's logs of a flight directory (the module's docstring)."""
    run = path / "run" if (path / "run").is_dir() else path
    logs = sorted(path.rglob("*.ulg")) or sorted((path.parent / f".{path.name}-px4").rglob("*.ulg"))
    if not logs:
        raise FileNotFoundError(f"{path}: no PX4 log (.ulg) beside the run")
    return RunDir.open(run), logs


class Room:
    """One PX4 log with the room's turn and the mocap's delay fitted (:func:`fit_room`), and
    which arming since PX4 started it logs (``arming``, set by :func:`rooms_of`)."""

    def __init__(self, path: Path) -> None:
        self.log = Log(path)
        self.arming = 0
        self.rot, self.offset, self.delay_s = fit_room(self.log)
        stamps = self.log.data["vehicle_local_position"]["timestamp"] * 1e-6
        self.span_s = (float(stamps[0]), float(stamps[-1]))

    def truth(self, fields: tuple[str, str], t_s: np.ndarray) -> np.ndarray:
        """SIH's true ``fields`` (north and east components) turned into the room: (n, 2)."""
        return self.log.at("vehicle_local_position_groundtruth", fields, t_s) @ self.rot.T

    def trial(self, j: int, epos_m: float, t_s: np.ndarray) -> tuple[Trial, np.ndarray, np.ndarray]:
        """Trial ``j``'s errors over its instants ``t_s`` on PX4's clock, with the true and
        the estimated track (n, 2) [m]."""
        log = self.log
        true_now = self.truth(("x", "y"), t_s) + self.offset
        estimate = log.at("vehicle_local_position", ("x", "y"), t_s)
        vision = log.data["vehicle_visual_odometry"]
        tv = vision["timestamp"] * 1e-6
        inside = (tv >= t_s[0]) & (tv <= t_s[-1])
        seen = np.column_stack([vision["position[0]"], vision["position[1]"]])[inside]
        mocap = seen - self.truth(("x", "y"), tv[inside] - self.delay_s) - self.offset
        innov = log.data["estimator_innovations"]
        ti = innov["timestamp"] * 1e-6
        keep = (ti >= t_s[0]) & (ti <= t_s[-1])
        innovation = np.column_stack([innov["ev_hpos[0]"][keep], innov["ev_hpos[1]"][keep]])
        tilt = np.degrees(rms(thrust_axis(log, t_s, self.rot)))
        bias_sd, bias_moved = accel_bias(log, t_s)
        velocity = log.at("vehicle_local_position", ("vx", "vy"), t_s) - self.truth(
            ("vx", "vy"), t_s
        )
        trial = Trial(
            trial=j,
            epos_mm=round(epos_m * 1e3, 1),
            mocap_mm=round(float(np.sqrt(np.mean(np.sum(mocap**2, axis=1)))) * 1e3, 1),
            estimate_mm=rms_axes(estimate - true_now),
            velocity_mm_s=rms_axes(velocity),
            innovation_mm=rms_axes(innovation),
            tilt_deg=tuple(round(float(v), 2) for v in tilt),
            arming=self.arming,
            accel_bias_sd_mm_s2=round(bias_sd, 1),
            accel_bias_moved_mm_s2=round(bias_moved, 1),
        )
        return trial, true_now, estimate


def rooms_of(paths: list[Path]) -> list[Room]:
    """The logs of ``paths`` (in the order PX4 wrote them: its folders and files are named by
    the date and time) with each one's arming since PX4 started: a log that starts earlier on
    PX4's clock than the one before it is the first of a PX4 started again."""
    rooms = [Room(p) for p in paths]
    for before, room in itertools.pairwise(rooms):
        room.arming = before.arming + 1 if room.span_s[0] > before.span_s[0] else 0
    return rooms


def analyse(path: Path) -> Flight:
    """The errors of every trial and pair of one flight directory."""
    rd, paths = flight_of(path)
    rooms = rooms_of(paths)
    grid = np.arange(rd.n_samples) * rd.t_ilc_s
    trials, tracks = [], {}
    for j in rd.complete_trials():
        status = rd.read_status(j)
        t_s = float(status.extra["t0_vehicle_s"]) + grid
        holding = [r for r in rooms if r.span_s[0] <= t_s[0] and t_s[-1] <= r.span_s[1]]
        if len(holding) != 1:
            raise ValueError(f"{path}: trial {j} is in {len(holding)} of the PX4 logs, not one")
        trial, true_now, estimate = holding[0].trial(j, status.epos_m, t_s)
        trials.append(trial)
        tracks[j] = (true_now, estimate)
    pairs = []
    for group in identical_groups(rd):
        for a, b in itertools.combinations(group, 2):
            (ta, ea), (tb, eb) = tracks[a], tracks[b]
            pairs.append(
                Pair((a, b), rms_axes(ta - tb), rms_axes(ea - eb), rms_axes((ea - ta) - (eb - tb)))
            )
    first = rooms[0]
    turn = float(np.degrees(np.arctan2(first.rot[1, 0], first.rot[0, 0])))
    return Flight(path.name, round(turn, 1), round(first.delay_s * 1e3), trials, pairs)


def both(values: tuple[float, float], digits: int = 0) -> str:
    """``north / east`` with ``digits`` decimals."""
    return " / ".join(f"{v:.{digits}f}" for v in values)


def medians(rows: list, field: str, digits: int = 0) -> str:
    """The medians of ``field`` (a pair of values) over ``rows``, as ``north / east``."""
    values = [getattr(r, field) for r in rows]
    if not values:
        return "-"
    return both(tuple(statistics.median(v[i] for v in values) for i in (0, 1)), digits)


def summary(rows: list[Trial]) -> str:
    """The medians over ``rows`` (one or more): the estimate's, velocity's, innovations' and
    tilt's errors (north / east) and the accel bias's sd and movement."""
    sd = statistics.median(t.accel_bias_sd_mm_s2 for t in rows)
    moved = statistics.median(t.accel_bias_moved_mm_s2 for t in rows)
    return (
        f"estimate {medians(rows, 'estimate_mm')} mm; "
        f"velocity {medians(rows, 'velocity_mm_s')} mm/s; "
        f"innovation {medians(rows, 'innovation_mm')} mm; "
        f"tilt {medians(rows, 'tilt_deg', 2)} deg; "
        f"accel bias sd {sd:.0f}, moved {moved:.1f} mm/s^2"
    )


def by_arming(trials: list[Trial]) -> list[str]:
    """:func:`summary` over the trials of the first arming since PX4 started and over those of
    the later ones."""
    first = [t for t in trials if t.arming == 0]
    later = [t for t in trials if t.arming > 0]
    return [
        f"  {label} ({len(rows)} trials): {summary(rows)}"
        for label, rows in (("first arming", first), ("later armings", later))
        if rows
    ]


def by_trial(flights: list[Flight]) -> list[str]:
    """:func:`summary` per trial number over the flights (flights of one plan: the same
    number is the same part of each), with the armings it was flown in."""
    numbers = sorted({t.trial for f in flights for t in f.trials})
    lines = []
    for j in numbers:
        rows = [t for f in flights for t in f.trials if t.trial == j]
        armings = ",".join(str(a) for a in sorted({t.arming for t in rows}))
        lines.append(f"  trial {j} ({len(rows)} flights, arming {armings}): {summary(rows)}")
    return lines


def table(flights: list[Flight]) -> str:
    """Markdown tables of the trials and the pairs, and the medians over all flights."""
    out = [
        "| flight | trial | arming | e_pos [mm] | mocap [mm] | estimate N / E [mm] | "
        "velocity N / E [mm/s] | innovation N / E [mm] | tilt N / E [deg] | "
        "accel bias: sd, moved [mm/s^2] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for f in flights:
        name = f"{f.name} ({f.turn_deg:+.1f} deg, {f.delay_ms:.0f} ms)"
        for t in f.trials:
            out.append(
                f"| {name} | {t.trial} | {t.arming} | {t.epos_mm:.0f} | {t.mocap_mm:.1f} | "
                f"{both(t.estimate_mm)} | {both(t.velocity_mm_s)} | {both(t.innovation_mm)} | "
                f"{both(t.tilt_deg, 2)} | {t.accel_bias_sd_mm_s2:.0f}, "
                f"{t.accel_bias_moved_mm_s2:.1f} |"
            )
    out += [
        "",
        "| flight | pair | truth N / E [mm] | estimate N / E [mm] | estimate's error N / E [mm] |",
        "|---|---|---|---|---|",
    ]
    for f in flights:
        for p in f.pairs:
            out.append(
                f"| {f.name} | {p.trials[0]}, {p.trials[1]} | {both(p.truth_mm)} | "
                f"{both(p.estimate_mm)} | {both(p.error_mm)} |"
            )
    trials = [t for f in flights for t in f.trials]
    pairs = [p for f in flights for p in f.pairs]
    out += [
        "",
        f"medians over {len(flights)} flights, {len(trials)} trials and {len(pairs)} pairs "
        "(north / east):",
        f"  trials: mocap {statistics.median(t.mocap_mm for t in trials):.1f} mm; {summary(trials)}"
        if trials
        else "  trials: -",
        f"  pairs: truth {medians(pairs, 'truth_mm')} mm; "
        f"estimate {medians(pairs, 'estimate_mm')} mm; "
        f"estimate's error {medians(pairs, 'error_mm')} mm",
        "by arming since PX4 started (0: the vehicle's first flight after PX4 started):",
        *by_arming(trials),
        "by trial:",
        *by_trial(flights),
    ]
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("flights", nargs="+", type=Path, help="flight directories (docstring)")
    parser.add_argument("--json", action="store_true", help="one JSON line per flight as well")
    args = parser.parse_args()
    flights = []
    for path in args.flights:
        flight = analyse(path)
        if args.json:
            print(json.dumps(asdict(flight)), flush=True)
        flights.append(flight)
    print(table(flights))


if __name__ == "__main__":
    main()
