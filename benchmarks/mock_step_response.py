"""Step responses of the mock drone's x and y closed loops next to the paper's eq. (11).

Writes ``docs/img/mock_step_response.png`` and prints the fitted table (Markdown) that
``docs/mock.md`` shows. Run: ``.venv/bin/python benchmarks/mock_step_response.py``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from gcs.mock.config import load_mock_config  # noqa: E402
from gcs.mock.physics import (  # noqa: E402
    EQ11,
    eq11_step,
    fit_step_response,
    second_order_step,
    step_response,
)

ROOT = Path(__file__).resolve().parents[1]


def main(out: Path = ROOT / "docs" / "img" / "mock_step_response.png") -> None:
    """Simulate, fit, plot and print the table.

    Parameters
    ----------
    out : Path
        PNG to write.
    """
    cfg = load_mock_config(ROOT / "profiles" / "mock.yaml")
    fig, ax = plt.subplots(figsize=(7.0, 4.0), dpi=120)
    rows = [("eq. (11)", EQ11)]
    t = None
    for axis, name, colour in ((0, "x (north)", "tab:blue"), (1, "y (east)", "tab:orange")):
        t, y = step_response(cfg, axis, amplitude_m=0.1)
        fit = fit_step_response(t, y)
        rows.append((f"mock {name}", fit))
        ax.plot(t, y, color=colour, lw=1.8, label=f"mock {name}")
        ax.plot(t, second_order_step(t, fit), color=colour, lw=0.8, ls=":")
    assert t is not None
    ax.plot(t, eq11_step(t), color="k", lw=1.4, ls="--", label="eq. (11)")
    ax.set_xlabel("time since the setpoint step [s]")
    ax.set_ylabel("position / step size [-]")
    ax.set_title("Mock drone, 0.1 m setpoint step at hover (dotted: fitted 2nd order + delay)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    print("| loop | wn [rad/s] | zeta | gain | delay [s] | wn / eq.11 | zeta / eq.11 |")
    print("|---|---|---|---|---|---|---|")
    for name, f in rows:
        print(
            f"| {name} | {f.wn_rad_s:.3f} | {f.zeta:.3f} | {f.gain:.3f} | {f.delay_s:.3f} "
            f"| {f.wn_rad_s / EQ11.wn_rad_s:.3f} | {f.zeta / EQ11.zeta:.3f} |"
        )
    print(f"wrote {out}", file=sys.stderr)


if __name__ == "__main__":
    main()
