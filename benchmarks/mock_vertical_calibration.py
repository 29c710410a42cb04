"""The mock's vertical loop against the shared PX4 v1.16 SITL capture, side by side.

What the capture (``shared/data/px4-sih-offboard.tlog``, read only) holds about the vertical
axis: one take-off in OFFBOARD from the ground to a 2 m setpoint, 155 s of held altitude
(hovers, eights, x steps) and one LAND; **no altitude step in flight**. PX4 publishes its
position controller's internal setpoints (POSITION_TARGET_LOCAL_NED: position and the velocity
setpoint after the P loop) and its thrust setpoint (ATTITUDE_TARGET), so each stage of the
cascade can be read separately:

- **take-off ramp**: PX4 spools up (``MPC_SPOOLUP_TIME``, 1 s) and then ramps the upward
  velocity limit from ``-g / MPC_Z_VEL_P_ACC`` (zero thrust) to ``MPC_Z_VEL_MAX_UP`` over
  ``MPC_TKO_RAMP_T`` (3 s; ``Takeoff.cpp``). A straight line through the ramp-limited velocity
  setpoints gives ``MPC_Z_VEL_P_ACC = g / start`` and, with the 3 s ramp,
  ``MPC_Z_VEL_MAX_UP = slope x 3 s - start``;
- **position loop**: the velocity setpoint against the height error during the climb, not
  limited: ``MPC_Z_P`` by least squares through the origin;
- **thrust**: the hover thrust (median of the hovers) and the idle thrust PX4 falls to after
  touch-down (``MPC_THR_MIN``): with PX4's normalisation (1 = ``MPC_THR_MAX`` = full thrust)
  ``physics.thrust_max_g = 1 / hover`` and ``thrust_min_g = idle / hover``;
- **closed loop in the air**: from lift-off to 8 s later the mock's cascade (``QuadPhysics``,
  no disturbances, no transport delay, PX4's ramp as the climb-speed limit) flies the same 2 m
  setpoint from the same height and speed; its velocity-integrator state at lift-off (PX4's is
  wound up by the ramp) is fitted with the velocity-loop gains and the thrust lag, against the
  reported height and vertical speed. Printed: the fit, its RMS residuals, and the same with
  the mock's defaults;
- **hold**: the height about its setpoint in the capture's hovers and the run directories'
  trials (GPS + barometer and external vision), against the mock's default and mock-gps
  profiles flying the same held altitude offline.

``--fit`` reads only the shared data and prints the fitted parameters and the fit quality;
without it the mock's side is printed too and ``docs/img/mock_vertical.png`` is written.

Usage::

    .venv/bin/python benchmarks/mock_vertical_calibration.py [--fit] [--json]
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import scipy.optimize

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from px4_data import shared  # noqa: E402

from gcs.mock.config import MockConfig, load_mock_config  # noqa: E402
from gcs.mock.physics import (  # noqa: E402
    QuadPhysics,
    Target,
    fit_step_response,
    step_response,
)

G = 9.81
SPOOLUP_S = 1.0  # PX4 MPC_SPOOLUP_TIME default (not in the capture)
RAMP_S = 3.0  # PX4 MPC_TKO_RAMP_T default (not in the capture)
CLIMB_S = 8.0  # length of the in-air take-off window fitted [s]
SITL = shared() / "data" / "px4-sitl"


@dataclass(frozen=True)
class VerticalCapture:
    """The vertical channels of the capture, on the vehicle's clock [s].

    ``lpn``: (t, z, vz) of LOCAL_POSITION_NED; ``target``: (t, z_sp, vz_sp) of
    POSITION_TARGET_LOCAL_NED (finite rows only); ``thrust``: (t, thrust) of ATTITUDE_TARGET;
    ``setpoint``: (t, north, east, down) of the client's SET_POSITION_TARGET_LOCAL_NED;
    ``armed_s`` (the arming command accepted), ``land_s`` (LAND commanded), ``landed_s``
    (PX4's "Landing detected"): events.
    """

    lpn: np.ndarray
    target: np.ndarray
    thrust: np.ndarray
    setpoint: np.ndarray
    armed_s: float
    land_s: float
    landed_s: float


def read_capture(path: Path) -> VerticalCapture:
    """Parse the vertical channels of the tlog (vehicle time = time_boot_ms)."""
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(path))
    lpn, tgt, thr, sp = [], [], [], []
    offset = None  # receipt time - vehicle time, for the client's messages
    armed = land = landed = math.nan
    types = [
        "LOCAL_POSITION_NED", "POSITION_TARGET_LOCAL_NED", "ATTITUDE_TARGET",
        "SET_POSITION_TARGET_LOCAL_NED", "COMMAND_ACK", "COMMAND_LONG", "STATUSTEXT",
    ]  # fmt: skip
    while (m := log.recv_match(type=types)) is not None:
        kind = m.get_type()
        if kind == "LOCAL_POSITION_NED" and m.get_srcSystem() == 1:
            t = m.time_boot_ms / 1000.0
            offset = m._timestamp - t
            lpn.append((t, m.z, m.vz))
        elif kind == "POSITION_TARGET_LOCAL_NED" and math.isfinite(m.vz):
            tgt.append((m.time_boot_ms / 1000.0, m.z, m.vz))
        elif kind == "ATTITUDE_TARGET":
            thr.append((m.time_boot_ms / 1000.0, m.thrust))
        elif offset is None:
            continue
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            sp.append((m._timestamp - offset, m.x, m.y, m.z))
        elif kind == "COMMAND_LONG" and m.command == 21:  # NAV_LAND
            land = m._timestamp - offset
        elif kind == "COMMAND_ACK" and m.command == 400 and m.result == 0 and math.isnan(armed):
            armed = m._timestamp - offset
        elif kind == "STATUSTEXT" and m.text.startswith("Landing detected"):
            landed = m._timestamp - offset
    return VerticalCapture(
        np.array(lpn), np.array(tgt), np.array(thr), np.array(sp), armed, land, landed
    )


def _at(rows: np.ndarray, t: np.ndarray, col: int) -> np.ndarray:
    return np.interp(t, rows[:, 0], rows[:, col])


def takeoff_ramp(cap: VerticalCapture, kp_z: float = 1.0) -> dict[str, float]:
    """Straight line through the ramp-limited velocity setpoints of the take-off."""
    tgt = cap.target
    sel = tgt[:, 0] < cap.armed_s + 20.0
    t, z_sp, vz_sp = tgt[sel, 0], tgt[sel, 1], tgt[sel, 2]
    z = _at(cap.lpn, t, 1)
    limited = vz_sp - kp_z * (z_sp - z) > 0.05  # the ramp, not the P loop, binds
    t_r, v_r = t[limited], vz_sp[limited]
    slope, intercept = np.polyfit(t_r - t_r[0], v_r, 1)
    start_t = cap.armed_s + SPOOLUP_S
    start_v = intercept + slope * (start_t - t_r[0])
    resid = v_r - (intercept + slope * (t_r - t_r[0]))
    return {
        "samples": int(len(t_r)),
        "start_vz_m_s": float(start_v),
        "slope_m_s2": float(-slope),
        "vel_p_z_1_s": G / float(start_v),
        "vel_max_up_m_s": float(-slope) * RAMP_S - float(start_v),
        "rms_m_s": float(np.sqrt(np.mean(resid**2))),
        "first_s": float(t_r[0] - cap.armed_s),
        "last_s": float(t_r[-1] - cap.armed_s),
    }


def liftoff_s(cap: VerticalCapture) -> float:
    """First time after arming that the height rises 5 cm above its value at arming."""
    t, z = cap.lpn[:, 0], cap.lpn[:, 1]
    ground = float(np.median(z[(t > cap.armed_s - 1.0) & (t < cap.armed_s)]))
    up = np.flatnonzero((t > cap.armed_s) & (z < ground - 0.05))
    return float(t[up[0]])


def position_gain(cap: VerticalCapture, t_from: float, t_to: float) -> dict[str, float]:
    """MPC_Z_P: velocity setpoint against the height error, through the origin."""
    tgt = cap.target
    sel = (tgt[:, 0] >= t_from) & (tgt[:, 0] < t_to)
    t, z_sp, vz_sp = tgt[sel, 0], tgt[sel, 1], tgt[sel, 2]
    err = z_sp - _at(cap.lpn, t, 1)
    kp = float(np.sum(err * vz_sp) / np.sum(err * err))
    resid = vz_sp - kp * err
    return {"pos_p_z_1_s": kp, "rms_m_s": float(np.sqrt(np.mean(resid**2))), "samples": len(t)}


def hover_windows(cap: VerticalCapture, settle_s: float = 4.0) -> list[tuple[float, float]]:
    """In-air stretches of a constant setpoint (all three axes), 4 s or longer after
    ``settle_s``, from 8 s after lift-off to the LAND command."""
    sp = cap.setpoint
    change = np.flatnonzero(np.any(np.abs(np.diff(sp[:, 1:], axis=0)) > 1e-4, axis=1)) + 1
    bounds = np.concatenate([[0], change, [len(sp)]])
    first = liftoff_s(cap) + CLIMB_S
    out = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        start, end = max(sp[a, 0] + settle_s, first), min(sp[b - 1, 0], cap.land_s)
        if end - start >= 4.0:
            out.append((float(start), float(end)))
    return out


def thrust_levels(cap: VerticalCapture) -> dict[str, float]:
    """Hover thrust (median in the air after the climb) and idle thrust (the least thrust
    between the LAND command and PX4's land detection: flying, PX4 keeps MPC_THR_MIN)."""
    t, thr = cap.thrust[:, 0], cap.thrust[:, 1]
    air = (t > liftoff_s(cap) + CLIMB_S) & (t < cap.land_s)
    hover = float(np.median(thr[air]))
    landing = (t > cap.land_s) & (t < cap.landed_s)
    idle = float(np.min(thr[landing]))
    return {
        "hover": hover,
        "idle": idle,
        "hover_p5": float(np.percentile(thr[air], 5)),
        "hover_p95": float(np.percentile(thr[air], 95)),
        "thrust_max_g": 1.0 / hover,
        "thrust_min_g": idle / hover,
    }


def hold_stats(t_s: np.ndarray, z: np.ndarray, z_sp: float) -> dict[str, float]:
    """Height about its setpoint in a hold: mean offset, RMS and fast (0.5 s) noise [m]."""
    dev = z - z_sp
    n = max(int(round(0.5 / max(np.median(np.diff(t_s)), 1e-3))), 3)
    smooth = np.convolve(dev, np.ones(n) / n, mode="valid")
    fast = dev[n // 2 : n // 2 + len(smooth)] - smooth
    return {
        "offset_m": float(np.mean(dev)),
        "rms_m": float(np.sqrt(np.mean(dev**2))),
        "fast_m": float(np.std(fast)),
    }


def capture_holds(cap: VerticalCapture) -> list[dict[str, float]]:
    """hold_stats of each in-air hover window of the capture."""
    out = []
    for a, b in hover_windows(cap):
        sel = (cap.lpn[:, 0] >= a) & (cap.lpn[:, 0] < b)
        z_sp = float(_at(cap.setpoint, np.array([a]), 3)[0])
        out.append(hold_stats(cap.lpn[sel, 0], cap.lpn[sel, 1], z_sp))
    return out


def trial_holds(pattern: str) -> list[dict[str, float]]:
    """hold_stats of the down axis of every trial CSV matching ``pattern`` (sp held there)."""
    out = []
    for path in sorted(glob.glob(str(SITL / pattern))):
        tab = np.genfromtxt(path, delimiter=",", names=True)
        if not np.allclose(tab["sp_down_m"], tab["sp_down_m"][0], atol=1e-6):
            continue
        out.append(hold_stats(tab["t_s"], tab["pos_down_m"], float(tab["sp_down_m"][0])))
    return out


# -- the mock's cascade flown over the capture's take-off ---------------------------------------


def quiet(cfg: MockConfig) -> MockConfig:
    """Disturbances, gusts, estimator and transport delay off (the capture's internal loop)."""
    return replace(
        cfg,
        physics=replace(cfg.physics, input_delay_s=0.0),
        disturbance=replace(cfg.disturbance, field_amplitude_m_s2=0.0, gust_sigma_m_s2=0.0),
        estimator=replace(cfg.estimator, enabled=False),
    )


def with_vertical(cfg: MockConfig, kv: float, ki: float, tau_s: float) -> MockConfig:
    """``cfg`` with vertical velocity gains and the lag replaced."""
    return replace(
        cfg,
        physics=replace(cfg.physics, tilt_lag_s=tau_s),
        controller=replace(cfg.controller, vel_p_z_1_s=kv, vel_i_z_1_s2=ki),
    )


def with_takeoff(cfg: MockConfig) -> MockConfig:
    """``cfg`` with PX4's take-off handling (spool-up 1 s, ramp 3 s: PX4's defaults)."""
    return replace(
        cfg, controller=replace(cfg.controller, spoolup_s=SPOOLUP_S, takeoff_ramp_s=RAMP_S)
    )


def ground_z(cap: VerticalCapture) -> float:
    """The reported height of the ground: the median in the second before arming [m]."""
    t, z = cap.lpn[:, 0], cap.lpn[:, 1]
    return float(np.median(z[(t > cap.armed_s - 1.0) & (t < cap.armed_s)]))


def fly_takeoff(
    cfg: MockConfig, cap: VerticalCapture
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The mock armed on the ground at the capture's arming, its setpoint 2 m up at once.

    Returns the capture's sample times from arming to 8 s after its lift-off, the mock's
    height above its ground and vertical speed there, and the mock's lift-off time [s].
    """
    z0 = ground_z(cap)
    z_sp = float(_at(cap.setpoint, np.array([cap.armed_s]), 3)[0]) - z0
    sel = (cap.lpn[:, 0] >= cap.armed_s) & (cap.lpn[:, 0] < liftoff_s(cap) + CLIMB_S)
    t = cap.lpn[sel, 0]
    sim = QuadPhysics(quiet(cfg), seed=0)
    sim.set_armed(True)
    sim.command(0.0, Target((0.0, 0.0, z_sp)))
    z, vz = np.empty(len(t)), np.empty(len(t))
    lift = math.nan
    for i, tk in enumerate(t):
        sim.advance_to(tk - cap.armed_s)
        z[i], vz[i] = sim.pos[2], sim.vel[2]
        if math.isnan(lift) and sim.pos[2] < -0.05:
            lift = tk
    return t, z, vz, lift


def takeoff_residual(cfg: MockConfig, cap: VerticalCapture) -> dict[str, float]:
    """RMS of the mock's take-off against the capture's (height above ground, speed)."""
    t, z, vz, lift = fly_takeoff(cfg, cap)
    dz = z - (_at(cap.lpn, t, 1) - ground_z(cap))
    dv = vz - _at(cap.lpn, t, 2)
    return {
        "liftoff_after_arming_s": lift - cap.armed_s,
        "rms_z_m": float(np.sqrt(np.mean(dz**2))),
        "rms_vz_m_s": float(np.sqrt(np.mean(dv**2))),
        "max_abs_z_m": float(np.max(np.abs(dz))),
    }


def fit_takeoff(cap: VerticalCapture, base: MockConfig) -> dict[str, float]:
    """Fit (vel_p_z, vel_i_z, lag) of ``base`` with PX4's take-off handling to the capture's
    take-off, from arming to 8 s after lift-off (height above the ground and climb speed)."""

    def res(x: np.ndarray) -> np.ndarray:
        t, z, vz, _ = fly_takeoff(with_takeoff(with_vertical(base, x[0], x[1], x[2])), cap)
        return np.concatenate([z - (_at(cap.lpn, t, 1) - ground_z(cap)), vz - _at(cap.lpn, t, 2)])

    sol = scipy.optimize.least_squares(
        res, [4.0, 2.0, 0.08], bounds=([0.5, 0.05, 0.005], [15.0, 10.0, 0.5]), x_scale=[1, 1, 0.05]
    )
    n = len(sol.fun) // 2
    fitted = with_takeoff(with_vertical(base, *(float(v) for v in sol.x)))
    return {
        "vel_p_z_1_s": float(sol.x[0]),
        "vel_i_z_1_s2": float(sol.x[1]),
        "lag_s": float(sol.x[2]),
        "rms_z_m": float(np.sqrt(np.mean(sol.fun[:n] ** 2))),
        "rms_vz_m_s": float(np.sqrt(np.mean(sol.fun[n:] ** 2))),
        "liftoff_after_arming_s": takeoff_residual(fitted, cap)["liftoff_after_arming_s"],
    }


def lag_profile(cap: VerticalCapture, base: MockConfig) -> list[dict[str, float]]:
    """The take-off residual with PX4's gains and ramp for a range of thrust lags."""
    rows = []
    for lag in (0.01, 0.03, 0.08, 0.15, 0.3):
        r = takeoff_residual(with_takeoff(with_vertical(base, 4.0, 2.0, lag)), cap)
        rows.append({"lag_s": lag, **r})
    return rows


def mock_hold(cfg: MockConfig, seeds: range, duration_s: float = 14.0) -> list[dict[str, float]]:
    """hold_stats of the reported height, the mock hovering at 1.5 m (first 4 s dropped)."""
    out = []
    for seed in seeds:
        sim = QuadPhysics(cfg, seed=seed, pos_ned_m=(0.0, 0.0, -1.5))
        sim.command(0.0, Target((0.0, 0.0, -1.5)))
        t = np.arange(0.0, duration_s, 0.05)
        z = np.empty(len(t))
        for i, tk in enumerate(t):
            sim.advance_to(float(tk))
            z[i] = sim.measure()[0][2]
        keep = t >= 4.0
        out.append(hold_stats(t[keep], z[keep], -1.5))
    return out


def _range(rows: list[dict[str, float]], key: str, scale: float = 1.0) -> str:
    vals = [scale * r[key] for r in rows]
    return f"{np.median(vals):.3f} ({min(vals):.3f} to {max(vals):.3f})" if vals else "-"


def data_side(cap: VerticalCapture) -> dict:
    """Every figure taken from the shared data alone."""
    ramp = takeoff_ramp(cap)
    t_lift = liftoff_s(cap)
    kp = position_gain(cap, t_lift + 0.5, t_lift + CLIMB_S)
    return {
        "ramp": ramp,
        "liftoff_after_arming_s": t_lift - cap.armed_s,
        "position_gain": kp,
        "thrust": thrust_levels(cap),
        "takeoff_fit": fit_takeoff(cap, MockConfig()),
        "lag_profile": lag_profile(cap, MockConfig()),
        "hold_capture": capture_holds(cap),
        "hold_gps_trials": trial_holds("*learn/trial-*.csv") + trial_holds("repeat/trial-*.csv"),
        "hold_vision_trials": trial_holds("vision-*/trial-*.csv"),
    }


def print_data(d: dict) -> None:
    """The fitted parameters and the fit quality (Markdown)."""
    r, k, th, c = d["ramp"], d["position_gain"], d["thrust"], d["takeoff_fit"]
    print("## Vertical loop of PX4 v1.16 SITL, from the shared capture")
    print("| parameter | fitted | PX4 default | from |")
    print("|---|---|---|---|")
    print(
        f"| MPC_Z_VEL_P_ACC [1/s] | {r['vel_p_z_1_s']:.2f} | 4.0 | take-off ramp start "
        f"{r['start_vz_m_s']:.3f} m/s = g / gain ({r['samples']} setpoints, "
        f"line RMS {r['rms_m_s']:.3f} m/s) |"
    )
    print(
        f"| MPC_Z_VEL_MAX_UP [m/s] | {r['vel_max_up_m_s']:.2f} | 3.0 | ramp slope "
        f"{r['slope_m_s2']:.3f} m/s^2 x {RAMP_S:.0f} s - start |"
    )
    print(
        f"| MPC_Z_P [1/s] | {k['pos_p_z_1_s']:.3f} | 1.0 (capture: 1.0) | velocity setpoint / "
        f"height error in the climb ({k['samples']} setpoints, RMS {k['rms_m_s']:.3f} m/s) |"
    )
    print(
        f"| hover thrust | {th['hover']:.3f} (5-95 %: {th['hover_p5']:.3f}-"
        f"{th['hover_p95']:.3f}) | MPC_THR_HOVER 0.5 (estimated) | ATTITUDE_TARGET in the air |"
    )
    print(
        f"| idle thrust | {th['idle']:.3f} | MPC_THR_MIN 0.12 | ATTITUDE_TARGET after touch-down |"
    )
    print(f"| thrust_max_g | {th['thrust_max_g']:.3f} | | 1 / hover |")
    print(f"| thrust_min_g | {th['thrust_min_g']:.3f} | | idle / hover |")
    print(
        f"| MPC_Z_VEL_P_ACC, MPC_Z_VEL_I_ACC, lag | {c['vel_p_z_1_s']:.2f}, "
        f"{c['vel_i_z_1_s2']:.2f}, {c['lag_s']:.3f} s | 4.0, 2.0, - | the mock's cascade with "
        f"PX4's take-off ramp over the take-off, arming to {CLIMB_S:.0f} s after lift-off: RMS "
        f"{c['rms_z_m']:.3f} m, {c['rms_vz_m_s']:.3f} m/s, lift-off "
        f"{c['liftoff_after_arming_s']:.2f} s after arming |"
    )
    print(
        "\n| thrust lag [s] (PX4 gains, ramp) | lift-off [s] | RMS height [m] | RMS speed [m/s] |"
    )
    print("|---|---|---|---|")
    for r in d["lag_profile"]:
        print(
            f"| {r['lag_s']:.2f} | {r['liftoff_after_arming_s']:.2f} | {r['rms_z_m']:.3f} "
            f"| {r['rms_vz_m_s']:.3f} |"
        )
    print(f"\nlift-off {d['liftoff_after_arming_s']:.2f} s after arming")
    print("\n| hold (height about its setpoint) | offset [m] | RMS [m] | fast noise [m] |")
    print("|---|---|---|---|")
    for name, key in (
        ("capture hovers", "hold_capture"),
        ("SITL trials, GPS", "hold_gps_trials"),
        ("SITL trials, vision", "hold_vision_trials"),
    ):
        rows = d[key]
        print(
            f"| {name} ({len(rows)}) | {_range(rows, 'offset_m')} | {_range(rows, 'rms_m')} "
            f"| {_range(rows, 'fast_m')} |"
        )


def mock_side(cap: VerticalCapture, d: dict) -> dict:
    """The mock's profiles over the same take-off and holds, and its small-step response."""
    out = {}
    for name in ("mock.yaml", "mock-gps.yaml"):
        cfg = load_mock_config(ROOT / "profiles" / name)
        t, y = step_response(cfg, 2, amplitude_m=-0.1)
        fit = fit_step_response(t, y)
        t_up, y_up = step_response(cfg, 2, amplitude_m=-20.0, duration_s=10.0)
        t_dn, y_dn = step_response(cfg, 2, amplitude_m=1.9, duration_s=4.0)
        climb_rate = float(np.max(20.0 * np.diff(y_up) / np.diff(t_up)))
        sink_rate = float(np.max(1.9 * np.diff(y_dn) / np.diff(t_dn)))
        out[name] = {
            "takeoff": takeoff_residual(cfg, cap),
            "takeoff_ramp": takeoff_residual(with_takeoff(cfg), cap),
            "step": {
                "wn_rad_s": fit.wn_rad_s,
                "zeta": fit.zeta,
                "gain": fit.gain,
                "delay_s": fit.delay_s,
                "rms": fit.rms_residual_m,
            },
            "climb_speed_20m_m_s": climb_rate,
            "sink_speed_1_9m_m_s": sink_rate,
            "hold": mock_hold(cfg, range(5)),
        }
    return out


def print_mock(m: dict) -> None:
    """The mock beside the capture (Markdown)."""
    print("\n## The whole take-off from arming (height above the ground)")
    print(
        "| profile | lift-off after arming [s] | RMS height [m] | max error [m] | RMS speed [m/s] |"
    )
    print("|---|---|---|---|---|")
    for name, r in m.items():
        for label, key in (("", "takeoff"), (" + PX4 take-off ramp", "takeoff_ramp")):
            c = r[key]
            print(
                f"| {name}{label} | {c['liftoff_after_arming_s']:.2f} | {c['rms_z_m']:.3f} "
                f"| {c['max_abs_z_m']:.3f} | {c['rms_vz_m_s']:.3f} |"
            )
    print("\n| profile | 0.1 m climb: wn [rad/s] | zeta | gain | delay [s] | top speed up, down |")
    print("|---|---|---|---|---|---|")
    for name, r in m.items():
        s = r["step"]
        print(
            f"| {name} | {s['wn_rad_s']:.3f} | {s['zeta']:.3f} | {s['gain']:.3f} | "
            f"{s['delay_s']:.3f} | {r['climb_speed_20m_m_s']:.2f}, "
            f"{r['sink_speed_1_9m_m_s']:.2f} m/s (20 m up, 1.9 m down) |"
        )
    print("\n| mock hold, reported height (5 seeds) | offset [m] | RMS [m] | fast noise [m] |")
    print("|---|---|---|---|")
    for name, r in m.items():
        rows = r["hold"]
        print(
            f"| {name} | {_range(rows, 'offset_m')} | {_range(rows, 'rms_m')} "
            f"| {_range(rows, 'fast_m')} |"
        )


def plot(cap: VerticalCapture, out: Path) -> None:
    """Height and climb speed of the take-off: PX4 against the mock, with and without PX4's
    take-off handling."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(7.0, 5.5), dpi=120, sharex=True)
    t0, z0 = cap.armed_s, ground_z(cap)
    end = liftoff_s(cap) + CLIMB_S
    sel = (cap.lpn[:, 0] >= t0) & (cap.lpn[:, 0] < end)
    axes[0].plot(cap.lpn[sel, 0] - t0, z0 - cap.lpn[sel, 1], "k", lw=1.8, label="PX4 SITL")
    axes[1].plot(cap.lpn[sel, 0] - t0, -cap.lpn[sel, 2], "k", lw=1.8, label="PX4 SITL")
    tsel = (cap.target[:, 0] >= t0) & (cap.target[:, 0] < end)
    axes[1].plot(
        cap.target[tsel, 0] - t0, -cap.target[tsel, 2], "k:", lw=1.0,
        label="PX4's velocity setpoint",
    )  # fmt: skip
    cfg = load_mock_config(ROOT / "profiles" / "mock.yaml")
    for label, c, style in (
        ("mock, PX4's take-off handling", with_takeoff(cfg), "-"),
        ("mock as shipped (leaves the ground at once)", cfg, "--"),
    ):
        t, z, vz, _ = fly_takeoff(c, cap)
        axes[0].plot(t - t0, -z, color="tab:blue", ls=style, lw=1.2, label=label)
        axes[1].plot(t - t0, -vz, color="tab:blue", ls=style, lw=1.2, label=label)
    axes[0].set_ylabel("height above the ground [m]")
    axes[1].set_ylabel("climb speed [m/s]")
    axes[1].set_xlabel("time since arming [s]")
    axes[0].set_title(
        "Take-off to a 2 m OFFBOARD setpoint: PX4 v1.16 SITL and the mock\n"
        "(mock: disturbances and transport delay off)",
        fontsize=10,
    )
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)


def main(argv: list[str] | None = None) -> int:
    """Run the calibration; see the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fit", action="store_true", help="the shared data only: fitted parameters")
    ap.add_argument("--json", action="store_true", help="print JSON instead of tables")
    ap.add_argument("--plot", type=Path, default=ROOT / "docs" / "img" / "mock_vertical.png")
    args = ap.parse_args(argv)
    cap = read_capture(shared() / "data" / "px4-sih-offboard.tlog")
    d = data_side(cap)
    m = None if args.fit else mock_side(cap, d)
    if args.json:
        print(json.dumps({"data": d, "mock": m}, indent=1))
    else:
        print_data(d)
        if m is not None:
            print_mock(m)
    if m is not None:
        plot(cap, args.plot)
        print(f"wrote {args.plot}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
