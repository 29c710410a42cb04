"""The terminal lines of ``gcs identify`` (gcs.app.identify_view)."""

from __future__ import annotations

import math
import re
from types import SimpleNamespace

import pytest

from gcs.app.identify_view import weaker_lines
from gcs.core.model import dc_gain, from_transfer_function


def loop(gain: float):  # noqa: ANN201
    """A second-order position loop of that steady-state gain (0.05 s)."""
    return from_transfer_function([4.0 * gain], [1.0, 2.8, 4.0], 0.0, 0.05)


def axis(name: str, vaf_pct: float, vaf_profile_pct: float, gain: float = 1.0) -> SimpleNamespace:
    return SimpleNamespace(
        axis=name, vaf_pct=vaf_pct, vaf_profile_pct=vaf_profile_pct, model=loop(gain)
    )


def test_an_axis_that_explains_the_validation_less_than_the_profile_is_named_once() -> None:
    """Seen on firmware over GPS: east identified from 30 s experiments explained the
    validation experiment at 1.37 % where the profile's model it started from gave 19.55 %."""
    results = [axis("x", 91.0, 5.77), axis("y", 1.37, 19.55), axis("z", 50.0, math.nan)]
    lines = weaker_lines(results, "antx")
    assert len(lines) == 1
    found = re.fullmatch(
        r"warning: y: the identified model explains the validation experiment less than "
        r"antx's \(VAF ([-\d.]+) % against ([-\d.]+) %\).*keep antx's model for this axis",
        lines[0],
    )
    assert found is not None, lines
    assert (float(found[1]), float(found[2])) == (1.37, 19.55)
    assert weaker_lines([axis("x", 20.0, 20.0)], "antx") == []  # as good: no warning


def test_an_axis_explained_less_than_by_its_mean_is_named_even_when_the_profile_did_worse() -> None:
    """Seen on firmware over GPS at load 14-21: VAF -146.8 % (the profile's -305.3 %)."""
    lines = weaker_lines([axis("x", -146.8, -305.34), axis("y", 12.0, -38.7)], "antx")
    assert len(lines) == 1, lines
    assert re.fullmatch(
        r"warning: x: the identified model explains the validation experiment less than its "
        r"mean does \(VAF -146\.80 %\): .* before flying this model",
        lines[0],
    ), lines
    assert weaker_lines([axis("x", -1.0, math.nan)], "antx")[0].startswith("warning: x: ")


@pytest.mark.parametrize("gain", [2.086, 0.45, 3.0])
def test_an_axis_of_an_implausible_steady_state_gain_is_named(gain: float) -> None:
    """Seen on firmware over GPS, 30 s experiments: east's gain 2.09 at a VAF of 57.6 %, above
    the profile's 54.9 %: no other warning, but the gain says the slow response is unknown."""
    lines = weaker_lines([axis("x", 93.4, 85.6), axis("y", 57.6, 54.9, gain)], "antx")
    assert len(lines) == 1, lines
    shown = f"{dc_gain(loop(gain)):.2f}"
    assert re.fullmatch(
        rf"warning: y: the identified model's steady-state gain is {re.escape(shown)}, where a "
        r"position loop holds 1: .* keep antx's model for this axis",
        lines[0],
    ), lines
    assert float(shown) == pytest.approx(gain, abs=0.005)  # the loop's gain, independently
    within = [axis("y", 57.6, 54.9, g) for g in (0.55, 1.0, 1.9)]
    assert weaker_lines(within, "antx") == []
    # one line per axis: a weaker axis is named as weaker, whatever its gain
    assert "less than antx's" in weaker_lines([axis("y", 10.0, 50.0, 3.0)], "antx")[0]
