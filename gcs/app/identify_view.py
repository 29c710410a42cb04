"""What ``gcs identify`` shows: the checks, the flight, the identified models, the files."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.progress import Progress
from rich.table import Table

from gcs.app.fly_view import live_progress, say
from gcs.app.identify_fit import AxisResult
from gcs.app.identify_plan import Experiments, IdentifyPlan
from gcs.core.model import dc_gain
from gcs.core.trajectory import Box
from gcs.io.rundir import RunDir
from gcs.io.settings import IdentifySettings

__all__ = ["IdentifyView", "results_table", "model_lines", "excitation_lines", "weaker_lines"]


def _poly(c: np.ndarray) -> str:
    n = len(c) - 1
    terms = []
    for i, v in enumerate(c):
        p = n - i
        s = "" if p == 0 else ("s" if p == 1 else f"s^{p}")
        terms.append(f"{v:.4g}" + (f" {s}" if s else ""))
    return " + ".join(terms).replace("+ -", "- ")


def _poles(z: np.ndarray) -> str:
    z = z[np.argsort(-np.abs(z))]
    seen = []
    for p in z:
        if p.imag < -1e-12:
            continue
        seen.append(f"{p.real:.4f} ± {p.imag:.4f}j" if abs(p.imag) > 1e-12 else f"{p.real:.4f}")
    return ", ".join(seen)


def results_table(results: Sequence[AxisResult], profile_name: str) -> Table:
    """Per axis: order, delay, wn and zeta, and the validation VAF and fit beside the VAF of
    the profile's model (80 columns).

    Parameters
    ----------
    results : sequence of AxisResult
    profile_name : str
        The input profile's name (title of the comparison's column).
    """
    table = Table(title="PBSID: setpoint -> position, validated on trial 1")
    for col in ("axis", "order", "delay", "wn [rad/s]", "zeta", "VAF [%]", "fit [%]"):
        table.add_column(escape(col), justify="left" if col == "axis" else "right", no_wrap=True)
    table.add_column(escape(f"VAF {profile_name} [%]"), justify="right")
    for r in results:
        d = r.result.delay_samples
        table.add_row(
            r.axis,
            str(r.result.order),
            f"{d} ({d * r.model.dt_s:.2f} s)",
            "-" if r.wn_rad_s is None else f"{r.wn_rad_s:.3f}",
            "-" if r.zeta is None else f"{r.zeta:.3f}",
            f"{r.vaf_pct:.2f}",
            f"{r.fit_pct:.1f}",
            "-" if math.isnan(r.vaf_profile_pct) else f"{r.vaf_profile_pct:.2f}",
        )
    return table


def model_lines(results: Sequence[AxisResult]) -> list[str]:
    """Per axis: the Tustin transfer function with its delay, and the discrete poles.

    Parameters
    ----------
    results : sequence of AxisResult
    """
    lines = []
    for r in results:
        delay_s = r.result.delay_samples * r.model.dt_s
        lines.append(
            f"{r.axis}: G(s) = ({_poly(r.num)}) / ({_poly(r.den)}) e^(-{delay_s:.2f} s); "
            f"poles z = {_poles(np.linalg.eigvals(r.model.A))}"
        )
    return lines


#: Steady-state gains of a position loop gcs takes as plausible: PX4's position controller
#: holds a constant setpoint (gain 1); an identified gain beyond a factor of 2 says the
#: experiments did not pin the slow response.
PLAUSIBLE_GAIN = (0.5, 2.0)


def weaker_lines(results: Sequence[AxisResult], profile_name: str) -> list[str]:
    """One warning per axis whose identified model explains the validation experiment less
    than the input profile's model did (both simulated free-running on trial 1).

    On short experiments over a hover that wanders (GPS: decimetres) an axis can come out
    worse than the model one started from; the profile is written all the same (it is what
    the data gave), and the line says which axis and what to do. An axis whose model explains
    the validation experiment less than its mean does (a negative VAF) is named too, also when
    the input profile's did worse: then the experiment did not show the axis's dynamics (seen
    on firmware over GPS on a machine at load 14-21: the hover wandered 0.89 m (95 %), VAF
    -146.8 % against -305.3 %, a steady-state gain of 3.0 identified). Else an axis whose
    steady-state gain lies outside :data:`PLAUSIBLE_GAIN` is named (seen over GPS on 30 s
    experiments: 2.09 at a VAF of 57.6 %, the profile's 54.9 %). One line per axis at most.

    Parameters
    ----------
    results : sequence of AxisResult
    profile_name : str
        The input profile's name.
    """
    lines = []
    for r in results:
        if not math.isnan(r.vaf_profile_pct) and r.vaf_pct < r.vaf_profile_pct:
            lines.append(
                f"warning: {r.axis}: the identified model explains the validation experiment "
                f"less than {profile_name}'s (VAF {r.vaf_pct:.2f} % against "
                f"{r.vaf_profile_pct:.2f} %): longer experiments (identification.duration_s) "
                f"or a steadier hover, or keep {profile_name}'s model for this axis"
            )
        elif r.vaf_pct < 0.0:
            lines.append(
                f"warning: {r.axis}: the identified model explains the validation experiment "
                f"less than its mean does (VAF {r.vaf_pct:.2f} %): the experiments did not "
                "show this axis's dynamics through the hover's wander; identify again with "
                "longer experiments (identification.duration_s) or a steadier hover before "
                "flying this model"
            )
        elif not PLAUSIBLE_GAIN[0] < (gain := dc_gain(r.model)) < PLAUSIBLE_GAIN[1]:
            lines.append(
                f"warning: {r.axis}: the identified model's steady-state gain is {gain:.2f}, "
                "where a position loop holds 1: the experiments did not pin its slow response "
                "through the hover's wander; identify again with longer experiments "
                "(identification.duration_s) or a steadier hover, or keep "
                f"{profile_name}'s model for this axis"
            )
    return lines


@dataclass(frozen=True)
class IdentifyView:
    """The terminal of ``gcs identify``: ``console`` for its lines, ``err_console`` for the
    figures' "wrote" lines."""

    console: Console
    err_console: Console

    def checked(self, plan: IdentifyPlan) -> None:
        """What was checked and would be done (``--check``).

        Parameters
        ----------
        plan : IdentifyPlan
        """
        profile, settings, exps = plan.profile, plan.settings, plan.experiments
        if plan.run is not None:
            self.console.print(
                f"checked: {plan.run.path}, profile '{profile.name}'; nothing identified"
            )
            return
        assert exps is not None
        self.console.print(
            f"checked: profile '{profile.name}', {settings.excitation} on "
            f"{', '.join(exps.axes)}, two experiments of "
            f"{settings.n_samples(profile.t_ilc_s)} samples; nothing flown"
        )
        if plan.mocap is not None:
            self.console.print(f"checked: {plan.mocap.describe()}")
        for line in excitation_lines(exps, settings, profile.t_ilc_s, profile.arena):
            self.console.print(line, highlight=False)

    def started(self, plan: IdentifyPlan, run: RunDir) -> None:
        """The new run and its excitation.

        Parameters
        ----------
        plan : IdentifyPlan
        run : RunDir
        """
        settings, exps, t_ilc_s = plan.settings, plan.experiments, plan.profile.t_ilc_s
        assert exps is not None
        n = settings.n_samples(t_ilc_s)
        self.console.print(
            f"identification run [bold]{run.path}[/]: {settings.excitation} "
            + ", ".join(f"{settings.amplitude_for(a):g} m on {a}" for a in exps.axes)
            + ", two experiments of "
            f"{n} samples ({n * t_ilc_s:.1f} s) around {exps.center_ned_m.tolist()}"
        )

    def flight(self) -> tuple[Progress, Callable[[object], None]]:
        """The live progress of the flight and its event callback."""
        return live_progress(self.console)

    def say(self, text: str) -> None:
        """A set-up line of the flight session.

        Parameters
        ----------
        text : str
        """
        say(self.console)(text)

    def interrupted(self, run: RunDir) -> None:
        """Ctrl-C: no profile, the experiments are kept.

        Parameters
        ----------
        run : RunDir
        """
        self.console.print(f"interrupted; no profile written. The experiments are in {run.path}")

    def results(self, results: Sequence[AxisResult], profile_name: str) -> None:
        """The table and the models.

        Parameters
        ----------
        results : sequence of AxisResult
        profile_name : str
        """
        self.console.print(results_table(results, profile_name))
        for line in model_lines(results):
            self.console.print(line, highlight=False)
        for line in weaker_lines(results, profile_name):
            self.console.print(line, highlight=False, markup=False)

    def wrote_profile(self, path: Path, new: bool) -> None:
        """The profile written (``new``), or already there with the same bytes.

        Parameters
        ----------
        path : Path
        new : bool
        """
        if new:
            self.console.print(f"wrote profile {path}")
        else:
            self.console.print(f"profile {path} holds this result already")

    def wrote(self, path: Path) -> None:
        """A figure written.

        Parameters
        ----------
        path : Path
        """
        self.err_console.print(f"wrote {path}")


def excitation_lines(
    experiments: Experiments, settings: IdentifySettings, t_ilc_s: float, arena: Box
) -> list[str]:
    """What the experiments ask of the vehicle: amplitudes, the box they sweep and its
    distance to the arena's walls, and how long they fly.

    Parameters
    ----------
    experiments : Experiments
    settings : IdentifySettings
    t_ilc_s : float
        Sample time [s].
    arena : Box
    """
    sp = np.vstack(experiments.setpoints_ned_m)
    lo, hi = sp.min(axis=0), sp.max(axis=0)
    bounds = arena.bounds()
    gap = float(min(np.min(lo - bounds[:, 0]), np.min(bounds[:, 1] - hi)))
    n = settings.n_samples(t_ilc_s)
    amplitudes = ", ".join(f"{settings.amplitude_for(a):g} m on {a}" for a in experiments.axes)
    return [
        f"sized up: {settings.excitation} of {amplitudes} about the hover point "
        f"{np.round(experiments.center_ned_m, 2).tolist()}",
        f"sized up: the setpoints sweep north {lo[0]:.2f}..{hi[0]:.2f}, east {lo[1]:.2f}.."
        f"{hi[1]:.2f}, down {lo[2]:.2f}..{hi[2]:.2f} m; closest to the arena's walls "
        f"{gap:.2f} m",
        f"sized up: two experiments of {n * t_ilc_s:.1f} s each ({2 * n * t_ilc_s / 60:.1f} min "
        "of excitation, plus take-off, settling between them and landing)",
    ]
