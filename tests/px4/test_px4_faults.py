"""Faults on real PX4 firmware (SIH on GPS): gcs killed mid-trial and the geofence gcs left on
the vehicle; the machine pausing PX4 and gcs together mid-trial (Ctrl-C mid-trial and its
resume: test_px4_gps.py, after its two trials). PX4 is
watched on its payload link (:class:`Px4Monitor`, no heartbeat of its own: with gcs gone PX4
has no ground station), so every time here is an event PX4 itself reported: its heartbeat
(armed, mode) and EXTENDED_SYS_STATE (landed state), which PX4 sends on that link about once a
second: the figures have that resolution."""

from __future__ import annotations

import json
import math
import os
import re
import signal
import time
from pathlib import Path

import pytest
import yaml
from test_fly_e2e import ROOT, wait_for_line

from gcs.io.rundir import RunDir
from gcs.io.settings import FlightSettings
from px4.flying import IN_AIR, ON_GROUND, finish, gcs, since, sitl_profile

pytestmark = pytest.mark.px4

OFFBOARD = 6 << 16  # PX4 custom_mode: main mode 6
FAILSAFE_S = 60.0  # bounds of the waits below, not waits


@pytest.mark.flight_s(59)
def test_gcs_killed_mid_trial_px4_lands_and_keeps_the_arena_fence(
    px4_booting, px4_figures, tmp_path: Path
) -> None:
    """gcs SIGKILLed mid-trial with NAV_DLL_ACT 3 (Land) set by the test: PX4 leaves offboard,
    lands and disarms on its own (the modes and messages it went through are recorded); the
    geofence gcs uploaded, read back from PX4 afterwards,
    is the arena plus the fence margin around PX4's local origin."""
    px4, profile = px4_booting, sitl_profile(tmp_path)
    with px4.monitor() as mon:
        mon.set_param("NAV_DLL_ACT", 3)
        run = tmp_path / "run"
        proc = gcs("fly", "--connect", px4.url, "--iter", 1, "--trajectory", "eight-short",
                   "--run", run, "--profile", profile)  # fmt: skip
        seen = wait_for_line(proc, "trial 0 started")
        mon.wait("in the air, offboard", lambda s: s.landed_state == IN_AIR, 10)
        assert mon.state.armed and mon.state.custom_mode == OFFBOARD, "".join(seen)
        proc.kill()
        t_kill = time.monotonic()
        proc.communicate(timeout=10)
        t_off = mon.wait("PX4 leaving offboard", lambda s: s.custom_mode != OFFBOARD, FAILSAFE_S)
        t_ground = mon.wait("landed", lambda s: s.landed_state == ON_GROUND, FAILSAFE_S)
        t_disarm = mon.wait("disarmed", lambda s: s.armed is False, FAILSAFE_S)
        origin = mon.global_origin()
        fence = mon.download_fence()
        events = mon.events_since(t_kill)
    px4_figures["fault"] = {
        "offboard_left_s": since(t_kill, t_off),
        "on_ground_s": since(t_kill, t_ground),
        "disarmed_s": since(t_kill, t_disarm),
        "events": events,
    }
    assert t_off <= t_ground <= t_disarm, events

    # the fence: four inclusion vertices, the arena +- margin (independent flat-earth projection)
    data = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    margin = FlightSettings().fence_margin_m
    (n0, n1), (e0, e1) = data["arena"]["north_m"], data["arena"]["east_m"]
    expected = {(n0 - margin, e0 - margin), (n0 - margin, e1 + margin),
                (n1 + margin, e1 + margin), (n1 + margin, e0 - margin)}  # fmt: skip
    r_earth = 6_371_000.0
    lat0, lon0 = origin
    got = []
    for item in fence:
        assert item.command == 5001, item  # MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
        assert item.param1 == len(fence), item  # one polygon of all the vertices
        north = math.radians(item.x * 1e-7 - lat0) * r_earth
        east = math.radians(item.y * 1e-7 - lon0) * r_earth * math.cos(math.radians(lat0))
        got.append((round(north, 3), round(east, 3)))
    px4_figures["fence"] = {"vertices_ned_m": got, "margin_m": margin}
    assert len(got) == 4, got
    for corner in expected:
        assert min(math.dist(corner, g) for g in got) < 0.05, (corner, got)


#: How long the machine's pause stops PX4 and gcs: longer than the tests' late-setpoint limit
#: (``CI_FLIGHT``'s 0.4 s), shorter than PX4's offboard-loss timeout (COM_OF_LOSS_T, 1 s) and
#: the tests' telemetry-age limit (1 s). A CI machine paused two flights for 0.5 s at once.
PAUSE_S = 0.6


@pytest.mark.flight_s(61)
def test_a_pause_of_the_machine_mid_trial_is_ridden_through_by_flying_the_trial_again(
    px4_booting, px4_figures, tmp_path: Path
) -> None:
    """PX4 and gcs stopped together (SIGSTOP, then SIGCONT) for :data:`PAUSE_S` once trial 0's
    stream has begun, as a loaded machine pauses a flight: gcs's next setpoint goes out late
    while the vehicle stays in OFFBOARD, so gcs keeps the attempt (the run's ``aborted/``),
    flies trial 0 again from its start point, lands and disarms, exit 0; PX4 never left
    OFFBOARD before the landing."""
    px4, run = px4_booting, tmp_path / "run"
    with px4.monitor() as mon:
        proc = gcs("fly", "--connect", px4.url, "--iter", 1, "--trajectory", "eight-short",
                   "--run", run, "--profile", sitl_profile(tmp_path))  # fmt: skip
        # the stream's first line: the first setpoint is out (a pause before it delays the
        # trial, not a setpoint, and is no fault: seen once, as "trial 0 started" came first)
        seen = wait_for_line(proc, "trial 0: 0/")
        mon.wait("in the air, offboard", lambda s: s.custom_mode == OFFBOARD, 10)
        t_pause = time.monotonic()
        os.killpg(px4.proc.pid, signal.SIGSTOP)  # PX4 runs in a session of its own
        os.kill(proc.pid, signal.SIGSTOP)
        time.sleep(PAUSE_S)  # the pause itself, not a wait for an event
        os.killpg(px4.proc.pid, signal.SIGCONT)
        os.kill(proc.pid, signal.SIGCONT)
        code, out = finish(proc, seen)
        mon.wait("disarmed", lambda s: s.armed is False and s.landed_state == ON_GROUND, 30)
        events = mon.events_since(t_pause)
    assert code == 0, out
    stopped = re.search(r"trial 0 stopped at sample \d+/\d+: setpoint \d+ sent (\d+) ms late", out)
    assert stopped is not None, out
    assert "flying trial 0 again (1 of 2)" in out and "landed and disarmed" in out, out
    assert out.count("trial 0 flown") == 1, out
    rd = RunDir.open(run)
    assert rd.complete_trials() == [0]
    kept = json.loads((run / "aborted" / "trial-000-attempt-1.json").read_text())
    assert kept["status"] == "incomplete" and "late" in kept["reason"], kept
    px4_figures["pause"] = {"pause_s": PAUSE_S, "late_ms": int(stopped.group(1)), "events": events}
    # PX4 stayed in OFFBOARD through the pause and the trial flown again: its first change of
    # mode is gcs's landing
    modes = [what for _, what in events if what.startswith("mode ")]
    assert modes and modes[0] == "mode AUTO.LAND", events
