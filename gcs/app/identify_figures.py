"""The figures of ``gcs identify``: validation (measured vs simulated) and Bode comparison."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from gcs.app.figures import save_figure
from gcs.app.identify_fit import AxisResult
from gcs.core.model import frequency_response
from gcs.io.config import Profile

__all__ = ["write_identification_plots"]


def write_identification_plots(
    results: Sequence[AxisResult], profile: Profile, out_dir: Path
) -> list[Path]:
    """Write ``identify_validation.png`` (as the paper's Fig. 3) and ``identify_bode.png``.

    The first has one panel per axis: setpoint, measured and simulated position on the
    validation experiment; the second the identified models against the profile's.

    Parameters
    ----------
    results : sequence of AxisResult
    profile : Profile
        The input profile (its models are drawn for comparison).
    out_dir : Path
        Where to write (created if missing).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    fig, axs = plt.subplots(len(results), 1, figsize=(9, 3.2 * len(results)), squeeze=False)
    for ax, r in zip(axs[:, 0], results, strict=True):
        label = {"x": "north", "y": "east", "z": "down"}[r.axis]
        ax.step(r.t_s, r.u_val_m, where="post", color="0.75", lw=0.8, label="setpoint")
        ax.plot(r.t_s, r.y_val_m, "k", lw=1.2, label="measured")
        ax.plot(r.t_s, r.y_sim_m, "C3--", lw=1.2, label="identified model (free run)")
        ax.set_ylabel(f"{label} [m]")
        ax.set_title(
            f"axis {r.axis}: validation experiment, VAF {r.vaf_pct:.1f} %, fit {r.fit_pct:.1f} %"
        )
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axs[-1, 0].set_xlabel("t [s]")
    paths.append(save_figure(fig, out_dir / "identify_validation.png"))

    dt = profile.t_ilc_s
    f = np.logspace(-2, math.log10(0.45 / dt), 300)
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    curves = [(f"identified {r.axis}", r.model, "-") for r in results]
    px, py = profile.models()
    curves.append((f"profile '{profile.name}' x", px, "k--"))
    if not (np.array_equal(px.A, py.A) and np.array_equal(px.B, py.B)):
        curves.append((f"profile '{profile.name}' y", py, "k:"))
    for label, model, style in curves:
        h = frequency_response(model, 2 * math.pi * f)
        ax_m.semilogx(f, 20 * np.log10(np.abs(h)), style, label=label)
        ax_p.semilogx(f, np.degrees(np.unwrap(np.angle(h))), style, label=label)
    ax_m.set_ylabel("|G| [dB]")
    ax_p.set_ylabel("phase [deg]")
    ax_p.set_xlabel("f [Hz]")
    ax_m.set_title("Closed loop setpoint -> position")
    for ax in (ax_m, ax_p):
        ax.grid(True, which="both", alpha=0.3)
    ax_m.legend(fontsize=8)
    paths.append(save_figure(fig, out_dir / "identify_bode.png"))
    return paths
