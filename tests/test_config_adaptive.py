"""Tests of the ``learning.adaptive`` profile section, as gcs.io.config.load_profile reads it."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from gcs.core.learning import AdaptiveSettings
from gcs.errors import ProfileError
from gcs.io.config import load_profile

ROOT = Path(__file__).resolve().parents[1]
ANTX = ROOT / "profiles" / "antx.yaml"
ADAPTIVE = ROOT / "profiles" / "antx-adaptive.yaml"


def with_adaptive(tmp_path: Path, section: object) -> Path:
    data = yaml.safe_load(ANTX.read_text())
    data["learning"]["adaptive"] = section
    path = tmp_path / "profile.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_antx_is_the_paper_and_antx_adaptive_differs_only_in_learning_adaptive() -> None:
    paper, adaptive = load_profile(ANTX), load_profile(ADAPTIVE)
    assert paper.learning.adaptive is None and paper.learning.repeats == 0
    ad = adaptive.learning.adaptive
    assert ad.noise == "data" and ad.refresh and ad.safeguard and not ad.is_paper
    # three flights of trial 0's setpoints: the floor's scatter between flights is measured
    assert adaptive.learning.repeats == 2
    a, b = yaml.safe_load(ANTX.read_text()), yaml.safe_load(ADAPTIVE.read_text())
    for key in ("model", "t_ilc_s", "vehicle", "arena", "flight"):
        assert a[key] == b[key], key
    a_learning = {k: v for k, v in a["learning"].items() if k != "adaptive"}
    b_learning = {k: v for k, v in b["learning"].items() if k != "adaptive"}
    assert a_learning == b_learning


def test_every_field_parses(tmp_path: Path) -> None:
    section = {
        "noise": "data",
        "drift_offset": False,
        "refresh": True,
        "refresh_min_snr": 2.0,
        "refresh_block_s": 0.5,
        "refresh_noise": "measured",
        "refresh_max_move": 1.5,
        "refresh_min_gain_z": 1.645,
        "refresh_takeback": True,
        "refresh_minmax_step": True,
        "refresh_holdout": True,
        "refresh_pool_repeats": True,
        "refresh_anchor": True,
        "robustness_cutoff_rad_s": 6.0,
        "robustness_order": 3,
        "safeguard": True,
        "safeguard_k_sigma": 2.5,
        "safeguard_step": 0.25,
        "floor_z": 1.5,
    }
    ad = load_profile(with_adaptive(tmp_path, section)).learning.adaptive
    assert ad == AdaptiveSettings(**section)


@pytest.mark.parametrize(
    ("section", "field"),
    [
        ({"noise": "kalman"}, "learning.adaptive.noise"),
        ({"refresh": "yes"}, "learning.adaptive.refresh"),
        ({"refresh_noise": "pink"}, "learning.adaptive.refresh_noise"),
        ({"refresh_max_move": 0.0}, "learning.adaptive.refresh_max_move"),
        ({"refresh_min_gain_z": -1.0}, "learning.adaptive.refresh_min_gain_z"),
        ({"safeguard": 1}, "learning.adaptive.safeguard"),
        ({"refresh_takeback": "yes"}, "learning.adaptive.refresh_takeback"),
        ({"refresh_minmax_step": "on"}, "learning.adaptive.refresh_minmax_step"),
        ({"refresh_holdout": "true"}, "learning.adaptive.refresh_holdout"),
        ({"refresh_pool_repeats": "no"}, "learning.adaptive.refresh_pool_repeats"),
        ({"refresh_anchor": 1}, "learning.adaptive.refresh_anchor"),
        ({"robustness_cutoff_rad_s": -2.0}, "learning.adaptive.robustness_cutoff_rad_s"),
        ({"robustness_cutoff_rad_s": "automatic"}, "learning.adaptive.robustness_cutoff_rad_s"),
        ({"robustness_order": 1.5}, "learning.adaptive.robustness_order"),
        ({"safeguard_step": 0.0}, "learning.adaptive.safeguard_step"),
        ({"safeguard_k_sigma": float("nan")}, "learning.adaptive.safeguard_k_sigma"),
        ({"refesh": True}, "learning.adaptive.refesh"),
        ("data", "learning.adaptive"),
    ],
)
def test_refusals_name_file_and_field(tmp_path: Path, section: object, field: str) -> None:
    path = with_adaptive(tmp_path, section)
    with pytest.raises(ProfileError) as info:
        load_profile(path)
    msg = str(info.value)
    assert str(path) in msg and f"'{field}'" in msg and "\n" not in msg


def test_out_of_range_values_refused_with_the_section_named(tmp_path: Path) -> None:
    with pytest.raises(ProfileError) as info:
        load_profile(with_adaptive(tmp_path, {"safeguard_step": 1.5}))
    assert "learning.adaptive" in str(info.value) and "step" in str(info.value)


def test_auto_cutoff_parses(tmp_path: Path) -> None:
    ad = load_profile(with_adaptive(tmp_path, {"robustness_cutoff_rad_s": "auto"}))
    assert ad.learning.adaptive.robustness_cutoff_rad_s == "auto"
