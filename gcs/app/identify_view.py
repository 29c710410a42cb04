"""The terminal side of ``gcs identify``: fly or read the experiments, show and write the result."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from gcs.app.identify import (
    AxisResult,
    Experiments,
    IdentifyRequest,
    create_identification_run,
    fly_identification,
    identified_profile_text,
    identify_run,
    plan_experiments,
    run_axes,
    write_identification_plots,
    write_identified_profile,
)
from gcs.core.trajectory import Box
from gcs.errors import PathError, RunLogError
from gcs.io.atomic import write_once
from gcs.io.config import Profile, load_profile
from gcs.io.paths import check_new_dir, check_output_dir, check_output_file
from gcs.io.rundir import RunDir
from gcs.io.settings import IdentifySettings

__all__ = ["results_table", "model_lines", "identify_with_display", "excitation_lines"]


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
    """The identification result per axis as a rich table (fits an 80-column terminal).

    Columns: axis, order, delay [samples] and [s], dominant continuous pair (wn, zeta; Tustin),
    and on the validation experiment the VAF and NRMSE fit of the identified model and the VAF
    of the profile's model. :func:`model_lines` gives the transfer functions and poles.

    Parameters
    ----------
    results : sequence of AxisResult
        Identified axes.
    profile_name : str
        Name of the input profile (column title of the comparison).

    Returns
    -------
    Table
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
        Identified axes.

    Returns
    -------
    list of str
    """
    lines = []
    for r in results:
        delay_s = r.result.delay_samples * r.model.dt_s
        lines.append(
            f"{r.axis}: G(s) = ({_poly(r.num)}) / ({_poly(r.den)}) e^(-{delay_s:.2f} s); "
            f"poles z = {_poles(np.linalg.eigvals(r.model.A))}"
        )
    return lines


def identify_with_display(
    console: Console, err_console: Console, request: IdentifyRequest
) -> Path | None:
    """Fly the two experiments (or read them), identify, print, write profile and plots.

    Everything is validated first (profile, identification and flight settings, the
    excitation against the arena, the run, the output paths, the connection URL or the mock's
    settings); only then is a run created, a vehicle connected or PBSID run.

    Parameters
    ----------
    console : Console
        Terminal output.
    err_console : Console
        Where "wrote ..." lines go.
    request : IdentifyRequest
        The command's options.

    Returns
    -------
    Path or None
        The profile written (None with ``check_only``).
    """
    profile_path, axis, out, from_log, plot, seed = (
        request.profile, request.axis, request.out, request.from_log, request.plot, request.seed
    )  # fmt: skip
    connect, use_mock, mock_config, logs, run_path = (
        request.connect, request.use_mock, request.mock_config, request.logs, request.run
    )  # fmt: skip
    check_only, mocap = request.check_only, request.mocap
    if plot is not None:
        check_output_dir(plot, "--plot")
    if from_log is not None:
        run = RunDir.open(from_log)
        run.require_kind("identification", "gcs identify --from-log")
        if profile_path is None:
            profile: Profile = run.profile()
            where = f"{run.manifest_path}:profile"
        else:
            profile, where = load_profile(profile_path), str(profile_path)
        settings = profile.identification
        run_axes(run, axis)
        for j, what in ((0, "fitting"), (1, "validation")):
            if not run.status_path(j).exists():
                raise RunLogError(f"{run.path}: trial {j} ({what} experiment) is missing")
            run.read_trial(j)
        _check_target(out, run.path)
        if check_only:
            console.print(f"checked: {run.path}, profile '{profile.name}'; nothing identified")
            return None
    else:
        from gcs.app.fly_view import live_progress, say
        from gcs.app.session import check_mock_config, check_url, plan_mocap, vehicle_url

        path = profile_path or request.default_profile
        assert path is not None
        profile, where = load_profile(path), str(path)
        settings = profile.identification
        if seed is not None:
            settings = replace(settings, seed=int(seed))
        flight = profile.flight
        mocap_plan = plan_mocap(profile, where, mocap, use_mock)
        if use_mock and mock_config is None and mocap_plan is not None and not mocap_plan.source:
            from gcs.io.paths import resolve_named

            mock_config = resolve_named("mock-mocap", "profile", "--mock-config")
        experiments = plan_experiments(
            settings, profile.t_ilc_s, axis or "both", profile.arena, where
        )
        if run_path is not None:
            check_new_dir(run_path, "--run")
        else:
            check_output_dir(logs, "--logs")
        _check_target(out, None)
        if use_mock:
            check_mock_config(mock_config)
        else:
            check_url(str(connect))
        if check_only:
            console.print(
                f"checked: profile '{profile.name}', {settings.excitation} on "
                f"{', '.join(experiments.axes)}, two experiments of "
                f"{settings.n_samples(profile.t_ilc_s)} samples; nothing flown"
            )
            if mocap_plan is not None:
                console.print(f"checked: {mocap_plan.describe()}")
            for line in excitation_lines(experiments, settings, profile.t_ilc_s, profile.arena):
                console.print(line, highlight=False)
            return None
        run_root, run_id = (logs, None) if run_path is None else (run_path.parent, run_path.name)
        run = create_identification_run(run_root, profile, settings, experiments, run_id)
        n = settings.n_samples(profile.t_ilc_s)
        console.print(
            f"identification run [bold]{run.path}[/]: {settings.excitation} "
            + ", ".join(f"{settings.amplitude_for(a):g} m on {a}" for a in experiments.axes)
            + ", two experiments of "
            f"{n} samples ({n * profile.t_ilc_s:.1f} s) around {experiments.center_ned_m.tolist()}"
        )
        progress, on_event = live_progress(console)
        mock_seed = settings.seed if seed is None else seed
        try:
            with (
                vehicle_url(
                    connect, use_mock, mock_config, mock_seed, say(console), mocap_plan
                ) as (
                    url,
                    link,
                ),
                progress,
            ):
                fly_identification(url, run, flight, on_event, link)
        except KeyboardInterrupt:
            console.print(f"interrupted; no profile written. The experiments are in {run.path}")
            raise
    results = identify_run(run, settings, profile, axis)
    console.print(results_table(results, profile.name))
    for line in model_lines(results):
        console.print(line, highlight=False)
    target = Path(out) if out is not None else run.identified_path
    text = identified_profile_text(
        profile, results, str(run.path), str(target), run.manifest.get("created_utc")
    )
    if _in_run(target, run.path):  # the run's own record: written once, never replaced
        if write_once(target, text):
            console.print(f"wrote profile {target}")
        else:
            console.print(f"profile {target} holds this result already")
    else:
        write_identified_profile(target, text)
        console.print(f"wrote profile {target}")
    if plot is not None:
        for p in write_identification_plots(results, profile, plot):
            err_console.print(f"wrote {p}")
    return target


def _in_run(target: Path, run_path: Path) -> bool:
    return target.absolute().parent.resolve() == run_path.absolute().resolve()


def _check_target(out: Path | None, run_path: Path | None) -> None:
    """``--out`` (or the default in the run directory) can be written."""
    if out is None:
        if run_path is not None:  # identifying an existing run again: it must take the file
            RunDir.open(run_path).check_writable()
        return
    if run_path is not None and _in_run(out, run_path):
        if out.name != RunDir.IDENTIFIED_FILE:
            raise PathError(
                f"--out {out}: inside the run directory only {RunDir.IDENTIFIED_FILE} is written"
            )
        RunDir.open(run_path).check_writable()
        return
    check_output_file(out, "--out")


def excitation_lines(
    experiments: Experiments, settings: IdentifySettings, t_ilc_s: float, arena: Box
) -> list[str]:
    """What identification asks of the vehicle, before it flies: the excitation's amplitude
    per axis, the box both experiments sweep and its closest distance to the arena's walls,
    and how long it flies.

    Parameters
    ----------
    experiments : Experiments
        From :func:`gcs.app.identify.plan_experiments`.
    settings : IdentifySettings
        The profile's identification settings.
    t_ilc_s : float
        Sample time [s].
    arena : Box
        The arena.

    Returns
    -------
    list of str
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
