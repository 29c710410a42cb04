"""End to end: the arena as a live fence, through the real MAVSDK on the mock drone.

Each flight injects one estimator fault into the mock (its times count from the first arming)
and checks, against the mock's own record (its statistics: the truth, the estimator's error,
every mode change and every setpoint it received):

- the abort (the vehicle's mode leaving OFFBOARD, or TAKEOFF, for Hold or Land) comes within a
  second of the moment the estimate broke the fence's limits, found by replaying the mock's
  record of the estimate (truth plus error, every 0.02 s) through the fence's monitor;
- the vehicle lands and disarms;
- nothing outside the arena was ever sent.

The geofence gcs uploads (MAVSDK's mission protocol to the mock) is checked in the mock's
record. The drift flight stays here on the wire; it and the other faults (a jump mid-trial, a
divergence in hover and in take-off, the vehicle's own geofence failsafe on a lost link) fly on
the virtual clock in tests/test_fence_virtual.py (docs/testing.md), with these helpers.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import numpy as np
import pytest
from test_flight_e2e import CircleSource

from gcs.core.frames import global_to_ned
from gcs.errors import TrialAborted, VehicleError
from gcs.flight.campaign import CampaignPlan, Status, fly_campaign
from gcs.flight.fence import EstimateMonitor, Fence
from gcs.flight.geofence import GF_ACTION, vertical_limit_m
from gcs.io.settings import FlightSettings
from gcs.mock.config import Faults
from gcs.mock.process import MockProcess

pytestmark = pytest.mark.e2e
ROOT = Path(__file__).resolve().parents[1]
T_ILC_S = 0.05
# the CI watchdog limits of tests/test_flight_e2e.py, and a 1 s hold to keep the flights short
SETTINGS = FlightSettings(
    settle_time_s=0.5, settle_tolerance_m=0.2, connect_timeout_s=5.0, max_setpoint_late_s=0.4,
    max_telemetry_age_s=1.0, hover_measure_s=2.0, hover_before_trial_s=1.0,
)  # fmt: skip
FENCE = Fence.around([[-3.0, 3.0], [-3.0, 3.0], [-3.0, 0.0]], SETTINGS, 3.0, 1.5)  # antx's
# After the first arming: OFFBOARD at about 3 s, the hold and the hover measurement until
# about 6.5 s, trial 0 (CircleSource of 8 s) from about 9 s to 17 s.
IN_HOVER_S = 4.5
IN_TRIAL_S = 12.0


def fly(tmp_path: Path, faults: Faults, source: CircleSource, config: Path | None = None):
    """Fly one trial of ``source`` on the mock with ``faults``: (statuses, error, stats)."""
    statuses: list[str] = []
    error: BaseException | None = None

    def on_event(event: object) -> None:
        if isinstance(event, Status):
            statuses.append(event.text)

    stats_path = tmp_path / "stats.json"
    with MockProcess(config, seed=0, faults=faults, stats_path=stats_path) as mock:
        try:
            asyncio.run(
                fly_campaign(
                    CampaignPlan(mock.url, 0, 1, T_ILC_S, SETTINGS, FENCE), source, on_event
                )
            )
        except (VehicleError, TrialAborted) as exc:
            error = exc
    return statuses, error, json.loads(stats_path.read_text())


def estimate_breach_s(stats: dict) -> tuple[float, str]:
    """When (vehicle time) the mock's estimate first broke the fence, and how: its record of
    truth and error replayed through the monitor gcs runs, from the first arming on."""
    rec = stats["estimator"]
    t = np.array(rec["t_vehicle_s"])
    true_pos = np.column_stack([rec["north_m"], rec["east_m"], rec["down_m"]])
    true_vel = np.column_stack([rec["vn_m_s"], rec["ve_m_s"], rec["vd_m_s"]])
    err_pos = np.column_stack([rec["err_north_m"], rec["err_east_m"], rec["err_down_m"]])
    err_vel = np.column_stack([rec["err_vn_m_s"], rec["err_ve_m_s"], rec["err_vd_m_s"]])
    monitor = EstimateMonitor(FENCE)
    for tk, p, v in zip(t, true_pos + err_pos, true_vel + err_vel, strict=True):
        if tk >= stats["first_armed_vehicle_s"] and (problem := monitor.update(tk, p, v)):
            return float(tk), problem
    raise AssertionError("the estimate never broke the fence")


def stop_s(stats: dict, after_s: float) -> dict:
    """The first change to Hold or Land at or after a vehicle time (the abort)."""
    return next(
        m for m in stats["modes"] if m["t_vehicle_s"] >= after_s and m["mode"] in ("HOLD", "LAND")
    )


def report(what: str, stats: dict, breach_s: float, stop: dict, how: str) -> None:
    """The measured abort latency (shown with ``pytest -s``; docs/flight.md quotes them):
    after the breach (on the record's 0.02 s grid) and after the fault's onset."""
    (fault,) = stats["estimator_faults"]
    after_ms = 1000.0 * (stop["t_vehicle_s"] - breach_s)
    onset_ms = 1000.0 * (stop["t_vehicle_s"] - fault["onset_vehicle_s"])
    mode = stop["mode"]
    print(f"\n{what}: {mode} {after_ms:.0f} ms after the breach, {onset_ms:.0f} ms after the onset")
    print(f"  ({how})")


def assert_nothing_outside_was_sent(stats: dict) -> None:
    sp = np.column_stack([stats["setpoints"][k] for k in ("north_m", "east_m", "down_m")])
    b = FENCE.bounds
    assert np.all((sp >= b[:, 0]) & (sp <= b[:, 1])), sp[np.any((sp < b[:, 0]) | (sp > b[:, 1]), 1)]


def assert_landed_and_disarmed(statuses: list[str], stats: dict) -> None:
    assert "emergency stop: landed and disarmed" in statuses, statuses
    assert stats["modes"][-1]["armed"] is False


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
