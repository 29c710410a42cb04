"""The identified profile: the input profile's YAML with the identified models, written."""

from __future__ import annotations

import copy
from collections.abc import Sequence
from pathlib import Path

import yaml

from gcs.app.identify_fit import AxisResult
from gcs.app.identify_plan import in_run
from gcs.errors import IdentificationError, ProfileError
from gcs.io.atomic import atomic_write_text, write_once
from gcs.io.config import Profile, profile_from_dict

__all__ = ["identified_profile_text", "write_identified_profile", "write_profile"]


def identified_profile_text(
    profile: Profile,
    results: Sequence[AxisResult],
    origin: str,
    where: str = "<out>",
    recorded_utc: str | None = None,
) -> str:
    """The input profile's YAML with the identified models in ``model`` / ``model_y`` /
    ``model_z``, checked by loading it.

    An axis not identified keeps the input profile's model. The text depends on the data and
    the settings only (no clock), so the run's own ``identified.yaml`` is written once.

    Parameters
    ----------
    profile : Profile
        The input profile (its ``source`` is copied).
    results : sequence of AxisResult
    origin : str
        Where the data came from (the run directory), for the header and ``description``.
    where : str
        Name in error messages if the result does not load.
    recorded_utc : str or None
        When the experiments were flown (the run's ``created_utc``), for the header.
    """
    data = copy.deepcopy(profile.source)
    old_x = copy.deepcopy(data["model"])
    old_y = copy.deepcopy(data.get("model_y", data["model"]))
    by_axis = {r.axis: r for r in results}
    data["model"] = by_axis["x"].model.as_dict() if "x" in by_axis else old_x
    data["model_y"] = by_axis["y"].model.as_dict() if "y" in by_axis else old_y
    if "z" in by_axis:
        data["model_z"] = by_axis["z"].model.as_dict()
    name = str(data.get("name", profile.name))
    summary = ", ".join(
        f"{r.axis}: order {r.result.order}, delay {r.result.delay_samples}, VAF {r.vaf_pct:.1f} %"
        for r in results
    )
    data["name"] = name if name.endswith("-identified") else f"{name}-identified"
    data["description"] = (
        f"Profile '{name}' with the closed-loop models identified by gcs identify (PBSID-opt) "
        f"from {origin} (trial 0 fit, trial 1 validation; {summary})."
    )
    keys = ("name", "description", "t_ilc_s", "model", "model_y", "model_z")
    ordered = {k: data[k] for k in keys if k in data}
    ordered.update({k: v for k, v in data.items() if k not in ordered})
    flown = f" (experiments flown {recorded_utc})" if recorded_utc else ""
    header = (
        f"# Written by 'gcs identify' from {origin}{flown}.\n"
        f"# model / model_y / model_z: identified discrete state spaces at t_ilc_s = "
        f"{profile.t_ilc_s:g} s\n"
        "# (x(k+1) = A x(k) + B u(k - delay_samples), y = C x; u setpoint, y position, both\n"
        "# relative to the hover point [m]). Everything else is the input profile's.\n"
    )
    text = header + yaml.safe_dump(ordered, sort_keys=False, default_flow_style=None, width=100)
    try:
        profile_from_dict(yaml.safe_load(text), where)
    except ProfileError as exc:
        raise IdentificationError(f"the identified profile does not load: {exc}") from None
    return text


def write_identified_profile(path: Path, text: str) -> Path:
    """Write the profile text atomically, its directories created.

    Parameters
    ----------
    path : Path
    text : str
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, text)
    return path


def write_profile(target: Path, run_path: Path, text: str) -> bool:
    """Write the profile; in the run directory once (False: it holds these bytes already).

    Parameters
    ----------
    target : Path
    run_path : Path
        The identification run.
    text : str
    """
    if in_run(target, run_path):  # the run's own record: written once, never replaced
        return write_once(target, text)
    write_identified_profile(target, text)
    return True
