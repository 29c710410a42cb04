"""Three-axis learning on the virtual clock: the flights of tests/test_axes_e2e.py in-process.

The same commands, settings and checks against the simulated drone (tests/virtual.py) instead
of the mock process over UDP; ``--mock`` starts a simulated drone of the same settings and seed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from synthetic import CI_FLIGHT, ROOT
from virtual import run_gcs

from gcs.io.rundir import RunDir
from gcs.mock.config import load_mock_config
from gcs.sim.drone import SimulatedDrone

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e


#: One loop of a 0.8 m circle that climbs 0.5 m by mid-manoeuvre and comes back (about 8 s).
HELIX = {
    "name": "helix-short",
    "type": "circle",
    "center_ned_m": [0.0, 0.0, -1.5],
    "radius_m": 0.8,
    "plane": "horizontal",
    "period_s": 5.0,
    "loops": 1,
    "ramp_s": 1.5,
    "hover_s": 0.5,
    "climb_m": 0.5,
}


def test_a_helix_learned_on_three_axes_reduces_every_error(tmp_path: Path) -> None:
    data = yaml.safe_load((ROOT / "profiles" / "antx-3d.yaml").read_text())
    data["flight"] = dict(data.get("flight") or {}, **CI_FLIGHT)
    profile = tmp_path / "antx-3d-ci.yaml"
    profile.write_text(yaml.safe_dump(data))
    trajectory = tmp_path / "helix.yaml"
    trajectory.write_text(yaml.safe_dump(HELIX))
    run_path = tmp_path / "run"
    with SimulatedDrone(load_mock_config(None), seed=0) as mock:
        code, out = run_gcs(
            *(
                "fly",
                "--connect",
                mock.url,
                "--iter",
                2,
                "--trajectory",
                trajectory,
                "--run",
                run_path,
                "--profile",
                profile,
            )  # fmt: skip
        )
    assert code == 0, out
    assert "3-D e_pos" in out and "e3d [m]" in out  # the live lines and the final table
    run = RunDir.open(run_path)
    assert run.complete_trials() == [0, 1]
    ref = run.reference().pos_ned_m
    assert np.ptp(ref[:, 2]) > 0.45
    # trial 0 flies the reference; trial 1's down setpoints are learned
    np.testing.assert_allclose(run.read_trial(0).sp_ned_m[:-1, 2], ref[:-1, 2], atol=1e-9)
    assert np.max(np.abs(run.read_trial(1).sp_ned_m[:-1, 2] - ref[:-1, 2])) > 0.01
    header = (run_path / "estimate-000.csv").read_text().splitlines()[0]
    assert header.endswith("d_down_m,p_down_m2")
    code, report = run_gcs(*("report", run_path, "--json"))
    assert code == 0, report
    rows = json.loads(report)["rows"]
    assert [r["iteration"] for r in rows] == [0, 1]
    for key in ("epos_m", "epos_3d_m", "rms_down_m"):
        assert rows[1][key] < rows[0][key], (key, rows)
