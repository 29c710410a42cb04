"""The frame check as the campaign flies it (:mod:`gcs.flight.mocap.campaign`), against a
vehicle and a mocap that replay a wandering hover: how long it waits at each window."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

import numpy as np
import pytest
from ekf2_origin import OriginRuleVehicle, standing_mocap

from gcs.core.frames import mapping_for
from gcs.errors import MocapError
from gcs.flight.hover import hover_stats, widened
from gcs.flight.link import TelemetrySample
from gcs.flight.mocap.campaign import MOVE_WINDOW_S, check_moves, ready_to_arm
from gcs.flight.mocap.client import MocapSample, series_of
from gcs.io.settings import FlightSettings


class WanderingVehicle:
    """Follows every command at once and wanders around it by ``wander_m`` (seeded): what
    the frame check sees of a vehicle that never settles within a few centimetres."""

    def __init__(
        self, wander_m: float, seed: int, later_wander_m: float | None = None, follows: bool = True
    ) -> None:
        self.rng = np.random.default_rng(seed)
        self.follows = follows
        self.home = np.array([0.0, 0.0, -1.5])
        self.wander_m = wander_m
        self.later_wander_m = wander_m if later_wander_m is None else later_wander_m
        self.target = np.array([0.0, 0.0, -1.5])
        self.fence = None
        self.settles: list[tuple[float, float]] = []
        self.holds: list[float] = []
        self.samples: list[TelemetrySample] = []
        self.t_s = 0.0  # its own clock: a window every 2 s whatever the machine

    async def hold_position(self) -> np.ndarray:
        return self.target.copy()

    async def goto(self, ned_m: np.ndarray, speed_m_s: float) -> None:
        self.target = np.asarray(ned_m, dtype=float)

    async def settle(self, ned_m: np.ndarray, tolerance_m: float, speed_m_s: float) -> bool:
        self.settles.append((tolerance_m, speed_m_s))
        return True

    async def hold(self, duration_s: float, what: str) -> list[TelemetrySample]:
        self.holds.append(duration_s)
        if what.startswith("the hold before"):  # not a window: nothing the check reads
            self.t_s += duration_s
            return []
        t0, self.t_s = self.t_s, self.t_s + duration_s + 0.5
        out = []
        wander_m = self.later_wander_m if self.samples else self.wander_m
        for k in range(int(duration_s * 50)):
            where = self.target if self.follows else self.home
            pos = where + np.append(self.rng.normal(0, wander_m, 2), 0.0)
            out.append(TelemetrySample(t0 + k / 50, tuple(pos), (0.0, 0.0, 0.0), k / 50))
        self.samples += out
        return out


class Mirror:
    """A mocap client that saw exactly what the vehicle estimated (NED, tracked)."""

    def __init__(self, vehicle: WanderingVehicle) -> None:
        self.vehicle = vehicle

    def recent(self, duration_s: float) -> object:
        return series_of([
            MocapSample(i, s.t_s, s.t_s, True, s.pos_ned_m, (1.0, 0.0, 0.0, 0.0))
            for i, s in enumerate(self.vehicle.samples)
        ])  # fmt: skip


def mirrored_mocap(vehicle: WanderingVehicle, forward: bool) -> SimpleNamespace:
    """The campaign's mocap link as the check uses it: the vehicle's own samples, in NED."""
    return SimpleNamespace(
        client=Mirror(vehicle),
        mapping=mapping_for("ned"),
        settings=SimpleNamespace(check_move_m=0.3, forward=forward),
        require_tracked=lambda: vehicle.target,
    )


def note_to(lines: list[str]):  # type: ignore[no-untyped-def]
    """A campaign's ``note`` that keeps the lines."""
    return lambda text, warning=False: lines.append(text)


def first_window_tolerances(
    vehicle: WanderingVehicle, settings: FlightSettings
) -> tuple[float, float]:
    """The settle tolerances of the first window's hover, computed here from its samples."""
    window = vehicle.samples[: round(MOVE_WINDOW_S * 50)]
    t = np.array([s.t_s for s in window])
    pos = np.array([s.pos_ned_m for s in window])
    home = np.array([0.0, 0.0, -1.5])
    floor = (settings.settle_tolerance_m, settings.settle_speed_m_s)
    return widened(*floor, hover_stats(t, pos, home), settings)


def test_the_windows_after_the_first_settle_within_the_first_hovers_tolerances() -> None:
    vehicle = WanderingVehicle(wander_m=0.1, seed=4)
    settings = FlightSettings()
    lines: list[str] = []
    records = asyncio.run(
        check_moves(vehicle, mirrored_mocap(vehicle, forward=True), settings, note_to(lines))
    )
    assert len(records) == 1, lines  # a 0.1 m wander: the first moves are long enough
    # the first window after a hold, as the hover before a trial: never a settle within the
    # profile's few centimetres, which a vehicle that wanders waits out to the timeout
    assert vehicle.holds[0] == settings.hover_before_trial_s
    expected = first_window_tolerances(vehicle, settings)
    assert expected[0] > 2 * settings.settle_tolerance_m  # the wander is what widened them
    assert vehicle.settles == [expected] * 4


def test_flown_once_more_the_check_keeps_the_tolerances_it_measured() -> None:
    # calm in the first window, wandering by decimetres after, and staying where it was: the
    # following cannot be judged from the first moves
    vehicle = WanderingVehicle(wander_m=0.02, seed=4, later_wander_m=0.3, follows=False)
    settings = FlightSettings()
    lines: list[str] = []
    records = asyncio.run(
        check_moves(vehicle, mirrored_mocap(vehicle, forward=True), settings, note_to(lines))
    )
    assert len(records) == 2, lines
    assert any("once more" in line for line in lines), lines
    # held before the first window of the first check only; every other window settles
    # within the first hover's tolerances, the first window of the check flown again too
    assert vehicle.holds.count(settings.hover_before_trial_s) == 1
    assert vehicle.settles == [first_window_tolerances(vehicle, settings)] * 9


def test_a_mapping_judged_along_one_direction_only_is_refused_after_the_second_check(
    monkeypatch,
) -> None:
    from gcs.errors import MocapError
    from gcs.flight.mocap import campaign
    from gcs.flight.mocap.checks import FrameCheck, Response

    ok = Response(1.0, 0.0)
    unjudged = FrameCheck(
        ((0.3, 0.0, 0.0), (0.0, 0.3, 0.0)), (ok, ok), (ok, ok), (ok, ok), 0.0, False, 0.2,
        "unjudged", None, mapping_judged=False,
    )  # fmt: skip
    monkeypatch.setattr(campaign, "frame_check", lambda *args, **kwargs: unjudged)
    for forward, refused in ((False, True), (True, False)):
        vehicle = WanderingVehicle(wander_m=0.02, seed=4)
        mocap = mirrored_mocap(vehicle, forward)
        lines: list[str] = []
        run = check_moves(vehicle, mocap, FlightSettings(), note_to(lines))
        if refused:
            with pytest.raises(MocapError, match="could not be judged"):
                asyncio.run(run)
        else:  # forwarded: the mapping is never judged in the air (docs/mocap.md)
            assert len(asyncio.run(run)) == 2
        assert any("once more" in line for line in lines), lines


def test_the_session_record_of_the_mocap_is_each_steps_part_in_the_order_they_came() -> None:
    import json
    from dataclasses import replace

    from gcs.app.session import session_record
    from gcs.flight.campaign import FlightSession
    from gcs.flight.mocap.campaign import ArmingAgreement, Ekf2Check, MocapReport
    from gcs.flight.mocap.checks import FrameCheck, Response
    from gcs.flight.preflight import navigation_source

    ok = Response(1.0, 0.0)
    check = FrameCheck(
        ((0.3, 0.0, 0.0), (0.0, 0.3, 0.0)), (ok, ok), (ok, ok), (ok, ok), 0.0, False, 0.02,
        "ok", None,
    )  # fmt: skip
    ekf2 = Ekf2Check({"EKF2_EV_CTRL": 11, "EKF2_EV_DELAY": 5.0}, ("EKF2_EV_DELAY 5 ms",))
    before = FlightSession(
        "udpin://", 0, navigation_source({}),
        mocap=MocapReport(ekf2, ArmingAgreement(0.012, (47.39, 8.54, 488.0), True)),
    )  # fmt: skip
    assert before.mocap is not None
    checked = replace(before, mocap=replace(before.mocap, moves=(check,)))
    assert checked.mocap is not None
    ended = replace(checked, mocap=replace(checked.mocap, link={"url": "natnet://x", "samples": 7}))
    early, middle, last = (session_record(s)["mocap"] for s in (before, checked, ended))
    assert list(early) == ["ekf2", "findings", "agreement_m", "origin", "origin_set"]
    assert early["ekf2"] == {"EKF2_EV_CTRL": 11, "EKF2_EV_DELAY": 5.0}
    assert early["findings"] == ["EKF2_EV_DELAY 5 ms"] and early["origin"] == [47.39, 8.54, 488.0]
    assert middle == early | {"moves": [check.as_record()]}
    assert last == middle | {"url": "natnet://x", "samples": 7}
    assert list(last)[-3:] == ["moves", "url", "samples"]
    # each session keeps what it had: the later parts did not reach into the earlier values
    assert session_record(before)["mocap"] == early and before.mocap.moves is None
    assert json.loads(json.dumps(last)) == last
    no_mocap = FlightSession("udpin://", 0, navigation_source({}))
    assert session_record(no_mocap)["mocap"] is None


def test_an_origin_set_before_the_vision_height_leaves_the_estimate_on_the_mocap() -> None:
    """The race of a loaded machine: gcs sets the origin 1 s before EKF2 fuses the vision
    height (PX4 v1.16 then moves the local height by the origin's altitude)."""
    vehicle, lines = OriginRuleVehicle(height_after_s=1.0), []
    agreement = asyncio.run(ready_to_arm(vehicle, standing_mocap(), note_to(lines)))  # type: ignore[arg-type]
    assert agreement.origin_set and agreement.agreement_m < 0.01
    assert vehicle.shift_m == 0.0 and any("global origin set to" in ln for ln in lines), lines


def test_an_estimate_off_by_the_origins_altitude_is_refused_at_once_naming_the_origin() -> None:
    """An origin someone else set at 488 m before EKF2 had a height: the estimate sits 488 m
    down for good; gcs says so at once instead of waiting out the agreement's bound."""
    vehicle = OriginRuleVehicle(0.0, origin=(47.39, 8.54, 488.0), shift_m=488.0, timeout_s=30.0)
    with pytest.raises(MocapError, match=r"488\.0 m below .* origin's altitude \(488 m\)"):
        asyncio.run(ready_to_arm(vehicle, standing_mocap(), note_to([])))  # type: ignore[arg-type]
    assert vehicle.t_s < 0.5  # at the first sample, not after 30 s
