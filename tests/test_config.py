"""Tests of gcs.io.config: profile and trajectory files, and every refusal naming file + field."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from gcs.core.model import from_transfer_function, markov_parameters
from gcs.errors import ProfileError, TrajectoryError
from gcs.io.config import (
    DEFAULT_MAX_VERTICAL_SPEED_M_S,
    load_profile,
    load_trajectory,
    profile_from_dict,
)
from gcs.io.settings import FlightSettings, IdentifySettings, MocapSettings

ROOT = Path(__file__).resolve().parents[1]
ANTX = ROOT / "profiles" / "antx.yaml"
EIGHT = ROOT / "trajectories" / "eight.yaml"


def antx_data() -> dict:
    return yaml.safe_load(ANTX.read_text())


def write(tmp_path: Path, data, name: str = "profile.yaml") -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
    return path


def refused(tmp_path, data, error, field, name="profile.yaml"):
    path = write(tmp_path, data, name)
    loader = load_profile if error is ProfileError else load_trajectory
    with pytest.raises(error) as info:
        loader(path)
    msg = str(info.value)
    assert str(path) in msg, msg
    if field is not None:
        assert f"'{field}'" in msg, msg
    assert "\n" not in msg
    assert isinstance(info.value, ValueError)
    return msg


# ------------------------------------------------------------------------------ loading


def test_antx_profile_loads_with_eq11_model_and_table_one_settings():
    p = load_profile(ANTX)
    assert p.name == "antx"
    assert p.t_ilc_s == 0.05
    expected = from_transfer_function([0.08, 1.94], [1.0, 1.752, 2.01], 0.25, 0.05)
    assert p.model_x.delay_samples == 5
    assert p.model_x.dt_s == 0.05
    np.testing.assert_allclose(markov_parameters(p.model_x, 40), markov_parameters(expected, 40))
    # Gx = Gy (paper): one model for both axes
    assert p.model_y is p.model_x
    assert p.models() == (p.model_x, p.model_y)
    ln = p.learning
    assert ln.algorithm == "smoother"
    assert (ln.weights.we, ln.weights.wdu, ln.weights.wu) == (1.0, 0.01, 0.0)
    for s in (ln.smoother, ln.kilc):
        assert (s.q, s.r, s.p0, s.d0) == (0.1, 0.01, 0.1, 0.0)
    assert ln.max_step_m == 0.5 and ln.max_deviation_m == 2.5
    assert (p.max_speed_m_s, p.max_accel_m_s2) == (3.0, 5.0)
    assert p.max_vertical_speed_m_s == DEFAULT_MAX_VERTICAL_SPEED_M_S == 1.5  # optional: default
    assert p.arena.north_m == (-3.0, 3.0) and p.arena.down_m == (-3.0, 0.0)
    assert p.flight == FlightSettings(**antx_data()["flight"])  # the rest: defaults
    ratio = p.flight.stream_rate_hz * p.t_ilc_s  # documented: integer multiple of 1/t_ilc
    assert ratio == pytest.approx(round(ratio)) and round(ratio) >= 1
    ident = antx_data()["identification"]
    ident["center_ned_m"] = tuple(ident["center_ned_m"])
    assert p.identification == IdentifySettings(**ident)
    assert p.mocap == MocapSettings()  # no section: every default
    assert p.source == antx_data()


def test_defaults_when_learning_section_absent(tmp_path):
    data = antx_data()
    del data["learning"]
    p = load_profile(write(tmp_path, data))
    assert p.learning.algorithm == "smoother"
    assert p.learning.smoother.q == 0.1 and p.learning.kilc.r == 0.01
    assert p.learning.max_step_m is None and p.learning.max_deviation_m is None


def test_per_axis_model_y(tmp_path):
    data = antx_data()
    data["model_y"] = {"num": [2.0], "den": [1.0, 2.5, 2.0], "delay_s": 0.1}
    p = load_profile(write(tmp_path, data))
    assert p.model_y is not p.model_x
    assert p.model_y.delay_samples == 2
    expected = from_transfer_function([2.0], [1.0, 2.5, 2.0], 0.1, 0.05)
    np.testing.assert_allclose(markov_parameters(p.model_y, 30), markov_parameters(expected, 30))
    assert p.model_x.delay_samples == 5


def test_state_space_model(tmp_path):
    data = antx_data()
    data["model"] = {
        "A": [[0.9, 0.05], [0.0, 0.8]],
        "B": [[0.0], [0.1]],
        "C": [[1.0, 0.0]],
        "D": [[0.0]],
        "dt_s": 0.05,
        "delay_samples": 3,
    }
    p = load_profile(write(tmp_path, data))
    np.testing.assert_array_equal(p.model_x.A, [[0.9, 0.05], [0.0, 0.8]])
    assert p.model_x.delay_samples == 3
    f = markov_parameters(p.model_x, 6)
    np.testing.assert_allclose(f, [0, 0, 0, 0.0, 0.1 * 0.05, 0.1 * 0.05 * (0.9 + 0.8)])


def test_trajectory_files_load():
    spec = load_trajectory(EIGHT)
    assert spec.name == "eight"
    s = spec.shape
    assert s.center_ned_m == (0.0, 0.0, -1.5)
    assert (s.amplitude_north_m, s.amplitude_east_m, s.period_s) == (1.2, 1.2, 5.0)
    assert (s.loops, s.ramp_s, s.hover_s) == (2, 2.0, 1.0)
    assert load_trajectory(ROOT / "trajectories" / "eight-short.yaml").shape.loops == 1


# ------------------------------------------------------------------------------ refusals


def test_malformed_yaml(tmp_path):
    msg = refused(tmp_path, "name: antx\nmodel: [1, 2\n", ProfileError, None)
    assert "malformed YAML" in msg
    msg = refused(tmp_path, "name: [\n", TrajectoryError, None, "traj.yaml")
    assert "malformed YAML" in msg


def test_missing_file_and_non_mapping(tmp_path):
    with pytest.raises(ProfileError, match="nope.yaml"):
        load_profile(tmp_path / "nope.yaml")
    refused(tmp_path, "- 1\n- 2\n", ProfileError, "<top>")


def _set(data: dict, dotted: str, value) -> dict:
    data = copy.deepcopy(data)
    *parents, last = dotted.split(".")
    node = data
    for key in parents:
        node = node[key]
    if value is _DELETE:
        del node[last]
    else:
        node[last] = value
    return data


_DELETE = object()


@pytest.mark.parametrize(
    "dotted, value, field",
    [
        # missing fields
        ("t_ilc_s", _DELETE, "t_ilc_s"),
        ("name", _DELETE, "name"),
        ("model", _DELETE, "model"),
        ("model.den", _DELETE, "model.den"),
        ("vehicle.max_speed_m_s", _DELETE, "vehicle.max_speed_m_s"),
        ("arena.east_m", _DELETE, "arena.east_m"),
        # wrong types
        ("t_ilc_s", "fast", "t_ilc_s"),
        ("t_ilc_s", True, "t_ilc_s"),
        ("learning.smoother.q", "0.1", "learning.smoother.q"),
        ("learning.weights.wdu", [0.01], "learning.weights.wdu"),
        ("model.num", "0.08 1.94", "model.num"),
        ("vehicle", 3.0, "vehicle"),
        ("arena.north_m", [-3.0, 3.0, 4.0], "arena.north_m"),
        ("name", 12, "name"),
        # unknown fields (typos)
        ("learning.smoother.qq", 0.1, "learning.smoother.qq"),
        ("learning.limits.max_stepm", 0.5, "learning.limits.max_stepm"),
        ("vehicle.max_sped_m_s", 3.0, "vehicle.max_sped_m_s"),
        ("model.delay", 0.25, "model.delay"),
        ("arean", {}, "arean"),
        # NaN / inf
        ("t_ilc_s", float("nan"), "t_ilc_s"),
        ("vehicle.max_accel_m_s2", float("inf"), "vehicle.max_accel_m_s2"),
        ("model.num", [0.08, float("nan")], "model.num"),
        ("model.delay_s", float("inf"), "model.delay_s"),
        ("learning.kilc.r", float("nan"), "learning.kilc.r"),
        ("arena.down_m", [float("-inf"), 0.0], "arena.down_m"),
        # out of range
        ("t_ilc_s", 0.0, "t_ilc_s"),
        ("vehicle.max_speed_m_s", -1.0, "vehicle.max_speed_m_s"),
        ("vehicle.max_vertical_speed_m_s", 0.0, "vehicle.max_vertical_speed_m_s"),
        ("vehicle.max_vertical_speed_m_s", "fast", "vehicle.max_vertical_speed_m_s"),
        ("learning.smoother.r", 0.0, "learning.smoother"),
        ("learning.weights.we", 0.0, "learning.weights.we"),
        ("model.delay_s", -0.05, "model"),
        ("model.den", [1.0, 2.0], "model"),  # not strictly proper
        ("model.den", [2.225073858507e-311, 0.0, 0.0], "model"),  # num / den[0] overflows
        # bad algorithm name
        ("learning.algorithm", "smooth", "learning.algorithm"),
        ("learning.algorithm", "KILC", "learning.algorithm"),
        # empty arena interval
        ("arena.north_m", [1.0, 1.0], "arena.north_m"),
        ("arena.east_m", [2.0, -2.0], "arena.east_m"),
    ],
)
def test_profile_refusals_name_file_and_field(tmp_path, dotted, value, field):
    refused(tmp_path, _set(antx_data(), dotted, value), ProfileError, field)


@pytest.mark.parametrize("key", ["model", "model_y"])
def test_unstable_model_refused(tmp_path, key):
    data = antx_data()
    data[key] = {"num": [1.0], "den": [1.0, -0.5, 2.0], "delay_s": 0.0}  # poles in the RHP
    msg = refused(tmp_path, data, ProfileError, key)
    assert "stable" in msg


def test_state_space_refusals(tmp_path):
    base = {"A": [[0.5]], "B": [[1.0]], "C": [[1.0]], "dt_s": 0.05}
    data = antx_data()
    data["model"] = {**base, "dt_s": 0.1}
    msg = refused(tmp_path, data, ProfileError, "model.dt_s")
    assert "0.1" in msg and "0.05" in msg
    data["model"] = {**base, "D": [[0.3]]}
    assert "feedthrough" in refused(tmp_path, data, ProfileError, "model")
    data["model"] = {**base, "A": [[1.5]]}
    refused(tmp_path, data, ProfileError, "model")
    data["model"] = {**base, "A": [[0.5, 0.1]]}
    refused(tmp_path, data, ProfileError, "model")
    data["model"] = {**base, "delay_samples": 1.5}
    refused(tmp_path, data, ProfileError, "model.delay_samples")
    data["model"] = {**base, "B": [[float("nan")]]}
    refused(tmp_path, data, ProfileError, "model.B")
    data["model_y"] = {**base, "Q": 1}
    data["model"] = base
    refused(tmp_path, data, ProfileError, "model_y.Q")


@pytest.mark.parametrize(
    "dotted, value, field",
    [
        ("amplitude_north_m", _DELETE, "amplitude_north_m"),
        ("name", _DELETE, "name"),
        ("period_s", "long", "period_s"),
        ("loops", 1.5, "loops"),
        ("amplitude_east_m", float("nan"), "amplitude_east_m"),
        ("period_s", float("inf"), "period_s"),
        ("amplitude_north_m", -1.0, "amplitude_north_m"),
        ("center_ned_m", [0.0, 0.0], "center_ned_m"),
        ("center_ned_m", [0.0, float("nan"), -1.0], "center_ned_m"),
        ("hover", 1.0, "hover"),
        ("type", "spiral", "type"),
    ],
)
def test_trajectory_refusals_name_file_and_field(tmp_path, dotted, value, field):
    data = yaml.safe_load(EIGHT.read_text())
    refused(tmp_path, _set(data, dotted, value), TrajectoryError, field, "traj.yaml")


@pytest.mark.parametrize("dotted, value", [("loops", 0), ("ramp_s", -1.0), ("hover_s", -0.5)])
def test_trajectory_shape_refusals_name_file(tmp_path, dotted, value):
    data = yaml.safe_load(EIGHT.read_text())
    msg = refused(tmp_path, _set(data, dotted, value), TrajectoryError, None, "traj.yaml")
    assert dotted in msg


def test_every_section_is_typed_and_checked_when_the_profile_loads():
    data = antx_data()
    data["mocap"] = {"measurement": "estimate", "origin_m": [1, 2, 3], "north_axis": "+z"}
    data["flight"] = {"stream_rate_hz": 100, "min_battery_pct": 0}
    p = profile_from_dict(data, "p.yaml")
    assert p.mocap.measurement == "estimate" and p.mocap.origin_m == (1.0, 2.0, 3.0)
    assert p.mocap.overrides == {"north_axis": "+z"}
    assert p.flight.sends_per_sample(p.t_ilc_s) == 5 and p.flight.min_battery_pct == 0.0
    for section, value, field in (
        ("mocap", {"measurement": "truth"}, "mocap.measurement"),
        ("flight", {"yaw_deg": "north"}, "flight.yaw_deg"),
        ("identification", {"past": 0}, "identification.past"),
    ):
        with pytest.raises(ProfileError, match=rf"^p\.yaml: field '{field}'"):
            profile_from_dict({**antx_data(), section: value}, "p.yaml")
