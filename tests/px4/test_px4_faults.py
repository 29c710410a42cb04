"""Faults on real PX4 firmware (SIH on GPS): gcs killed mid-trial, Ctrl-C mid-trial, and the
geofence gcs left on the vehicle. PX4 is watched on its payload link (:class:`Px4Monitor`, no
heartbeat of its own: with gcs gone PX4 has no ground station), so every time here is an event
PX4 itself reported: its heartbeat (armed, mode) and EXTENDED_SYS_STATE (landed state), which
PX4 sends on that link about once a second: the figures have that resolution."""

from __future__ import annotations

import math
import signal
import time
from pathlib import Path

import pytest
import yaml
from test_fly_e2e import ROOT, wait_for_line

from gcs.io.rundir import RunDir
from gcs.io.settings import FlightSettings
from px4.flying import finish, gcs, report_rows, sitl_profile

pytestmark = pytest.mark.px4

ON_GROUND, IN_AIR = 1, 2  # MAV_LANDED_STATE
OFFBOARD = 6 << 16  # PX4 custom_mode: main mode 6
FAILSAFE_S = 60.0  # bounds of the waits below, not waits


def _since(t0: float, t: float) -> float:
    return round(t - t0, 1)


def first(events: list[tuple[float, str]], what: str) -> float:
    """When ``what`` first happened in a monitor's events [s after their start]."""
    return next(t for t, said in events if said == what)


def test_gcs_killed_mid_trial_px4_lands_and_keeps_the_arena_fence(
    px4, px4_figures, tmp_path: Path
) -> None:
    """gcs SIGKILLed mid-trial with NAV_DLL_ACT 3 (Land) set by the test: PX4 leaves offboard,
    lands and disarms on its own (the modes and messages it went through are recorded); the
    geofence gcs uploaded, read back from PX4 afterwards,
    is the arena plus the fence margin around PX4's local origin."""
    with px4.monitor() as mon:
        mon.set_param("NAV_DLL_ACT", 3)
        run = tmp_path / "run"
        proc = gcs("fly", "--connect", px4.url, "--iter", 1, "--trajectory", "eight-short",
                   "--run", run, "--profile", sitl_profile(tmp_path))  # fmt: skip
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
        "offboard_left_s": _since(t_kill, t_off),
        "on_ground_s": _since(t_kill, t_ground),
        "disarmed_s": _since(t_kill, t_disarm),
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


def test_ctrl_c_mid_trial_lands_and_resume_completes_on_the_same_vehicle(
    px4, px4_figures, tmp_path: Path
) -> None:
    """Ctrl-C (SIGINT) during trial 1: gcs lands and disarms, trial 0 stays complete and trial 1
    is marked interrupted; `gcs fly --resume` then flies trial 1 on the same vehicle."""
    run = tmp_path / "run"
    with px4.monitor() as mon:
        proc = gcs("fly", "--connect", px4.url, "--iter", 2, "--trajectory", "eight-short",
                   "--run", run, "--profile", sitl_profile(tmp_path))  # fmt: skip
        seen = wait_for_line(proc, "trial 1 started")
        mon.wait("in the air", lambda s: s.landed_state == IN_AIR and s.armed, 10)
        proc.send_signal(signal.SIGINT)
        t_int = time.monotonic()
        code, out = finish(proc, seen)
        t_exit = time.monotonic()
        mon.wait("disarmed", lambda s: s.armed is False and s.landed_state == ON_GROUND, 10)
        events = mon.events_since(t_int)
        assert code == 130, out
        assert "landed and disarmed" in out, out
        rd = RunDir.open(run)
        assert rd.complete_trials() == [0]
        status = rd.read_status(1)
        assert not status.complete and "interrupt" in status.reason, status
        px4_figures["fault"] = {
            "gcs_exit_s": _since(t_int, t_exit),
            "on_ground_s": first(events, "on ground"),
            "disarmed_s": first(events, "disarmed"),
            "events": events,
        }

        code, out = finish(gcs("fly", "--connect", px4.url, "--resume", run, "--iter", 1))
        assert code == 0, out
        assert "landed and disarmed" in out, out
        mon.wait("disarmed after the resumed run", lambda s: s.armed is False, 10)
    assert RunDir.open(run).complete_trials() == [0, 1]
    px4_figures["e_pos_m"] = [round(r["epos_m"], 4) for r in report_rows(run)]
