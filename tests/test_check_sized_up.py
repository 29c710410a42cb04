"""--check sizes a flight up before it flies: gcs fly (duration, peak speed and acceleration
against the limits, the box, the closest wall), gcs identify (amplitude, box, duration) and
gcs study (a measured time estimate)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import invoke as gcs_invoke
from synthetic import ROOT

from gcs.app.fly import flown_reference
from gcs.io.config import load_profile, load_trajectory


def invoke(*args: object):
    return gcs_invoke([str(a) for a in args], env={"COLUMNS": "300"})


def _flat(text: str) -> str:
    return " ".join(text.split())


def test_fly_check_sizes_up_the_trajectory(tmp_path: Path, monkeypatch) -> None:
    import gcs.cli

    monkeypatch.setattr(gcs.cli.console, "width", 300)
    result = invoke("fly", "--mock", "--check", "--offline", "--iter", "4", "--logs",
                    tmp_path / "logs", "--trajectory", "circle")  # fmt: skip
    assert result.exit_code == 0, result.output
    out = _flat(result.output)
    prof = load_profile(ROOT / "profiles" / "antx.yaml")
    ref = flown_reference(prof, load_trajectory(ROOT / "trajectories" / "circle.yaml"), "circle")
    duration = ref.t_s[-1] - ref.t_s[0]
    assert f"each trial flies {duration:.1f} s (4 trials: {4 * duration / 60:.1f} min" in out
    speed = np.max(np.hypot(ref.vel_ned_m_s[:, 0], ref.vel_ned_m_s[:, 1]))
    accel = np.max(np.hypot(ref.acc_ned_m_s2[:, 0], ref.acc_ned_m_s2[:, 1]))
    assert f"peak speed {speed:.2f} m/s of {prof.max_speed_m_s:g}" in out
    assert f"acceleration {accel:.2f} m/s² of {prof.max_accel_m_s2:g}" in out
    lo, hi = ref.pos_ned_m.min(axis=0), ref.pos_ned_m.max(axis=0)
    assert f"north {lo[0]:.2f}..{hi[0]:.2f}, east {lo[1]:.2f}..{hi[1]:.2f}" in out
    b = prof.arena.bounds()
    gap = min(np.min(ref.pos_ned_m - b[:, 0]), np.min(b[:, 1] - ref.pos_ned_m))
    assert f"closest to the arena's walls {gap:.2f} m" in out
    assert not (tmp_path / "logs").exists()  # nothing flown, nothing created


def test_identify_check_sizes_up_the_excitation(tmp_path: Path, monkeypatch) -> None:
    import gcs.cli

    monkeypatch.setattr(gcs.cli.console, "width", 300)
    result = invoke("identify", "--mock", "--check", "--logs", tmp_path / "logs")
    assert result.exit_code == 0, result.output
    out = _flat(result.output)
    ident = load_profile(ROOT / "profiles" / "antx.yaml").identification
    amp = ident.amplitude_m
    assert f"prbs of {amp:g} m on x, {amp:g} m on y" in out
    c = ident.center_ned_m
    found = re.search(r"sweep north (-?[\d.]+)\.\.(-?[\d.]+), east (-?[\d.]+)\.\.(-?[\d.]+)", out)
    assert found is not None, out
    n_lo, n_hi, e_lo, e_hi = map(float, found.groups())
    # a PRBS of amplitude a about the centre: the setpoints reach centre +- a
    assert (n_lo, n_hi) == pytest.approx((c[0] - amp, c[0] + amp), abs=0.01)
    assert (e_lo, e_hi) == pytest.approx((c[1] - amp, c[1] + amp), abs=0.01)
    assert f"two experiments of {ident.duration_s:.1f} s each" in out


def test_study_check_estimates_the_time_by_measuring_one_plant(tmp_path: Path) -> None:
    study = {
        "name": "tiny", "profile": "antx", "trajectory": "eight-short", "plants": 6,
        "iterations": 1, "chunk_plants": 2, "uncertainty": {"levels": [0.2, 0.4]},
    }  # fmt: skip
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(study))
    result = invoke("study", path, "--check", "--workers", "3")
    assert result.exit_code == 0, result.output
    out = _flat(result.output)
    found = re.search(
        r"about ([\d.]+) s on 3 workers \(([\d.]+) s of computing\); measured by flying one "
        r"simulated plant of each setting here \(([\d.]+) s\)",
        out,
    )
    assert found is not None, out
    wall, cpu, one = map(float, found.groups())
    assert cpu == pytest.approx(one * 2 * 6, abs=0.6)  # levels x plants, rounded in print
    assert wall == pytest.approx(cpu / 3, abs=0.6)
    assert not (tmp_path / "study-tiny").exists()


def test_the_quick_example_study_is_shipped_and_documented() -> None:
    path = ROOT / "docs" / "studies" / "quick.yaml"
    study = yaml.safe_load(path.read_text())
    assert study["plants"] * len(study["uncertainty"]["levels"]) <= 4
    assert "docs/studies/quick.yaml" in (ROOT / "docs" / "studies.md").read_text()
