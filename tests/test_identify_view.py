"""The terminal lines of ``gcs identify`` (gcs.app.identify_view)."""

from __future__ import annotations

import math
import re
from types import SimpleNamespace

from gcs.app.identify_view import weaker_lines


def axis(name: str, vaf_pct: float, vaf_profile_pct: float) -> SimpleNamespace:
    return SimpleNamespace(axis=name, vaf_pct=vaf_pct, vaf_profile_pct=vaf_profile_pct)


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
