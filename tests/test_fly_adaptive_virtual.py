"""``gcs fly`` adaptive on the virtual clock:
the flights of tests/test_fly_adaptive_e2e.py in-process.

The same commands, settings and checks against the simulated drone (tests/virtual.py) instead
of the mock process over UDP; ``--mock`` starts a simulated drone of the same settings and seed.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from synthetic import CI_FLIGHT
from virtual import fly_virtual, run_gcs, sim_mock

from gcs.flight.campaign import CampaignPlan, FlightSession, Status, TrialStarted, fly_campaign
from gcs.flight.fence import Fence
from gcs.flight.trial import TrialRecording
from gcs.io.rundir import RunDir
from gcs.io.settings import FlightSettings
from gcs.mock.config import load_mock_config
from gcs.sim.drone import SimulatedDrone

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[1]
SHORT = ROOT / "trajectories" / "eight-short.yaml"


def adaptive_ci_profile(tmp: Path, repeats: int = 1) -> Path:
    """antx-adaptive.yaml with the CI watchdog limits, a model 40 % too strong and
    ``repeats`` repeats of trial 0.

    The model's gain is off on purpose, by far more than the mock's loop is from eq. (11): the
    first pair of trials of different setpoints must refresh it (cross-validated), whatever the
    gusts of the day. One repeat (the profile ships two): these flights test the campaign,
    its records and resuming, on the trial plan of one repeat (trial 2 the first learned one),
    one flight shorter; the floor of three flights is tests/test_learn_history_run.py's.
    """
    data = yaml.safe_load((ROOT / "profiles" / "antx-adaptive.yaml").read_text())
    data["model"]["num"] = [1.4 * v for v in data["model"]["num"]]
    data["learning"]["adaptive"]["repeats"] = repeats
    data["flight"] = dict(data.get("flight") or {}, **CI_FLIGHT)
    path = tmp / "antx-adaptive-ci.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_fly_adaptive_repeats_records_refreshes_resumes_and_stops_when_converged(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:

    sim_mock(monkeypatch)
    run_path = tmp_path / "run"
    profile = adaptive_ci_profile(tmp_path)
    first = ["--iter", 3, "--trajectory", SHORT, "--profile", profile, "--run", run_path]
    code, out = run_gcs(*("fly", "--mock", "--seed", 3, *first))
    assert code == 0, out
    assert "trial 1 repeats trial 0 (identical setpoints, j = 0)" in out, out
    assert "trial 1 (j = 0, a repeat): e_pos" in out and "trial 2 (j = 1): e_pos" in out, out
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1, 2]
    setpoints = [(run_path / f"setpoints-00{j}.csv").read_bytes() for j in (0, 1)]
    assert setpoints[0] == setpoints[1]  # the repeat flew trial 0's setpoints exactly
    floor = run.read_floor()
    assert floor["trials"] == [0, 1] and 0 < floor["epos_m"] < 0.1
    assert not (run_path / "learn-000.json").exists()  # a repeat learns nothing
    records = {j: run.read_learn_record(j) for j in (1, 2)}
    assert records[2]["learned_from"] == [0, 1, 2] and records[2]["next_iteration"] == 2
    # the first pair of different setpoints refreshed the model that was 40 % too strong
    assert records[2]["model_file"] == "model-002.yaml", records[2]["decision"]["axes"]
    moved = [ax["refresh"]["moved"] for ax in records[2]["decision"]["axes"]]
    assert max(moved) > 0.15, moved
    assert "model refreshed: " in out, out

    # resume: the next step starts from the refreshed model, read back from the run directory
    more = ["--resume", run_path, "--iter", 2, "--until-converged"]
    code, out = run_gcs(*("fly", "--mock", "--seed", 4, *more))
    assert code == 0, out
    assert run.read_learn_record(3)["models_from"] == "model-002.yaml"
    flown = run.complete_trials()
    converged = [j for j in flown[3:] if run.read_learn_record(j)["decision"]["converged"]]
    if converged:  # landed after the first trial that converged, and said so
        assert flown[-1] == converged[0], (flown, converged)
        assert f"no further trial after trial {converged[0]}: learning has converged" in out
    else:  # flew to the cap, never claiming convergence
        assert flown == [0, 1, 2, 3, 4] and "learning has converged" not in out, out
        assert "learning has not converged within --iter 2" in out, out
    assert "landed and disarmed" in out

    code, out = run_gcs(*("report", run_path, "--json"))
    assert code == 0, out
    assert json.loads(out)["run"]["seeds"] == [3, 4]  # the mock's seed of each session
    rows = json.loads(out)["rows"]
    assert [(r["trial"], r["iteration"], r["repeat_of"]) for r in rows[:3]] == [
        (0, 0, None), (1, 0, 0), (2, 1, None)
    ]  # fmt: skip
    assert all(r["floor_m"] == pytest.approx(floor["epos_m"], rel=1e-8) for r in rows)  # 9 digits
    assert rows[2]["sp_rms_m"] > 0.3 and rows[2]["epos_m"] < 0.5 * rows[0]["epos_m"]


class StopAfter:
    """A trial source that says "no further trial" after one trial (the hook of
    ``--until-converged``), with a short hover line for setpoints."""

    def __init__(self, stop_after: int) -> None:
        self.stop_after = stop_after
        self.asked: list[int] = []
        self.recorded: list[int] = []

    def setpoints_for(self, j: int):  # type: ignore[no-untyped-def]
        import numpy as np

        self.asked.append(j)
        n = 40
        return np.column_stack([np.linspace(0, 0.3, n), np.zeros(n), np.full(n, -2.0)])

    def hover_point_for(self, j: int):  # type: ignore[no-untyped-def]
        import numpy as np

        return np.array([0.0, 0.0, -2.0])

    def record(self, j: int, recording: TrialRecording) -> str | None:
        self.recorded.append(j)
        return "enough for today" if j == self.stop_after else None

    def record_incomplete(self, j: int, recording: TrialRecording, reason: str) -> None:
        raise AssertionError(f"trial {j} incomplete: {reason}")

    def record_session(self, session: FlightSession) -> None:
        pass


def test_a_source_that_says_no_further_trial_lands_the_vehicle_early(tmp_path: Path) -> None:
    settings = FlightSettings(
        max_setpoint_late_s=0.4, max_telemetry_age_s=1.0, hover_measure_s=2.0,
        hover_before_trial_s=1.0,
    )  # fmt: skip
    fence = Fence.around([[-3.0, 3.0], [-3.0, 3.0], [-3.0, 0.0]], settings, 3.0, 1.5)  # antx's
    source, events = StopAfter(0), []
    with SimulatedDrone(load_mock_config(None), seed=0) as mock:
        campaign = fly_campaign(
            CampaignPlan(mock.url, 0, 3, 0.05, settings, fence), source, events.append
        )
        fly_virtual(campaign)
    assert source.asked == [0] and source.recorded == [0]
    assert sum(isinstance(e, TrialStarted) for e in events) == 1
    texts = [e.text for e in events if isinstance(e, Status)]
    assert "no further trial after trial 0: enough for today" in texts
    assert texts[-2:] == ["landing", "landed and disarmed"]
    final = mock.stats()["modes"][-1]
    assert final["armed"] is False


def test_fly_again_flies_an_earlier_trials_setpoints_and_until_converged_lands_on_a_drift(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--resume --again K`` flies trial K's setpoints byte for byte and keeps the learned
    ones. A flight of earlier setpoints above the floor is their scatter, never a drift; but
    when the vehicle changes (here its link slower by 0.15 s between sessions) two learned
    trials above the floor are, and ``--until-converged`` lands on it and names the best
    trial at the floor."""
    sim_mock(monkeypatch)
    run_path = tmp_path / "run"
    profile = adaptive_ci_profile(tmp_path)
    first = ["--iter", 6, "--trajectory", SHORT, "--profile", profile, "--run", run_path]
    code, out = run_gcs(*("fly", "--mock", "--seed", 3, *first))
    assert code == 0, out
    run = RunDir.open(run_path)
    verdicts = run.read_learn_record(5)["decision"]["verdicts"]
    at_floor = [v["trial"] for v in verdicts if v["at_floor"] and v["trial"] >= 2]
    assert at_floor, verdicts  # the learned trials reached the floor: what a drift leaves
    learned = (run_path / "setpoints-006.csv").read_bytes()

    code, out = run_gcs(*("fly", "--mock", "--seed", 4, "--resume", run_path, "--iter", 1,
                          "--again", 0))  # fmt: skip
    assert code == 0, out
    assert run.complete_trials() == [0, 1, 2, 3, 4, 5, 6]
    assert (run_path / "setpoints-006.csv").read_bytes() == (
        run_path / "setpoints-000.csv"
    ).read_bytes()
    assert (run_path / "superseded" / "setpoints-006-1.csv").read_bytes() == learned
    assert run.again_of(6) == 0 and run.again_of(5) is None
    assert run.read_learn_record(6)["learned_from"] == list(range(7))  # learning goes on

    slower = tmp_path / "mock-slower.yaml"  # the mock with 0.15 s more transport delay
    slower.write_text(yaml.safe_dump({"physics": {"input_delay_s": 0.34}}))
    more = ["--resume", run_path, "--iter", 3, "--until-converged", "--mock-config", slower]
    code, out = run_gcs(*("fly", "--mock", "--seed", 5, *more))
    assert code == 0, out
    assert run.complete_trials() == list(range(9)), out  # landed after trial 8, not 9
    verdicts = run.read_learn_record(8)["decision"]["verdicts"]
    assert verdicts[6]["repeat_of"] == 0, verdicts  # trial 6 flew trial 0's: never "above"
    above = [v["trial"] for v in verdicts if not v["at_floor"]]
    assert 7 in above and 8 in above, verdicts
    best = min(
        (v for v in verdicts if v["at_floor"] and v["trial"] < 7),
        key=lambda v: (v["ratio"], v["trial"]),
    )["trial"]
    assert (
        f"trials 7 and 8 are above it again; the best setpoints at the floor are trial {best}'s"
    ) in out, out
    assert f"--until-converged: landed, learning left the floor; to fly trial {best}'s" in out, out
    assert f"--again {best}" in out and "landed and disarmed" in out

    code, out = run_gcs(*("report", run_path))
    assert code == 0, out
    assert "trial 6: flew trial 0's setpoints again (gcs fly --again)" in out, out
    assert "trial 7: flew trial 0's setpoints again" not in out
    assert f"--again {best} flies them again" in out
