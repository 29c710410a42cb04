"""The profile's mocap section: defaults per system, overrides, refusals (one line each)."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.core.frames import SYSTEM_FRAMES
from gcs.errors import ProfileError
from gcs.io.config import mocap_settings
from gcs.io.mocap_source import parse_mocap_url


def test_defaults_follow_the_urls_system() -> None:
    s = mocap_settings({}, "p.yaml")
    assert s.forward and s.message == "vision_position_estimate" and s.measurement == "mocap"
    for system, convention in (("optitrack", "optitrack"), ("vicon", "vicon")):
        source = parse_mocap_url(f"{system}://10.0.0.1/body")
        assert s.mapping(source) == SYSTEM_FRAMES[convention]
    # Motive's default Y-up: a point 1 m up in Motive is 1 m up (negative down) in NED
    motive = s.mapping(parse_mocap_url("optitrack://10.0.0.1/body"))
    np.testing.assert_allclose(motive.position_to_ned(np.array([0.0, 1.0, 0.0])), [0, 0, -1])


def test_frame_yaw_origin_and_overrides_are_applied() -> None:
    s = mocap_settings(
        {"frame": "optitrack-zup", "yaw_offset_deg": 90, "origin_m": [1, 2, 0],
         "north_axis": "+y"},
        "p.yaml",
    )  # fmt: skip
    m = s.mapping(parse_mocap_url("optitrack://10.0.0.1/body"))
    assert (m.up_axis, m.north_axis, m.yaw_offset_deg, m.origin_m) == ("+z", "+y", 90, (1, 2, 0))


def test_profile_url_is_the_default_and_the_command_line_wins() -> None:
    s = mocap_settings({"url": "vicon://10.0.0.5:801/cf1"}, "p.yaml")
    assert s.source(None).system == "vicon"
    assert s.source("optitrack://10.0.0.1/drone").system == "optitrack"
    assert mocap_settings({}, "p.yaml").source(None) is None


@pytest.mark.parametrize(
    ("section", "field"),
    [
        ({"right_handed": False}, "mocap.right_handed"),
        ({"frame": "motive"}, "mocap.frame"),
        ({"forward": "yes"}, "mocap.forward"),
        ({"message": "pose"}, "mocap.message"),
        ({"measurement": "truth"}, "mocap.measurement"),
        ({"position_std_m": 0}, "mocap.position_std_m"),
        ({"origin_m": [0, 0]}, "mocap.origin_m"),
        ({"yaw_offset_deg": float("nan")}, "mocap.yaw_offset_deg"),
        ({"check_move_m": -0.1}, "mocap.check_move_m"),
        ({"url": "optitrack://host/drone"}, "mocap.url"),
        ({"colour": 1}, "mocap.colour"),
    ],
)
def test_bad_fields_are_one_line_naming_them(section: dict, field: str) -> None:
    with pytest.raises(ProfileError, match=rf"p\.yaml: field '{field}'") as info:
        mocap_settings(section, "p.yaml")
    assert "\n" not in str(info.value)


def test_a_north_axis_along_up_is_refused() -> None:
    with pytest.raises(ProfileError, match="north_axis"):
        mocap_settings({"frame": "vicon", "north_axis": "+z"}, "p.yaml")


def test_a_mirrored_mapping_names_the_consequence() -> None:
    with pytest.raises(ProfileError, match="mirrors an axis"):
        mocap_settings({"right_handed": False}, "p.yaml")
