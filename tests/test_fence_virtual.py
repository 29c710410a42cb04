"""The arena as a live fence on the virtual clock: tests/test_fence_e2e.py's faults in seconds.

The same flights, checks and records (the mock's estimator faults, its truth-and-error record
replayed through the fence's monitor, its mode log, the geofence in force), flown in-process
on the simulated drone (tests/virtual.py). The drift flight of tests/test_fence_e2e.py stays
on the wire: the geofence upload through MAVSDK's mission protocol.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from synthetic import SHORT, ci_profile
from test_fence_e2e import (
    FENCE,
    IN_HOVER_S,
    IN_TRIAL_S,
    SETTINGS,
    T_ILC_S,
    assert_landed_and_disarmed,
    assert_nothing_outside_was_sent,
    estimate_breach_s,
    report,
    stop_s,
)
from test_flight_e2e import CircleSource
from virtual import fly_virtual, run_gcs

from gcs.core.frames import global_to_ned
from gcs.errors import TrialAborted, VehicleError
from gcs.flight.campaign import CampaignPlan, Status, fly_campaign
from gcs.flight.geofence import GF_ACTION, vertical_limit_m
from gcs.io.rundir import RunDir
from gcs.mock.config import Faults, load_mock_config
from gcs.sim.drone import SimulatedDrone

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e


def fly(tmp_path: Path, faults: Faults, source: CircleSource, config: Path | None = None):
    """Fly one trial of ``source`` on the simulated drone: (statuses, error, stats)."""
    statuses: list[str] = []
    error: BaseException | None = None

    def on_event(event: object) -> None:
        if isinstance(event, Status):
            statuses.append(event.text)

    cfg = load_mock_config(config)
    with SimulatedDrone(cfg, seed=0, faults=faults) as drone:
        plan = CampaignPlan(drone.url, 0, 1, T_ILC_S, SETTINGS, FENCE)
        try:
            fly_virtual(fly_campaign(plan, source, on_event))
        except (VehicleError, TrialAborted) as exc:
            error = exc
    return statuses, error, drone.stats()


def test_a_drift_in_hover_aborts_within_a_second_and_the_geofence_is_on_the_vehicle(
    tmp_path: Path,
) -> None:
    # the estimate walks east at 3 m/s for 1 s (its velocity does not show it)
    faults = Faults(drift_start_s=IN_HOVER_S, drift_duration_s=1.0, drift_ned_m_s=(0.0, 3.0, 0.0))
    source = CircleSource(duration_s=4.0)
    statuses, error, stats = fly(tmp_path, faults, source)
    assert error is not None and "against its velocity" in str(error), (error, statuses)
    breach_s, how = estimate_breach_s(stats)
    assert "against its velocity" in how
    (fault,) = stats["estimator_faults"]
    onset = fault["onset_vehicle_s"]
    # 2 m against the velocity at 3 m/s: 0.67 s after the onset (the record's 0.02 s grid)
    assert breach_s - onset == pytest.approx(FENCE.drift_m / 3.0, abs=0.03)
    stop = stop_s(stats, onset)
    report("drift", stats, breach_s, stop, how)
    assert stop["mode"] == "HOLD" and -0.03 <= stop["t_vehicle_s"] - breach_s < 1.0, (
        stop,
        breach_s,
    )
    assert any(s.startswith("aborting: fence: the position moved") for s in statuses)
    assert_landed_and_disarmed(statuses, stats)
    assert_nothing_outside_was_sent(stats)
    assert not source.recorded and not source.incomplete  # no trial had begun
    # the geofence: the arena plus margin around the mock's origin, GF_ACTION Land, the ceiling
    fence = stats["geofence"]
    origin = (47.3977431, 8.5455947)  # profiles/mock.yaml's px4.home_*, the local origin
    corners = [global_to_ned(*origin, i["x"] * 1e-7, i["y"] * 1e-7) for i in fence["items"]]
    m = FENCE.margin_m
    np.testing.assert_allclose(
        corners, [(-3 - m, -3 - m), (-3 - m, 3 + m), (3 + m, 3 + m), (3 + m, -3 - m)], atol=0.02
    )
    assert [i["command"] for i in fence["items"]] == [5001] * 4 and fence["areas_in_force"] == 1
    assert fence["params"]["GF_ACTION"] == GF_ACTION == 5
    assert fence["params"]["GF_MAX_VER_DIST"] == pytest.approx(vertical_limit_m(FENCE)) == 4.5
    before, after = source.sessions
    assert before.geofence is not None and before.geofence.ok and before.abort_reason is None
    assert after.abort_reason is not None and "against its velocity" in after.abort_reason
    line = next(s for s in statuses if s.startswith("geofence: "))
    assert "GF_ACTION 5 (Land)" in line and "GF_MAX_VER_DIST 4.5 m" in line, line


def test_a_jump_mid_trial_aborts_at_once_and_the_trial_is_kept_incomplete(tmp_path: Path) -> None:
    faults = Faults(jump_at_s=IN_TRIAL_S, jump_ned_m=(1.0, 0.0, 0.0))  # a mis-solved frame
    source = CircleSource(duration_s=8.0)
    statuses, error, stats = fly(tmp_path, faults, source)
    assert isinstance(error, TrialAborted) and "jumped" in str(error), (error, statuses)
    (fault,) = stats["estimator_faults"]
    breach_s, how = estimate_breach_s(stats)
    assert "jumped" in how and breach_s - fault["onset_vehicle_s"] < 0.03
    stop = stop_s(stats, fault["onset_vehicle_s"])
    report("jump", stats, breach_s, stop, how)
    assert stop["mode"] == "HOLD" and stop["t_vehicle_s"] - breach_s < 1.0, (stop, breach_s)
    (j, rec, reason) = source.incomplete[0]
    assert j == 0 and not rec.complete and "jumped" in reason
    assert 0 < np.isfinite(rec.pos_ned_m[:, 0]).sum() < len(rec.pos_ned_m)
    assert_landed_and_disarmed(statuses, stats)
    assert_nothing_outside_was_sent(stats)


def test_a_divergence_in_hover_aborts_within_a_second(tmp_path: Path) -> None:
    # the height estimate runs away downwards as 1.5 t^2, while the vehicle climbs to hold it
    faults = Faults(
        divergence_start_s=IN_HOVER_S, divergence_duration_s=2.0,
        divergence_ned_m_s2=(0.0, 0.0, 3.0),
    )  # fmt: skip
    source = CircleSource(duration_s=4.0)
    statuses, error, stats = fly(tmp_path, faults, source)
    assert error is not None and str(error).startswith("fence: "), (error, statuses)
    (fault,) = stats["estimator_faults"]
    breach_s, how = estimate_breach_s(stats)
    assert 0.3 < breach_s - fault["onset_vehicle_s"] < 1.5, (breach_s, how)
    stop = stop_s(stats, fault["onset_vehicle_s"])
    report("divergence", stats, breach_s, stop, how)
    assert -0.03 <= stop["t_vehicle_s"] - breach_s < 1.0, (stop, breach_s, how)
    assert_landed_and_disarmed(statuses, stats)
    assert_nothing_outside_was_sent(stats)


def test_a_height_estimate_sinking_below_the_floor_while_landing_lets_the_vehicle_land(
    tmp_path: Path,
) -> None:
    # PX4 SITL on GPS, landing: on the ground the estimate sank 1.5 m below it before the land
    # detector said so, and the fence ended a complete identification with an error. Here the
    # height estimate sinks 1.94 m (0.8 t^2 / 2 for 2.2 s) from 0.3 s after LAND.
    source = CircleSource(duration_s=4.0)
    _, error, clean = fly(tmp_path, Faults(), source)
    assert error is None
    land_s = next(m["t_vehicle_s"] for m in clean["modes"] if m["mode"] == "LAND")
    faults = Faults(
        divergence_start_s=land_s - clean["first_armed_vehicle_s"] + 0.3,
        divergence_duration_s=2.2, divergence_ned_m_s2=(0.0, 0.0, 0.8),
    )  # fmt: skip
    statuses, error, stats = fly(tmp_path, faults, source)
    (fault,) = stats["estimator_faults"]
    assert fault["onset_vehicle_s"] > land_s
    assert error is None, (error, statuses)
    assert statuses[-2] == "landed and disarmed", statuses
    assert statuses[-1].startswith("while landing the position estimate read up to 1.9"), statuses
    assert "m below the arena's floor" in statuses[-1]
    assert [m["mode"] for m in stats["modes"] if m["t_vehicle_s"] >= land_s][0] == "LAND"
    assert not any(m["mode"] == "HOLD" for m in stats["modes"] if m["t_vehicle_s"] > land_s)
    assert not any(s.startswith(("aborting", "emergency stop")) for s in statuses), statuses
    assert stats["modes"][-1]["armed"] is False


def test_the_incident_a_divergence_during_take_off_is_caught_before_anything_is_streamed(
    tmp_path: Path,
) -> None:

    # as once on PX4 SITL: EKF2's height diverged during take-off; gcs took off, started
    # offboard at the diverged position and streamed a transit from far outside the arena for
    # ten minutes
    trajectory = tmp_path / "tiny.yaml"
    trajectory.write_text(yaml.safe_dump(SHORT))
    run_path = tmp_path / "run"
    faults = Faults(
        divergence_start_s=0.3, divergence_duration_s=4.0, divergence_ned_m_s2=(0.0, 0.0, 2.0)
    )
    with SimulatedDrone(seed=0, faults=faults) as drone:
        code, out = run_gcs(
            "fly", "--connect", drone.url, "--iter", "1", "--trajectory", trajectory,
            "--run", run_path, "--profile", ci_profile(tmp_path),
        )  # fmt: skip
    stats = drone.stats()
    assert code == 2, out
    assert stats["setpoints"]["north_m"] == []  # not one setpoint: no offboard, no transit
    (fault,) = stats["estimator_faults"]
    breach_s, how = estimate_breach_s(stats)
    stop = stop_s(stats, fault["onset_vehicle_s"])
    report("divergence in take-off", stats, breach_s, stop, how)
    takeoff = next(m for m in stats["modes"] if m["mode"] == "TAKEOFF")
    assert stop["mode"] == "LAND" and takeoff["t_vehicle_s"] < breach_s, stats["modes"]
    assert -0.03 <= stop["t_vehicle_s"] - breach_s < 1.0, (stop, breach_s, how)
    assert "aborting: fence: " in out and "emergency stop: landed and disarmed" in out, out
    assert "geofence: the arena + 1.5 m uploaded" in out, out
    assert stats["modes"][-1]["armed"] is False
    # the vehicle really climbed while its estimate sank: the estimate was far below the truth
    rec = stats["estimator"]
    assert max(rec["err_down_m"]) > 10.0 and min(rec["down_m"]) < -2.0
    (session,) = RunDir.open(run_path).sessions()
    assert session["geofence"]["uploaded"] and session["geofence"]["gf_action"] == GF_ACTION
    assert session["abort_reason"].startswith("fence: ") and session["hovers"] == []
    assert session["fence"]["margin_m"] == FENCE.margin_m
    assert not list(run_path.glob("trial-*"))


def test_with_the_link_lost_the_vehicle_itself_lands_on_a_geofence_breach(tmp_path: Path) -> None:
    # the link goes for 5 s at 3 s after the first OFFBOARD (about 6.5 s after arming); at 9 s
    # after arming the estimate jumps 6 m east, out of the geofence (the arena + 1.5 m)
    faults = Faults(
        link_loss_at_s=3.0, link_loss_duration_s=5.0, jump_at_s=9.0, jump_ned_m=(0.0, 6.0, 0.0)
    )
    source = CircleSource(duration_s=4.0)
    statuses, error, stats = fly(tmp_path, faults, source)
    assert isinstance(error, VehicleError) and "telemetry" in str(error), (error, statuses)
    lost_s = stats["first_offboard_vehicle_s"] + 3.0
    (fault,) = stats["estimator_faults"]
    jump_s = fault["onset_vehicle_s"]
    assert lost_s < jump_s < lost_s + 5.0  # the jump came while gcs could not see or send
    (breach,) = stats["geofence"]["breaches"]
    assert breach["action"] == 5 and breach["kinds"] == ["fence"]
    assert 0.0 <= breach["t_vehicle_s"] - jump_s <= 0.25  # PX4 checks every 0.2 s
    land = next(m for m in stats["modes"] if m["t_vehicle_s"] >= jump_s and m["mode"] == "LAND")
    assert land["t_vehicle_s"] - breach["t_vehicle_s"] < 0.05 and land["t_vehicle_s"] < lost_s + 5
    texts = [t["text"] for t in stats["statustexts"] if t["t_vehicle_s"] >= jump_s]
    assert texts[:2] == ["Geofence: approaching or outside geofence", "Failsafe activated"]
    assert stats["modes"][-1]["armed"] is False
    assert "emergency stop: landed and disarmed" in statuses, statuses
    assert_nothing_outside_was_sent(stats)
