"""Profiles and trajectory files (YAML) -> frozen configuration objects.

Every section is parsed here, once: the learning settings into the numerics' own classes, and
``flight``, ``identification`` and ``mocap`` into :mod:`gcs.io.settings`. Nothing below this
module reads a YAML mapping again.

Every refusal is one line naming the file and the field, raised as :class:`ProfileError` or
:class:`TrajectoryError` (both ``ValueError``). Unknown fields are refused too: a typo in a
safety limit must not silently fall back to a default. The reading and the messages are
:mod:`gcs.io.fields`'; the ranges of ``flight`` and ``mocap`` are declared on their dataclasses.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from gcs.core.estimators import KilcSettings, SmootherSettings
from gcs.core.frames import SYSTEM_FRAMES, mapping_for
from gcs.core.learning import NOISE_MODELS, REFRESH_NOISE, AdaptiveSettings
from gcs.core.model import DiscreteModel, from_state_space, from_transfer_function
from gcs.core.trajectory import MAX_SAMPLES, Box, EightShape
from gcs.core.trajectory_sources import PLANES, EllipseShape, SamplesShape, WaypointsShape
from gcs.core.update import UpdateWeights
from gcs.errors import GcsError, ProfileError, TrajectoryError
from gcs.io.fields import Fields, Rule
from gcs.io.mocap_source import parse_mocap_url
from gcs.io.samples_file import read_samples
from gcs.io.settings import (
    MAPPING_AXES,
    FlightSettings,
    IdentifySettings,
    MocapSettings,
)
from gcs.io.yamlfile import read_yaml

__all__ = [
    "LearningConfig",
    "Profile",
    "TrajectorySpec",
    "load_profile",
    "load_trajectory",
    "profile_from_dict",
    "mocap_settings",
    "trajectory_from_dict",
    "ALGORITHMS",
    "DEFAULT_MAX_VERTICAL_SPEED_M_S",
    "DEFAULT_MAX_VERTICAL_ACCEL_M_S2",
    "DEFAULT_MAX_YAW_RATE_DEG_S",
    "TRAJECTORY_TYPES",
]

ALGORITHMS = ("smoother", "kilc")
#: The axis sets ``learning.axes`` may name: the paper's horizontal pair, or all three.
LEARNED_AXES = {("north", "east"): (0, 1), ("north", "east", "down"): (0, 1, 2)}
#: Most repeats of trial 0 a profile may ask for (each is a flight: a battery's worth is a few).
MAX_REPEATS = 5
#: ``vehicle.max_vertical_speed_m_s`` when a profile leaves it out [m/s]: PX4's take-off speed
#: (``MPC_TKO_SPEED`` 1.5 m/s, v1.16); gcs itself moves at ``flight.transit_speed_m_s`` (1 m/s).
DEFAULT_MAX_VERTICAL_SPEED_M_S = 1.5
#: ``vehicle.max_vertical_accel_m_s2`` when a profile leaves it out [m/s^2]: the smaller of
#: PX4's vertical acceleration limits (``MPC_ACC_DOWN_MAX`` 3, ``MPC_ACC_UP_MAX`` 4, v1.16).
DEFAULT_MAX_VERTICAL_ACCEL_M_S2 = 3.0
#: ``vehicle.max_yaw_rate_deg_s`` when a profile leaves it out [deg/s]: gcs's own cautious
#: bound on the yaw a trajectory may ask for (a quarter turn a second), well inside what
#: PX4's attitude loop allows (``MC_YAWRATE_MAX``); raise it for a vehicle tuned for more.
DEFAULT_MAX_YAW_RATE_DEG_S = 90.0
#: Trajectory sources (the ``type`` of a trajectory file).
TRAJECTORY_TYPES = ("eight", "circle", "ellipse", "waypoints", "samples")
#: A trajectory's name becomes part of a run directory's name.
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
AT_LEAST_0 = Rule(ge=0)


@dataclass(frozen=True)
class LearningConfig:
    """Learning settings of a profile (Table I by default).

    Parameters
    ----------
    algorithm : str
        ``"smoother"`` (the paper's method) or ``"kilc"`` (the baseline).
    weights : UpdateWeights
        We, W_du, Wu of eq. (8).
    smoother : SmootherSettings
        Q, R, P(0) and the initial estimate of Algorithm 1.
    kilc : KilcSettings
        Q, R, P(0) of the iteration-domain Kalman filter.
    max_step_m : float or None
        Bound on the change of a setpoint from one sample to the next [m].
    max_deviation_m : float or None
        Bound on the distance of a setpoint from the reference [m].
    max_vertical_step_m, max_vertical_deviation_m : float or None
        The same bounds on the down axis when it is learned (``learning.limits``; absent:
        the horizontal ones) [m].
    axes : tuple of int
        Learned local NED axes (``learning.axes``): (0, 1) north and east (default, the
        paper's), or (0, 1, 2) with down (the profile then needs ``model_z``). Axes not
        learned are flown as the reference.
    adaptive : AdaptiveSettings or None
        Options beyond the paper (``learning.adaptive``): ``gcs learn`` and ``gcs fly`` then
        learn from every complete trial (:func:`gcs.core.learning.plan_next_trial`) and
        record every decision and every refreshed model in the run directory. None (no
        section): the paper's step on the newest trial, exactly as before the section existed.
    repeats : int
        Flights of trial 0's setpoints after the first (``learning.adaptive.repeats``,
        default 1 in the section, 0 without it): identical flights measure the vehicle's
        repeatability, the floor of learning.
    """

    algorithm: str = "smoother"
    weights: UpdateWeights = field(default_factory=UpdateWeights)
    smoother: SmootherSettings = field(default_factory=SmootherSettings)
    kilc: KilcSettings = field(default_factory=KilcSettings)
    max_step_m: float | None = None
    max_deviation_m: float | None = None
    adaptive: AdaptiveSettings | None = None
    max_vertical_step_m: float | None = None
    max_vertical_deviation_m: float | None = None
    axes: tuple[int, ...] = (0, 1)
    repeats: int = 0


@dataclass(frozen=True)
class Profile:
    """A vehicle profile: closed-loop models, learning settings, limits and arena.

    Parameters
    ----------
    name : str
        Profile name.
    t_ilc_s : float
        ILC sample time [s].
    model_x, model_y : DiscreteModel
        Closed-loop models north setpoint -> north position and east -> east.
    model_z : DiscreteModel or None
        Closed-loop model down setpoint -> down position (``model_z``; PX4's vertical loop
        differs from the horizontal one); required when ``learning.axes`` has down.
    learning : LearningConfig
        Learning settings.
    max_speed_m_s, max_accel_m_s2 : float
        Vehicle limits a trajectory must respect (horizontal) [m/s], [m/s^2].
    max_vertical_speed_m_s : float
        Vehicle's vertical speed limit, up or down [m/s] (optional in the file, default
        :data:`DEFAULT_MAX_VERTICAL_SPEED_M_S`); the live fence watches it (with
        ``max_speed_m_s``) from arming to disarming.
    max_vertical_accel_m_s2 : float
        Vertical acceleration a trajectory may ask for, up or down [m/s^2] (optional, default
        :data:`DEFAULT_MAX_VERTICAL_ACCEL_M_S2`).
    max_jerk_m_s3, max_vertical_jerk_m_s3 : float or None
        Horizontal and vertical jerk a trajectory may ask for [m/s^3] (optional; absent: not
        checked).
    max_yaw_rate_deg_s : float
        Yaw rate a trajectory's yaw may ask for [deg/s] (optional in the file, default
        :data:`DEFAULT_MAX_YAW_RATE_DEG_S`).
    arena : Box
        Flight volume, local NED [m].
    flight : FlightSettings
        The ``flight`` section: stream rate, timeouts, hover and fence limits.
    identification : IdentifySettings
        The ``identification`` section: excitation and PBSID settings of ``gcs identify``.
    mocap : MocapSettings
        The ``mocap`` section: frame mapping, forwarding, what learning measures.
    source : dict
        The parsed YAML as read, stored in run manifests.
    """

    name: str
    t_ilc_s: float
    model_x: DiscreteModel
    model_y: DiscreteModel
    learning: LearningConfig
    max_speed_m_s: float
    max_accel_m_s2: float
    arena: Box
    flight: FlightSettings = field(default_factory=FlightSettings)
    identification: IdentifySettings = field(default_factory=IdentifySettings)
    mocap: MocapSettings = field(default_factory=MocapSettings)
    source: dict = field(default_factory=dict)
    max_vertical_speed_m_s: float = DEFAULT_MAX_VERTICAL_SPEED_M_S
    max_vertical_accel_m_s2: float = DEFAULT_MAX_VERTICAL_ACCEL_M_S2
    max_jerk_m_s3: float | None = None
    max_vertical_jerk_m_s3: float | None = None
    model_z: DiscreteModel | None = None
    max_yaw_rate_deg_s: float = DEFAULT_MAX_YAW_RATE_DEG_S

    def models(self) -> tuple[DiscreteModel, DiscreteModel]:
        """The (north, east) models."""
        return self.model_x, self.model_y

    def learned_models(self) -> tuple[DiscreteModel, ...]:
        """The model of every learned axis, in the order of ``learning.axes``."""
        by_axis = (self.model_x, self.model_y, self.model_z)
        return tuple(by_axis[a] for a in self.learning.axes)  # type: ignore[misc]


def _model(f: Fields, t_ilc_s: float) -> DiscreteModel:
    try:
        if f.has("num") or f.has("den"):
            delay_s = f.number("delay_s", 0.0)
            if delay_s / t_ilc_s > MAX_SAMPLES:  # before the delay line is built
                raise f.fail("delay_s", f"is longer than the longest trial ({MAX_SAMPLES} samples)")
            model = from_transfer_function(f.numbers("num"), f.numbers("den"), delay_s, t_ilc_s)
        else:
            dt = f.number("dt_s", positive=True)
            if abs(dt - t_ilc_s) > 1e-9:
                raise f.fail("dt_s", f"is {dt:g} s but the profile's t_ilc_s is {t_ilc_s:g} s")
            model = from_state_space(
                f.matrix("A"),
                f.matrix("B"),
                f.matrix("C"),
                f.matrix("D") if f.has("D") else 0.0,
                dt,
                _delay_samples(f),
            )
    except GcsError as exc:
        if isinstance(exc, ProfileError):
            raise
        raise ProfileError(f"{f.where}: field '{f.path}': {exc}") from exc
    except ValueError as exc:
        raise ProfileError(f"{f.where}: field '{f.path}': {exc}") from exc
    f.done()
    if not model.is_stable():
        raise ProfileError(f"{f.where}: field '{f.path}': the model is not asymptotically stable")
    return model


def _delay_samples(f: Fields) -> int:
    return f.integer("delay_samples", 0, Rule(ge=0, le=MAX_SAMPLES))


def _interval(f: Fields, key: str) -> tuple[float, float]:
    lo, hi = f.numbers(key, 2)
    if lo >= hi:
        raise f.fail(key, f"must be [min, max] with min < max, got [{lo:g}, {hi:g}]")
    return lo, hi


def _learning(f: Fields) -> LearningConfig:
    w = f.sub("weights", {})
    weights = UpdateWeights(
        we=w.number("we", 1.0, positive=True),
        wdu=w.number("wdu", 0.01, rule=AT_LEAST_0),
        wu=w.number("wu", 0.0, rule=AT_LEAST_0),
    )
    w.done()
    settings = {}
    for key, cls in (("smoother", SmootherSettings), ("kilc", KilcSettings)):
        s = f.sub(key, {})
        try:
            settings[key] = cls(
                q=s.number("q", 0.1),
                r=s.number("r", 0.01),
                p0=s.number("p0", 0.1),
                d0=s.number("d0", 0.0),
            )
        except ValueError as exc:
            if isinstance(exc, GcsError):
                raise
            raise ProfileError(f"{s.where}: field '{s.path}': {exc}") from exc
        s.done()
    limits = f.sub("limits", {})
    history = f.has("adaptive")
    adaptive = f.sub("adaptive", {})
    repeats = adaptive.integer("repeats", 1 if history else 0, Rule(ge=0, le=MAX_REPEATS))
    axes = _learned_axes(f)
    if history and 2 in axes:
        raise f.fail(
            "axes", "down cannot be learned with learning.adaptive (defined on north and east)"
        )
    max_step_m = limits.optional_number("max_step_m")
    max_deviation_m = limits.optional_number("max_deviation_m")
    vertical = {}
    for key, horizontal in (("step", max_step_m), ("deviation", max_deviation_m)):
        value = limits.optional_number(f"max_vertical_{key}_m")
        vertical[key] = horizontal if value is None else value
    config = LearningConfig(
        algorithm=f.string("algorithm", "smoother", ALGORITHMS),
        weights=weights,
        smoother=settings["smoother"],
        kilc=settings["kilc"],
        max_step_m=max_step_m,
        max_deviation_m=max_deviation_m,
        adaptive=_adaptive(adaptive) if history else None,
        repeats=repeats,
        max_vertical_step_m=vertical["step"],
        max_vertical_deviation_m=vertical["deviation"],
        axes=axes,
    )
    limits.done()
    f.done()
    return config


def _learned_axes(f: Fields) -> tuple[int, ...]:
    """``learning.axes``: [north, east] (default) or [north, east, down]."""
    value = f.raw("axes", ["north", "east"])
    ok = isinstance(value, list) and all(isinstance(v, str) for v in value)
    names = tuple(value) if ok else ()
    if names not in LEARNED_AXES:
        raise f.fail("axes", f"must be [north, east] or [north, east, down], got {value!r}")
    return LEARNED_AXES[names]


def _adaptive(f: Fields) -> AdaptiveSettings:
    """``learning.adaptive``: the options beyond the paper (absent: the paper's method)."""
    d = AdaptiveSettings()
    flags = (
        "drift_offset", "refresh", "refresh_takeback", "refresh_minmax_step", "refresh_holdout",
        "refresh_pool_repeats", "refresh_anchor", "safeguard",
    )  # fmt: skip
    flag = {k: f.value(k, bool, getattr(d, k)) for k in flags}
    cutoff = f.raw("robustness_cutoff_rad_s", None)
    order = f.integer("robustness_order", d.robustness_order)
    try:
        settings = AdaptiveSettings(
            noise=f.string("noise", d.noise, NOISE_MODELS),
            drift_offset=flag["drift_offset"],
            refresh=flag["refresh"],
            refresh_min_snr=f.number("refresh_min_snr", d.refresh_min_snr),
            refresh_block_s=f.number("refresh_block_s", d.refresh_block_s, positive=True),
            refresh_noise=f.string("refresh_noise", d.refresh_noise, REFRESH_NOISE),
            refresh_max_move=None
            if f.raw("refresh_max_move", None) is None
            else f.number("refresh_max_move", positive=True),
            refresh_min_gain_z=f.number(
                "refresh_min_gain_z", d.refresh_min_gain_z, rule=Rule(ge=0)
            ),
            refresh_takeback=flag["refresh_takeback"],
            refresh_minmax_step=flag["refresh_minmax_step"],
            refresh_holdout=flag["refresh_holdout"],
            refresh_pool_repeats=flag["refresh_pool_repeats"],
            refresh_anchor=flag["refresh_anchor"],
            robustness_cutoff_rad_s=cutoff
            if cutoff is None or cutoff == "auto"
            else f.number("robustness_cutoff_rad_s", positive=True),
            robustness_order=order,
            safeguard=flag["safeguard"],
            safeguard_k_sigma=f.number("safeguard_k_sigma", d.safeguard_k_sigma),
            safeguard_step=f.number("safeguard_step", d.safeguard_step, positive=True),
            floor_z=f.number("floor_z", d.floor_z, positive=True),
        )
    except ValueError as exc:
        if isinstance(exc, GcsError):
            raise
        raise ProfileError(f"{f.where}: field '{f.path}': {exc}") from exc
    f.done()
    return settings


def profile_from_dict(data: Any, where: str = "<profile>") -> Profile:
    """Build a :class:`Profile` from parsed YAML.

    Parameters
    ----------
    data : dict
        The parsed profile.
    where : str
        Name of the source (file path) used in error messages.

    Returns
    -------
    Profile
    """
    f = Fields(data, where, "", ProfileError)
    t_ilc_s = f.number("t_ilc_s", positive=True)
    model_x = _model(f.sub("model"), t_ilc_s)
    model_y = _model(f.sub("model_y"), t_ilc_s) if f.has("model_y") else model_x
    model_z = _model(f.sub("model_z"), t_ilc_s) if f.has("model_z") else None
    vehicle = f.sub("vehicle")
    arena = f.sub("arena")
    box = Box(_interval(arena, "north_m"), _interval(arena, "east_m"), _interval(arena, "down_m"))
    learning = _learning(f.sub("learning", {}))
    if 2 in learning.axes and model_z is None:
        raise f.fail("model_z", "is required when learning.axes has down (the vertical loop)")
    profile = Profile(
        name=f.string("name"),
        t_ilc_s=t_ilc_s,
        model_x=model_x,
        model_y=model_y,
        learning=learning,
        model_z=model_z,
        max_speed_m_s=vehicle.number("max_speed_m_s", positive=True),
        max_accel_m_s2=vehicle.number("max_accel_m_s2", positive=True),
        max_vertical_speed_m_s=vehicle.number(
            "max_vertical_speed_m_s", DEFAULT_MAX_VERTICAL_SPEED_M_S, positive=True
        ),
        max_vertical_accel_m_s2=vehicle.number(
            "max_vertical_accel_m_s2", DEFAULT_MAX_VERTICAL_ACCEL_M_S2, positive=True
        ),
        max_jerk_m_s3=vehicle.optional_number("max_jerk_m_s3"),
        max_vertical_jerk_m_s3=vehicle.optional_number("max_vertical_jerk_m_s3"),
        max_yaw_rate_deg_s=vehicle.number(
            "max_yaw_rate_deg_s", DEFAULT_MAX_YAW_RATE_DEG_S, positive=True
        ),
        arena=box,
        flight=_flight(f.sub("flight", {}), t_ilc_s),
        identification=_identification(f.sub("identification", {}), t_ilc_s),
        mocap=mocap_settings(f.raw("mocap", None), where),
        source=data,
    )
    f.text("description")
    vehicle.done()
    arena.done()
    f.done()
    return profile


def load_profile(path: str | Path) -> Profile:
    """Read and validate a profile YAML file.

    Parameters
    ----------
    path : str or Path
        The profile file.

    Returns
    -------
    Profile
    """
    return profile_from_dict(read_yaml(Path(path), ProfileError), str(path))


#: A trajectory source's parameters.
Shape = EightShape | EllipseShape | WaypointsShape | SamplesShape


@dataclass(frozen=True)
class TrajectorySpec:
    """A trajectory file: its name, its source's parameters and the parsed YAML.

    Parameters
    ----------
    name : str
        Trajectory name.
    shape : EightShape, EllipseShape, WaypointsShape, SamplesShape or None
        The source's parameters (``gcs.core.trajectory_sources.sample_reference`` samples
        them); None for a sequence that is not sampled from a source (identification
        excitation), or a ``samples`` trajectory read from a run's manifest (its file is not
        read there: the run's ``reference.csv`` holds what was sampled from it).
    source : dict
        The parsed YAML as read, stored in run manifests.
    """

    name: str
    shape: Shape | None
    source: dict


def trajectory_from_dict(
    data: Any, where: str = "<trajectory>", base_dir: Path | None = None
) -> TrajectorySpec:
    """Build a :class:`TrajectorySpec` from parsed YAML.

    Parameters
    ----------
    data : dict
        The parsed trajectory.
    where : str
        Name of the source (file path) used in error messages.
    base_dir : Path or None
        Directory a ``samples`` trajectory's ``file`` is relative to (the trajectory file's);
        None: the file is not read (``shape`` is None).

    Returns
    -------
    TrajectorySpec
    """
    f = Fields(data, where, "", TrajectoryError)
    kind = f.string("type", "eight", TRAJECTORY_TYPES)
    try:
        shape = _SOURCES[kind](f, base_dir)
    except TrajectoryError as exc:
        if str(exc).startswith(where):
            raise
        raise TrajectoryError(f"{where}: {exc}") from exc
    name = f.string("name")
    if not _NAME.match(name):
        raise f.fail(
            "name",
            f"must be 1 to 64 letters, digits, '.', '_' or '-' (it names run directories), "
            f"got {name!r}",
        )
    f.text("description")
    f.done()
    return TrajectorySpec(name=name, shape=shape, source=data)


def _yaw(f: Fields) -> float | None:
    return None if f.raw("yaw_deg", None) is None else f.number("yaw_deg")


def _eight(f: Fields, base_dir: Path | None) -> EightShape:
    defaults = EightShape()
    return EightShape(
        center_ned_m=tuple(f.numbers("center_ned_m", 3, list(defaults.center_ned_m))),
        amplitude_north_m=f.number("amplitude_north_m", positive=True),
        amplitude_east_m=f.number("amplitude_east_m", positive=True),
        period_s=f.number("period_s", positive=True),
        loops=f.integer("loops", defaults.loops),
        ramp_s=f.number("ramp_s", defaults.ramp_s),
        hover_s=f.number("hover_s", defaults.hover_s),
        yaw_deg=_yaw(f),
    )


def _ellipse(f: Fields, base_dir: Path | None) -> EllipseShape:
    if f.data.get("type") == "circle":
        radius = f.number("radius_m", positive=True)
        radii = (radius, radius)
    else:
        a, b = f.numbers("radii_m", 2)
        if not (a > 0 and b > 0):
            raise f.fail("radii_m", f"must be two numbers > 0, got [{a:g}, {b:g}]")
        radii = (a, b)
    plane = f.raw("plane", "horizontal")
    if isinstance(plane, list):
        plane = tuple(f.numbers("plane", 3))
        if all(v == 0 for v in plane):
            raise f.fail("plane", "must be a normal vector, not [0, 0, 0]")
    elif plane not in PLANES:
        raise f.fail(
            "plane", f"must be one of {', '.join(PLANES)} or a normal vector, got {plane!r}"
        )
    d = {x.name: x.default for x in fields(EllipseShape)}
    return EllipseShape(
        center_ned_m=tuple(f.numbers("center_ned_m", 3)),
        radii_m=radii,
        period_s=f.number("period_s", positive=True),
        plane=plane,
        start_angle_deg=f.number("start_angle_deg", d["start_angle_deg"]),
        loops=f.integer("loops", d["loops"]),
        ramp_s=f.number("ramp_s", d["ramp_s"]),
        hover_s=f.number("hover_s", d["hover_s"]),
        climb_m=f.number("climb_m", d["climb_m"]),
        yaw_deg=_yaw(f),
    )


def _waypoints(f: Fields, base_dir: Path | None) -> WaypointsShape:
    raw = f.raw("points_ned_m")
    if not isinstance(raw, list) or len(raw) < 3:
        raise f.fail("points_ned_m", "must be a list of at least three [north, east, down]")
    points = []
    for i, point in enumerate(raw):
        ok = isinstance(point, list) and len(point) == 3
        if ok:
            ok = all(
                not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
                for v in point
            )
        if not ok:
            raise f.fail(f"points_ned_m[{i}]", f"must be three finite numbers, got {point!r}")
        points.append(tuple(float(v) for v in point))
    has_times = f.has("times_s")
    if has_times == f.has("speed_m_s"):
        raise f.fail("times_s", "or 'speed_m_s' must be given (one of them, not both)")
    times = tuple(f.numbers("times_s")) if has_times else None
    speed = None if has_times else f.number("speed_m_s", positive=True)
    try:
        return WaypointsShape(
            points_ned_m=tuple(points),
            times_s=times,
            speed_m_s=speed,
            hover_s=f.number("hover_s", 1.0),
            yaw_deg=_yaw(f),
        )
    except TrajectoryError as exc:
        key = "times_s" if str(exc).startswith("times_s") else "points_ned_m"
        raise f.fail(key, f"is refused: {exc}") from None


def _samples(f: Fields, base_dir: Path | None) -> SamplesShape | None:
    name = f.string("file")
    hover_s = f.number("hover_s", 1.0, rule=AT_LEAST_0)
    yaw_deg = _yaw(f)
    if base_dir is None:
        return None
    path = Path(name) if Path(name).is_absolute() else base_dir / name
    data = read_samples(path)
    yaw = None if data.yaw_deg is None else np.radians(data.yaw_deg)
    if yaw_deg is not None:
        if yaw is not None:
            raise f.fail("yaw_deg", f"and the yaw_deg column of {path} both give the yaw")
        yaw = np.full(data.t_s.size, np.radians(yaw_deg))
    return SamplesShape(data.t_s, data.pos_ned_m, yaw, hover_s, str(path))


_SOURCES = {
    "eight": _eight,
    "circle": _ellipse,
    "ellipse": _ellipse,
    "waypoints": _waypoints,
    "samples": _samples,
}


#: Files taken as a ``samples`` trajectory themselves (``--trajectory lemniscate.csv``).
SAMPLES_SUFFIXES = (".csv", ".npy", ".npz")


def samples_trajectory(path: Path) -> dict:
    """The trajectory a samples file given on its own stands for.

    ``--trajectory lemniscate.csv`` is read as if wrapped in ``{name: lemniscate, type:
    samples, file: lemniscate.csv}`` (the defaults of a ``samples`` trajectory otherwise).

    Parameters
    ----------
    path : Path
        A ``.csv``, ``.npy`` or ``.npz`` file (docs/trajectories.md).

    Returns
    -------
    dict
        The trajectory mapping, as a run's manifest keeps it.
    """
    name = re.sub(r"[^A-Za-z0-9._-]", "-", path.stem).lstrip("._-")[:64] or "samples"
    return {"name": name, "type": "samples", "file": path.name}


def load_trajectory(path: str | Path) -> TrajectorySpec:
    """Read and validate a trajectory YAML file (and a ``samples`` trajectory's file).

    A ``.csv``, ``.npy`` or ``.npz`` file is a ``samples`` trajectory of its own
    (:func:`samples_trajectory`).

    Parameters
    ----------
    path : str or Path
        The trajectory file.

    Returns
    -------
    TrajectorySpec
    """
    path = Path(path)
    if path.suffix.lower() in SAMPLES_SUFFIXES:
        return trajectory_from_dict(samples_trajectory(path), str(path), path.parent)
    return trajectory_from_dict(read_yaml(path, TrajectoryError), str(path), path.parent)


def _flight(f: Fields, t_ilc_s: float) -> FlightSettings:
    """The ``flight`` section by :class:`FlightSettings`' declared ranges, and its stream rate
    against the profile's sample time."""
    settings = f.read(FlightSettings)
    try:
        settings.sends_per_sample(t_ilc_s)
    except ProfileError as exc:  # names the field itself
        raise ProfileError(f"{f.where}: {exc}") from None
    return settings


def _identification(f: Fields, t_ilc_s: float) -> IdentifySettings:
    """The ``identification`` section by :class:`IdentifySettings`' declared ranges, and the
    rules between its fields: the band of its excitation (and not the other's) below Nyquist,
    a duration within a trial, the PBSID windows and order."""

    def read(name: str, required: bool = False) -> Any:
        return f.field(IdentifySettings, name, required=required)

    excitation = read("excitation")
    nyquist = 0.5 / t_ilc_s
    other = ("f_min_hz", "f_max_hz") if excitation == "prbs" else ("bandwidth_hz",)
    for key in other:
        if f.has(key):
            raise f.fail(key, f"does not apply to excitation {excitation}")
    if excitation == "prbs":
        bandwidth = read("bandwidth_hz")
        if bandwidth > nyquist:
            raise f.fail("bandwidth_hz", f"must be <= Nyquist {nyquist:g} Hz, got {bandwidth:g}")
        band = {"bandwidth_hz": bandwidth}
    else:
        f_min, f_max = read("f_min_hz", True), read("f_max_hz", True)
        if not f_min < f_max:
            raise f.fail("f_min_hz", f"must be in [0, f_max_hz = {f_max:g}), got {f_min:g}")
        if f_max >= nyquist:
            raise f.fail("f_max_hz", f"must be below Nyquist {nyquist:g} Hz, got {f_max:g}")
        band = {"bandwidth_hz": None, "f_min_hz": f_min, "f_max_hz": f_max}
    duration = read("duration_s")
    if duration / t_ilc_s > MAX_SAMPLES:
        raise f.fail("duration_s", f"gives more than {MAX_SAMPLES} samples of {t_ilc_s:g} s")
    past, future, order = read("past"), read("future"), read("order")
    if future > past:
        raise f.fail("future", f"must be in [2, past = {past}], got {future}")
    if order is not None and order >= future:
        raise f.fail("order", f"must be in [1, future - 1 = {future - 1}], got {order}")
    windows = {"past": past, "future": future, "order": order, "duration_s": duration}
    return f.read(IdentifySettings, excitation=excitation, **band, **windows)


def mocap_settings(section: Any, where: str) -> MocapSettings:
    """Check a profile's ``mocap`` section (unknown keys, types, ranges, mirrored mapping).

    Parameters
    ----------
    section : dict
        The parsed section (empty: defaults).
    where : str
        The profile's file, for messages.

    Returns
    -------
    MocapSettings

    Raises
    ------
    ProfileError
        One line naming the field.
    """
    f = Fields({} if section is None else section, where, "mocap", ProfileError)
    url = f.text("url")
    if url is not None:
        try:
            parse_mocap_url(url)
        except ProfileError as exc:
            raise f.fail("url", f"is not usable: {exc}") from None
    frame = f.raw("frame", None)
    if frame is not None and (not isinstance(frame, str) or frame.lower() not in SYSTEM_FRAMES):
        raise f.fail("frame", f"must be one of {', '.join(SYSTEM_FRAMES)}, got {frame!r}")
    if not f.value("right_handed", bool, True):
        raise f.fail(
            "right_handed",
            "is false: a left-handed mapping mirrors an axis of the room (OptiTrack, Vicon, "
            "Qualisys and VRPN all stream right-handed axes) and the vehicle would fly the "
            "wrong way on it; set up_axis and north_axis instead",
        )
    overrides = {k: f.raw(k) for k in MAPPING_AXES if f.has(k)}
    for key, axis in overrides.items():
        if not isinstance(axis, str):
            raise f.fail(key, f"must be one of +x -x +y -y +z -z, got {axis!r}")
    frame = None if frame is None else frame.lower()
    settings = f.read(MocapSettings, url=url, frame=frame, overrides=overrides)
    try:  # the axes: each a signed axis, north and forward horizontal
        system = parse_mocap_url(url).system if url is not None else "optitrack"
        base = mapping_for(settings.frame or system)
        dataclasses.replace(base, **overrides)
    except ValueError as exc:
        raise ProfileError(f"{where}: field 'mocap': {exc}") from None
    return settings
