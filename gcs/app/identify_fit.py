"""PBSID on an identification run: per axis, fit on trial 0, validate on trial 1.

The numerics are :mod:`gcs.core.pbsid`'s. Row k of a trial holds the setpoint ``u(k)`` sent at
``k t_ilc_s`` and the position ``y(k)`` measured then; the models have no feedthrough, so
``u(k)`` acts on ``y(k+1)`` onwards. Both are taken relative to the hover point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gcs.app.identify_plan import require_experiment, run_axes, run_source
from gcs.core.model import DiscreteModel
from gcs.core.pbsid import (
    IdentificationResult,
    identify,
    natural_frequency_damping,
    nrmse_fit,
    simulate_free,
    to_continuous_tf,
    vaf,
)
from gcs.errors import IdentificationError, ModelError
from gcs.io.config import Profile
from gcs.io.records import TrialRecord
from gcs.io.rundir import RunDir
from gcs.io.settings import AXES, IdentifySettings

__all__ = ["AxisResult", "identify_run"]


@dataclass(frozen=True)
class AxisResult:
    """Identification and validation of one axis.

    Parameters
    ----------
    axis : str
        ``"x"`` (north), ``"y"`` (east) or ``"z"`` (down).
    result : IdentificationResult
        PBSID output (fitted on trial 0).
    vaf_pct, fit_pct : float
        VAF and NRMSE fit of the free-run simulation on the validation experiment [%].
    vaf_profile_pct : float
        VAF of the input profile's model on the same data [%] (NaN for z when the profile
        has no ``model_z``).
    t_s : ndarray, shape (M,)
        Validation time grid [s].
    u_val_m, y_val_m, y_sim_m : ndarray, shape (M,)
        Validation setpoint, measured and simulated position, relative to the hover point [m].
    wn_rad_s, zeta : float or None
        Dominant continuous pole pair (Tustin); None for a first-order model.
    num, den : ndarray
        Tustin transfer function (descending powers of s).
    """

    axis: str
    result: IdentificationResult
    vaf_pct: float
    fit_pct: float
    vaf_profile_pct: float
    t_s: np.ndarray
    u_val_m: np.ndarray
    y_val_m: np.ndarray
    y_sim_m: np.ndarray
    wn_rad_s: float | None
    zeta: float | None
    num: np.ndarray
    den: np.ndarray

    @property
    def model(self) -> DiscreteModel:
        """The identified model."""
        return self.result.model


def identify_run(
    run: RunDir,
    settings: IdentifySettings,
    profile: Profile,
    axis: str | None = None,
) -> list[AxisResult]:
    """Identify every axis of an identification run on trial 0 and validate it on trial 1.

    Raises :class:`RunLogError` for a run that is not an identification run or lacks
    complete trials, :class:`IdentificationError` for data PBSID refuses or an unstable model.

    Parameters
    ----------
    run : RunDir
    settings : IdentifySettings
        PBSID windows, order and delay search.
    profile : Profile
        Whose models are compared with the identified ones.
    axis : str or None
        Axes to identify (None: those the run excited).
    """
    axes = run_axes(run, axis)
    center = np.asarray(run_source(run)["center_ned_m"], dtype=float)
    trials = []
    for j in (0, 1):  # as identification measures them (the run's mocap.measurement)
        require_experiment(run, j)
        trials.append(run.measured_trial(j))
    fit_trial, val_trial = trials
    return [_axis(a, fit_trial, val_trial, center, run.t_ilc_s, settings, profile) for a in axes]


def _axis(
    a: str,
    fit_trial: TrialRecord,
    val_trial: TrialRecord,
    center: np.ndarray,
    t_ilc_s: float,
    settings: IdentifySettings,
    profile: Profile,
) -> AxisResult:
    c = AXES[a]
    u_fit = fit_trial.sp_ned_m[:, c] - center[c]
    y_fit = fit_trial.pos_ned_m[:, c] - center[c]
    u_val = val_trial.sp_ned_m[:, c] - center[c]
    y_val = val_trial.pos_ned_m[:, c] - center[c]
    try:
        res = identify(
            [(u_fit, y_fit)], t_ilc_s, past=settings.past, future=settings.future,
            order=settings.order, max_delay=settings.max_delay,
        )  # fmt: skip
    except IdentificationError as exc:
        raise IdentificationError(f"axis {a}, trial 0: {exc}") from None
    model = res.model
    if not model.is_stable():
        rho = float(np.max(np.abs(np.linalg.eigvals(model.A))))
        raise IdentificationError(
            f"axis {a}: the identified model is unstable (largest |pole| {rho:.3f}); "
            "excite longer or with more amplitude"
        )
    if np.ptp(u_val) <= 0.0:
        raise IdentificationError(f"axis {a}, trial 1: the validation input is constant")
    y_sim = simulate_free(model, u_val)
    prof_model = (*profile.models(), profile.model_z)[c]
    y_prof = None if prof_model is None else simulate_free(prof_model, u_val)
    try:
        wn, zeta = natural_frequency_damping(model)
    except ModelError:
        wn = zeta = None
    num, den, _ = to_continuous_tf(model)
    return AxisResult(
        axis=a,
        result=res,
        vaf_pct=vaf(y_val, y_sim),
        fit_pct=nrmse_fit(y_val, y_sim),
        vaf_profile_pct=float("nan") if y_prof is None else vaf(y_val, y_prof),
        t_s=val_trial.t_s,
        u_val_m=u_val,
        y_val_m=y_val,
        y_sim_m=y_sim,
        wn_rad_s=wn,
        zeta=zeta,
        num=num,
        den=den,
    )
