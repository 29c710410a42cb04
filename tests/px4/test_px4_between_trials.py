"""The learning between trials does not delay the flight's streams, on real PX4 firmware, from
PX4's own flight log.

The lab flight of tests/px4/test_px4_lab.py (EKF2 on vision only, the rig's OptiTrack, ``gcs
fly --mocap``) with the adaptive profile (profiles/antx-adaptive.yaml with the tests' watchdog
limits and one repeat) and a process burning CPU beside it: trial 0, its repeat (trial 1: the
floor), then learned trials. The learning step after trial 2, the first from two trials of different
setpoints, refits the model (the model refresh: the heavy step, seconds of numerics in gcs's
worker process) while the vehicle hovers on the vision and setpoints gcs streams, and trial 3
is flown after it. PX4 logs every vision and setpoint message it receives
(:func:`px4.ulog.log_every_message`); the gaps between their arrivals at PX4 in the trials, in
the computation after each and over the whole flight are compared (:mod:`px4.ulog`).

What is asserted and what is measured. The test asserts that the log holds the streams (not
the logger's subsample), that the computation ran where the windows say, and that neither
stream ever stopped: from arming to landing no vision gap reaches gcs's own stale limit, in
OFFBOARD no setpoint gap the trial watchdog's. How the largest gaps in the computation compare
with those in the trials (the goal: within 10 ms) is a figure, kept in the test's record and
printed by benchmarks/flight_gaps_px4.py: on a loaded 2-core machine the largest gap of a
window is one outlier that falls in any phase of the flight (docs/flight.md), so a 10 ms
comparison would judge the machine, not gcs. PX4 SITL stamps an arrival with its lockstep
clock, which moves 4 ms at a time (the log's ``tick_s``). The setpoints are compared above
their stream's period: in a trial gcs streams at ``stream_rate_hz`` (60 Hz), while it hovers
MAVSDK re-sends the last setpoint every 50 ms by itself.
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import pytest
import yaml
from synthetic import CI_FLIGHT
from test_source_worker_e2e import cpu_burner

from gcs.flight.mocap.health import HealthLimits
from gcs.io.rundir import RunDir
from px4.flying import sitl_profile
from px4.sitl import STARTED_LINE, Px4Sitl
from px4.test_px4_lab import (
    FLY_TIMEOUT_S,
    LANDED,
    Gcs,
    LabConditions,
    lab_conditions,  # noqa: F401 (a fixture)
    lab_rig,
    tiny,  # noqa: F401 (a fixture)
)
from px4.ulog import (
    LOGGED_TOPICS,
    largest_gap_over,
    learning_windows,
    log_every_message,
    px4_gaps,
    read_flight_log,
    trial_windows,
)

pytestmark = pytest.mark.px4

#: trial 0, its repeat (the floor), trial 2 learned; the step after trial 2 refreshes the
#: model, and trial 3 is flown after it
TRIALS = 4
REFRESHED_AFTER = 2
#: MAVSDK re-sends the last setpoint every 50 ms by itself: the setpoint stream while gcs hovers
MAVSDK_RESEND_S = 0.05


class TimedGcs(Gcs):
    """:class:`px4.test_px4_lab.Gcs` that also keeps the monotonic time each line came."""

    def __init__(self, *args: object) -> None:
        self.timed: list[tuple[float, str]] = []
        self._timed_lock = threading.Lock()
        super().__init__(*args)

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._timed_lock:
                self.timed.append((time.monotonic(), line.strip()))
            with self._cond:
                self.lines.append(line.rstrip("\n"))
                self._cond.notify_all()
        with self._cond:
            self._cond.notify_all()


def adaptive_lab_profile(tmp: Path) -> Path:
    """profiles/antx-adaptive.yaml with the tests' watchdog limits, a ``mocap`` section (no
    frame check: tests/px4/test_px4_lab.py flies it; here it would only lengthen the flight)
    and one repeat of trial 0 (the profile ships two): the streams during the refresh are
    tested, not the floor, and :data:`TRIALS` flights reach the refresh with one repeat."""
    return sitl_profile(
        tmp, "antx-adaptive", limits=CI_FLIGHT, mocap={"check_move_m": 0.0},
        fields={"learning.adaptive.repeats": 1},
    )  # fmt: skip


def refresh_reasons(run: RunDir, j: int) -> list[str]:
    """Why each axis's model was refreshed or kept by the learning step after trial ``j``."""
    record = json.loads(run.learn_path(j).read_text())
    decision = record.get("decision", record)
    return [str((ax.get("refresh") or {}).get("reason")) for ax in decision["axes"]]


@pytest.mark.flight_s(98)
def test_learning_between_trials_does_not_delay_vision_or_setpoints_at_px4(
    px4_factory,
    px4_build,
    lab_conditions: LabConditions,  # noqa: F811
    tmp_path: Path,
    tiny: Path,  # noqa: F811
    px4_figures: dict,
) -> None:
    """gcs fly --mocap --iter 4 with the adaptive profile on a fresh PX4 set up for vision only,
    a CPU burner beside it: armed once on the first attempt, four trials, the model refit (the
    refresh) between trials 2 and 3, landed and disarmed. In PX4's own log (every vision and
    setpoint message it received, at the streams' rates): neither stream ever stopped beyond
    gcs's own watchdog limits, the between-trial computation included; the largest gaps in the
    computation against those in the trials (goal: within 10 ms) are the test's figures."""
    workdir = tmp_path / "px4-0"  # the factory's first vehicle
    log_every_message(workdir, px4_build.root)
    lab_px4: Px4Sitl = px4_factory(params=lab_conditions.px4_params(), ready=STARTED_LINE)
    assert lab_px4.workdir == workdir
    lab_px4.output.wait_for(f"logging {len(LOGGED_TOPICS)} topics from logger_topics.txt", 1)
    run_path = tmp_path / "run"
    profile = adaptive_lab_profile(tmp_path)
    with (
        lab_rig(lab_px4, lab_conditions) as server,
        lab_px4.monitor() as mon,
        cpu_burner(FLY_TIMEOUT_S),
    ):
        gcs = TimedGcs(
            "fly", "--connect", lab_px4.url, "--mocap", server.url, "--iter", TRIALS,
            "--trajectory", tiny, "--profile", profile, "--run", run_path,
        )  # fmt: skip
        code = gcs.wait()
        out = gcs.output()
        assert code == 0, out
        mon.wait(
            "disarmed on the ground", lambda s: s.armed is False and s.landed_state == LANDED, 30
        )
        arms = [c for c in mon.state.changes if c[1] == "armed" and c[2] is True]
        texts = [t for _, t in mon.state.statustext]
    lab_px4.stop()  # its log closed and complete
    # gcs's lines with their times, kept with the run when the test fails
    (tmp_path / "gcs-lines.json").write_text(json.dumps(gcs.timed))
    # what tests/px4/test_px4_lab.py's lab flight asks
    assert "global origin set to" in out
    assert len(arms) == 1, texts  # armed once: the first attempt
    assert not any("Arming denied" in t for t in texts), texts
    assert "as vision_position_estimate" in out and "landed and disarmed" in out
    run = RunDir.open(run_path)
    assert run.complete_trials() == list(range(TRIALS))
    # the step after trial 2 refit the model, accepted or not ("skipped": no fit)
    reasons = refresh_reasons(run, REFRESHED_AFTER)
    assert any(r.startswith(("accepted", "rejected")) for r in reasons), (reasons, out)
    after = out.split(f"trial {REFRESHED_AFTER} flown")[1]
    refresh = next(ln.strip() for ln in after.splitlines() if "model " in ln)

    logs = lab_px4.ulogs()
    assert logs, f"PX4 wrote no log in {lab_px4.workdir}"
    log = read_flight_log(max(logs, key=lambda p: p.stat().st_size))
    trials, between = trial_windows(run, log)
    learning = learning_windows(run, log, gcs.timed)
    assert len(between) == len(learning) == TRIALS, (between, learning, gcs.timed)
    assert all(b > a for a, b in learning), learning
    # the trials lie in PX4's first OFFBOARD span: t0_vehicle_s is PX4's clock, the log's
    offboard_s, landing_s = log.offboard_spans()[0]
    assert all(offboard_s <= t0 and t1 <= landing_s for t0, t1 in trials), log.nav_states
    g = px4_gaps(run, log, gcs.timed)
    rate_hz = yaml.safe_load(profile.read_text())["flight"]["stream_rate_hz"]
    forwarded = run.sessions()[-1]["mocap"]["forwarded"]
    figures = {"refresh": refresh, **g.as_dict(), "vision_logged": len(log.vision_s),
               "vision_forwarded": forwarded}  # fmt: skip
    px4_figures.update(figures)
    print(json.dumps(figures))
    # the log holds the streams, not the logger's subsample (by default vision every 30 ms,
    # setpoints every 100 ms): the median gap in the trials is at most the stream's period
    assert g.vision_period_s <= 1.0 / lab_conditions.rate_hz + g.tick_s, g
    assert g.setpoint_period_s <= 1.0 / rate_hz + g.tick_s, g
    # the computation against the trials (goal: within 10 ms) is a figure, not asserted: the
    # largest gap of a window on a loaded machine is one outlier of any phase (docstring)
    late_in_trials_s = max(g.setpoint_trial_s - 1.0 / rate_hz, 0.0)
    px4_figures.update(
        vision_learning_minus_trial_ms=round(1e3 * (g.vision_learning_s - g.vision_trial_s)),
        setpoint_learning_minus_trial_ms=round(
            1e3 * (g.setpoint_learning_s - MAVSDK_RESEND_S - late_in_trials_s)
        ),
    )
    # and neither stream ever stopped: from arming to the landing no vision gap beyond gcs's own
    # stale limit, in OFFBOARD no setpoint later than the trial watchdog's limit
    armed_s = next(t for t, armed in log.armed if armed)
    assert largest_gap_over(log.vision_s, armed_s, landing_s) < HealthLimits().max_age_s, g
    late_limit_s = MAVSDK_RESEND_S + CI_FLIGHT["max_setpoint_late_s"]
    assert largest_gap_over(log.setpoints_s, offboard_s, landing_s) < late_limit_s, g
