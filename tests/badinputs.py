"""The bad-input catalogue: every command, walked with bad paths, files and values.

Each case builds its input in a fresh workspace (a copy of the packaged profile and trajectory,
a synthetic learning run with two complete trials, a synthetic identification run), runs one
command in-process from the workspace, and records what happened: the exit code, the output,
and whether anything in the workspace was created, changed or moved. Used by
``tests/test_bad_inputs.py`` (every case must exit 2 with one line and change nothing) and by
``tools/bad_inputs.py`` (which writes ``docs/bad-inputs.md`` from the same catalogue).

Flights and identifications use ``--connect`` to a closed loopback port: a case whose
validation wrongly passed would try to connect, create its run and print more than one line,
and fail.
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from cli_runner import invoke as gcs_invoke
from synthetic import ROOT, fly_synthetic, make_run

from gcs.core.model import from_transfer_function, simulate
from gcs.io.config import profile_from_dict
from gcs.io.records import TrialRecord, TrialStatus
from gcs.io.rundir import RunDir

UNREACHABLE = "udpout://127.0.0.1:9"  # the discard port: nothing answers there
DELETE = object()


# --------------------------------------------------------------------------- the workspace


def _set(data: Any, dotted: str, value: Any) -> Any:
    data = copy.deepcopy(data)
    *parents, last = dotted.split(".")
    node = data
    for key in parents:
        node = node[key]
    if value is DELETE:
        del node[last]
    else:
        node[last] = value
    return data


def _identification_run(root: Path) -> Path:
    """A synthetic identification run (two 30 s PRBS experiments of a known loop)."""
    from gcs.app.identify import create_identification_run
    from gcs.app.identify_plan import plan_experiments

    data = yaml.safe_load((ROOT / "profiles" / "antx.yaml").read_text())
    data["identification"]["duration_s"] = 30.0
    profile = profile_from_dict(data, "antx")
    settings = profile.identification
    exps = plan_experiments(settings, profile.t_ilc_s, "both", profile.arena)
    run = create_identification_run(root, profile, settings, exps, run_id="ident")
    truth = from_transfer_function([2.56], [1.0, 1.76, 2.56], 0.25, profile.t_ilc_s)
    rng = np.random.default_rng(0)
    for j, sp in enumerate(exps.setpoints_ned_m):
        n, c = sp.shape[0], exps.center_ned_m
        rows = np.vstack([sp, sp[-1]])
        pos = np.tile(c, (n + 1, 1))
        for a in (0, 1):
            pos[1:, a] += simulate(truth, sp[:, a] - c[a]) + rng.normal(0, 0.003, n)
        record = TrialRecord(
            t_s=np.arange(n + 1) * profile.t_ilc_s,
            ref_ned_m=rows,
            sp_ned_m=rows,
            pos_ned_m=pos,
            vel_ned_m_s=np.gradient(pos, profile.t_ilc_s, axis=0),
            sp_sent_s=np.append(np.arange(n) * profile.t_ilc_s, np.nan),
            interpolated=np.zeros(n + 1, dtype=bool),
        )
        run.write_trial(j, record, TrialStatus(j, True))
    return run.path


def _learning_run(root: Path) -> Path:
    """A synthetic learning run: trials 0 and 1 complete, setpoints of trial 2 learned."""
    from gcs.app.learn import learn_run

    run = make_run(root, trials=2)
    learn_run(run)
    return run.path


def _adaptive_run(root: Path) -> Path:
    """A synthetic run with antx-adaptive.yaml flying one repeat (``repeats: 1``, the
    catalogue's trial plan): trials 0, 1 (the repeat of 0), 2 and 3 complete, learned with
    history after each (model-002.yaml refreshed), setpoints of 4."""
    from synthetic import make_adaptive_run

    run = make_adaptive_run(root, trials=4, repeats=1)
    assert (run.path / "model-002.yaml").exists()  # the catalogue damages it
    return run.path


class Templates:
    """Runs built once and copied into every workspace that needs one."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._built: dict[str, Path] = {}

    def get(self, name: str) -> Path:
        if name not in self._built:
            where = self.root / name
            where.mkdir(parents=True)
            build = {
                "learning": _learning_run, "ident": _identification_run,
                "adaptive": _adaptive_run,
            }[name]  # fmt: skip
            self._built[name] = build(where)
        return self._built[name]


@dataclass
class Workspace:
    """One case's directory; everything a case builds or names lives in it."""

    path: Path
    templates: Templates
    cleanups: list[Callable[[], None]] = field(default_factory=list)

    def file(self, name: str, text: str | bytes) -> Path:
        p = self.path / name
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            p.write_text(text)
        return p

    def profile(
        self, dotted: str | None = None, value: Any = None, base: str = "antx.yaml", **more: Any
    ) -> Path:
        data = yaml.safe_load((ROOT / "profiles" / base).read_text())
        if dotted is not None:
            data = _set(data, dotted, value)
        for key, v in more.items():
            data = _set(data, key.replace("__", "."), v)
        return self.file("profile.yaml", yaml.safe_dump(data))

    def trajectory(self, dotted: str | None = None, value: Any = None) -> Path:
        data = yaml.safe_load((ROOT / "trajectories" / "eight.yaml").read_text())
        if dotted is not None:
            data = _set(data, dotted, value)
        return self.file("trajectory.yaml", yaml.safe_dump(data))

    def run(self, kind: str = "learning") -> Path:
        source = self.templates.get(kind)
        target = self.path / source.name
        shutil.copytree(source, target, symlinks=True)
        return target

    def read_only(self, path: Path) -> Path:
        """Make ``path`` unwritable (also for root: the immutable attribute)."""
        if os.geteuid() == 0:
            subprocess.run(["chattr", "+i", str(path)], check=True, capture_output=True)
            self.cleanups.append(lambda: subprocess.run(["chattr", "-i", str(path)], check=True))
        else:
            mode = path.stat().st_mode
            path.chmod(0o555)
            self.cleanups.append(lambda: path.chmod(mode))
        return path


def _edit_json(path: Path, key: str, value: Any) -> None:
    data = json.loads(path.read_text())
    data = _set(data, key, value)
    path.write_text(json.dumps(data))


def _edit_csv(path: Path, row: int, column: str, value: str) -> None:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[row + 1].split(",")
    cells[header.index(column)] = value
    lines[row + 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


def _truncate(path: Path, keep: float = 0.5) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


def _swap(a: Path, b: Path) -> None:
    tmp = a.with_name(".swap")
    a.rename(tmp)
    b.rename(a)
    tmp.rename(b)


# ------------------------------------------------------------------------------ the cases


@dataclass(frozen=True)
class Case:
    """One bad input: its class, the command, what is wrong, how to build it, the message."""

    klass: str
    command: str
    what: str
    build: Callable[[Workspace], list[str]]
    expect: str


def _fly(ws: Workspace, *args: str, profile: Path | None = None, traj: Path | None = None):
    argv = ["fly", "--connect", UNREACHABLE, "--iter", "1"]
    if profile is not None:
        argv += ["--profile", str(profile)]
    if traj is not None:
        argv += ["--trajectory", str(traj)]
    return [*argv, *args]


def _profile_cases() -> Iterator[Case]:
    k = "profile file"
    yield Case(
        k, "fly", "missing file", lambda ws: _fly(ws, profile=ws.path / "no.yaml"), "no such file"
    )
    yield Case(
        k,
        "fly",
        "unknown packaged name",
        lambda ws: _fly(ws, "--profile", "antz"),
        "); did you mean 'antx'?",  # after the list of packaged profiles
    )
    yield Case(k, "fly", "a directory", lambda ws: _fly(ws, profile=ws.path), "is a directory")
    yield Case(
        k,
        "fly",
        "malformed YAML",
        lambda ws: _fly(ws, profile=ws.file("p.yaml", "name: antx\nmodel: [1, 2\n")),
        "malformed YAML",
    )
    yield Case(
        k,
        "fly",
        "empty file",
        lambda ws: _fly(ws, profile=ws.file("p.yaml", "")),
        "must be a mapping",
    )
    yield Case(
        k,
        "fly",
        "not UTF-8",
        lambda ws: _fly(ws, profile=ws.file("p.yaml", b"name: \xff\xfe\n")),
        "not UTF-8",
    )
    yield Case(
        k,
        "fly",
        "a list at the top",
        lambda ws: _fly(ws, profile=ws.file("p.yaml", "- 1\n- 2\n")),
        "must be a mapping",
    )
    yield Case(
        k,
        "fly",
        "truncated in the middle",
        lambda ws: _fly(
            ws, profile=ws.file("p.yaml", (ROOT / "profiles" / "antx.yaml").read_text()[:700])
        ),
        "field",
    )
    k = "profile field: missing"
    for dotted in ("t_ilc_s", "name", "model", "vehicle", "arena.down_m", "model.den"):
        yield Case(
            k, "fly", dotted, lambda ws, d=dotted: _fly(ws, profile=ws.profile(d, DELETE)), dotted
        )
    k = "profile field: wrong type"
    for dotted, value in (
        ("t_ilc_s", "fast"),
        ("vehicle.max_speed_m_s", [3]),
        ("name", 5),
        ("learning.weights.wdu", "0.01"),
        ("arena.north_m", "wide"),
        ("flight.stream_rate_hz", "60"),
        ("description", 7),
        ("learning.limits.max_step_m", True),
    ):
        yield Case(
            k,
            "fly",
            f"{dotted}: {value!r}",
            lambda ws, d=dotted, v=value: _fly(ws, profile=ws.profile(d, v)),
            dotted,
        )
    k = "profile field: section not a mapping"
    for dotted, value in (
        ("flight", 5),
        ("identification", [1, 2]),
        ("learning", 3),
        ("vehicle", "fast"),
        ("arena", 1),
        ("model", 7),
        ("learning.weights", [1]),
        ("model_y", "x"),
    ):
        yield Case(
            k,
            "fly",
            f"{dotted}: {value!r}",
            lambda ws, d=dotted, v=value: _fly(ws, profile=ws.profile(d, v)),
            dotted,
        )
    k = "profile field: NaN, infinite or out of range"
    for dotted, value, expect in (
        ("t_ilc_s", float("nan"), "t_ilc_s"),
        ("t_ilc_s", 0.0, "t_ilc_s"),
        ("vehicle.max_accel_m_s2", float("inf"), "vehicle.max_accel_m_s2"),
        ("vehicle.max_speed_m_s", -1.0, "vehicle.max_speed_m_s"),
        ("vehicle.max_vertical_speed_m_s", 0.0, "vehicle.max_vertical_speed_m_s"),
        ("vehicle.max_vertical_accel_m_s2", -3.0, "vehicle.max_vertical_accel_m_s2"),
        ("vehicle.max_jerk_m_s3", 0.0, "vehicle.max_jerk_m_s3"),
        ("vehicle.max_vertical_jerk_m_s3", "high", "vehicle.max_vertical_jerk_m_s3"),
        ("vehicle.max_yaw_rate_deg_s", 0.0, "vehicle.max_yaw_rate_deg_s"),
        ("model.delay_s", -0.1, "model"),
        ("model.den", [2.225073858507e-311, 0.0, 0.0], "model"),  # dividing by it overflows
        ("learning.weights.we", 0.0, "learning.weights.we"),
        ("arena.north_m", [3.0, -3.0], "arena.north_m"),
        ("arena.east_m", [0.0, 0.0], "arena.east_m"),
        ("learning.smoother.r", float("nan"), "learning.smoother.r"),
        ("learning.algorithm", "smooth", "learning.algorithm"),
    ):
        yield Case(
            k,
            "fly",
            f"{dotted}: {value!r}",
            lambda ws, d=dotted, v=value: _fly(ws, profile=ws.profile(d, v)),
            expect,
        )
    k = "profile field: learned axes and the vertical model"
    for dotted, value, expect, base in (
        ("learning.axes", ["north", "east", "down"], "model_z", "antx.yaml"),
        ("learning.axes", ["up"], "learning.axes", "antx.yaml"),
        ("learning.axes", "north", "learning.axes", "antx.yaml"),
        ("learning.axes", ["east", "north"], "learning.axes", "antx.yaml"),
        ("model_z", 7, "model_z", "antx-3d.yaml"),
        ("model_z.C", "tall", "model_z.C", "antx-3d.yaml"),
        ("model_z.dt_s", 0.02, "model_z.dt_s", "antx-3d.yaml"),
        ("learning.limits.max_vertical_step_m", 0.0, "max_vertical_step_m", "antx-3d.yaml"),
        ("learning.limits.max_vertical_deviation_m", "far", "max_vertical_deviation_m",
         "antx-3d.yaml"),
        ("learning.adaptive", {}, "learning.axes", "antx-3d.yaml"),
        ("identification.vertical_amplitude_m", -0.3, "vertical_amplitude_m", "antx.yaml"),
    ):  # fmt: skip
        yield Case(
            k,
            "fly",
            f"{base}: {dotted}: {value!r}",
            lambda ws, d=dotted, v=value, b=base: _fly(ws, profile=ws.profile(d, v, b)),
            expect,
        )
    k = "profile field: unknown (a typo)"
    for dotted, meant in (
        ("arean", "arena"),
        ("learning.smoother.qq", "q"),
        ("vehicle.max_sped_m_s", "max_speed_m_s"),
        ("flight.stream_rate", "stream_rate_hz"),
    ):
        yield Case(
            k,
            "fly",
            dotted,
            lambda ws, d=dotted: _fly(ws, profile=ws.profile(d, 1.0)),
            f"'{dotted}' is not a known field; did you mean '{meant}'?",
        )
    yield Case(
        "trajectory file",
        "fly",
        "unknown field (a typo): start_angel_deg",
        lambda ws: _fly(ws, traj=_traj(ws, _set(CIRCLE, "start_angel_deg", 10.0))),
        "field 'start_angel_deg' is not a known field; did you mean 'start_angle_deg'?",
    )
    k = "profile: flight settings"
    for dotted, value, expect in (
        ("flight.stream_rate_hz", 50, "integer multiple"),
        ("flight.stream_rate_hz", 1, "stream_rate_hz"),
        ("flight.connect_timeout_s", -1, "connect_timeout_s"),
        ("flight.yaw_deg", float("nan"), "yaw_deg"),
        ("flight.min_battery_pct", 120, "min_battery_pct"),
        ("flight.hover_measure_s", 0.5, "hover_measure_s"),
        ("flight.fence_margin_m", 0.0, "fence_margin_m"),
        ("flight.fence_speed_factor", 0.5, "fence_speed_factor"),
        ("flight.paused_trial_retries", -1, "paused_trial_retries"),
        ("flight.paused_trial_retries", 1.5, "paused_trial_retries"),
    ):
        yield Case(
            k,
            "fly",
            f"{dotted}: {value!r}",
            lambda ws, d=dotted, v=value: _fly(ws, profile=ws.profile(d, v)),
            expect,
        )
    k = "profile: model"
    yield Case(
        k,
        "fly",
        "unstable model",
        lambda ws: _fly(ws, profile=ws.profile("model.den", [1.0, -0.5, 2.0])),
        "not asymptotically stable",
    )
    yield Case(
        k,
        "fly",
        "state space at another dt_s",
        lambda ws: _fly(
            ws,
            profile=ws.profile("model", {"A": [[0.9]], "B": [[0.1]], "C": [[1.0]], "dt_s": 0.02}),
        ),
        "dt_s",
    )
    k = "profile: limits that admit no learning"
    yield Case(
        k,
        "fly",
        "max_step_m 0.01 m and max_deviation_m 0.05 m",
        lambda ws: _fly(
            ws, profile=ws.profile("learning.limits", {"max_step_m": 0.01, "max_deviation_m": 0.05})
        ),
        "learning cannot start",
    )
    yield Case(
        k,
        "fly",
        "arena smaller than the eight",
        lambda ws: _fly(ws, profile=ws.profile("arena.north_m", [-1.0, 1.0])),
        "arena",
    )


def _trajectory_cases() -> Iterator[Case]:
    k = "trajectory file"
    yield Case(
        k, "fly", "missing file", lambda ws: _fly(ws, traj=ws.path / "no.yaml"), "no such file"
    )
    yield Case(
        k,
        "fly",
        "unknown packaged name",
        lambda ws: _fly(ws, "--trajectory", "eigth"),
        "); did you mean 'eight'?",  # after the list of packaged trajectories
    )
    yield Case(
        k,
        "fly",
        "malformed YAML",
        lambda ws: _fly(ws, traj=ws.file("t.yaml", "name: [\n")),
        "malformed YAML",
    )
    yield Case(
        k, "fly", "empty file", lambda ws: _fly(ws, traj=ws.file("t.yaml", "")), "must be a mapping"
    )
    k = "trajectory field"
    for dotted, value, expect in (
        ("name", "a/b", "name"),
        ("name", "", "name"),
        ("name", 8, "name"),
        ("name", "../up", "name"),
        ("type", "spiral", "type"),
        ("amplitude_north_m", "big", "amplitude_north_m"),
        ("amplitude_east_m", -1.0, "amplitude_east_m"),
        ("period_s", float("nan"), "period_s"),
        ("loops", 0, "loops"),
        ("loops", 1.5, "loops"),
        ("ramp_s", 20.0, "ramp_s"),
        ("center_ned_m", [0, 0], "center_ned_m"),
        ("hover_s", -1.0, "hover_s"),
        ("speed", 3.0, "speed"),
        ("period_s", DELETE, "period_s"),
    ):
        yield Case(
            k,
            "fly",
            f"{dotted}: {value if value is not DELETE else 'missing'!r}",
            lambda ws, d=dotted, v=value: _fly(ws, traj=ws.trajectory(d, v)),
            expect,
        )
    k = "trajectory beyond the vehicle or the arena"
    for dotted, value, expect in (
        ("ramp_s", 0.0, "acceleration on the flown grid"),
        ("period_s", 2.0, "exceeds the vehicle limit"),
        ("center_ned_m", [2.5, 0.0, -1.5], "leaves the arena"),
        ("center_ned_m", [0.0, 0.0, 1.0], "leaves the arena"),
    ):
        yield Case(
            k,
            "fly",
            f"{dotted}: {value!r}",
            lambda ws, d=dotted, v=value: _fly(ws, traj=ws.trajectory(d, v)),
            expect,
        )


CIRCLE = {
    "name": "c", "type": "circle", "center_ned_m": [0.0, 0.0, -1.5], "radius_m": 1.0,
    "period_s": 5.0,
}  # fmt: skip
WAYPOINTS = {
    "name": "w", "type": "waypoints", "speed_m_s": 1.0,
    "points_ned_m": [[0.0, 0.0, -1.5], [1.5, 0.0, -1.5], [1.5, 1.5, -2.0], [0.0, 0.0, -1.5]],
}  # fmt: skip


def _samples_csv(dt: float = 0.1) -> str:
    """A planner's file: 0.5 m north and back in 40 samples of ``dt``, at 1.5 m altitude."""
    return "t_s,north_m,east_m,down_m\n" + "".join(
        f"{dt * i:.3f},{0.5 * (1 - np.cos(2 * np.pi * i / 40)):.6f},0.0,-1.5\n" for i in range(41)
    )


SAMPLES_CSV = _samples_csv()


def _samples_csv_yaw(deg_per_sample: float) -> str:
    """:data:`SAMPLES_CSV` with a yaw column turning ``deg_per_sample`` each 0.1 s sample."""
    lines = SAMPLES_CSV.splitlines()
    return (
        "\n".join(
            [lines[0] + ",yaw_deg"]
            + [f"{line},{deg_per_sample * i:g}" for i, line in enumerate(lines[1:])]
        )
        + "\n"
    )


def _traj(ws: Workspace, base: dict, dotted: str | None = None, value: Any = None) -> Path:
    data = base if dotted is None else _set(base, dotted, value)
    return ws.file("trajectory.yaml", yaml.safe_dump(data))


def _samples(ws: Workspace, text: str | bytes, name: str = "p.csv", **more: Any) -> Path:
    ws.file(name, text)
    return _traj(ws, {"name": "s", "type": "samples", "file": name, **more})


def _csv_edit(line: int, cell: int, value: str) -> str:
    lines = SAMPLES_CSV.splitlines()
    cells = lines[line].split(",")
    cells[cell] = value
    lines[line] = ",".join(cells)
    return "\n".join(lines) + "\n"


def _source_cases() -> Iterator[Case]:
    k = "trajectory source: circle and ellipse"
    for dotted, value, expect in (
        ("radius_m", DELETE, "radius_m"),
        ("radius_m", -1.0, "radius_m"),
        ("plane", "sideways", "plane"),
        ("plane", [0, 0, 0], "plane"),
        ("plane", [1, 0], "plane"),
        ("loops", 0, "loops"),
        ("climb_m", 2.0, "above the ceiling"),
        ("center_ned_m", [2.5, 0.0, -1.5], "leaves the arena"),
        ("period_s", 2.5, "exceeds the vehicle limit"),
        ("yaw_deg", "north", "yaw_deg"),
    ):
        yield Case(
            k,
            "fly",
            f"circle {dotted}: {value if value is not DELETE else 'missing'!r}",
            lambda ws, d=dotted, v=value: _fly(ws, traj=_traj(ws, CIRCLE, d, v)),
            expect,
        )
    ellipse = dict(CIRCLE, type="ellipse")
    del ellipse["radius_m"]
    yield Case(
        k,
        "fly",
        "ellipse radii_m: one number",
        lambda ws: _fly(ws, traj=_traj(ws, ellipse, "radii_m", [1.0])),
        "radii_m",
    )
    k = "trajectory source: waypoints"
    pts = WAYPOINTS["points_ned_m"]
    for what, dotted, value, expect in (
        ("last point not the first", "points_ned_m", pts[:-1], "last waypoint"),
        ("a point of two numbers", "points_ned_m", [pts[0], [1.0, 0.0], pts[0]], "points_ned_m[1]"),
        ("two points", "points_ned_m", [pts[0], pts[0]], "points_ned_m"),
        ("repeated point", "points_ned_m", [pts[0], pts[1], pts[1], pts[0]], "the same point"),
        ("times_s and speed_m_s", "times_s", [0.0, 2.0, 4.0, 6.0], "times_s"),
        ("point below the floor", "points_ned_m", [pts[0], [1.0, 0.0, 0.5], pts[0]], "floor"),
        ("too fast", "speed_m_s", 4.0, "exceeds the vehicle limit"),
    ):
        yield Case(
            k,
            "fly",
            f"waypoints: {what}",
            lambda ws, d=dotted, v=value: _fly(ws, traj=_traj(ws, WAYPOINTS, d, v)),
            expect,
        )
    climb = dict(WAYPOINTS, speed_m_s=2.5, points_ned_m=[pts[0], [0.2, 0.0, -2.9], pts[0]])
    yield Case(
        k,
        "fly",
        "waypoints: climbing too fast",
        lambda ws: _fly(ws, traj=_traj(ws, climb)),
        "vertical speed",
    )
    timed = {key: v for key, v in WAYPOINTS.items() if key != "speed_m_s"}
    for what, times, expect in (
        ("times_s not increasing", [0.0, 3.0, 2.0, 6.0], "not after"),
        ("times_s not from 0", [1.0, 3.0, 4.0, 6.0], "start at 0"),
        ("times_s one per point missing", [0.0, 3.0, 6.0], "times_s"),
        ("two too close in time", [0.0, 3.0, 3.02, 6.0], "less than one ILC sample"),
    ):
        yield Case(
            k,
            "fly",
            f"waypoints: {what}",
            lambda ws, t=times: _fly(ws, traj=_traj(ws, timed, "times_s", t)),
            expect,
        )
    yield Case(
        k,
        "fly",
        "waypoints: neither times_s nor speed_m_s",
        lambda ws: _fly(ws, traj=_traj(ws, WAYPOINTS, "speed_m_s", DELETE)),
        "speed_m_s",
    )
    k = "trajectory source: samples file"
    header = "t_s,north_m,east_m,down_m\n"
    for what, text, expect in (
        ("a NaN", _csv_edit(5, 1, "nan"), "line 6: column 'north_m' is nan"),
        ("a value not a number", _csv_edit(5, 2, "x"), "line 6: column 'east_m' is not a number"),
        ("times not sorted", _csv_edit(5, 0, "0.1"), "line 6: t_s 0.1 s goes back"),
        ("a repeated time", _csv_edit(5, 0, "0.3"), "line 6: t_s 0.3 s repeats"),
        ("a missing column", SAMPLES_CSV.replace(",-1.5", "").replace(",down_m", ""), "down_m"),
        ("an unknown column", SAMPLES_CSV.replace("down_m", "down_m,speed").replace(
            "-1.5\n", "-1.5,1\n"), "column 'speed' is not a known column"),
        ("a short line", _csv_edit(5, 3, "0\n1"), "values"),
        ("header only", header, "at least 2"),
        ("empty", "", "empty"),
        ("end not at the start", SAMPLES_CSV + "4.1,1.0,0.0,-1.5\n", "where it began"),
        ("beyond the arena", SAMPLES_CSV.replace(",0.0,", ",3.5,"), "leaves the arena"),
        ("too fast", _samples_csv(0.01), "exceeds the vehicle limit"),
        ("a yaw turning faster than the vehicle", _samples_csv_yaw(20.0),
            "exceeds the vehicle limit 90 deg/s (vehicle.max_yaw_rate_deg_s"),
        ("a NaN yaw", _samples_csv_yaw(1.0).replace(",3\n", ",nan\n"),
            "line 5: column 'yaw_deg' is nan"),
    ):  # fmt: skip
        yield Case(
            k, "fly", f"samples CSV: {what}", lambda ws, x=text: _fly(ws, traj=_samples(ws, x)),
            expect,
        )  # fmt: skip
    for what, name, text, expect in (
        ("wrong columns", "lemniscate.csv", "t_s,x,y\n0,0,0\n1,0,0\n",
            "lemniscate.csv: line 1: column 'north_m' is missing"),
        ("an .npz without t_s", "lemniscate.npz", _npz(north_m=np.zeros(5)), "t_s"),
    ):  # fmt: skip
        yield Case(
            k, "fly", f"a samples file given as --trajectory: {what}",
            lambda ws, n=name, x=text: _fly(ws, traj=ws.file(n, x)), expect,
        )  # fmt: skip
    yield Case(
        k,
        "fly",
        "samples file missing",
        lambda ws: _fly(ws, traj=_traj(ws, {"name": "s", "type": "samples", "file": "no.csv"})),
        "no.csv",
    )
    yield Case(
        k,
        "fly",
        "samples file of another kind",
        lambda ws: _fly(ws, traj=_samples(ws, SAMPLES_CSV, "p.txt")),
        ".csv, .npy or .npz",
    )
    yield Case(
        k,
        "fly",
        "samples .npy of three columns",
        lambda ws: _fly(ws, traj=_samples(ws, _npy(np.zeros((5, 3))), "p.npy")),
        "4 columns",
    )
    yield Case(
        k,
        "fly",
        "samples .npy not NumPy",
        lambda ws: _fly(ws, traj=_samples(ws, b"not numpy", "p.npy")),
        "not a readable NumPy file",
    )
    yield Case(
        k,
        "fly",
        "samples yaw_deg field and column",
        lambda ws: _fly(
            ws,
            traj=_samples(ws, SAMPLES_CSV.replace("down_m", "down_m,yaw_deg").replace(
                "-1.5\n", "-1.5,0\n"), yaw_deg=10.0),
        ),
        "yaw_deg",
    )  # fmt: skip


def _npz(**arrays: np.ndarray) -> bytes:
    import io

    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def _npy(array: np.ndarray) -> bytes:
    import io

    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def _learning_run_damage() -> list[tuple[str, Callable[[Path], None], str]]:
    """(what, damage to a learning run, expected message): trials 0, 1 complete."""
    return [
        ("manifest.json missing", lambda r: (r / "manifest.json").unlink(), "manifest.json"),
        ("manifest.json truncated", lambda r: _truncate(r / "manifest.json"), "malformed JSON"),
        ("manifest.json a list", lambda r: (r / "manifest.json").write_text("[1]"), "JSON object"),
        (
            "manifest n_samples a string",
            lambda r: _edit_json(r / "manifest.json", "n_samples", "x"),
            "n_samples",
        ),
        (
            "manifest t_ilc_s negative",
            lambda r: _edit_json(r / "manifest.json", "t_ilc_s", -0.05),
            "t_ilc_s",
        ),
        (
            "manifest algorithm unknown",
            lambda r: _edit_json(r / "manifest.json", "algorithm", "ilc"),
            "algorithm",
        ),
        (
            "manifest profile a list",
            lambda r: _edit_json(r / "manifest.json", "profile", [1]),
            "profile",
        ),
        (
            "manifest profile field wrong type",
            lambda r: _edit_json(r / "manifest.json", "profile.t_ilc_s", "x"),
            "t_ilc_s",
        ),
        (
            "trial-001.json names trial 0",
            lambda r: _edit_json(r / "trial-001.json", "trial", 0),
            "as the file's name says",
        ),
        (
            "trial-001.json status unknown",
            lambda r: _edit_json(r / "trial-001.json", "status", "done"),
            "status",
        ),
        (
            "trial-001.json not JSON",
            lambda r: (r / "trial-001.json").write_text("{"),
            "malformed trial status",
        ),
        (
            "trial-001.json epos_m a string",
            lambda r: _edit_json(r / "trial-001.json", "epos_m", "x"),
            "epos_m",
        ),
        ("trial-001.csv truncated", lambda r: _truncate(r / "trial-001.csv"), "trial-001.csv"),
        (
            "trial-001.csv NaN position",
            lambda r: _edit_csv(r / "trial-001.csv", 9, "pos_east_m", "nan"),
            "NaN",
        ),
        (
            "trial-001.csv not a number",
            lambda r: _edit_csv(r / "trial-001.csv", 9, "pos_east_m", "abc"),
            "trial-001.csv",
        ),
        (
            "trial-001.csv wrong time grid",
            lambda r: _edit_csv(r / "trial-001.csv", 3, "t_s", "0.2"),
            "t_ilc_s",
        ),
        ("trial-001.csv missing", lambda r: (r / "trial-001.csv").unlink(), "trial-001.csv"),
        (
            "trial CSVs swapped",
            lambda r: _swap(r / "trial-000.csv", r / "trial-001.csv"),
            "do not belong together",
        ),
        (
            "setpoints-001.csv missing",
            lambda r: (r / "setpoints-001.csv").unlink(),
            "setpoints-001.csv",
        ),
        ("reference.csv truncated", lambda r: _truncate(r / "reference.csv"), "reference.csv"),
    ]


def _edit_yaml(path: Path, dotted: str, value: Any) -> None:
    path.write_text(yaml.safe_dump(_set(yaml.safe_load(path.read_text()), dotted, value)))


def _adaptive_run_damage() -> list[tuple[str, Callable[[Path], None], str]]:
    """(what, damage to a run learned with history, expected message): trials 0-3 complete."""
    return [
        (
            "learn-002.json names trial 1",
            lambda r: _edit_json(r / "learn-002.json", "trial", 1),
            "as the file's name says",
        ),
        (
            "learn-002.json truncated",
            lambda r: _truncate(r / "learn-002.json"),
            "malformed learning record",
        ),
        ("learn-002.json missing", lambda r: (r / "learn-002.json").unlink(), "learn-002.json"),
        (
            "learn-002.json without its model",
            lambda r: _edit_json(r / "learn-002.json", "model_file", None),
            "must name the refreshed model",
        ),
        (
            "model-002.yaml holds another model",
            lambda r: _edit_yaml(r / "model-002.yaml", "model.C", [[1.5, 0.0]]),
            "is not the one learn-002.json records",
        ),
        ("model-002.yaml missing", lambda r: (r / "model-002.yaml").unlink(), "model-002.yaml"),
        (
            "model-002.yaml not a profile",
            lambda r: (r / "model-002.yaml").write_text("model: 5\n"),
            "model-002.yaml",
        ),
        (
            "a trial of the history missing",
            lambda r: [(r / f"trial-001.{e}").unlink() for e in ("json", "csv")],
            "trial 1 is not complete",
        ),
        (
            "the repeat's setpoints changed",
            lambda r: _edit_csv(r / "setpoints-001.csv", 5, "sp_north_m", "0.123"),
            "do not belong together",
        ),
    ]


def _adaptive_cases() -> Iterator[Case]:
    k = "run directory: learning with history"
    for what, damage, expect in _adaptive_run_damage():

        def learn(ws: Workspace, d=damage) -> list[str]:
            run = ws.run("adaptive")
            (run / "setpoints-004.csv").unlink()  # learning from trial 3 reads the history
            d(run)
            return ["learn", str(run)]

        def resume(ws: Workspace, d=damage) -> list[str]:
            run = ws.run("adaptive")
            d(run)
            return ["fly", "--connect", UNREACHABLE, "--resume", str(run)]

        yield Case(k, "learn", what, learn, expect)
        yield Case(k, "fly", what, resume, expect)

    def floor_changed(ws: Workspace) -> list[str]:
        run = ws.run("adaptive")
        _edit_json(run / "floor.json", "epos_m", 0.5)
        return ["learn", str(run)]

    yield Case(k, "learn", "floor.json changed", floor_changed, "never rewritten")

    def record_damaged(ws: Workspace) -> list[str]:
        run = ws.run("adaptive")
        _edit_json(run / "learn-001.json", "decision.converged", "yes")
        return ["report", str(run)]

    yield Case(k, "report", "learn-001.json field of the wrong type", record_damaged,
               "decision.converged")  # fmt: skip
    k = "options: fly --until-converged"
    yield Case(
        k,
        "fly",
        "a profile without learning.adaptive",
        lambda ws: _fly(ws, "--until-converged", profile=ws.profile()),
        "no learning.adaptive section",
    )
    yield Case(
        k,
        "fly",
        "learning.adaptive.repeats 0",
        lambda ws: _fly(
            ws,
            "--until-converged",
            profile=ws.profile("learning.adaptive.repeats", 0, base="antx-adaptive.yaml"),
        ),  # fmt: skip
        "repeats to 0",
    )
    yield Case(
        k,
        "fly",
        "resuming a run of the paper's method",
        lambda ws: [
            "fly",
            "--connect",
            UNREACHABLE,
            "--resume",
            str(ws.run()),
            "--until-converged",
        ],  # fmt: skip
        "no learning.adaptive section",
    )
    k = "profile field: learning.adaptive.repeats"
    for value in (-1, 6, "one", 1.5, True):
        yield Case(
            k,
            "fly",
            f"learning.adaptive.repeats {value!r}",
            lambda ws, v=value: _fly(
                ws, profile=ws.profile("learning.adaptive.repeats", v, base="antx-adaptive.yaml")
            ),
            "learning.adaptive.repeats",
        )
    k = "profile field: learning.adaptive.refresh_noise"
    for value in ("pink", 1, None):
        yield Case(
            k,
            "fly",
            f"learning.adaptive.refresh_noise {value!r}",
            lambda ws, v=value: _fly(
                ws,
                profile=ws.profile("learning.adaptive.refresh_noise", v, base="antx-adaptive.yaml"),
            ),
            "learning.adaptive.refresh_noise",
        )

    # the options that are on or off, each given a word and a number; the numbers out of range
    fields = (
        ("refresh_takeback", ("yes", 1)), ("refresh_minmax_step", ("on", 0)),
        ("refresh_holdout", ("true", 1)), ("refresh_pool_repeats", ("no", 0)),
        ("refresh_anchor", ("yes", 1)),
        ("refresh_max_move", (0, -0.5, "far", float("nan"))),
        ("refresh_min_gain_z", (-1.645, "strict", float("inf"))),
    )  # fmt: skip
    for name, values in fields:
        field = f"learning.adaptive.{name}"
        for value in values:
            yield Case(
                f"profile field: {field}",
                "fly",
                f"{field} {value!r}",
                lambda ws, f=field, v=value: _fly(
                    ws, profile=ws.profile(f, v, base="antx-adaptive.yaml")
                ),
                field,
            )


def _run_cases() -> Iterator[Case]:
    k = "run directory: learn"
    yield Case(
        k,
        "learn",
        "not a directory",
        lambda ws: ["learn", str(ws.path / "nope")],
        "not a run directory",
    )
    for what, damage, expect in _learning_run_damage():

        def build(ws: Workspace, d=damage) -> list[str]:
            run = ws.run()
            d(run)
            return ["learn", str(run)]

        yield Case(k, "learn", what, build, expect)
    yield Case(
        "run directory: kind and algorithm",
        "learn",
        "an identification run",
        lambda ws: ["learn", str(ws.run("ident"))],
        "not a learning run",
    )

    def learned_differently(ws: Workspace) -> list[str]:
        run = ws.run()
        _edit_csv(run / "setpoints-002.csv", 5, "sp_north_m", "0.123")
        return ["learn", str(run)]

    yield Case(
        "run directory: rewriting recorded data",
        "learn",
        "setpoints-002.csv exists with other content",
        learned_differently,
        "never rewritten",
    )

    def read_only(ws: Workspace) -> list[str]:
        run = ws.run()
        (run / "setpoints-002.csv").unlink()
        (run / "estimate-001.csv").unlink()
        ws.read_only(run)
        return ["learn", str(run)]

    yield Case(
        "run directory: read-only", "learn", "read-only run directory", read_only, "not writable"
    )
    k = "run directory: report"
    for what, damage, expect in _learning_run_damage()[:12]:

        def build(ws: Workspace, d=damage) -> list[str]:
            run = ws.run()
            d(run)
            return ["report", str(run)]

        yield Case(k, "report", what, build, expect)

    def no_trial_0(ws: Workspace) -> list[str]:
        run = ws.run()
        (run / "trial-000.json").unlink()
        return ["report", str(run)]

    def incomplete_trial_0(ws: Workspace) -> list[str]:
        run = ws.run()
        _edit_json(run / "trial-000.json", "status", "incomplete")
        return ["report", str(run)]

    def epos0_zero(ws: Workspace) -> list[str]:
        run = ws.run()
        lines = (run / "trial-000.csv").read_text().splitlines()
        header = lines[0].split(",")
        out = [lines[0]]
        for line in lines[1:]:
            cells = line.split(",")
            for axis in ("north", "east", "down"):
                cells[header.index(f"pos_{axis}_m")] = cells[header.index(f"ref_{axis}_m")]
            out.append(",".join(cells))
        (run / "trial-000.csv").write_text("\n".join(out) + "\n")
        return ["report", str(run)]

    k = "run directory: percentages without trial 0"
    yield Case(k, "report", "trial-000.json missing", no_trial_0, "trial 0 is missing")
    yield Case(k, "report", "trial 0 incomplete", incomplete_trial_0, "trial 0 is incomplete")
    yield Case(k, "report", "e_pos,0 = 0", epos0_zero, "e_pos,0 = 0")


def _resume_cases() -> Iterator[Case]:
    k = "run directory: fly --resume"

    def resume(ws: Workspace, damage: Callable[[Path], None] | None = None, *extra: str):
        run = ws.run()
        if damage is not None:
            damage(run)
        return ["fly", "--connect", UNREACHABLE, "--resume", str(run), *extra]

    yield Case(
        k,
        "fly",
        "an identification run",
        lambda ws: ["fly", "--connect", UNREACHABLE, "--resume", str(ws.run("ident"))],
        "not a learning run",
    )
    yield Case(
        k,
        "fly",
        "next setpoints missing",
        lambda ws: resume(ws, lambda r: (r / "setpoints-002.csv").unlink()),
        "gcs learn",
    )
    yield Case(
        k,
        "fly",
        "next setpoints outside the arena",
        lambda ws: resume(
            ws, lambda r: _edit_csv(r / "setpoints-002.csv", 40, "sp_north_m", "9.0")
        ),
        "outside the arena",
    )
    yield Case(
        k,
        "fly",
        "next setpoints jump beyond max_step_m",
        lambda ws: resume(ws, lambda r: _edit_csv(r / "setpoints-002.csv", 40, "sp_east_m", "1.9")),
        "max_step_m",
    )
    yield Case(
        k,
        "fly",
        "a different --profile",
        lambda ws: resume(ws, None, "--profile", str(ws.profile("vehicle.max_speed_m_s", 2.9))),
        "vehicle.max_speed_m_s",
    )
    yield Case(
        k,
        "fly",
        "a different --trajectory",
        lambda ws: resume(ws, None, "--trajectory", "eight"),
        "differs",
    )
    yield Case(
        k,
        "fly",
        "another --algorithm",
        lambda ws: resume(ws, None, "--algorithm", "kilc"),
        "learns with 'smoother'",
    )
    yield Case(
        k,
        "fly",
        "--resume and --run",
        lambda ws: resume(ws, None, "--run", str(ws.path / "new")),
        "at most one",
    )

    k_again = "options: fly --again"
    yield Case(
        k_again, "fly", "--again without --resume", lambda ws: _fly(ws, "--again", "0"),
        "give it with --resume",
    )  # fmt: skip
    yield Case(
        k_again, "fly", "--again of a trial that was not flown",
        lambda ws: resume(ws, None, "--again", "5"), "not a complete trial",
    )  # fmt: skip
    yield Case(
        k_again, "fly", "--again of a negative trial", lambda ws: resume(ws, None, "--again", "-1"),
        "--again",
    )  # fmt: skip

    def read_only(ws: Workspace) -> list[str]:
        run = ws.run()
        ws.read_only(run)
        return ["fly", "--connect", UNREACHABLE, "--resume", str(run)]

    yield Case(
        "run directory: read-only", "fly", "read-only run to resume", read_only, "not writable"
    )
    for what, damage, expect in _learning_run_damage()[:9]:
        yield Case(k, "fly", what, lambda ws, d=damage: resume(ws, d), expect)


def _identify_cases() -> Iterator[Case]:
    k = "run directory: identify --from-log"

    def from_log(ws: Workspace, damage=None, *extra: str) -> list[str]:
        run = ws.run("ident")
        if damage is not None:
            damage(run)
        return ["identify", "--from-log", str(run), *extra]

    yield Case(
        k,
        "identify",
        "a learning run",
        lambda ws: ["identify", "--from-log", str(ws.run())],
        "not an identification run",
    )
    yield Case(
        k,
        "identify",
        "trial-001.json missing",
        lambda ws: from_log(ws, lambda r: (r / "trial-001.json").unlink()),
        "missing",
    )
    yield Case(
        k,
        "identify",
        "trial-000.csv NaN",
        lambda ws: from_log(ws, lambda r: _edit_csv(r / "trial-000.csv", 30, "pos_north_m", "nan")),
        "NaN",
    )
    yield Case(
        k,
        "identify",
        "trial CSVs swapped",
        lambda ws: from_log(ws, lambda r: _swap(r / "trial-000.csv", r / "trial-001.csv")),
        "do not belong together",
    )
    yield Case(
        k,
        "identify",
        "manifest trajectory not an excitation",
        lambda ws: from_log(
            ws, lambda r: _edit_json(r / "manifest.json", "trajectory.type", "eight")
        ),
        "trajectory.type",
    )
    yield Case(
        k, "identify", "axis z not excited", lambda ws: from_log(ws, None, "--axis", "z"),
        "axis z was not excited",
    )  # fmt: skip
    yield Case(
        k, "identify", "no such axis", lambda ws: from_log(ws, None, "--axis", "w"), "--axis"
    )
    yield Case(
        k,
        "identify",
        "identification settings wrong type",
        lambda ws: from_log(
            ws, None, "--profile", str(ws.profile("identification.past", "twenty"))
        ),
        "identification.past",
    )
    k = "output path: identify"
    yield Case(
        k,
        "identify",
        "--out is a directory",
        lambda ws: from_log(ws, None, "--out", str(ws.path)),
        "is a directory",
    )
    yield Case(
        k,
        "identify",
        "--out under a file",
        lambda ws: from_log(ws, None, "--out", str(ws.file("f.txt", "x") / "p.yaml")),
        "is a file",
    )
    yield Case(
        k,
        "identify",
        "--plot is a file",
        lambda ws: from_log(ws, None, "--plot", str(ws.file("f.png", "x"))),
        "is a file",
    )
    yield Case(
        k,
        "identify",
        "--out is a recorded file of another run",
        lambda ws: from_log(ws, None, "--out", str(ws.run() / "manifest.json")),
        "run directory",
    )
    k = "flight options: identify"
    idf = ["identify", "--connect", UNREACHABLE]
    yield Case(
        k, "identify", "--run exists", lambda ws: [*idf, "--run", str(ws.run())], "exists already"
    )
    yield Case(
        k,
        "identify",
        "--logs is a file",
        lambda ws: [*idf, "--logs", str(ws.file("logs", "x"))],
        "is a file",
    )
    yield Case(
        k,
        "identify",
        "excitation leaves the arena",
        lambda ws: [*idf, "--profile", str(ws.profile("identification.amplitude_m", 5.0))],
        "arena",
    )
    yield Case(
        k,
        "identify",
        "vertical excitation leaves the arena",
        lambda ws: [
            *idf,
            "--axis",
            "z",
            "--profile",
            str(ws.profile("identification.vertical_amplitude_m", 2.0)),
        ],  # fmt: skip
        "vertical_amplitude_m",
    )
    yield Case(
        k,
        "identify",
        "experiments too short",
        lambda ws: [*idf, "--profile", str(ws.profile("identification.duration_s", 2.0))],
        "too short",
    )
    yield Case(
        k,
        "identify",
        "flight section not a mapping",
        lambda ws: [*idf, "--profile", str(ws.profile("flight", 3))],
        "flight",
    )
    yield Case(
        k,
        "identify",
        "bad connection URL",
        lambda ws: ["identify", "--connect", "http://x"],
        "connection URL",
    )
    yield Case(
        k,
        "identify",
        "--mock and --from-log",
        lambda ws: ["identify", "--mock", "--from-log", str(ws.path)],
        "exactly one",
    )
    yield Case(
        k,
        "identify",
        "--mock-config malformed",
        lambda ws: ["identify", "--mock", "--mock-config", str(ws.file("m.yaml", "physics: [\n"))],
        "malformed YAML",
    )


def _output_cases() -> Iterator[Case]:
    k = "output path: report"

    def report(ws: Workspace, *extra: str) -> list[str]:
        return ["report", str(ws.run()), *extra]

    yield Case(
        k,
        "report",
        "--plot is a file",
        lambda ws: report(ws, "--plot", str(ws.file("f", "x"))),
        "is a file",
    )
    yield Case(
        k,
        "report",
        "--plot under a file",
        lambda ws: report(ws, "--plot", str(ws.file("f", "x") / "d")),
        "is a file",
    )
    yield Case(
        k,
        "report",
        "--html is a directory",
        lambda ws: report(ws, "--html", str(ws.path)),
        "is a directory",
    )
    yield Case(
        k,
        "report",
        "--html under a file",
        lambda ws: report(ws, "--html", str(ws.file("f", "x") / "r.html")),
        "is a file",
    )
    yield Case(
        k,
        "report",
        "--html onto the run's manifest",
        lambda ws: ["report", str(r := ws.run()), "--html", str(r / "manifest.json")],
        "run directory",
    )
    yield Case(
        k,
        "report",
        "--html onto a learning record of the run",
        lambda ws: ["report", str(r := ws.run()), "--html", str(r / "learn-001.json")],
        "run directory",
    )
    k = "options: report"
    yield Case(
        k,
        "report",
        "--iterations not numbers",
        lambda ws: report(ws, "--iterations", "a,b"),
        "--iterations",
    )
    yield Case(
        k,
        "report",
        "--iterations of a trial not flown",
        lambda ws: report(ws, "--iterations", "0,7"),
        "trial 7",
    )
    yield Case(
        k,
        "report",
        "--iterations negative",
        lambda ws: report(ws, "--iterations", "-1"),
        "--iterations",
    )
    k = "output path: report exports"
    yield Case(
        k,
        "report",
        "--csv in a read-only directory",
        lambda ws: report(ws, "--csv", str(ws.read_only(ws.file("ro/x", "").parent) / "t.csv")),
        "not writable",
    )
    yield Case(
        k,
        "report",
        "--csv is a directory",
        lambda ws: report(ws, "--csv", str(ws.path)),
        "is a directory",
    )
    yield Case(
        k,
        "report",
        "--csv not a .csv",
        lambda ws: report(ws, "--csv", str(ws.path / "table.txt")),
        "must end in .csv",
    )
    yield Case(
        k,
        "report",
        "--export-setpoints in a read-only directory",
        lambda ws: report(
            ws, "--export-setpoints", str(ws.read_only(ws.file("ro/x", "").parent) / "s.csv")
        ),
        "not writable",
    )
    yield Case(
        k,
        "report",
        "--export-setpoints not a .csv",
        lambda ws: report(ws, "--export-setpoints", str(ws.path / "s.yaml")),
        "must end in .csv",
    )
    yield Case(
        k,
        "report",
        "--export-setpoints of an identification run",
        lambda ws: ["report", str(ws.run("ident")), "--export-setpoints", str(ws.path / "s.csv")],
        "identification run",
    )
    yield Case(
        k,
        "report",
        "--format not a figure format",
        lambda ws: report(ws, "--plot", str(ws.path / "p"), "--format", "jpeg"),
        "--format jpeg",
    )
    k = "options: report of several runs"

    def second(ws: Workspace) -> str:
        """A second copy of the learning run, beside the first."""
        target = ws.path / "second" / "run"
        shutil.copytree(ws.templates.get("learning"), target, symlinks=True)
        return str(target)

    yield Case(
        k,
        "report",
        "--html with two runs",
        lambda ws: [*report(ws), second(ws), "--html", str(ws.path / "r.html")],
        "--html: reports one run",
    )
    yield Case(
        k,
        "report",
        "--export-setpoints with two runs",
        lambda ws: [*report(ws), second(ws), "--export-setpoints", str(ws.path / "s.csv")],
        "--export-setpoints: reports one run",
    )
    yield Case(
        k,
        "report",
        "compared with an identification run",
        lambda ws: [*report(ws), str(ws.run("ident"))],
        "only learning runs are compared",
    )
    yield Case(
        k,
        "report",
        "compared with a missing run",
        lambda ws: [*report(ws), str(ws.path / "no-such-run")],
        "no-such-run",
    )
    k = "output path: montecarlo"
    mc = ["montecarlo", "--plants", "2", "--repeats", "1", "--levels", "0.05"]
    yield Case(
        k,
        "montecarlo",
        "--json is a directory",
        lambda ws: [*mc, "--json", str(ws.path)],
        "is a directory",
    )
    yield Case(
        k,
        "montecarlo",
        "--json under a file",
        lambda ws: [*mc, "--json", str(ws.file("f", "x") / "mc.json")],
        "is a file",
    )
    k = "options: montecarlo"
    for args, expect in (
        (["--iterations", "5"], "--iterations"),
        (["--levels", "abc"], "--levels"),
        (["--levels", ","], "--levels"),
        (["--levels", "nan"], "--levels"),
        (["--levels", "-0.1"], "--levels"),
        (["--plants", "1"], "--plants"),
        (["--samples", "5"], "--samples"),
        (["--repeats", "0"], "--repeats"),
    ):
        yield Case(k, "montecarlo", " ".join(args), lambda ws, a=args: ["montecarlo", *a], expect)
    k = "output path: fly"
    yield Case(
        k, "fly", "--run exists", lambda ws: _fly(ws, "--run", str(ws.run())), "exists already"
    )
    yield Case(
        k,
        "fly",
        "--run under a file",
        lambda ws: _fly(ws, "--run", str(ws.file("f", "x") / "run")),
        "is a file",
    )
    yield Case(
        k,
        "fly",
        "--logs is a file",
        lambda ws: _fly(ws, "--logs", str(ws.file("f", "x"))),
        "is a file",
    )

    def read_only_logs(ws: Workspace) -> list[str]:
        (ws.path / "ro").mkdir()
        return _fly(ws, "--logs", str(ws.read_only(ws.path / "ro")))

    yield Case(
        "run directory: read-only", "fly", "--logs read-only", read_only_logs, "not writable"
    )
    k = "options: fly"
    for args, expect in (
        (["--connect", UNREACHABLE, "--iter", "0"], "--iter"),
        (["--connect", UNREACHABLE, "--algorithm", "ilc"], "--algorithm"),
        (["--mock", "--connect", UNREACHABLE], "exactly one"),
        (["--connect", "http://x:1"], "connection URL"),
        (["--connect", "udpin://0.0.0.0:99999"], "connection URL"),
        (["--connect", "udpin://0.0.0.0"], "connection URL"),
    ):
        yield Case(k, "fly", " ".join(args), lambda ws, a=args: ["fly", *a], expect)

    yield Case(k, "fly", "neither --mock nor --connect", lambda ws: ["fly"], "exactly one")
    yield Case(
        k,
        "fly",
        "--mock-config malformed",
        lambda ws: ["fly", "--mock", "--mock-config", str(ws.file("m.yaml", "physics: [\n"))],
        "malformed YAML",
    )
    yield Case(
        k,
        "fly",
        "--mock-config unknown field",
        lambda ws: ["fly", "--mock", "--mock-config", str(ws.file("m.yaml", "physic: {}\n"))],
        "physic",
    )
    k = "options and paths: mock"
    for args, expect in (
        (["--port", "70000"], "--port"),
        (["--loss", "2"], "--loss"),
        (["--dropout", "abc"], "--dropout"),
        (["--clock-rate", "0"], "--clock-rate"),
    ):
        yield Case(k, "mock", " ".join(args), lambda ws, a=args: ["mock", *a], expect)
    yield Case(
        k, "mock", "--config missing", lambda ws: ["mock", "--config", "nope.yaml"], "nope.yaml"
    )
    yield Case(
        k,
        "mock",
        "--config malformed",
        lambda ws: ["mock", "--config", str(ws.file("m.yaml", "physics: [\n"))],
        "malformed YAML",
    )
    for text, expect in (
        ("controller: {thrust_xy_margin: 1.0}\n", "controller.thrust_xy_margin' must be in [0, 1)"),
        ("controller: {takeoff_ramp_s: -3}\n", "controller.takeoff_ramp_s' must be >= 0"),
        ("physics: {thrust_min_g: 1.2}\n", "physics.thrust_min_g' must be in [0, 1)"),
    ):
        yield Case(
            k,
            "mock",
            f"--config {text.strip()}",
            lambda ws, t=text: ["mock", "--config", str(ws.file("m.yaml", t))],
            expect,
        )
    yield Case(
        k,
        "mock",
        "--stats-out is a directory",
        lambda ws: ["mock", "--stats-out", str(ws.path)],
        "is a directory",
    )
    k = "options: learn"
    yield Case(
        k,
        "learn",
        "another --algorithm",
        lambda ws: ["learn", str(ws.run()), "--algorithm", "kilc"],
        "learns with",
    )
    yield Case(
        k,
        "learn",
        "a different --profile",
        lambda ws: [
            "learn",
            str(ws.run()),
            "--profile",
            str(ws.profile("learning.weights.wdu", 0.02)),
        ],
        "learning.weights.wdu",
    )
    yield Case(k, "learn", "no run directory given", lambda ws: ["learn"], "run_dir")


def _mocap_cases() -> Iterator[Case]:
    k = "motion capture (--mocap, the profile's mocap section)"
    for section, what, expect in (
        ({"right_handed": False}, "a mirrored (left-handed) mapping", "mocap.right_handed"),
        ({"frame": "motive"}, "an unknown frame convention", "mocap.frame"),
        ({"north_axis": "+y"}, "north along Motive's up axis", "north_axis"),
        ({"message": "pose"}, "an unknown message", "mocap.message"),
        ({"measurement": "truth"}, "an unknown measurement", "mocap.measurement"),
        ({"position_std_m": 0.0}, "a zero position standard deviation", "position_std_m"),
        ({"max_age_s": 0.0}, "a zero stale limit", "mocap.max_age_s"),
        ({"forward": "yes"}, "forward not true or false", "mocap.forward"),
        ({"url": "optitrack://motive.local/drone"}, "a host name for OptiTrack", "IPv4"),
        ({"colour": 1}, "an unknown field", "mocap.colour"),
    ):
        yield Case(
            k,
            "fly",
            f"mocap: {section!r} ({what})",
            lambda ws, v=section: _fly(
                ws, "--mocap", "optitrack://127.0.0.1/drone", profile=ws.profile("mocap", v)
            ),  # fmt: skip
            expect,
        )
    for url, what, expect in (
        ("natnet://127.0.0.1/drone", "an unknown system", "scheme must be one of"),
        ("optitrack://127.0.0.1", "no rigid body", "rigid body name is missing"),
        ("optitrack://127.0.0.1:99999/drone", "a port out of range", "bad port"),
        ("vicon://10.0.0.5/cf1?iface=1", "an unknown option", "unknown option"),
        ("mock", "the mock's arena without --mock", "needs --mock"),
    ):
        yield Case(k, "fly", f"--mocap {url} ({what})", lambda ws, u=url: _fly(ws, "--mocap", u),
                   expect)  # fmt: skip


def catalogue() -> list[Case]:
    """Every case, in a stable order."""
    return [
        *_profile_cases(),
        *_trajectory_cases(),
        *_source_cases(),
        *_mocap_cases(),
        *_run_cases(),
        *_resume_cases(),
        *_identify_cases(),
        *_output_cases(),
        *_adaptive_cases(),
        *_study_cases(),
    ]


STUDY = {
    "name": "tiny",
    "profile": "antx",
    "trajectory": "eight-short",
    "plants": 2,
    "iterations": 1,
    "uncertainty": {"levels": [0.2]},
    "grid": {"wdu": [0.01, 0.1]},
}


def _study(ws: Workspace, *args: str, **changes: Any) -> list[str]:
    data = copy.deepcopy(STUDY)
    for key, value in changes.items():
        data = _set(data, key.replace("__", "."), value) if value is not DELETE else data
        if value is DELETE:
            data.pop(key, None)
    path = ws.file("study.yaml", yaml.safe_dump(data))
    return ["study", str(path), "--workers", "0", "--out", str(ws.path / "out"), *args]


def _study_cases() -> Iterator[Case]:
    k = "study file"
    for what, changes, expect in (
        ("an unknown setting", {"settings": [{"colour": 1}]}, "settings[0].colour"),
        ("an unknown setting in the grid", {"grid": {"wdux": [1.0]}}, "grid.wdux"),
        ("an empty grid", {"grid": {"wdu": []}}, "grid.wdu"),
        ("an empty list of settings", {"settings": []}, "settings"),
        ("a setting's bad value", {"settings": [{"we": 0.0}]}, "settings[0].we"),
        ("a setting's profile missing", {"settings": [{"profile": "nope"}]}, "settings[0].profile"),
        (
            "a setting's profile learns down",
            {"settings": [{"profile": "antx-3d"}]},
            "settings[0].profile': learning.axes",
        ),
        ("a setting's unknown algorithm", {"settings": [{"algorithm": "pid"}]}, "algorithm"),
        ("no name", {"name": DELETE}, "name"),
        ("an unknown field", {"colour": "red"}, "colour"),
        ("plants 0", {"plants": 0}, "plants"),
        ("iterations not an integer", {"iterations": 2.5}, "iterations"),
        ("steady_trials beyond the iterations", {"steady_trials": 3}, "steady_trials"),
        ("a level above 1", {"uncertainty": {"levels": [1.5]}}, "uncertainty.levels"),
        ("an unknown uncertainty field", {"uncertainty": {"spread": 0.2}}, "uncertainty.spread"),
        ("unknown parameters", {"uncertainty": {"parameters": "poles"}}, "parameters"),
        ("a negative noise", {"uncertainty": {"noise_std_m": -0.1}}, "noise_std_m"),
        ("noise from a floor without a run", {"uncertainty": {"noise_std_m": "floor"}}, "run"),
        ("a run that is not a directory", {"uncertainty": {"run": "nope"}}, "uncertainty.run"),
        (
            "a bias that makes the nominal plant unstable",
            {"uncertainty": {"levels": [0.2], "bias": {"zeta": -1.5}}},
            "unstable",
        ),
        ("an unknown trajectory", {"trajectory": "nine"}, "trajectory"),
    ):
        yield Case(k, "study", what, lambda ws, c=changes: _study(ws, **c), expect)

    def long_trajectory(ws: Workspace) -> list[str]:
        traj = ws.trajectory("loops", 200)
        return _study(ws, trajectory=str(traj))

    yield Case(k, "study", "trials beyond the longest gcs flies", long_trajectory, "samples")
    yield Case(
        k,
        "study",
        "the study file missing",
        lambda ws: ["study", str(ws.path / "none.yaml"), "--workers", "0"],
        "none.yaml",
    )
    k = "options: study"
    yield Case(
        k,
        "study",
        "--scheduler not an address",
        lambda ws: _study(ws, "--scheduler", "localhost:8786")[:2] + ["--scheduler", "localhost"],
        "--scheduler",
    )
    yield Case(
        k,
        "study",
        "--scheduler and --workers",
        lambda ws: _study(ws, "--scheduler", "tcp://127.0.0.1:9"),
        "--workers",
    )
    yield Case(
        k,
        "study",
        "--out is a file",
        lambda ws: [*_study(ws)[:4], "--out", str(ws.file("f", "x"))],
        "--out",
    )

    def other_study(ws: Workspace) -> list[str]:
        ws.file("out/definition.json", "{}\n")
        return _study(ws)

    yield Case(k, "study", "--out holds another study", other_study, "holds another study")
    k = "options: montecarlo"
    for args, expect in (
        (["--samples", "10000000"], "--samples"),
        (["--scheduler", "localhost:8786"], "--scheduler"),
        (["--scheduler", "tcp://127.0.0.1:99999"], "--scheduler"),
    ):
        yield Case(k, "montecarlo", " ".join(args), lambda ws, a=args: ["montecarlo", *a], expect)


# ----------------------------------------------------------------------------- running one


@dataclass(frozen=True)
class Outcome:
    """What a case did."""

    exit_code: int
    output: str
    changed: list[str]

    @property
    def lines(self) -> list[str]:
        return [line for line in self.output.splitlines() if line.strip()]


def snapshot(root: Path) -> dict[str, Any]:
    """Every path under ``root``: file bytes, link targets, directories."""
    out: dict[str, Any] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            key = str(p.relative_to(root))
            if p.is_symlink():
                out[key] = ("link", os.readlink(p))
            elif p.is_dir():
                out[key] = ("dir",)
            else:
                out[key] = ("file", p.read_bytes())
    return out


@contextmanager
def _cwd(path: Path) -> Iterator[None]:
    old = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


def run_case(case: Case, root: Path, templates: Templates) -> Outcome:
    """Build ``case`` in a fresh workspace under ``root``, run it, compare the workspace."""
    ws_path = Path(tempfile.mkdtemp(dir=root, prefix="case-"))
    ws = Workspace(ws_path, templates)
    try:
        argv = case.build(ws)
        before = snapshot(ws_path)
        with _cwd(ws_path):
            result = gcs_invoke(argv, env={"COLUMNS": "400"})
        after = snapshot(ws_path)
    finally:
        for undo in reversed(ws.cleanups):
            undo()
    changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
    output = result.output
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        output += f"\n[exception] {type(result.exception).__name__}: {result.exception}"
    shutil.rmtree(ws_path, ignore_errors=True)
    return Outcome(result.exit_code, output, changed)


def learning_template(root: Path) -> RunDir:
    """A learning run as the catalogue uses it (for other tests)."""
    return RunDir.open(_learning_run(root))


__all__ = ["Case", "Outcome", "Templates", "catalogue", "run_case", "snapshot", "fly_synthetic"]
