"""One strict reader of YAML mappings: each field's type and range declared once.

A frozen dataclass declares the range of a field beside the field itself, with :func:`ranged`
(its type is the field's annotation). :meth:`Fields.read` builds such a dataclass from a
mapping by those declarations; :func:`check` applies the same rules to an object built in code
(a ``__post_init__``). Cross-field rules stay small named functions beside their dataclass.

Every refusal is one line ``<file>: field '<a.b>' <what>, got <value>`` raised as the caller's
error class (:class:`gcs.errors.ProfileError`, ``TrajectoryError``, ``StudyError``), and an
unknown field is refused with the closest known name: a typo in a safety limit must not fall
back to a default silently.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from dataclasses import dataclass
from typing import Any

from gcs.errors import GcsError
from gcs.io.suggest import did_you_mean

__all__ = ["Fields", "Rule", "check", "ranged"]

#: The metadata key of a field's :class:`Rule`.
RULE = "gcs.rule"


def _text(value: float) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"


@dataclass(frozen=True)
class Rule:
    """What a value must be beyond its type: bounds, choices, and why.

    Parameters
    ----------
    gt, ge, lt, le : float or None
        Bounds (greater than, at least, less than, at most); None: none.
    choices : tuple
        The values allowed (empty: any).
    unit : str
        Unit said after the bounds (``"s"``, ``"ms"``).
    why : str
        Reason said after the bounds.
    """

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: tuple = ()
    unit: str = ""
    why: str = ""

    def problem(self, value: Any) -> str | None:
        """What is wrong with a value of the right type, or None.

        Parameters
        ----------
        value : Any
            A number (or a choice).

        Returns
        -------
        str or None
            ``"must be in [0, 100], got 120"`` and the like.
        """
        note = (f" {self.unit}" if self.unit else "") + (f" ({self.why})" if self.why else "")
        if self.choices and value not in self.choices:
            listed = ", ".join(str(c) for c in self.choices)
            return f"must be one of {listed}{note}, got {value!r}"
        if not isinstance(value, int | float):
            return None
        lo = self.ge if self.gt is None else self.gt
        hi = self.le if self.lt is None else self.lt
        low_ok = lo is None or (value > lo if self.gt is not None else value >= lo)
        high_ok = hi is None or (value < hi if self.lt is not None else value <= hi)
        if low_ok and high_ok:
            return None
        if lo is not None and hi is not None:
            left, right = "(" if self.gt is not None else "[", ")" if self.lt is not None else "]"
            bounds = f"in {left}{_text(lo)}, {_text(hi)}{right}"
        elif lo is not None:
            bounds = f"{'>' if self.gt is not None else '>='} {_text(lo)}"
        else:
            bounds = f"{'<' if self.lt is not None else '<='} {_text(hi)}"  # type: ignore[arg-type]
        return f"must be {bounds}{note}, got {value!r}"


FINITE = Rule()
POSITIVE = Rule(gt=0)
_UNIONS = (typing.Union, types.UnionType)
_hints = functools.cache(typing.get_type_hints)  # a class's resolved annotations


def ranged(default: Any, **rule: Any) -> Any:
    """A dataclass field with a default and a :class:`Rule` (``ge=0, le=100``...).

    Parameters
    ----------
    default : Any
        The field's default.
    **rule : Any
        The :class:`Rule`'s fields.

    Returns
    -------
    dataclasses.Field
    """
    return dataclasses.field(default=default, metadata={RULE: Rule(**rule)})


def _rule(f: dataclasses.Field, default: Rule = FINITE) -> Rule:
    return f.metadata.get(RULE, default)


def _typed(value: Any, kind: Any) -> tuple[Any, str | None]:
    """``value`` as ``kind`` (bool, int, float, str, a tuple of floats), or what is wrong."""
    origin = typing.get_origin(kind)
    if origin in _UNIONS:
        args = [a for a in typing.get_args(kind) if a is not type(None)]
        return (None, None) if value is None else _typed(value, args[0])
    if origin is tuple:
        n = len(typing.get_args(kind))
        if not (isinstance(value, list | tuple) and len(value) == n):
            shape = "three numbers [north, east, down]" if n == 3 else f"{n} numbers"
            return None, f"must be {shape}, got {value!r}"
        items = [_typed(v, float) for v in value]
        bad = next((p for _, p in items if p), None)
        return (None, bad) if bad else (tuple(v for v, _ in items), None)
    if kind is bool:
        ok = isinstance(value, bool)
        return value, None if ok else f"must be true or false, got {value!r}"
    if kind is str:
        return value, None if isinstance(value, str) else f"must be a string, got {value!r}"
    if kind not in (int, float):
        raise TypeError(f"unsupported field type {kind!r}")  # a programming error
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None, f"must be {'an integer' if kind is int else 'a number'}, got {value!r}"
    if kind is int:
        return value, None if isinstance(value, int) else f"must be an integer, got {value!r}"
    if not math.isfinite(value):
        return None, f"must be finite, got {value!r}"
    return float(value), None


def _problem(value: Any, kind: Any, rule: Rule) -> tuple[Any, str | None]:
    """``value`` typed and checked against ``rule`` (each entry of a tuple)."""
    typed, problem = _typed(value, kind)
    if problem or typed is None:
        return typed, problem
    for v in value if isinstance(typed, tuple) else (value,):  # said as given
        problem = rule.problem(v)
        if problem:
            return typed, problem
    return typed, None


def check(obj: Any, section: str, error: type[GcsError], default: Rule = FINITE) -> None:
    """Check every field of a dataclass built in code against its declared rule.

    Parameters
    ----------
    obj : dataclass instance
        Typically ``self`` in ``__post_init__``.
    section : str
        Dotted name said before the field (``"flight"``).
    error : type
        The error raised.
    default : Rule
        The rule of a number field that declares none.

    Raises
    ------
    GcsError
        ``field 'section.name' must be ..., got ...``.
    """
    hints = _hints(type(obj))
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            check(value, f"{section}.{f.name}", error, default)
            continue
        _, problem = _problem(value, hints[f.name], _rule(f, default))
        if problem:
            raise error(f"field '{section}.{f.name}' {problem}")


class Fields:
    """Strict reader of one YAML mapping; refusals name the file and the dotted field.

    Parameters
    ----------
    data : Any
        The parsed mapping (anything else is refused).
    where : str
        The file, for messages.
    path : str
        Dotted path of the mapping in the file (``""``: the top).
    error : type
        The error raised (a :class:`gcs.errors.GcsError`).
    """

    def __init__(self, data: Any, where: str, path: str, error: type[GcsError]) -> None:
        if not isinstance(data, dict):
            got = f", got {data!r}" if path else ""  # a whole file: not repeated
            raise error(f"{where}: field '{path or '<top>'}' must be a mapping{got}")
        self.data, self.where, self.path, self.error = data, where, path, error
        self.used: set[str] = set()
        self.asked: set[str] = set()  # every field looked for: the known ones

    def _name(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def fail(self, key: str, message: str) -> GcsError:
        """The refusal of one field (to raise).

        Parameters
        ----------
        key : str
            The field, within this mapping.
        message : str
            What is wrong with it.

        Returns
        -------
        GcsError
        """
        return self.error(f"{self.where}: field '{self._name(key)}' {message}")

    def has(self, key: str) -> bool:
        """Whether the mapping gives ``key`` (a known field either way).

        Parameters
        ----------
        key : str
            The field.

        Returns
        -------
        bool
        """
        self.asked.add(key)
        return key in self.data

    def raw(self, key: str, default: Any = ...) -> Any:
        """A field as given, or ``default`` (none: the field is required).

        Parameters
        ----------
        key : str
            The field.
        default : Any
            Its default; ``...``: required.

        Returns
        -------
        Any
        """
        self.asked.add(key)
        if key not in self.data:
            if default is ...:
                raise self.fail(key, "is missing")
            return default
        self.used.add(key)
        return self.data[key]

    def value(self, key: str, kind: Any, default: Any = ..., rule: Rule = FINITE) -> Any:
        """A field of type ``kind`` checked against ``rule`` (the default is not checked).

        Parameters
        ----------
        key : str
            The field.
        kind : type
            ``float``, ``int``, ``bool``, ``str``, ``tuple[float, ...]`` or ``X | None``.
        default : Any
            Its default; ``...``: required.
        rule : Rule
            Bounds and choices.

        Returns
        -------
        Any
        """
        if not self.has(key) and default is not ...:
            return default
        value, problem = _problem(self.raw(key), kind, rule)
        if problem:
            raise self.fail(key, problem)
        return value

    def field(self, cls: type, name: str, *, required: bool = False) -> Any:
        """One field of dataclass ``cls`` read by its declaration (type, rule, default).

        Parameters
        ----------
        cls : type
            The dataclass.
        name : str
            The field (the key in the mapping).
        required : bool
            Refuse its absence instead of taking the default.

        Returns
        -------
        Any
        """
        declared = next(f for f in dataclasses.fields(cls) if f.name == name)
        kind = _hints(cls)[name]
        if (required or declared.default is not None) and typing.get_origin(kind) in _UNIONS:
            kind = next(a for a in typing.get_args(kind) if a is not type(None))  # no null
        return self.value(name, kind, ... if required else declared.default, _rule(declared))

    def number(
        self, key: str, default: Any = ..., *, positive: bool = False, rule: Rule = FINITE
    ) -> float:
        """A finite number (``positive``: > 0; else within ``rule``).

        Parameters
        ----------
        key : str
            The field.
        default : Any
            Its default; ``...``: required.
        positive : bool
            Refuse numbers <= 0.
        rule : Rule
            Bounds otherwise.

        Returns
        -------
        float
        """
        return self.value(key, float, default, POSITIVE if positive else rule)

    def optional_number(self, key: str) -> float | None:
        """A number > 0, or None when absent or null.

        Parameters
        ----------
        key : str
            The field.

        Returns
        -------
        float or None
        """
        return self.value(key, float | None, None, POSITIVE)

    def integer(self, key: str, default: Any = ..., rule: Rule = FINITE) -> int:
        """An integer within ``rule``.

        Parameters
        ----------
        key : str
            The field.
        default : Any
            Its default; ``...``: required.
        rule : Rule
            Bounds.

        Returns
        -------
        int
        """
        return self.value(key, int, default, rule)

    def string(self, key: str, default: Any = ..., choices: tuple[str, ...] = ()) -> str:
        """A string, one of ``choices`` when given.

        Parameters
        ----------
        key : str
            The field.
        default : Any
            Its default; ``...``: required.
        choices : tuple of str
            The strings allowed (empty: any).

        Returns
        -------
        str
        """
        return self.value(key, str, default, Rule(choices=choices))

    def numbers(self, key: str, length: int | None = None, default: Any = ...) -> list[float]:
        """A non-empty list of finite numbers (of ``length`` entries when given).

        Parameters
        ----------
        key : str
            The field.
        length : int or None
            The number of entries required.
        default : Any
            Its default; ``...``: required.

        Returns
        -------
        list of float
        """
        value = self.raw(key, default)
        if not isinstance(value, list) or not value:
            raise self.fail(key, f"must be a non-empty list of numbers, got {value!r}")
        if length is not None and len(value) != length:
            raise self.fail(key, f"must have {length} entries, got {len(value)}")
        return self._finite(key, value)

    def _finite(self, key: str, row: list) -> list[float]:
        for v in row:
            if _typed(v, float)[1]:
                raise self.fail(key, f"must contain only finite numbers, got {v!r}")
        return [float(v) for v in row]

    def matrix(self, key: str) -> list[list[float]]:
        """A matrix: a list of lists of finite numbers (one list: a row).

        Parameters
        ----------
        key : str
            The field.

        Returns
        -------
        list of list of float
        """
        value = self.raw(key)
        rows = (
            value if isinstance(value, list) and value and isinstance(value[0], list) else [value]
        )
        if not all(isinstance(row, list) for row in rows):
            raise self.fail(key, "must be a matrix (list of lists of numbers)")
        return [self._finite(key, row) for row in rows]

    def text(self, key: str) -> str | None:
        """An optional free text (``description``).

        Parameters
        ----------
        key : str
            The field.

        Returns
        -------
        str or None
        """
        return self.value(key, str | None, None)

    def sub(self, key: str, default: Any = ...) -> Fields:
        """The reader of a nested mapping (null: an empty one).

        Parameters
        ----------
        key : str
            The field.
        default : Any
            Its default; ``...``: required.

        Returns
        -------
        Fields
        """
        value = self.raw(key, default)
        return Fields({} if value is None else value, self.where, self._name(key), self.error)

    def read(self, cls: type, default: Rule = FINITE, **given: Any) -> Any:
        """Build dataclass ``cls`` from this mapping by its fields' types and rules.

        A field absent from the mapping takes its default; a nested dataclass is read from
        its own section; unknown fields are refused (:meth:`done`).

        Parameters
        ----------
        cls : type
            A dataclass whose fields are bool, int, float, str, tuples of floats or nested
            dataclasses (optionally ``| None``).
        default : Rule
            The rule of a number field that declares none (also for nested dataclasses).
        **given : Any
            Fields the caller has read itself (not read here).

        Returns
        -------
        cls
        """
        hints = _hints(cls)
        values = dict(given)
        for f in dataclasses.fields(cls):
            if f.name in given:
                continue
            if dataclasses.is_dataclass(hints[f.name]):
                if self.has(f.name):
                    values[f.name] = self.sub(f.name).read(hints[f.name], default)
            elif self.has(f.name):
                values[f.name] = self.value(f.name, hints[f.name], ..., _rule(f, default))
        self.done()
        return cls(**values)

    def done(self) -> None:
        """Refuse any field that was not read (with the closest known name)."""
        extra = sorted((k for k in self.data if k not in self.used), key=str)
        if extra:
            hint = did_you_mean(str(extra[0]), self.asked)
            raise self.fail(extra[0], f"is not a known field{hint}")
