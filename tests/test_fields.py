"""Tests of gcs.io.fields: one reader, the rules declared beside the dataclass fields."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from gcs.errors import ProfileError, StudyError
from gcs.io.fields import Fields, Rule, check, ranged
from gcs.io.settings import FlightSettings


@dataclass(frozen=True)
class Inner:
    gain: float = ranged(1.0, gt=0, lt=10, unit="s")
    on: bool = False


@dataclass(frozen=True)
class Outer:
    rate_hz: float = ranged(50.0, ge=2, why="the autopilot's own floor")
    mode: str = ranged("a", choices=("a", "b"))
    count: int = 3
    offset_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    spare_m: float = 1.0
    inner: Inner = field(default_factory=Inner)


def read(data, default: Rule = Rule()) -> Outer:  # noqa: B008
    return Fields(data, "f.yaml", "", ProfileError).read(Outer, default)


@pytest.mark.parametrize(
    ("rule", "value", "message"),
    [
        (Rule(gt=0), 0, "must be > 0, got 0"),
        (Rule(ge=1, unit="s"), 0.5, "must be >= 1 s, got 0.5"),
        (Rule(lt=1), 1.0, "must be < 1, got 1.0"),
        (Rule(le=5), 6, "must be <= 5, got 6"),
        (Rule(ge=0, le=100, unit="%"), 120, "must be in [0, 100] %, got 120"),
        (Rule(gt=0, lt=80), 80, "must be in (0, 80), got 80"),
        (Rule(ge=0, lt=1), -0.1, "must be in [0, 1), got -0.1"),
        (Rule(gt=0, le=1, why="a fraction"), 0, "must be in (0, 1] (a fraction), got 0"),
        (Rule(choices=(0, 1, 3)), 2, "must be one of 0, 1, 3, got 2"),
        (Rule(ge=1, le=1_000_000), 0, "must be in [1, 1000000], got 0"),
    ],
)
def test_a_rule_says_its_bounds_and_the_value_as_given(rule, value, message) -> None:
    assert rule.problem(value) == message


@pytest.mark.parametrize("value", [0.001, 5, 9.99])
def test_a_value_within_the_rule_passes(value) -> None:
    assert Rule(gt=0, lt=10).problem(value) is None


def test_a_dataclass_is_read_by_its_declared_types_and_ranges() -> None:
    got = read({"rate_hz": 2, "count": 4, "offset_ned_m": [1, 2, 3], "inner": {"gain": 2}})
    assert got == Outer(2.0, "a", 4, (1.0, 2.0, 3.0), 1.0, Inner(2.0, False))
    assert isinstance(got.rate_hz, float) and isinstance(got.offset_ned_m[0], float)
    assert read({}) == Outer() and read({"inner": None}) == Outer()


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"rate_hz": 1}, "field 'rate_hz' must be >= 2 (the autopilot's own floor), got 1"),
        ({"rate_hz": "60"}, "field 'rate_hz' must be a number, got '60'"),
        ({"rate_hz": True}, "field 'rate_hz' must be a number, got True"),
        ({"spare_m": float("nan")}, "field 'spare_m' must be finite, got nan"),
        ({"mode": "c"}, "field 'mode' must be one of a, b, got 'c'"),
        ({"mode": 1}, "field 'mode' must be a string, got 1"),
        ({"count": 2.5}, "field 'count' must be an integer, got 2.5"),
        ({"offset_ned_m": [1, 2]}, "must be three numbers [north, east, down], got [1, 2]"),
        ({"offset_ned_m": [1, "x", 2]}, "field 'offset_ned_m' must be a number, got 'x'"),
        ({"inner": {"gain": 10}}, "field 'inner.gain' must be in (0, 10) s, got 10"),
        ({"inner": {"on": "yes"}}, "field 'inner.on' must be true or false, got 'yes'"),
        ({"inner": [1]}, "field 'inner' must be a mapping, got [1]"),
        ({"inner": {"gian": 1}}, "field 'inner.gian' is not a known field; did you mean 'gain'?"),
        ({"rate": 60}, "field 'rate' is not a known field; did you mean 'rate_hz'?"),
    ],
)
def test_every_refusal_is_one_line_naming_file_and_field(data, message) -> None:
    with pytest.raises(ProfileError) as info:
        read(data)
    assert str(info.value).startswith("f.yaml: field '") and message in str(info.value)


def test_the_reader_s_default_rule_covers_the_numbers_that_declare_none() -> None:
    with pytest.raises(ProfileError, match=r"field 'spare_m' must be >= 0, got -1$"):
        read({"spare_m": -1}, Rule(ge=0))
    with pytest.raises(ProfileError, match=r"field 'offset_ned_m' must be >= 0, got -2$"):
        read({"offset_ned_m": [1, -2, 3]}, Rule(ge=0))
    assert read({"rate_hz": 3}, Rule(ge=5)).rate_hz == 3.0  # a declared rule wins


def test_the_same_rules_check_an_object_built_in_code() -> None:
    check(Outer(), "outer", ProfileError)
    with pytest.raises(ProfileError, match=r"^field 'outer.inner.gain' must be in \(0, 10\) s"):
        check(Outer(inner=Inner(gain=0.0)), "outer", ProfileError)
    with pytest.raises(ProfileError, match=r"^field 'outer.rate_hz' must be >= 2 .*got 1$"):
        check(Outer(rate_hz=1), "outer", ProfileError)


def test_flight_settings_declare_their_ranges_once_for_files_and_code() -> None:
    with pytest.raises(
        ProfileError, match=r"^field 'flight.min_battery_pct' must be in \[0, 100\]"
    ):
        FlightSettings(min_battery_pct=101.0)
    f = Fields({"min_battery_pct": 101}, "p.yaml", "flight", ProfileError)
    with pytest.raises(ProfileError, match=r"^p.yaml: field 'flight.min_battery_pct' must be in"):
        f.read(FlightSettings)
    assert Fields({"yaw_deg": -90}, "p", "flight", ProfileError).read(FlightSettings).yaw_deg == -90


def test_required_fields_defaults_and_the_error_class() -> None:
    f = Fields({"n": 3}, "s.yaml", "study", StudyError)
    with pytest.raises(StudyError, match=r"^s.yaml: field 'study.seed' is missing$"):
        f.integer("seed")
    assert f.integer("n", 1, Rule(ge=1)) == 3 and f.number("x", 0.5) == 0.5
    assert f.optional_number("y") is None and f.text("description") is None
    f.done()
    with pytest.raises(StudyError, match="must be a mapping$"):
        Fields([1], "s.yaml", "", StudyError)  # the whole file is not repeated


def test_one_field_is_read_by_its_declaration() -> None:
    f = Fields({"rate_hz": 1, "mode": "b"}, "f.yaml", "x", ProfileError)
    assert f.field(Outer, "mode") == "b" and f.field(Outer, "count") == 3  # the default
    with pytest.raises(ProfileError, match=r"field 'x.rate_hz' must be >= 2 .*got 1$"):
        f.field(Outer, "rate_hz")
    with pytest.raises(ProfileError, match=r"field 'x.spare_m' is missing$"):
        f.field(Outer, "spare_m", required=True)
