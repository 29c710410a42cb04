"""Learning holds at the floor in a lab as real ones are, on real PX4 firmware.

The lab of the flight in which learning seemed to leave its floor (docs/learning-floor.md, "On
firmware: the rise was the floor's measure"): Motive at 100 Hz, 30 ms from the body's motion
to the frame with EKF2_EV_DELAY told 30 ms (a careful lab), 1 mm of marker noise per axis,
and the room's axes turned 30 deg from gcs's mapping (PX4, on vision only, flies in the
room's frame). The README's flight in it: ``gcs fly --mocap ... --profile antx-adaptive``, the
floor measured from four flights of trial 0 (three repeats), so that the scatter between flights
is measured too (``gcs.core.floor``). What the test asserts is the bound: no learned
trial from j = 2 on above 2 floors. How close to the floor the trials came (the goal: within
1.5 floors, the median within 1.25) is a figure, kept in the test's record;
``benchmarks/lab_floor_px4.py`` flies this point and others for the table.

**The trajectory is the packaged eight flown slower** (:func:`eight_this_vehicle_follows`:
``period_s`` 7.5 s instead of 5, so 1.5 times the speed and 2.25 times the acceleration below
the paper's eight). The paper's eight asks more than PX4's SIH vehicle gives: it lags the
reference by 1.2 m in trial 0, and the learned setpoints fly it twice as fast as trial 0 did,
where the linear model foresees the vehicle worst: at j = 3 the flights came out 0.57 floors
(median of 14 flights) farther from what the learning step predicted than noise alone puts
them (the model predicted 9-48 mm), against 0.03 on the slower eight (4 flights), and a
learned trial's e_pos in floors is that distance (docs/learning-floor.md, "What the model
foresaw"). The bound in floors judges learning where
its model holds; the paper's eight is flown by ``benchmarks/lab_floor_px4.py``. Flown eleven
times as shipped on the paper's eight, this test held 7 times; docs/testing.md has the runs
on both.

**The floor from four flights, not three** (the shipped profile's two repeats): one flight's
e_pos at the floor varies by 22-31 % of the floor from flight to flight, so a floor drawn from
three flights is itself a draw. Replayed on twelve recorded flights of identical setpoints at
this point on this eight (``benchmarks/floor_targets.py --run``), a learner with a right model
and the shipped estimate's weights holds the bound on two trials in 98.4 % of flights against a
floor from three flights and in 99.8 % against one from four (docs/testing.md): ten flights in
a row about 85 % and 98 % of the time. It is part of ``make test`` (the flights go first, and
this one first of them); ``make test-lab-floor`` flies it alone.

**Two flights, as a lab with a battery change flies it**: trial 0 and its repeats (the floor)
in the vehicle's first flight after PX4 started, then ``gcs fly --resume`` learns j = 1, 2, 3 in
a second flight of the same PX4. The first flight after PX4 starts flies its later trials worse
than any flight after it: the j = 2 setpoints of ten one-flight runs, flown again later on the
same PX4, scored 1.15 floors (median of twenty), and in nine of the ten the test's own flight of
them came out above both later ones (docs/learning-floor.md, "The same learned setpoints, flown
again on the same PX4"; the cause is PX4's, not found). Flown in one flight, this test failed
its bound in five of twenty-four fresh-clone runs of one day, mostly at j = 2. Nineteen flights
alternated on 2026-12-03 (docs/testing.md, "Two flights"): j = 2 at 1.03 floors (median of
eight, largest 1.63) in two flights against 1.45 (median of eleven, largest 2.19, one above the
bound) in one, 254 against 304 mm; the floor is measured alike in both (the first four trials of
the first flight). When j = 2 still fails, look first at its setpoints: the refresh after
j = 1 moved a model far and the step's prediction missed (the report's "after trial 4" and
"the step before trial 5" lines).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from synthetic import CI_FLIGHT

from gcs.io.rundir import RunDir
from px4.flying import ROOT, report_rows, sitl_profile
from px4.sitl import STARTED_LINE
from px4.test_px4_lab import LANDED, Gcs, LabConditions, lab_rig

pytestmark = [pytest.mark.px4, pytest.mark.lab_floor]

#: the lab: 100 Hz, 30 ms told to EKF2, 1 mm, the room turned 30 deg
LAB = LabConditions(rate_hz=100.0, latency_ms=30.0, noise_mm=1.0, yaw_offset_deg=30.0,
                    match_ev_delay=True)  # fmt: skip
#: trial 0 and three repeats (the floor from four flights), then learned trials j = 1, 2, 3
REPEATS = 3
TRIALS = REPEATS + 4
#: the first flight's trials: trial 0 and its repeats (the floor); the second flies the rest
FLOOR_TRIALS = REPEATS + 1
#: the issue's bound on a learned trial from j = 2 on [floors]
BOUND = 2.0
#: one loop of the eight [s]: the paper's 5 s asks more than the SIH vehicle gives (above)
PERIOD_S = 7.5
#: a hung flight, not a slow one: four trials of the 19 s eight, the frame check, the hover
FLY_TIMEOUT_S = 1200.0
#: the two flights' length [s] (the firmware tests' order and slots): 335-421 s, median 412,
#: beside another lab flight, where one flight took 284 (274 on a quiet machine)
FLIGHT_S = 400


def eight_this_vehicle_follows(tmp: Path) -> Path:
    """trajectories/eight.yaml with ``period_s`` :data:`PERIOD_S`, written to ``tmp``."""
    data = yaml.safe_load((ROOT / "trajectories" / "eight.yaml").read_text())
    data.update(name="eight-slower", period_s=PERIOD_S)
    path = tmp / "eight-slower.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def lab_adaptive_profile(tmp: Path) -> Path:
    """profiles/antx-adaptive.yaml with the tests' watchdog limits, a ``mocap`` section (the
    frame check as shipped) and ``learning.adaptive.repeats`` :data:`REPEATS`."""
    return sitl_profile(
        tmp, "antx-adaptive", limits=CI_FLIGHT, mocap={},
        fields={"learning.adaptive.repeats": REPEATS},
    )  # fmt: skip


@pytest.mark.flight_s(FLIGHT_S)
def test_learning_stays_within_two_floors_in_a_realistic_lab(
    px4_factory, tmp_path: Path, px4_figures: dict
) -> None:
    """The README's adaptive flight in the lab of :data:`LAB` on the eight of
    :func:`eight_this_vehicle_follows`, in two flights of one PX4 as a lab with a battery change
    flies it: the floor from the four flights of trial 0 in the first, then ``gcs fly --resume``
    learns on in the second; each lands and disarms, and no learned trial from j = 2 on is above
    :data:`BOUND` floors."""
    px4 = px4_factory(params=LAB.px4_params(), ready=STARTED_LINE)
    run_path = tmp_path / "run"
    outputs = []
    with lab_rig(px4, LAB) as rig, px4.monitor() as mon:
        vehicle = ["--connect", px4.url, "--mocap", rig.url]
        for flight, trials_after in (
            (["--iter", FLOOR_TRIALS, "--profile", lab_adaptive_profile(tmp_path),
              "--run", run_path, "--trajectory", eight_this_vehicle_follows(tmp_path)],
             FLOOR_TRIALS),
            (["--iter", TRIALS - FLOOR_TRIALS, "--resume", run_path], TRIALS),
        ):  # fmt: skip
            gcs = Gcs("fly", *vehicle, *flight)
            code = gcs.wait(FLY_TIMEOUT_S)
            outputs.append(gcs.output())
            assert code == 0, outputs[-1]
            assert "landed and disarmed" in outputs[-1], outputs[-1]
            mon.wait("on the ground", lambda s: s.landed_state == LANDED, 60)
            mon.wait("disarmed", lambda s: s.armed is False, 30)
            complete = RunDir.open(run_path).complete_trials()
            assert complete == list(range(trials_after)), outputs[-1]
    out = "\n".join(outputs)
    rows = report_rows(run_path)
    floor_m = rows[0]["floor_m"]
    learned = {r["iteration"]: r["floor_ratio"] for r in rows if r["repeat_of"] is None}
    from_j2 = [learned[j] for j in sorted(learned) if j >= 2]
    px4_figures.update(
        lab=LAB.rig_args() + [f"EKF2_EV_DELAY {LAB.px4_params()['EKF2_EV_DELAY']:g}"],
        period_s=PERIOD_S,
        floor_m=floor_m,
        e_pos_m=[round(r["epos_m"], 4) for r in rows],
        floors={j: round(x, 2) for j, x in sorted(learned.items())},
        # how far from the start point each trial began, by the mocap [m]
        start_offset_m=[round(r["start_offset_m"], 3) for r in rows],
        # how far each learned trial came out from what the step before it predicted, and
        # how far noise alone puts it [floors]
        from_prediction={
            r["iteration"]: [
                round(r["prediction_miss_ratio"], 2),
                round(r["prediction_noise_ratio"], 2),
            ]
            for r in rows
            if r["prediction_miss_ratio"] is not None
        },
    )
    assert [r["repeat_of"] for r in rows[: REPEATS + 1]] == [None] + [0] * REPEATS, rows
    assert len(from_j2) == TRIALS - REPEATS - 2, learned
    assert max(from_j2) <= BOUND, (learned, floor_m, out)
