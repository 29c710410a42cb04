"""Study definitions (YAML) -> :class:`StudyDefinition`, every field checked.

A refusal is one line naming the file and the field (:class:`gcs.errors.StudyError`). The
fields are documented in ``docs/studies.md``. A setting is its profile (the study's, or its
own ``profile``) with the overrides it lists; the overrides go into the profile's YAML and the
profile is read again, so that a setting is checked by the same rules as a profile.
"""

from __future__ import annotations

import copy
import itertools
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcs.errors import GcsError, PathError, StudyError
from gcs.io.config import Profile, TrajectorySpec, load_trajectory, profile_from_dict
from gcs.io.fields import Fields, Rule
from gcs.io.paths import resolve_named
from gcs.io.rundir import RunDir
from gcs.io.yamlfile import read_yaml

__all__ = [
    "SETTING_KEYS",
    "SettingSpec",
    "StudyDefinition",
    "load_study",
    "study_from_dict",
    "MAX_PLANTS",
]

#: A setting's overrides and where they go in a profile's YAML.
SETTING_KEYS: dict[str, tuple[str, ...]] = {
    "algorithm": ("learning", "algorithm"),
    "we": ("learning", "weights", "we"),
    "wdu": ("learning", "weights", "wdu"),
    "wu": ("learning", "weights", "wu"),
    "smoother_q": ("learning", "smoother", "q"),
    "smoother_r": ("learning", "smoother", "r"),
    "smoother_p0": ("learning", "smoother", "p0"),
    "kilc_q": ("learning", "kilc", "q"),
    "kilc_r": ("learning", "kilc", "r"),
    "kilc_p0": ("learning", "kilc", "p0"),
    "max_step_m": ("learning", "limits", "max_step_m"),
    "max_deviation_m": ("learning", "limits", "max_deviation_m"),
    "repeats": ("learning", "adaptive", "repeats"),
    "noise": ("learning", "adaptive", "noise"),
    "drift_offset": ("learning", "adaptive", "drift_offset"),
    "refresh": ("learning", "adaptive", "refresh"),
    "refresh_takeback": ("learning", "adaptive", "refresh_takeback"),
    "refresh_minmax_step": ("learning", "adaptive", "refresh_minmax_step"),
    "refresh_holdout": ("learning", "adaptive", "refresh_holdout"),
    "refresh_pool_repeats": ("learning", "adaptive", "refresh_pool_repeats"),
    "refresh_anchor": ("learning", "adaptive", "refresh_anchor"),
    "refresh_min_gain_z": ("learning", "adaptive", "refresh_min_gain_z"),
    "robustness_cutoff_rad_s": ("learning", "adaptive", "robustness_cutoff_rad_s"),
    "safeguard": ("learning", "adaptive", "safeguard"),
    "safeguard_k_sigma": ("learning", "adaptive", "safeguard_k_sigma"),
    "safeguard_step": ("learning", "adaptive", "safeguard_step"),
}
#: Most plants per level (each is a simulated vehicle flying every trial of every setting).
MAX_PLANTS = 1_000_000
#: Most settings after the grid is expanded.
MAX_SETTINGS = 1000


@dataclass(frozen=True)
class SettingSpec:
    """One setting as the study file gives it.

    Parameters
    ----------
    name : str
        Label (given, or made from the profile and the overrides).
    profile : Profile
        The profile with the overrides applied.
    overrides : dict
        The overrides, for the JSON.
    """

    name: str
    profile: Profile
    overrides: dict


@dataclass(frozen=True)
class StudyDefinition:
    """A study file, read and checked.

    Parameters
    ----------
    name : str
        Study name.
    path : str
        The file.
    profile : Profile
        The study's profile: the model the plants are drawn around, the default setting.
    trajectory : TrajectorySpec
        The manoeuvre.
    seed, plants, iterations, chunk_plants, steady_trials : int
        See ``docs/studies.md``.
    uncertainty : dict
        The ``uncertainty`` section with ``floor`` resolved: keyword arguments of
        :class:`gcs.core.study.Uncertainty`.
    settings : tuple of SettingSpec
        The settings, the grid expanded.
    source : dict
        The parsed YAML as read.
    """

    name: str
    path: str
    profile: Profile
    trajectory: TrajectorySpec
    seed: int
    plants: int
    iterations: int
    chunk_plants: int
    steady_trials: int
    uncertainty: dict
    settings: tuple[SettingSpec, ...]
    source: dict


def _named(f: Fields, key: str, kind: str, default: Any = ...) -> Path:
    value = f.raw(key, default)
    if not isinstance(value, str):
        raise f.fail(key, f"must be a {kind} name or path, got {value!r}")
    base = Path(f.where).parent
    candidate = base / value
    try:
        return resolve_named(candidate if candidate.is_file() else value, kind, "")
    except PathError as exc:
        raise f.fail(key, str(exc).lstrip()) from None


def _profile(f: Fields, key: str, default: Any = ...) -> tuple[Profile, Path]:
    path = _named(f, key, "profile", default)
    try:
        return profile_from_dict(read_yaml(path, StudyError), str(path)), path
    except GcsError as exc:
        raise f.fail(key, f"{exc}") from None


def _pair(f: Fields, key: str, default: float) -> tuple[float, float]:
    value = f.raw(key, default)
    v = f.numbers(key, 2) if isinstance(value, list) else [f.number(key, default)] * 2
    if any(x < 0 for x in v):
        raise f.fail(key, f"must be >= 0, got {value!r}")
    return v[0], v[1]


def _floor_rms(f: Fields, run: Path | None, key: str) -> tuple[float, float]:
    if run is None:
        raise f.fail(key, "is 'floor': give the run directory with its floor.json in 'run'")
    path = run / RunDir.FLOOR_FILE  # a directory with the file will do: not opened as a run
    try:
        data = json.loads(path.read_text())
        rms = data["axis_rms_m"]
        out = (float(rms[0]), float(rms[1]))
    except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
        raise f.fail(key, f"is 'floor' but {path} has no readable axis_rms_m ({exc})") from None
    if not all(math.isfinite(x) and x >= 0 for x in out):
        raise f.fail(key, f"is 'floor' but {path} gives {list(out)}")
    return out


def _uncertainty(f: Fields) -> dict:
    levels = f.numbers("levels", None, [0.2])
    if any(v < 0 or v > 1 for v in levels):
        raise f.fail("levels", f"must be relative spreads in [0, 1], got {levels}")
    parameters = f.string("parameters", "modes", ("modes", "markov"))
    b = f.sub("bias", {})
    bias = (b.number("wn", 0.0), b.number("zeta", 0.0), b.number("gain", 0.0))
    b.done()
    delay = f.raw("extra_delay_s", 0.0)
    if isinstance(delay, list):
        lo, hi = f.numbers("extra_delay_s", 2)
    else:
        lo = 0.0
        hi = f.number("extra_delay_s", 0.0)
    if not 0 <= lo <= hi:
        raise f.fail("extra_delay_s", f"must be a delay >= 0 or [lo, hi], got {delay!r}")
    run_value = f.raw("run", None)
    if run_value is not None and not isinstance(run_value, str):
        raise f.fail("run", f"must be a run directory, got {run_value!r}")
    run = None if run_value is None else (Path(f.where).parent / run_value)
    if run is not None and not run.is_dir():
        raise f.fail("run", f"{run_value}: not a directory")
    out: dict[str, Any] = {
        "levels": tuple(levels),
        "parameters": parameters,
        "bias": bias,
        "extra_delay_s": (lo, hi),
        "disturbance_bandwidth_hz": f.number("disturbance_bandwidth_hz", 0.5, positive=True),
        "floor_source": None,
    }
    for key in ("noise_std_m", "disturbance_rms_m"):
        if f.raw(key, 0.0) == "floor":
            out[key] = _floor_rms(f, run, key)
            out["floor_source"] = str(run / RunDir.FLOOR_FILE)
        else:
            out[key] = _pair(f, key, 0.0)
    f.done()
    return out


def _set(doc: dict, path: tuple[str, ...], value: Any) -> None:
    for key in path[:-1]:
        nxt = doc.get(key)
        if not isinstance(nxt, dict):
            nxt = {}
            doc[key] = nxt
        doc = nxt
    doc[path[-1]] = value


def _setting_error(f: Fields, i: int, combo: dict, profile: str, message: str) -> StudyError:
    """A profile's refusal of a setting, said with the setting's own field."""
    m = re.search(r"field '([^']+)'", message)
    path = tuple(m.group(1).split(".")) if m else ()
    key = next((k for k, v in SETTING_KEYS.items() if v == path), None)
    rest = message[m.end() :].lstrip(": ") if m else message.lstrip(": ")
    grid = f" (grid {combo})" if combo else ""
    where = f"settings[{i}].{key}" if key else f"settings[{i}]"
    inner = "" if key else f" ({'.'.join(path) or 'profile'} of profile {profile})"
    return StudyError(f"{f.where}: field '{where}'{grid}{inner} {rest}")


def _setting_name(profile: Profile, overrides: dict) -> str:
    parts = [profile.name] + [f"{k}={v}" for k, v in overrides.items()]
    return " ".join(parts)


def _settings(f: Fields, study_profile: tuple[Profile, Path]) -> tuple[SettingSpec, ...]:
    entries = f.raw("settings", [{}])
    if not isinstance(entries, list) or not entries:
        raise f.fail("settings", "must be a non-empty list of settings (an empty grid)")
    grid_raw = f.raw("grid", {}) or {}
    if not isinstance(grid_raw, dict):
        raise f.fail("grid", f"must be a mapping of setting -> list of values, got {grid_raw!r}")
    for key, values in grid_raw.items():
        if key not in SETTING_KEYS:
            known = ", ".join(SETTING_KEYS)
            raise f.fail(f"grid.{key}", f"is not a known setting ({known})")
        if not isinstance(values, list) or not values:
            raise f.fail(f"grid.{key}", "must be a non-empty list of values (an empty grid)")
    combos = [dict(zip(grid_raw, c, strict=True)) for c in itertools.product(*grid_raw.values())]
    if len(entries) * len(combos) > MAX_SETTINGS:
        count = len(entries) * len(combos)
        raise f.fail("grid", f"gives {count} settings (at most {MAX_SETTINGS})")
    out: list[SettingSpec] = []
    names: set[str] = set()
    for i, entry in enumerate(entries):
        e = Fields(entry, f.where, f"settings[{i}]", StudyError)
        given_name = e.text("name")
        profile, _ = _profile(e, "profile") if e.has("profile") else study_profile
        own = {k: e.raw(k) for k in list(entry) if k in SETTING_KEYS}
        e.done()  # any other key is not a setting
        for combo in combos:
            overrides = own | combo
            doc = copy.deepcopy(profile.source)
            for key, value in overrides.items():
                _set(doc, SETTING_KEYS[key], value)
            try:
                applied = profile_from_dict(doc, "")
            except GcsError as exc:
                raise _setting_error(f, i, combo, profile.name, str(exc)) from None
            base = given_name or _setting_name(profile, own)
            name = " ".join([base] + [f"{k}={v}" for k, v in combo.items()])
            if name in names:
                raise e.fail("name", f"{name!r} names two settings")
            names.add(name)
            out.append(SettingSpec(name, applied, {"profile": profile.name} | overrides))
    return tuple(out)


def _positive_int(f: Fields, key: str, default: int, most: int) -> int:
    return f.integer(key, default, Rule(ge=1, le=most))


def study_from_dict(data: Any, where: str = "<study>") -> StudyDefinition:
    """Build a :class:`StudyDefinition` from parsed YAML.

    Parameters
    ----------
    data : dict
        The parsed study.
    where : str
        The file, for messages and for profile, trajectory and run paths relative to it.

    Returns
    -------
    StudyDefinition

    Raises
    ------
    StudyError
        One line naming the file and the field.
    """
    f = Fields(data, where, "", StudyError)
    name = f.string("name")
    f.text("description")
    study_profile = _profile(f, "profile")
    traj_path = _named(f, "trajectory", "trajectory", "eight")
    try:
        trajectory = load_trajectory(traj_path)
    except GcsError as exc:
        raise f.fail("trajectory", str(exc)) from None
    seed = f.integer("seed", 1, Rule(ge=0))
    plants = _positive_int(f, "plants", 20, MAX_PLANTS)
    iterations = _positive_int(f, "iterations", 10, 1000)
    chunk_plants = _positive_int(f, "chunk_plants", 10, MAX_PLANTS)
    steady = _positive_int(f, "steady_trials", min(3, iterations), iterations)
    uncertainty = _uncertainty(f.sub("uncertainty", {}))
    settings = _settings(f, study_profile)
    f.done()
    return StudyDefinition(
        name=name,
        path=where,
        profile=study_profile[0],
        trajectory=trajectory,
        seed=seed,
        plants=plants,
        iterations=iterations,
        chunk_plants=chunk_plants,
        steady_trials=steady,
        uncertainty=uncertainty,
        settings=settings,
        source=data,
    )


def load_study(path: str | Path) -> StudyDefinition:
    """Read and check a study file.

    Parameters
    ----------
    path : str or Path
        The study YAML.

    Returns
    -------
    StudyDefinition
    """
    return study_from_dict(read_yaml(Path(path), StudyError), str(path))
