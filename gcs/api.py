"""The public Python API: a learner made from a profile, and the learning core's names.

``from gcs import Learner``. The learning itself is pure numerics (:mod:`gcs.core.learner`);
this module adds what needs files: reading a profile (by packaged name or path, through
:mod:`gcs.io`) into the learner's settings. Nothing here needs MAVSDK or a terminal.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gcs.core import learner as _core
from gcs.core.estimators import KilcState
from gcs.core.floor import Floor
from gcs.core.learning import LearnerSettings
from gcs.core.model import DiscreteModel
from gcs.core.trajectory import Reference
from gcs.io.config import Profile, load_profile
from gcs.io.paths import resolve_named

__all__ = ["Learner", "learner_settings", "profile_of"]


def profile_of(profile: str | Path | Profile) -> Profile:
    """A profile given by packaged name (``"antx"``), path, or already loaded.

    Parameters
    ----------
    profile : str, Path or Profile
        What to load.

    Returns
    -------
    Profile

    Raises
    ------
    PathError, ProfileError
        No such profile; a bad field (named).
    """
    if isinstance(profile, Profile):
        return profile
    return load_profile(resolve_named(profile, "profile", "profile"))


def learner_settings(
    profile: str | Path | Profile, algorithm: str | None = None
) -> LearnerSettings:
    """The learning settings of a profile: the models of its learned axes (north and east, or
    with down), weights, Table I variances, arena and setpoint limits.

    Parameters
    ----------
    profile : str, Path or Profile
        Packaged name, path, or a loaded profile.
    algorithm : str, optional
        ``"smoother"`` or ``"kilc"``; default the profile's ``learning.algorithm``.

    Returns
    -------
    LearnerSettings
    """
    prof = profile_of(profile)
    ln = prof.learning
    return LearnerSettings(
        models=prof.learned_models(),
        algorithm=algorithm or ln.algorithm,
        weights=ln.weights,
        smoother=ln.smoother,
        kilc=ln.kilc,
        arena=prof.arena,
        max_step_m=ln.max_step_m,
        max_deviation_m=ln.max_deviation_m,
        axes=ln.axes,
        max_vertical_step_m=ln.max_vertical_step_m,
        max_vertical_deviation_m=ln.max_vertical_deviation_m,
    )


class Learner(_core.Learner):
    """Iterative learning of a repeated trajectory, one call per trial.

    The learner of :class:`gcs.core.learner.Learner` (its parameters, :meth:`step`,
    :attr:`history`, :attr:`floor`, :attr:`decisions`), plus :meth:`from_profile`.
    """

    @classmethod
    def from_profile(
        cls,
        profile: str | Path | Profile,
        reference_m: np.ndarray | Reference,
        algorithm: str | None = None,
        *,
        floor: Floor | None = None,
        models: tuple[DiscreteModel, ...] | None = None,
        kilc_states: tuple[KilcState, ...] | None = None,
        history: tuple[_core.Trial, ...] | list[_core.Trial] = (),
    ) -> Learner:
        """A learner with a profile's settings: Table I, or its ``learning.adaptive`` options
        and repeats when it has that section.

        Parameters
        ----------
        profile : str, Path or Profile
            Packaged name (``"antx"``, ``"antx-adaptive"``), path, or a loaded profile.
        reference_m : ndarray, shape (N+1, n_axes), or Reference
            Reference yd(0..N) of the learnt axes (``learning.axes``: north and east, or with
            down) [m] (a :class:`Reference`: the columns of its ``pos_ned_m`` the learner
            learns); row 0 is the start point.
        algorithm : str, optional
            ``"smoother"`` or ``"kilc"``; default the profile's.
        floor, models, kilc_states, history
            As for :class:`gcs.core.learner.Learner` (to resume a run).

        Returns
        -------
        Learner
        """
        prof = profile_of(profile)
        settings = learner_settings(prof, algorithm)
        ref = reference_m
        if isinstance(reference_m, Reference):
            ref = reference_m.pos_ned_m[:, settings.axes]
        ln = prof.learning
        return cls(
            settings, ref, ln.adaptive, ln.repeats,
            floor, models=models, kilc_states=kilc_states, history=history,
        )  # fmt: skip
