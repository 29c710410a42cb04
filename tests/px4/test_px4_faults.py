"""Faults on real PX4 firmware (SIH on GPS): gcs killed mid-trial and the geofence gcs left on
the vehicle (Ctrl-C mid-trial and its resume: test_px4_gps.py, after its two trials). PX4 is
watched on its payload link (:class:`Px4Monitor`, no heartbeat of its own: with gcs gone PX4
has no ground station), so every time here is an event PX4 itself reported: its heartbeat
(armed, mode) and EXTENDED_SYS_STATE (landed state), which PX4 sends on that link about once a
second: the figures have that resolution."""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest
import yaml
from test_fly_e2e import ROOT, wait_for_line

from gcs.io.settings import FlightSettings
from px4.flying import IN_AIR, ON_GROUND, gcs, since, sitl_profile

pytestmark = pytest.mark.px4

OFFBOARD = 6 << 16  # PX4 custom_mode: main mode 6
FAILSAFE_S = 60.0  # bounds of the waits below, not waits


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
