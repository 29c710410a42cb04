"""Results compared with records made on another machine: numbers within a tolerance, the rest
exactly (docs/results.md, "Reproducibility")."""

from __future__ import annotations

import re

import numpy as np

# a decimal number as Python, numpy, JSON and YAML write it (an integer, a float, an exponent)
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def deviation(now: object, recorded: object, atol: float = 0.0) -> float:
    """The largest ``|now - recorded| / (atol + |recorded|)`` (0 where both are equal)."""
    a, b = np.asarray(now, dtype=float), np.asarray(recorded, dtype=float)
    diff = np.abs(a - b)
    scale = atol + np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(diff == 0, 0.0, diff / scale)
    return float(np.max(ratio, initial=0.0))


def assert_close(
    now: object, recorded: object, rtol: float, atol: float = 0.0, what: str = ""
) -> None:
    """Arrays of the same shape, equal within ``atol + rtol |recorded|`` element by element."""
    a, b = np.asarray(now, dtype=float), np.asarray(recorded, dtype=float)
    assert a.shape == b.shape, f"{what}: shape {a.shape}, recorded {b.shape}"
    assert np.array_equal(np.isnan(a), np.isnan(b)), f"{what}: NaN where the record has none"
    ok = np.isnan(b) | (np.abs(a - b) <= atol + rtol * np.abs(b))
    if not ok.all():
        worst = np.unravel_index(np.argmax(np.where(ok, 0.0, np.abs(a - b))), a.shape)
        raise AssertionError(
            f"{what}: {int((~ok).sum())} of {a.size} values beyond rtol {rtol:g} atol "
            f"{np.max(atol):g}; "
            f"at {tuple(int(i) for i in worst)}: {a[worst]!r}, recorded {b[worst]!r}"
        )


def assert_scaled(
    now: object, recorded: object, rtol: float, what: str = "", axis: int | None = None
) -> None:
    """Equal within ``rtol`` of the record's largest magnitude (along ``axis``: per column)."""
    b = np.asarray(recorded, dtype=float)
    scale = np.max(np.abs(b), axis=axis, keepdims=True, initial=0.0)
    assert_close(now, b, 0.0, rtol * np.broadcast_to(scale, b.shape), what)


def printed_unit(x: object, digits: int) -> np.ndarray:
    """One unit of the last of ``digits`` significant digits of each value (0 for 0)."""
    a = np.abs(np.asarray(x, dtype=float))
    with np.errstate(divide="ignore"):
        exponent = np.floor(np.log10(np.where(a > 0, a, 1.0)))
    return np.where(a > 0, 10.0 ** (exponent - (digits - 1)), 0.0)


def split_numbers(text: str) -> tuple[list[str], list[float]]:
    """The text around its numbers, and the numbers."""
    return NUMBER.split(text), [float(m) for m in NUMBER.findall(text)]


def assert_text_close(
    now: str, recorded: str, rtol: float, atol: float = 0.0, what: str = ""
) -> None:
    """Texts whose numbers agree within the tolerance and whose other characters are equal."""
    words_now, numbers_now = split_numbers(now)
    words_rec, numbers_rec = split_numbers(recorded)
    assert words_now == words_rec, f"{what}: the text differs beyond its numbers"
    assert_close(numbers_now, numbers_rec, rtol, atol, what)


def assert_json_close(
    now: object, recorded: object, rtol: float, atol: float = 0.0, what: str = ""
) -> None:
    """JSON documents of the same structure: floats within the tolerance, all else exactly."""
    if isinstance(recorded, dict):
        assert isinstance(now, dict) and sorted(now) == sorted(recorded), f"{what}: keys differ"
        for key, value in recorded.items():
            assert_json_close(now[key], value, rtol, atol, f"{what}/{key}")
    elif isinstance(recorded, list):
        assert isinstance(now, list) and len(now) == len(recorded), f"{what}: lengths differ"
        for i, (a, b) in enumerate(zip(now, recorded, strict=True)):
            assert_json_close(a, b, rtol, atol, f"{what}[{i}]")
    elif isinstance(recorded, float) and not isinstance(recorded, bool):
        assert isinstance(now, (int, float)), f"{what}: {now!r}, recorded {recorded!r}"
        assert_close(now, recorded, rtol, atol, what)
    else:
        assert now == recorded, f"{what}: {now!r}, recorded {recorded!r}"
