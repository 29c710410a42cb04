"""What PX4 itself received, from its own flight log (ULog), for the real-firmware tests.

PX4's mavlink receiver turns every ``VISION_POSITION_ESTIMATE`` gcs forwards into a
``vehicle_visual_odometry`` message and every ``SET_POSITION_TARGET_LOCAL_NED`` into an
``offboard_control_mode`` message (and, in OFFBOARD only, a ``trajectory_setpoint``), each
stamped ``timestamp = hrt_absolute_time()`` on arrival (PX4 v1.16,
``src/modules/mavlink/mavlink_receiver.cpp``): PX4's time since boot, the clock of its
``time_boot_ms``, which gcs records as each trial's ``t0_vehicle_s``. The arrivals in the log
are the arrivals at the vehicle, on the vehicle's clock; ``vehicle_status`` gives its
navigation state (OFFBOARD, the landing) on the same clock.

PX4's logger subsamples most topics (``trajectory_setpoint`` every 200 ms, ``offboard_control_mode``
every 100 ms, ``vehicle_visual_odometry`` every 30 ms with SITL's logging profiles). When a file
``etc/logging/logger_topics.txt`` exists in PX4's root folder (its working directory in SITL),
the logger logs the topics listed there instead, each ``<topic> <interval ms>``, 0 meaning every
message (``src/modules/logger/logged_topics.cpp``). :func:`log_every_message` writes one into a
vehicle's working directory before it starts: there ``etc`` is then a folder of our own holding
links to the build's start-up scripts beside ``logging/`` (PX4 links ``etc`` to the build only
when no folder of that name exists). The logger still takes the newest message per topic at its
own rate (every 3.5 ms): a message arriving less than a logger cycle after another may be
missed, which makes a gap in the log longer than it was, never shorter.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pyulog import ULog

from gcs.io.rundir import RunDir

#: vehicle_status.nav_state values (PX4 v1.16 msg/VehicleStatus.msg)
NAV_OFFBOARD = 14

VISION = "vehicle_visual_odometry"
OFFBOARD_MODE = "offboard_control_mode"
TRAJECTORY = "trajectory_setpoint"

#: Logged at every message (interval 0): the streams measured, and the events that frame them.
FULL_RATE = (VISION, OFFBOARD_MODE, TRAJECTORY, "vehicle_status", "vehicle_land_detected",
             "actuator_armed", "vehicle_command", "vehicle_command_ack", "vehicle_control_mode",
             "failsafe_flags")  # fmt: skip
#: Logged subsampled, for a reader of a failed test's log [ms].
SUBSAMPLED = {"vehicle_local_position": 100, "vehicle_local_position_setpoint": 100,
              "vehicle_attitude": 50, "estimator_status_flags": 100, "cpuload": 0}  # fmt: skip
#: The topics the module asks PX4's logger for: ``(name, interval_ms)``.
LOGGED_TOPICS: tuple[tuple[str, int], ...] = (
    *((name, 0) for name in FULL_RATE),
    *SUBSAMPLED.items(),
)


def log_every_message(workdir: Path, build_root: Path) -> Path:
    """Make PX4 started in ``workdir`` log :data:`LOGGED_TOPICS` (the streams at full rate).

    Parameters
    ----------
    workdir : Path
        The vehicle's working directory, before PX4 starts there.
    build_root : Path
        The PX4 build (``bin/`` and ``etc/``).

    Returns
    -------
    Path
        The topics file written.
    """
    etc = workdir / "etc"
    etc.mkdir(parents=True, exist_ok=True)
    for entry in (build_root / "etc").iterdir():
        if not (etc / entry.name).exists():
            (etc / entry.name).symlink_to(entry.resolve())
    path = etc / "logging" / "logger_topics.txt"
    path.parent.mkdir(exist_ok=True)
    lines = ["# written by the gcs tests: every vision and setpoint message PX4 receives"]
    lines += [f"{name} {interval_ms}" for name, interval_ms in LOGGED_TOPICS]
    path.write_text("\n".join(lines) + "\n")
    return path


@dataclass(frozen=True)
class FlightLog:
    """Arrivals at PX4 and its navigation states, on PX4's clock (seconds since boot).

    Parameters
    ----------
    vision_s : ndarray
        Arrival of each external-vision message (``vehicle_visual_odometry.timestamp``).
    setpoints_s : ndarray
        Arrival of each position setpoint (``offboard_control_mode.timestamp``: every
        ``SET_POSITION_TARGET_LOCAL_NED``, in any mode).
    trajectory_s : ndarray
        Arrival of each setpoint PX4 took as its trajectory (``trajectory_setpoint``: in
        OFFBOARD only).
    nav_states : tuple of (float, int)
        ``vehicle_status.nav_state`` at each change: (time, state).
    armed : tuple of (float, bool)
        Armed or not (``vehicle_status.arming_state``) at each change: (time, armed).
    tick_s : float
        The step of PX4's clock in these stamps: the largest time dividing them all (PX4 SITL
        in lockstep with SIH advances its clock 4 ms at a time; a vehicle's, 1 us).
    dropouts_s : float
        Time the logger lost to a full buffer (the ULog's dropouts).
    """

    vision_s: np.ndarray
    setpoints_s: np.ndarray
    trajectory_s: np.ndarray
    nav_states: tuple[tuple[float, int], ...]
    armed: tuple[tuple[float, bool], ...]
    tick_s: float
    dropouts_s: float

    def offboard_spans(self) -> list[tuple[float, float]]:
        """The spans PX4 was in OFFBOARD: (entered, left) [s]; one it never left ends at the
        last state's time."""
        spans, start = [], None
        for t, state in self.nav_states:
            if state == NAV_OFFBOARD and start is None:
                start = t
            elif state != NAV_OFFBOARD and start is not None:
                spans.append((start, t))
                start = None
        if start is not None:
            spans.append((start, self.nav_states[-1][0]))
        return spans

    def next_nav_change(self, after_s: float) -> float | None:
        """The first change of navigation state after ``after_s`` [s], or None."""
        return next((t for t, _ in self.nav_states if t > after_s), None)


def _changes(t_s: np.ndarray, values: np.ndarray) -> list[tuple[float, int]]:
    keep = np.r_[True, values[1:] != values[:-1]] if values.size else np.zeros(0, bool)
    return [(float(t), int(v)) for t, v in zip(t_s[keep], values[keep], strict=True)]


def read_flight_log(path: Path) -> FlightLog:
    """The arrivals and navigation states in a PX4 ULog.

    Parameters
    ----------
    path : Path
        A ``.ulg`` file of PX4 v1.16 (logging :data:`LOGGED_TOPICS`).

    Returns
    -------
    FlightLog

    Raises
    ------
    ValueError
        The log has no vision, setpoint or vehicle status messages (not a flight gcs flew with
        these topics logged).
    """
    ulog = ULog(str(path), [VISION, OFFBOARD_MODE, TRAJECTORY, "vehicle_status"])
    data = {d.name: d.data for d in ulog.data_list if d.multi_id == 0}
    missing = [name for name in (VISION, OFFBOARD_MODE, "vehicle_status") if name not in data]
    if missing:
        raise ValueError(f"{path}: no {', '.join(missing)} in the log")

    def stamps_us(name: str) -> np.ndarray:
        return np.asarray(data[name]["timestamp"] if name in data else [], dtype=np.int64)

    status = data["vehicle_status"]
    t_status = stamps_us("vehicle_status") * 1e-6
    armed = (np.asarray(status["arming_state"]) == 2).astype(int)  # ARMING_STATE_ARMED
    streams = np.concatenate([stamps_us(VISION), stamps_us(OFFBOARD_MODE)])
    return FlightLog(
        vision_s=stamps_us(VISION) * 1e-6,
        setpoints_s=stamps_us(OFFBOARD_MODE) * 1e-6,
        trajectory_s=stamps_us(TRAJECTORY) * 1e-6,
        nav_states=tuple(_changes(t_status, np.asarray(status["nav_state"]))),
        armed=tuple((t, bool(v)) for t, v in _changes(t_status, armed)),
        tick_s=float(np.gcd.reduce(streams)) * 1e-6 if streams.size else math.nan,
        dropouts_s=sum(d.duration for d in ulog.dropouts) * 1e-3,
    )


Spans = list[tuple[float, float]]


def trial_windows(run: RunDir, log: FlightLog) -> tuple[Spans, Spans]:
    """The run's trials and the spans after each of them, on PX4's clock [s].

    A trial is ``[t0, t0 + N t_ilc_s]`` (``t0_vehicle_s`` of its sidecar); the span after it
    runs to the next trial's ``t0`` (the hover while gcs records the trial and learns the next
    setpoints, then the move to the start point, the settle and the hold); after the last trial
    it runs to PX4's next change of navigation state (the landing).
    """
    duration = run.n_samples * run.t_ilc_s
    starts = [float(run.read_status(j).extra["t0_vehicle_s"]) for j in run.complete_trials()]
    trials = [(t0, t0 + duration) for t0 in starts]
    after = [(end, nxt) for (_, end), nxt in zip(trials, starts[1:], strict=False)]
    if trials:
        landing = log.next_nav_change(trials[-1][1])
        if landing is not None:
            after.append((trials[-1][1], landing))
    return trials, after


#: gcs's first line after the learning step that follows a trial (its hover is over)
AFTER_LEARNING = ("moving to the start point of trial", "landing")


def learning_windows(run: RunDir, log: FlightLog, lines: Sequence[tuple[float, str]]) -> Spans:
    """The between-trial computation on PX4's clock: from the end of each trial to gcs's next
    step once the trial was recorded and the next setpoints learned [s].

    ``lines``: gcs's output lines with the local monotonic time each came [s]. The step's end
    (the first of :data:`AFTER_LEARNING` after "trial j started") goes to PX4's clock from the
    trial's own start: ``t0 + (its time - the start line's time) * rate``, ``rate`` the trial's
    vehicle-time rate (its sidecar); good to the pipe's delay and the rate's drift over the
    seconds since (tens of milliseconds). After the last trial it is at most the landing.
    """
    duration = run.n_samples * run.t_ilc_s
    _, after = trial_windows(run, log)
    spans = []
    for j, (_, next_s) in zip(run.complete_trials(), after, strict=False):
        status = run.read_status(j)
        started = next((t for t, ln in lines if ln.startswith(f"trial {j} started")), None)
        if started is None:
            continue
        done = next((t for t, ln in lines if t > started and ln.startswith(AFTER_LEARNING)), None)
        if done is None:
            continue
        rate = status.extra.get("vehicle_time_rate") or 1.0
        t0 = float(status.extra["t0_vehicle_s"])
        spans.append((t0 + duration, min(t0 + (done - started) * rate, next_s)))
    return spans


def largest_gap_within(t_s: np.ndarray, spans: Spans) -> float:
    """The largest gap between consecutive arrivals both inside one of ``spans`` [s] (0 when
    none is).

    Both ends inside, unlike ``tests/flight_gaps.py``'s gaps that overlap a span: a gap across
    a trial's edge joins the hover's setpoint stream (MAVSDK's 20 Hz re-send) to the trial's
    (60 Hz) and belongs to neither. A stream that stops across an edge is caught by the gaps
    over the whole flight.
    """
    t = np.sort(np.asarray(t_s, dtype=float))
    gap = np.diff(t)
    best = 0.0
    for a, b in spans:
        inside = (t[:-1] >= a) & (t[1:] <= b)
        if inside.any():
            best = max(best, float(gap[inside].max()))
    return best


def largest_gap_over(t_s: np.ndarray, a_s: float, b_s: float) -> float:
    """The largest gap in ``[a_s, b_s]`` between consecutive arrivals, the span's edges counted
    as arrivals (a stream that stopped in it shows as a gap to its end) [s]."""
    t = np.asarray(t_s, dtype=float)
    points = np.r_[a_s, np.sort(t[(t >= a_s) & (t <= b_s)]), b_s]
    return float(np.max(np.diff(points)))


def median_gap(t_s: np.ndarray, spans: Spans) -> float:
    """The median gap between consecutive arrivals both inside one of ``spans`` [s] (NaN if
    none)."""
    t = np.sort(np.asarray(t_s, dtype=float))
    gap = np.diff(t)
    inside = np.zeros(gap.shape, bool)
    for a, b in spans:
        inside |= (t[:-1] >= a) & (t[1:] <= b)
    return float(np.median(gap[inside])) if inside.any() else math.nan


@dataclass(frozen=True)
class PX4Gaps:
    """The largest gaps of what PX4 received, in the trials and between them [s].

    ``*_learning_s``: in the between-trial computation (:func:`learning_windows`);
    ``*_between_s``: in the whole spans between trials (:func:`trial_windows`: the computation,
    then the move, the settle and the hold). ``hover_between_s``: from the end of each trial to
    the start of the next; ``learning_s``: how long each computation's hover lasted (PX4's
    clock). ``vision_period_s``, ``setpoint_period_s``: the median gaps in the trials, the
    streams' periods as logged (a subsampled log would show the logger's interval instead).
    ``tick_s``: PX4's clock step (:class:`FlightLog`).
    """

    vision_trial_s: float
    vision_learning_s: float
    vision_between_s: float
    setpoint_trial_s: float
    setpoint_learning_s: float
    setpoint_between_s: float
    hover_between_s: tuple[float, ...]
    learning_s: tuple[float, ...]
    vision_period_s: float
    setpoint_period_s: float
    tick_s: float

    def as_dict(self) -> dict:
        """Gaps in milliseconds and times in seconds, rounded, for figures and tables."""
        out: dict = {k: round(1e3 * v, 1) for k, v in self.__dict__.items() if k.endswith("_s")
                     and isinstance(v, float)}  # fmt: skip
        out = {k.removesuffix("_s") + "_ms": v for k, v in out.items()}
        return out | {
            "hover_between_s": [round(h, 2) for h in self.hover_between_s],
            "learning_s": [round(h, 2) for h in self.learning_s],
        }


def px4_gaps(run: RunDir, log: FlightLog, lines: Sequence[tuple[float, str]]) -> PX4Gaps:
    """The largest vision and setpoint gaps at PX4 in the run's trials, in the computation
    after each and in the whole spans between them."""
    trials, after = trial_windows(run, log)
    learning = learning_windows(run, log, lines)
    return PX4Gaps(
        vision_trial_s=largest_gap_within(log.vision_s, trials),
        vision_learning_s=largest_gap_within(log.vision_s, learning),
        vision_between_s=largest_gap_within(log.vision_s, after),
        setpoint_trial_s=largest_gap_within(log.setpoints_s, trials),
        setpoint_learning_s=largest_gap_within(log.setpoints_s, learning),
        setpoint_between_s=largest_gap_within(log.setpoints_s, after),
        hover_between_s=tuple(b - a for a, b in after[: len(trials) - 1]),
        learning_s=tuple(b - a for a, b in learning),
        vision_period_s=median_gap(log.vision_s, trials),
        setpoint_period_s=median_gap(log.setpoints_s, trials),
        tick_s=log.tick_s,
    )


#: vehicle_status.nav_state names (PX4 v1.16 msg/VehicleStatus.msg), for a failure's digest
NAV_STATE_NAMES = {0: "MANUAL", 1: "ALTCTL", 2: "POSCTL", 3: "MISSION", 4: "HOLD", 5: "RTL",
                   10: "ACRO", 12: "DESCEND", 13: "TERMINATION", 14: "OFFBOARD", 15: "STAB",
                   17: "TAKEOFF", 18: "LAND", 20: "PRECLAND", 21: "ORBIT"}  # fmt: skip
#: PX4 console lines a reader of a failed flight wants first
CONSOLE_EVENTS = ("WARN", "ERROR", "INFO  [commander]", "INFO  [navigator]")


#: Topics fed by work items PX4 SITL runs on its interval timer, as the default logging profile
#: names them: the barometer, magnetometer and GPS simulators (through the sensor data they
#: feed), the battery simulator and the CPU-load monitor.
TIMER_FED = ("vehicle_air_data", "vehicle_magnetometer", "vehicle_gps_position",
             "battery_status", "cpuload")  # fmt: skip
#: SIH's IMU: published from the simulator's own loop, not the interval timer.
IMU = "sensor_combined"


def timer_stopped(last_s: Mapping[str, float], min_gap_s: float = 2.0) -> str | None:
    """Say, in one line, whether PX4 SITL's interval timer stopped before its IMU did.

    PX4 SITL's emulation of the hardware timer can lose its list of calls (see ``SITL_PARAMS``
    in tests/px4/sitl.py): the simulated barometer, compass, GPS and battery and the CPU-load
    monitor stop for good while SIH's IMU, and EKF2 and the controllers it feeds, go on. A
    flight that then fails has failed on the simulator, and this line says so at the top of
    the digest.

    Parameters
    ----------
    last_s : mapping of str to float
        The time of each topic's last message in the log (PX4's clock) [s]; topics the log
        does not hold are absent. A log holding SIH's IMU was written with PX4's default
        logging profile, which logs every topic of :data:`TIMER_FED`: one absent from it
        stopped before the log began (at the disarming before, say).
    min_gap_s : float
        How long the IMU must have gone on after a topic's last message for it to count as
        stopped [s] (the slowest of them, the CPU load, comes every 0.5 s).

    Returns
    -------
    str or None
        The line, when the IMU went on ``min_gap_s`` past at least two of :data:`TIMER_FED`;
        None otherwise (one topic alone may stop for a reason of its own).
    """
    if IMU not in last_s:
        return None
    end_s = last_s[IMU]
    stopped = [n for n in TIMER_FED if end_s - last_s.get(n, -math.inf) > min_gap_s]
    if len(stopped) < 2:
        return None
    seen = [last_s[n] for n in stopped if n in last_s]
    since = f"at {min(seen):.2f} s of PX4's clock" if seen else "before this log began"
    return (
        f"PX4 SITL's interval timer stopped {since}: no {', '.join(stopped)} after it while "
        f"its IMU ({IMU}) went on to {end_s:.2f} s (the simulated barometer, compass and GPS "
        "gone: a fault of the simulator)"
    )


def failure_digest(output: str, ulogs: Sequence[Path], last_s: float = 40.0) -> str:
    """What a failed firmware flight did, short enough for a CI transcript.

    First, when the newest log shows it, that PX4 SITL's interval timer stopped
    (:func:`timer_stopped`). Then the last 25 of PX4's console warnings, errors and
    commander/navigator messages, then the last ``last_s`` seconds of its newest log once a
    second: navigation state, armed and landed, the estimated position and velocity (NED,
    local frame) and the position setpoint (NaN where PX4 set none).

    Parameters
    ----------
    output : str
        PX4's console output.
    ulogs : sequence of Path
        Its ``.ulg`` files, oldest first.
    last_s : float
        Seconds of the newest log to show [s].

    Returns
    -------
    str
        Lines of text; a log that cannot be read says why in one line.
    """
    lines = [ln for ln in output.splitlines() if ln.startswith(CONSOLE_EVENTS)]
    out = ["PX4 console (last warnings, errors, commander and navigator messages):"]
    out += ["  " + ln.strip() for ln in lines[-25:]]
    if not ulogs:
        return "\n".join([*out, "no ULog written"])
    topics = ["vehicle_local_position", "vehicle_local_position_setpoint", "vehicle_status",
              "vehicle_land_detected", *TIMER_FED, IMU]  # fmt: skip
    try:
        ulog = ULog(str(ulogs[-1]), topics)
    except Exception as exc:  # a log cut short by the failure is worth a line, not a crash
        return "\n".join([*out, f"{ulogs[-1].name}: unreadable ({exc})"])
    data = {d.name: d.data for d in ulog.data_list if d.multi_id == 0}
    ends_s = {name: d["timestamp"][-1] * 1e-6 for name, d in data.items() if len(d["timestamp"])}
    stopped = timer_stopped(ends_s)
    if stopped:
        out.insert(0, stopped)
    if "vehicle_local_position" not in data:
        return "\n".join([*out, f"{ulogs[-1].name}: no vehicle_local_position"])
    stamps_s = {name: np.asarray(d["timestamp"]) * 1e-6 for name, d in data.items()}
    t_pos = stamps_s["vehicle_local_position"]

    def at(name: str, field: str, t: float) -> float:
        if name not in data:
            return math.nan
        i = int(np.searchsorted(stamps_s[name], t, side="right")) - 1
        return float(data[name][field][i]) if i >= 0 else math.nan

    out.append(f"{ulogs[-1].name}, the last {last_s:g} s once a second (PX4's clock; NED m, m/s):")
    out.append("      t  state       armed landed   x      y      z     vx     vy     vz"
               "    sp_x   sp_y   sp_z")  # fmt: skip
    for t in np.arange(max(t_pos[0], t_pos[-1] - last_s), t_pos[-1] + 1e-9, 1.0):
        state = at("vehicle_status", "nav_state", t)
        name = NAV_STATE_NAMES.get(int(state), str(state)) if math.isfinite(state) else "?"
        armed = at("vehicle_status", "arming_state", t) == 2
        landed = at("vehicle_land_detected", "landed", t) == 1
        values = [at("vehicle_local_position", f, t) for f in ("x", "y", "z", "vx", "vy", "vz")]
        values += [at("vehicle_local_position_setpoint", f, t) for f in ("x", "y", "z")]
        numbers = " ".join(f"{v:6.2f}" for v in values)
        out.append(f"  {t:7.1f} {name:<11} {armed!s:<5} {landed!s:<6} {numbers}")
    return "\n".join(out)
