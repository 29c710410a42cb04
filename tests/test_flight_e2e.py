"""End-to-end: the flight layer flies the mock drone through real MAVSDK over UDP loopback.

Each test starts its own mock process on a free port (``--port 0``) and runs in real time.
The take-off-to-landing campaign stays here to prove the wire; its link loss and cancellation,
and the same campaign again, fly on the virtual clock in tests/test_campaign_virtual.py
(docs/testing.md).
"""

from __future__ import annotations

import asyncio
import gc
import json
import os
import socket
import time
from pathlib import Path

import numpy as np
import pytest
from realtime import RAISED

from gcs.errors import VehicleError
from gcs.flight.campaign import (
    CampaignPlan,
    FlightSession,
    Status,
    TrialFinished,
    TrialProgress,
    TrialStarted,
    fly_campaign,
)
from gcs.flight.fence import Fence
from gcs.flight.trial import TrialRecording
from gcs.flight.vehicle import Vehicle
from gcs.io.settings import FlightSettings
from gcs.mock.config import Faults
from gcs.mock.process import MockProcess

pytestmark = pytest.mark.e2e

T_ILC_S = 0.05
# watchdog limits tolerant of a loaded CI machine (see tests/synthetic.py: CI_FLIGHT)
SETTINGS = FlightSettings(
    settle_time_s=0.5, settle_tolerance_m=0.2, connect_timeout_s=5.0,
    max_setpoint_late_s=0.4, max_telemetry_age_s=1.0, hover_measure_s=2.0,
)  # fmt: skip
FENCE = Fence.around([[-3.0, 3.0], [-3.0, 3.0], [-3.0, 0.0]], SETTINGS, 3.0, 1.5)  # antx's


class CircleSource:
    """Tiny TrialSource: the same circle every trial; keeps what it is handed."""

    def __init__(self, duration_s: float = 4.0, radius_m: float = 0.5, height_m: float = 2.0):
        n = round(duration_s / T_ILC_S)
        phase = np.linspace(0.0, 2.0 * np.pi, n)
        self.setpoints = np.stack(
            [radius_m * np.sin(phase), radius_m * (1.0 - np.cos(phase)), -height_m + 0 * phase],
            axis=1,
        )
        self.asked: list[int] = []
        self.recorded: list[tuple[int, TrialRecording]] = []
        self.incomplete: list[tuple[int, TrialRecording, str]] = []
        self.sessions: list[FlightSession] = []

    def setpoints_for(self, j: int) -> np.ndarray:
        self.asked.append(j)
        return self.setpoints.copy()

    def hover_point_for(self, j: int) -> np.ndarray:
        return self.setpoints[0]

    def record(self, j: int, recording: TrialRecording) -> None:
        self.recorded.append((j, recording))

    def record_incomplete(self, j: int, recording: TrialRecording, reason: str) -> None:
        self.incomplete.append((j, recording, reason))

    def record_session(self, session: FlightSession) -> None:
        self.sessions.append(session)


def _mock(tmp_path: Path, **faults: float) -> MockProcess:
    return MockProcess(
        config_path=None, seed=0, faults=Faults(**faults), stats_path=tmp_path / STATS
    )


STATS = "stats.json"


def _final_mode(tmp_path: Path) -> dict:
    """Last mode-log entry of the mock's stats: ``{"t_monotonic_s", "mode", "armed"}``."""
    stats = json.loads((tmp_path / STATS).read_text())
    return stats["modes"][-1]


def _best_lag_correlation(measured: np.ndarray, commanded: np.ndarray) -> tuple[int, float]:
    """Lag (samples) maximising the correlation of measured(k + lag) with commanded(k)."""
    best = (0, -1.0)
    for lag in range(0, 40):
        a, b = measured[lag : lag + len(commanded) - 40], commanded[: len(commanded) - 40]
        r = float(np.corrcoef(a, b)[0, 1])
        if r > best[1]:
            best = (lag, r)
    return best


@pytest.mark.flight_s(36)
def test_campaign_flies_two_trials_lands_and_disarms(tmp_path: Path) -> None:
    source = CircleSource()
    events: list[object] = []
    stamps: list[float] = []

    policies: list[int] = []

    def on_event(event: object) -> None:
        events.append(event)
        stamps.append(time.monotonic())
        if isinstance(event, TrialStarted):
            policies.append(os.sched_getscheduler(0))

    started = time.monotonic()
    with _mock(tmp_path) as mock:
        asyncio.run(
            fly_campaign(CampaignPlan(mock.url, 0, 2, T_ILC_S, SETTINGS, FENCE), source, on_event)
        )
    assert time.monotonic() - started < 50.0
    # the flight loop ran raised where allowed (gcs.io.scheduling) and got its policy back
    assert policies == [RAISED[0]] * 2 and os.sched_getscheduler(0) == os.SCHED_OTHER
    assert gc.get_freeze_count() == 0
    assert source.asked == [0, 1]
    assert [j for j, _ in source.recorded] == [0, 1] and not source.incomplete
    n = source.setpoints.shape[0]
    for _, rec in source.recorded:
        assert rec.complete and rec.abort_reason is None
        assert rec.t_s.shape == (n + 1,) and rec.pos_ned_m.shape == (n + 1, 3)
        assert rec.vel_ned_m_s.shape == (n + 1, 3) and rec.sent_s.shape == (n,)
        # flagged exactly where the grid point's bracketing samples are more than the gap
        # apart (a busy machine may delay the telemetry: how much is not this test's to judge)
        grid = np.arange(n + 1) * T_ILC_S
        after = np.searchsorted(rec.raw_t_s, grid, side="left")
        before = np.searchsorted(rec.raw_t_s, grid, side="right") - 1
        span = rec.raw_t_s[after] - rec.raw_t_s[before]
        assert rec.interpolated.tolist() == (span > SETTINGS.telemetry_gap_s).tolist()
        assert rec.interpolated_share < 0.5  # the stream lived through most of the trial
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
        assert stamps[s] - stamps[h] >= SETTINGS.hover_before_trial_s
    # the hover before trial 0 was measured (after a hold of its own), judged and handed over
    (measuring,) = [i for i, t in enumerate(events) if getattr(t, "text", "").startswith("meas")]
    assert measuring < holds[0]
    assert stamps[holds[0]] - stamps[measuring] >= (
        SETTINGS.hover_before_trial_s + SETTINGS.hover_measure_s
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
    assert _final_mode(tmp_path)["armed"] is False


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_unreachable_url_gives_vehicle_error_quickly() -> None:
    async def connect(url: str) -> None:
        vehicle = Vehicle(SETTINGS)
        await vehicle.connect(url, timeout_s=1.0)

    started = time.monotonic()
    with pytest.raises(VehicleError, match="no autopilot answered"):
        asyncio.run(connect(f"udpout://127.0.0.1:{_free_udp_port()}"))
    assert time.monotonic() - started < 3.0
    with pytest.raises(VehicleError, match="cannot open connection"):
        asyncio.run(connect("foo://bar"))
    # neither attempt left this thread under the flight's policy or the heap frozen
    assert os.sched_getscheduler(0) == os.SCHED_OTHER and gc.get_freeze_count() == 0
