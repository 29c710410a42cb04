"""Altitude steps in the air: PX4 v1.16 SITL against the mock, side by side (a validation).

The shared capture holds no altitude step in flight (``mock_vertical_calibration.py``
calibrates on its take-off). This benchmark checks the calibrated vertical loop on steps that
the calibration never saw: ``--record`` flies real PX4 SITL (SIH quadrotor, GPS + EKF2,
default parameters) through OFFBOARD altitude steps and writes what it reported; the default
mode reads such a recording and flies the mock's profiles (physics alone, disturbances and
transport delay off) through the same steps, each from hover at the previous setpoint.

Per step: the time to cover 90 % of the step, the peak vertical speed, and the RMS difference
of the two height responses over the first 4 s (the transient) and over the whole hold (where
PX4's reported height wanders by decimetres with its GPS + barometer estimate). PX4's response
is measured from where its reported height was before the step.

Usage::

    # PX4 SITL instance 20 running (shared/px4-v1.16-sitl/README.md), then:
    .venv/bin/python benchmarks/mock_vertical_steps.py --record OUT.csv \
        --connect udpout:127.0.0.1:14600 --sysid 21
    .venv/bin/python benchmarks/mock_vertical_steps.py [RECORDING.csv] [--plot PNG]

The recording used in ``docs/mock.md`` is ``benchmarks/data/px4-sitl-altitude-steps.csv``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from gcs.mock.config import MockConfig, load_mock_config
from gcs.mock.physics import QuadPhysics, Target

ROOT = Path(__file__).resolve().parents[1]
RECORDING = ROOT / "benchmarks" / "data" / "px4-sitl-altitude-steps.csv"
TRANSIENT_S = 4.0  # after this PX4's reported height wanders with its estimate
GRID_S = 0.04  # both responses on this grid [s]
SPEED_S = 0.2  # speeds over this span [s]
#: Seconds after OFFBOARD -> down setpoint [m]; None: LAND.
SCHEDULE = (
    (0.0, -2.0), (15.0, -3.0), (30.0, -2.0), (45.0, -7.0), (63.0, -2.0), (83.0, -2.5),
    (95.0, -2.0), (107.0, None),
)  # fmt: skip


def record(out: Path, url: str, sysid: int) -> None:
    """Fly the schedule on PX4 (arm, OFFBOARD from the ground, steps, LAND); write the CSV.

    Columns: ``t_s`` (vehicle time since OFFBOARD), ``z_m``, ``vz_m_s`` (LOCAL_POSITION_NED),
    ``sp_z_m`` (the setpoint sent); rows at 25 Hz while in the air.
    """
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(url, source_system=245, source_component=190)
    while True:  # PX4 answers the address it first hears from
        m.mav.heartbeat_send(6, 8, 0, 0, 0)
        hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=1)
        if hb is not None and hb.get_srcSystem() == sysid:
            break

    def cmd(c: int, *p: float) -> None:
        m.mav.command_long_send(sysid, 1, c, 0, *(list(p) + [0.0] * (7 - len(p))))

    cmd(511, 32, 20000)  # LOCAL_POSITION_NED at 50 Hz
    rows: list[tuple[float, float, float, float]] = []
    t_boot, t_off, z_sp = 0.0, None, float(SCHEDULE[0][1])  # type: ignore[arg-type]
    start = last_sp = last_hb = time.monotonic()
    armed = land = False
    while True:
        now = time.monotonic()
        if now - last_hb > 1.0:
            m.mav.heartbeat_send(6, 8, 0, 0, 0)
            last_hb = now
        if t_off is not None and not land:
            wanted = [z for t, z in SCHEDULE if t_boot - t_off >= t][-1]
            if wanted is None:
                cmd(21)
                land = True
            else:
                z_sp = float(wanted)
        if now - last_sp >= 0.05 and not land:
            m.mav.set_position_target_local_ned_send(
                0, sysid, 1, 1, 2552, 0.0, 0.0, z_sp, 0, 0, 0, 0, 0, 0, 0.0, 0
            )
            last_sp = now
        if not armed and now - start > 1.5:
            cmd(400, 1)
            cmd(176, 1, 6)
            armed = True
            t_off = t_boot
        msg = m.recv_match(blocking=True, timeout=0.01)
        if msg is None:
            continue
        kind = msg.get_type()
        if kind == "LOCAL_POSITION_NED":
            t_boot = msg.time_boot_ms / 1000.0
            if t_off is not None and not land:
                rows.append((t_boot - t_off, msg.z, msg.vz, z_sp))
        elif kind == "STATUSTEXT" and "Disarmed" in msg.text:
            break
    tab = np.array(rows)
    keep = np.concatenate([[True], np.diff(np.floor(tab[:, 0] * 25.0)) > 0])
    np.savetxt(
        out, tab[keep], delimiter=",", fmt="%.4f", header="t_s,z_m,vz_m_s,sp_z_m", comments=""
    )


def steps(tab: np.ndarray) -> list[tuple[float, float, float, float]]:
    """(t_step, t_end, z_from, z_to) of every in-air setpoint change of a recording."""
    t, sp = tab[:, 0], tab[:, 3]
    change = np.flatnonzero(np.abs(np.diff(sp)) > 1e-3) + 1
    out = []
    for i, k in enumerate(change):
        end = t[change[i + 1]] if i + 1 < len(change) else t[-1]
        out.append((float(t[k]), float(end), float(sp[k - 1]), float(sp[k])))
    return out


def mock_step(cfg: MockConfig, z_from: float, z_to: float, t_s: np.ndarray) -> np.ndarray:
    """The mock hovering at ``z_from``, setpoint ``z_to`` at t = 0: heights at ``t_s``."""
    quiet = replace(
        cfg,
        physics=replace(cfg.physics, input_delay_s=0.0),
        disturbance=replace(cfg.disturbance, field_amplitude_m_s2=0.0, gust_sigma_m_s2=0.0),
        estimator=replace(cfg.estimator, enabled=False),
    )
    sim = QuadPhysics(quiet, pos_ned_m=(0.0, 0.0, z_from))
    sim.command(0.0, Target((0.0, 0.0, z_to)))
    z = np.empty(len(t_s))
    for i, tk in enumerate(t_s):
        sim.advance_to(float(tk))
        z[i] = sim.pos[2]
    return z


def features(t: np.ndarray, z: np.ndarray, z_from: float, z_to: float) -> dict[str, float]:
    """Time to cover 90 % of the step [s] and the peak vertical speed over SPEED_S [m/s]."""
    y = (z - z_from) / (z_to - z_from)
    reached = np.flatnonzero(y >= 0.9)
    n = int(round(SPEED_S / GRID_S))
    speed = np.abs(z[n:] - z[:-n]) / (t[n:] - t[:-n])
    return {
        "t90_s": float(t[reached[0]]) if reached.size else float("nan"),
        "peak_speed_m_s": float(np.max(speed)),
    }


def compare(path: Path, plot: Path | None) -> None:
    """Print the table; draw the figure."""
    tab = np.genfromtxt(path, delimiter=",", skip_header=1)
    print(
        f"| step [m] | t90 [s] PX4, mock | peak speed [m/s] PX4, mock | RMS difference [m], "
        f"first {TRANSIENT_S:.0f} s | RMS difference [m], whole hold |"
    )
    print("|---|---|---|---|---|")
    panels = []
    cfg = load_mock_config(ROOT / "profiles" / "mock.yaml")
    for t0, t1, z_from, z_to in steps(tab):
        t = np.arange(0.0, t1 - t0, GRID_S)  # a uniform grid, a multiple of the physics step
        z = np.interp(t0 + t, tab[:, 0], tab[:, 1])
        # PX4's reported hover sits off its setpoint (GPS + baro): measure from where it was
        z_px4_from = float(np.median(tab[(tab[:, 0] >= t0 - 2.0) & (tab[:, 0] < t0), 1]))
        z_px4 = z - z_px4_from + z_from
        zm = mock_step(cfg, z_from, z_to, t)
        px4, mock = features(t, z_px4, z_from, z_to), features(t, zm, z_from, z_to)
        early = t < TRANSIENT_S
        rms_early = float(np.sqrt(np.mean((zm[early] - z_px4[early]) ** 2)))
        rms = float(np.sqrt(np.mean((zm - z_px4) ** 2)))
        print(
            f"| {-z_from:.1f} -> {-z_to:.1f} m | {px4['t90_s']:.2f}, {mock['t90_s']:.2f} | "
            f"{px4['peak_speed_m_s']:.2f}, {mock['peak_speed_m_s']:.2f} | {rms_early:.3f} | "
            f"{rms:.3f} |"
        )
        panels.append((z_from, z_to, t, z_px4, zm))
    if plot is None:
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(9.0, 5.0), dpi=120)
    for ax, (z_from, z_to, t, z_px4, zm) in zip(axes.flat, panels, strict=False):
        ax.plot(t, -z_px4, "k", lw=1.5, label="PX4 SITL")
        ax.plot(t, -zm, "tab:blue", lw=1.2, label="mock.yaml")
        ax.axhline(-z_to, color="grey", lw=0.6, ls=":")
        ax.set_title(f"{-z_from:.1f} m -> {-z_to:.1f} m", fontsize=9)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=8)
    axes.flat[0].legend(fontsize=8)
    for ax in axes[1]:
        ax.set_xlabel("time since the step [s]", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("height [m]", fontsize=8)
    fig.suptitle(
        "Altitude steps in OFFBOARD: PX4 v1.16 SITL and the mock (disturbances, delay off)",
        fontsize=10,
    )
    fig.tight_layout()
    plot.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(plot)
    print(f"wrote {plot}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Record or compare; see the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("recording", nargs="?", type=Path, default=RECORDING)
    ap.add_argument("--record", type=Path, help="fly PX4 SITL and write this CSV")
    ap.add_argument("--connect", default="udpout:127.0.0.1:14600")
    ap.add_argument("--sysid", type=int, default=21)
    ap.add_argument("--plot", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.record is not None:
        record(args.record, args.connect, args.sysid)
        return 0
    compare(args.recording, args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
