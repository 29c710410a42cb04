"""The campaign on the virtual clock: tests/test_flight_e2e.py's flights in seconds.

The same campaigns, sources and checks, flown in-process on the simulated drone
(tests/virtual.py); the event times are the loop's virtual time. tests/test_flight_e2e.py keeps
the take-off-to-landing flight on the wire (MAVSDK over UDP to the mock process).
"""

from __future__ import annotations

import asyncio
import itertools
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_flight_e2e import (
    FENCE,
    SETTINGS,
    T_ILC_S,
    CircleSource,
    _best_lag_correlation,
)
from virtual import fly_virtual

from gcs.errors import TrialAborted, TrialPaused, VehicleError
from gcs.flight.campaign import (
    CampaignPlan,
    Status,
    TrialFinished,
    TrialProgress,
    TrialStarted,
    fly_campaign,
)
from gcs.flight.hover import SPEED_SPAN_S
from gcs.mock.config import Faults, load_mock_config
from gcs.sim.drone import SimulatedDrone

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e


def test_campaign_flies_two_trials_lands_and_disarms(tmp_path: Path) -> None:
    source = CircleSource()
    events: list[object] = []
    stamps: list[float] = []

    def on_event(event: object) -> None:
        events.append(event)
        stamps.append(asyncio.get_running_loop().time())  # virtual time

    with SimulatedDrone(seed=0) as drone:
        fly_virtual(
            fly_campaign(CampaignPlan(drone.url, 0, 2, T_ILC_S, SETTINGS, FENCE), source, on_event)
        )
    assert source.asked == [0, 1]
    assert [j for j, _ in source.recorded] == [0, 1] and not source.incomplete
    n = source.setpoints.shape[0]
    for _, rec in source.recorded:
        assert rec.complete and rec.abort_reason is None
        assert rec.t_s.shape == (n + 1,) and rec.pos_ned_m.shape == (n + 1, 3)
        assert rec.vel_ned_m_s.shape == (n + 1, 3) and rec.sent_s.shape == (n,)
        assert rec.interpolated.shape == (n + 1,) and rec.interpolated_share < 0.05
        assert np.all(np.isfinite(rec.pos_ned_m)) and np.all(np.isfinite(rec.sent_s))
        np.testing.assert_allclose(rec.sent_s, rec.t_s[:-1], atol=SETTINGS.max_setpoint_late_s)
        # the vehicle follows the circle, with the closed loop's lag
        for axis in (0, 1):
            lag, r = _best_lag_correlation(rec.pos_ned_m[1:, axis], rec.setpoints_ned_m[:, axis])
            assert r > 0.9, (axis, lag, r)
            assert 0 <= lag * T_ILC_S <= 1.5
        assert np.max(np.abs(rec.pos_ned_m[:, 2] - rec.setpoints_ned_m[0, 2])) < 0.3
    kinds = [type(e) for e in events]
    assert kinds.count(TrialStarted) == 2 and kinds.count(TrialFinished) == 2
    assert TrialProgress in kinds
    texts = [e.text for e in events if isinstance(e, Status)]
    assert texts[-1] == "landed and disarmed"
    # each trial starts after holding the start point (the initial reset), not before
    holds = [i for i, e in enumerate(events) if isinstance(e, Status) and "holding" in e.text]
    starts = [i for i, e in enumerate(events) if isinstance(e, TrialStarted)]
    assert len(holds) == 2 and all(h < s for h, s in zip(holds, starts, strict=True))
    for h, s in zip(holds, starts, strict=True):
        # (on virtual time exactly the hold: the float sum's last bit aside)
        assert stamps[s] - stamps[h] >= SETTINGS.hover_before_trial_s - 1e-9
    # the hover before trial 0 was measured (after a hold of its own), judged and handed over
    (measuring,) = [i for i, t in enumerate(events) if getattr(t, "text", "").startswith("meas")]
    assert measuring < holds[0]
    assert stamps[holds[0]] - stamps[measuring] >= (
        SETTINGS.hover_before_trial_s + SETTINGS.hover_measure_s - 1e-9
    )
    # recorded before take-off (fence, the vehicle's geofence), again once the hover was judged
    before, session = source.sessions
    assert not before.hovers and before.fence == FENCE and before.geofence is not None
    assert before.geofence.ok and session.geofence == before.geofence
    assert session.abort_reason is None
    (hover,) = session.hovers
    assert hover.verdict.ok and hover.why == "measurement" and hover.before_trial == 0
    assert hover.stats.duration_s == pytest.approx(SETTINGS.hover_measure_s, abs=0.1)
    assert session.tolerance_m >= SETTINGS.settle_tolerance_m
    assert session.navigation.name == "GPS"  # the mock reports PX4's EKF2 defaults
    assert hover.clock_rate == pytest.approx(1.0, abs=1e-3)
    for _, rec in source.recorded:
        assert rec.clock is not None and rec.clock.rate == pytest.approx(1.0, abs=1e-3)
    assert drone.stats()["modes"][-1]["armed"] is False


#: the estimate steps 0.4 m east this long after arming: in the last 0.2 s of the hold before
#: trial 1 as the campaign flew it when the settle came before the hold
JUMP_AT_S = 26.5


def test_a_trial_starts_settled_at_its_start_point_whatever_the_hold_left() -> None:
    """The settle is the last thing before u(0): a vehicle pushed off the start point near the
    end of the hold (here its estimate steps 0.4 m, twice the settle tolerance) starts its
    trial once it is back within the tolerance, not where the hold left it (0.38 m off when
    the settle came first)."""
    source = CircleSource()
    faults = Faults(jump_at_s=JUMP_AT_S, jump_ned_m=(0.0, 0.4, 0.0))
    with SimulatedDrone(seed=0, faults=faults) as drone:
        fly_virtual(fly_campaign(CampaignPlan(drone.url, 0, 2, T_ILC_S, SETTINGS, FENCE), source))
    session = source.sessions[-1]
    assert [j for j, _ in source.recorded] == [0, 1]
    for _, rec in source.recorded:
        offset_m = np.linalg.norm(rec.pos_ned_m[0] - rec.setpoints_ned_m[0])
        assert offset_m <= session.tolerance_m, (offset_m, session.tolerance_m)


def test_link_loss_mid_trial_marks_it_incomplete(tmp_path: Path) -> None:
    source = CircleSource(duration_s=8.0)
    events: list[object] = []
    # 4 s after the first OFFBOARD plus what comes before trial 0: the hold and the hover
    # measurement, the shortest settle (its window and 1 s of speed span) and the hold
    loss_at_s = 4.0 + 2 * SETTINGS.hover_before_trial_s + SETTINGS.hover_measure_s
    loss_at_s += SETTINGS.settle_time_s + SPEED_SPAN_S
    config = tmp_path / "mock.yaml"  # a vehicle set up to land on a lost link
    config.write_text("px4:\n  nav_dll_act: 3\n  com_dl_loss_t_s: 3.0\n")
    faults = Faults(link_loss_at_s=loss_at_s)
    with SimulatedDrone(load_mock_config(config), faults=faults) as drone:  # noqa: SIM117
        with pytest.raises((TrialAborted, VehicleError)):
            fly_virtual(
                fly_campaign(
                    CampaignPlan(drone.url, 0, 1, T_ILC_S, SETTINGS, FENCE), source, events.append
                )
            )
    assert not source.recorded
    assert len(source.incomplete) == 1
    j, rec, reason = source.incomplete[0]
    assert j == 0 and not rec.complete and rec.abort_reason
    assert "telemetry" in reason or "link" in reason
    measured = np.isfinite(rec.pos_ned_m[:, 0])
    assert 0 < measured.sum() < len(measured)  # some of it, not all of it
    assert any(isinstance(e, Status) and e.text.startswith("emergency stop") for e in events)
    # The link is gone for good, so nothing we send arrives: the vehicle's own failsafes act.
    # The offboard-loss failsafe (COM_OF_LOSS_T) holds, then the data-link-loss failsafe
    # (COM_DL_LOSS_T, NAV_DLL_ACT = 3) lands, and the land detector disarms.
    modes = drone.stats()["modes"]
    last_offboard = max(i for i, m in enumerate(modes) if m["mode"] == "OFFBOARD" and m["armed"])
    armed_modes = [m["mode"] for m in modes[last_offboard + 1 :] if m["armed"]]
    assert [mode for mode, _ in itertools.groupby(armed_modes)] == ["HOLD", "LAND"], modes
    assert modes[-1]["armed"] is False, modes


def test_cancellation_mid_trial_lands_and_marks_incomplete(tmp_path: Path) -> None:
    source = CircleSource(duration_s=6.0)
    statuses: list[str] = []

    async def fly_then_cancel() -> None:
        in_trial = asyncio.Event()

        def on_event(event: object) -> None:
            if isinstance(event, TrialProgress) and event.k >= 20:
                in_trial.set()
            if isinstance(event, Status):
                statuses.append(event.text)

        task = asyncio.create_task(
            fly_campaign(CampaignPlan(drone.url, 0, 2, T_ILC_S, SETTINGS, FENCE), source, on_event)
        )
        await in_trial.wait()
        task.cancel()  # what Ctrl-C does to asyncio.run's main task
        with pytest.raises(asyncio.CancelledError):
            await task

    with SimulatedDrone(seed=0) as drone:
        fly_virtual(asyncio.wait_for(fly_then_cancel(), 40.0))
    assert not source.recorded
    assert len(source.incomplete) == 1
    j, rec, reason = source.incomplete[0]
    assert j == 0 and not rec.complete and "interrupted" in reason
    assert np.isfinite(rec.pos_ned_m[:20]).all()
    assert "emergency stop: landed and disarmed" in statuses
    assert drone.stats()["modes"][-1]["armed"] is False


def _pausing(pauses: int, trial: int, events: list[object]):  # type: ignore[no-untyped-def]
    """An event callback that blocks the loop for 0.6 s (virtual) in the first ``pauses``
    attempts of ``trial``, at its 20th sample, as a machine that paused gcs would."""
    attempt = [-1]  # the attempt of ``trial`` in flight (0 the first)
    paused: set[int] = set()

    def on_event(event: object) -> None:
        events.append(event)
        if isinstance(event, TrialStarted) and event.trial == trial:
            attempt[0] += 1
        ours = isinstance(event, TrialProgress) and event.trial == trial and event.k >= 20
        if ours and attempt[0] < pauses and attempt[0] not in paused:
            paused.add(attempt[0])
            asyncio.get_running_loop().advance(0.6)  # type: ignore[attr-defined]

    return on_event


def test_a_trial_whose_stream_fell_behind_is_kept_and_flown_again() -> None:
    source = CircleSource()
    events: list[object] = []
    with SimulatedDrone(seed=0) as drone:
        plan = CampaignPlan(drone.url, 0, 2, T_ILC_S, SETTINGS, FENCE)
        fly_virtual(fly_campaign(plan, source, _pausing(1, 1, events)))
    assert [j for j, _ in source.recorded] == [0, 1]
    ((j, partial, reason),) = source.incomplete
    assert j == 1 and not partial.complete and "late" in reason
    assert 20 <= np.isfinite(partial.pos_ned_m[:, 0]).sum() < partial.pos_ned_m.shape[0]
    for _, rec in source.recorded:  # the trial flown again streamed on time
        assert rec.complete and rec.max_send_late_s < SETTINGS.max_setpoint_late_s
    texts = [e.text for e in events if isinstance(e, Status)]
    agains = [t for t in texts if "flying trial" in t]
    assert len(agains) == 1, texts
    again = agains[0]
    assert again.startswith("trial 1 stopped at sample ") and "ms late (limit 400 ms)" in again
    assert again.endswith("flying trial 1 again (1 of 2)")
    after = texts[texts.index(again) :]
    assert after[1] == "moving to the start point of trial 1" and "holding" in after[-3]
    assert [e.trial for e in events if isinstance(e, TrialStarted)] == [0, 1, 1]
    assert sum(t.startswith("measuring the hover") for t in texts) == 1
    assert texts[-1] == "landed and disarmed"
    assert drone.stats()["modes"][-1]["armed"] is False


def test_a_trial_paused_more_often_than_the_profile_allows_ends_the_flight() -> None:
    source = CircleSource()
    events: list[object] = []
    settings = replace(SETTINGS, paused_trial_retries=1)
    with SimulatedDrone(seed=0) as drone:
        plan = CampaignPlan(drone.url, 0, 2, T_ILC_S, settings, FENCE)
        with pytest.raises(TrialPaused, match="late"):
            fly_virtual(fly_campaign(plan, source, _pausing(2, 0, events)))
    assert not source.recorded
    assert [j for j, _, _ in source.incomplete] == [0, 0]
    texts = [e.text for e in events if isinstance(e, Status)]
    assert sum("flying trial 0 again (1 of 1)" in t for t in texts) == 1
    assert texts[-1] == "emergency stop: landed and disarmed"
    assert drone.stats()["modes"][-1]["armed"] is False
