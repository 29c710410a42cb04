"""What learning writes into a run directory, and reads back: estimates, next setpoints,
decision records, refreshed models and the floor.

:class:`LearnLog` holds these files' methods; :class:`gcs.io.rundir.RunDir` has them (it
derives from it), so that a run is one object and each room of code has one purpose.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from gcs.core.model import DiscreteModel
from gcs.errors import RunLogError
from gcs.io.atomic import write_once
from gcs.io.config import profile_from_dict
from gcs.io.records import (
    ESTIMATE_COLUMNS,
    ESTIMATE_DOWN_COLUMNS,
    check_plausible,
    csv_text,
    is_number,
    json_text,
    read_csv,
    read_json,
)
from gcs.io.yamlfile import read_yaml

__all__ = ["LearnLog"]


class LearnLog:
    """The learning files of a run directory (a base of :class:`gcs.io.rundir.RunDir`).

    It relies on the run's ``path``, ``n_samples``, ``t_ilc_s``, the names of its files
    (``estimate_path``, ``learn_path``, ``model_path``, ``floor_path``, ``setpoints_path``,
    ``_numbered``: the run names its own files) and its setpoints (``_setpoints_text``,
    ``write_setpoints``, ``read_setpoints``).
    """

    path: Path
    n_samples: int
    t_ilc_s: float

    # ----------------------------------------------------------------- estimates
    def write_estimate(self, j: int, d_hat_ne_m: np.ndarray, p_ne_m2: np.ndarray) -> None:
        """Write the disturbance estimate learned from trial j.

        ``j``: trial index the estimate was learned from. ``d_hat_ne_m``: estimate of d(1..N), north
        and east, learning coordinates [m]. ``p_ne_m2``: its error variance [m^2] (K-ILC: the
        filter's scalar, repeated).
        """
        write_once(self.estimate_path(j), self._estimate_text(d_hat_ne_m, p_ne_m2))

    def _estimate_text(self, d_hat_ne_m: np.ndarray, p_ne_m2: np.ndarray) -> str:
        k = np.arange(1, self.n_samples + 1)
        d, p = np.asarray(d_hat_ne_m), np.asarray(p_ne_m2)
        table = np.column_stack([k, k * self.t_ilc_s, d[:, :2], p[:, :2], d[:, 2:], p[:, 2:]])
        columns = ESTIMATE_COLUMNS + (ESTIMATE_DOWN_COLUMNS if d.shape[1] == 3 else ())
        return csv_text(columns, table)

    def write_learned(
        self, j: int, d_hat_ne_m: np.ndarray, p_ne_m2: np.ndarray, sp_ned_m: np.ndarray
    ) -> Path:
        """Record what was learned from trial j: its estimate, then trial j+1's setpoints.

        Both files are checked first: if either exists with other content nothing is
        written (refused), so that a refusal never leaves one of the two behind. The setpoints
        come last: they are what says the next trial can be flown.

        ``j``: trial learned from. ``sp_ned_m``: setpoints of trial j+1, as :meth:`write_setpoints`.
        """
        for path, text in (
            (self.estimate_path(j), self._estimate_text(d_hat_ne_m, p_ne_m2)),
            (self.setpoints_path(j + 1), self._setpoints_text(j + 1, sp_ned_m)),
        ):
            if path.exists() and path.read_bytes() != text.encode("utf-8"):
                raise RunLogError(
                    f"{path}: exists with different content; recorded data are never rewritten"
                )
        self.write_estimate(j, d_hat_ne_m, p_ne_m2)
        return self.write_setpoints(j + 1, sp_ned_m)

    # ----------------------------------------------------------------- learning with history
    def write_repeat(self, j: int) -> Path:
        """Trial j repeats trial 0: its setpoints are ``setpoints-000.csv``'s, byte for byte.

        ``j``: the repeating trial (``>= 1``).
        """
        if j < 1:
            raise RunLogError(f"trial {j} cannot repeat trial 0")
        return self.write_setpoints(j, self.read_setpoints(0))

    def write_plan(
        self,
        j: int,
        d_hat_ne_m: np.ndarray,
        p_ne_m2: np.ndarray,
        record: dict[str, Any],
        sp_ned_m: np.ndarray,
        model_text: str | None = None,
        floor: dict[str, Any] | None = None,
    ) -> Path:
        """Record a learning step from trials 0..j, in an order an interruption cannot break.

        ``model-JJJ.yaml`` (when a model was refreshed), ``floor.json`` (when the floor is
        known), ``estimate-JJJ.csv``, ``learn-JJJ.json``, and last ``setpoints-(J+1).csv``:
        the setpoints are what says the next trial can be flown, and learning again from trial
        j writes the same bytes, so an interrupted step is completed by learning again. Every
        file is checked first: if one exists with other content nothing is written.

        ``j``: the newest trial learned from. ``record``: the decision record (JSON-ready; NaN
        becomes null); its ``trial`` must be ``j``. ``sp_ned_m``: setpoints of trial j+1, as
        :meth:`write_setpoints`. ``model_text``: a profile (YAML) with the refreshed models.
        ``floor``: the floor (JSON-ready), with the trials it was measured from.
        """
        if record.get("trial") != j:
            raise RunLogError(f"learning record of trial {j} names trial {record.get('trial')!r}")
        files = [
            (self.model_path(j), model_text),
            (self.floor_path, None if floor is None else json_text(floor)),
            (self.estimate_path(j), self._estimate_text(d_hat_ne_m, p_ne_m2)),
            (self.learn_path(j), json_text(record)),
            (self.setpoints_path(j + 1), self._setpoints_text(j + 1, sp_ned_m)),
        ]
        files = [(path, text) for path, text in files if text is not None]
        for path, text in files:
            if path.exists() and path.read_bytes() != text.encode("utf-8"):
                raise RunLogError(
                    f"{path}: exists with different content; recorded data are never rewritten"
                )
        for path, text in files:
            write_once(path, text)
        return files[-1][0]

    def read_learn_record(self, j: int) -> dict[str, Any]:
        """The decision record ``learn-JJJ.json`` of the learning step from trial j.

        ``j``: the newest trial that step learned from.

        Returns: ``trial``, ``next_trial``, ``next_iteration``, ``learned_from``, ``models_from``,
        ``model_file``, ``setpoints`` and ``decision`` (the record of
        :func:`gcs.core.learning.plan_next_trial`), each checked against its type.
        """
        path = self.learn_path(j)
        if not path.exists():
            raise RunLogError(f"{path}: missing; trial {j + 1} was learned without its record")
        data = read_json(path, "learning record")
        return _check_learn_record(path, j, self.model_path(j).name, data)

    def learn_records(self) -> dict[int, dict[str, Any]]:
        """Every decision record of the run, by the trial it learned from."""
        return {j: self.read_learn_record(j) for j in self._numbered("learn", "json")}

    def read_model(self, j: int) -> tuple[DiscreteModel, DiscreteModel]:
        """The (north, east) models refreshed when learning from trial j (``model-JJJ.yaml``).

        The file must be a loadable profile, and its models the ones ``learn-JJJ.json``
        records (the file agrees with the record of the step that wrote it).

        ``j``: the trial learned from.
        """
        path, learn = self.model_path(j), self.learn_path(j).name
        record = self.read_learn_record(j)
        if record["model_file"] is None:
            raise RunLogError(f"{path}: {learn} records no refreshed model")
        if not path.exists():
            raise RunLogError(f"{path}: missing, but {learn} records a refreshed model")
        models = profile_from_dict(read_yaml(path, RunLogError), str(path)).models()
        for a, (name, model) in enumerate(zip(("north", "east"), models, strict=True)):
            refresh = record["decision"]["axes"][a]["refresh"]
            recorded = refresh.get("model") if isinstance(refresh, dict) else None
            if not _same_model(model, recorded):
                raise RunLogError(
                    f"{path}: its {name} model is not the one {learn} records; the "
                    "files do not belong together"
                )
        return models

    def read_floor(self) -> dict[str, Any] | None:
        """The floor recorded in ``floor.json`` (None before it is measured).

        Returns: ``trials`` (the flights of identical setpoints), ``epos_m``, ``scatter_m`` and the
        rest of :meth:`gcs.core.floor.Floor.as_dict`.
        """
        path = self.floor_path
        if not path.exists():
            return None
        data = read_json(path, "floor record")
        trials = data.get("trials") if isinstance(data, dict) else None
        if not (
            isinstance(trials, list)
            and len(trials) >= 2
            and all(isinstance(t, int) and not isinstance(t, bool) for t in trials)
        ):
            raise RunLogError(f"{path}: field 'trials' must list two or more trial numbers")
        for key in ("epos_m", "scatter_m"):
            if not is_number(data.get(key)):
                raise RunLogError(f"{path}: field '{key}' must be a number, got {data.get(key)!r}")
        return data

    def read_estimate(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """The estimate learned from trial j: ``(d_hat (N, n) [m], p (N, n) [m^2])``, n = 2
        (north, east) or 3 when down was learned.
        """
        path = self.estimate_path(j)
        if not path.exists():
            raise RunLogError(f"{path}: no estimate for trial {j} (run 'gcs learn' on it)")
        table = read_csv(path, ESTIMATE_COLUMNS, ESTIMATE_DOWN_COLUMNS)
        if table.shape[0] != self.n_samples or not np.all(np.isfinite(table)):
            raise RunLogError(f"{path}: expected {self.n_samples} finite rows")
        columns = (ESTIMATE_COLUMNS + ESTIMATE_DOWN_COLUMNS)[2 : table.shape[1]]
        check_plausible(path, table[:, 2:], columns)
        if table.shape[1] == len(ESTIMATE_COLUMNS):
            return table[:, 2:4], table[:, 4:6]
        return table[:, [2, 3, 6]], table[:, [4, 5, 7]]


def _check_learn_record(path: Path, j: int, model_file: str, data: Any) -> dict[str, Any]:
    """A ``learn-JJJ.json`` checked against its name and the types its readers rely on
    (``model_file``: the name of the model file it may name, ``model-JJJ.yaml``)."""
    if not isinstance(data, dict):
        raise RunLogError(f"{path}: malformed learning record (not a JSON object)")

    def fail(key: str, what: str) -> RunLogError:
        return RunLogError(f"{path}: field '{key}' {what}")

    if data.get("trial") != j or isinstance(data.get("trial"), bool):
        raise fail("trial", f"must be {j}, as the file's name says, got {data.get('trial')!r}")
    if data.get("next_trial") != j + 1:
        raise fail("next_trial", f"must be {j + 1}, got {data.get('next_trial')!r}")
    learned = data.get("learned_from")
    if learned != list(range(j + 1)):
        raise fail("learned_from", f"must list the trials 0..{j}, got {learned!r}")
    if not (isinstance(data.get("next_iteration"), int) and data["next_iteration"] >= 1):
        raise fail("next_iteration", f"must be an integer >= 1, got {data.get('next_iteration')!r}")
    named = data.get("model_file")
    if named not in (None, model_file):
        raise fail("model_file", f"must be null or '{model_file}', got {named!r}")
    decision = data.get("decision")
    if not isinstance(decision, dict):
        raise fail("decision", "must be an object")
    axes = decision.get("axes")
    if not (isinstance(axes, list) and len(axes) == 2 and all(isinstance(a, dict) for a in axes)):
        raise fail("decision.axes", "must be a list of two objects (north, east)")
    for a, axis in enumerate(axes):
        refresh = axis.get("refresh")
        if refresh is not None and not (
            isinstance(refresh, dict) and isinstance(refresh.get("accepted"), bool)
        ):
            raise fail(f"decision.axes[{a}].refresh", "must be null or an object with 'accepted'")
    refreshed = any(isinstance(a.get("refresh"), dict) and a["refresh"]["accepted"] for a in axes)
    if refreshed != (named is not None):
        raise fail("model_file", "must name the refreshed model exactly when one was refreshed")
    verdicts = decision.get("verdicts")
    if not (isinstance(verdicts, list) and all(isinstance(v, dict) for v in verdicts)):
        raise fail("decision.verdicts", "must be a list of objects")
    if not isinstance(decision.get("converged"), bool):
        raise fail("decision.converged", "must be true or false")
    for key in ("safeguard", "floor"):
        if decision.get(key) is not None and not isinstance(decision[key], dict):
            raise fail(f"decision.{key}", "must be an object or null")
    setpoints = data.get("setpoints")
    if not (isinstance(setpoints, dict) and all(is_number(setpoints.get(k)) for k in
                                                ("rms_m", "max_m"))):  # fmt: skip
        raise fail("setpoints", "must be an object with numbers 'rms_m' and 'max_m'")
    return data


def _same_model(model: DiscreteModel, recorded: Any) -> bool:
    """Whether ``model`` is the state space a learning record holds (None: the axis kept its
    model, which then only has to be a valid one)."""
    if recorded is None:
        return True
    if not isinstance(recorded, dict):
        return False
    try:
        same = all(
            np.array_equal(np.asarray(recorded[k], dtype=float), getattr(model, k))
            for k in ("A", "B", "C")
        )
    except (KeyError, TypeError, ValueError):
        return False
    return same and recorded.get("delay_samples") == model.delay_samples
