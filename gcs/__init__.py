"""gcs: a ground-control-station CLI that learns a repeated manoeuvre with smoother-based ILC.

The learning core as a Python library (no command line, files or MAVSDK needed)::

    from gcs import Learner
    learner = Learner.from_profile("antx", reference_m)   # (N+1, 2) north/east [m]
    u_next = learner.step(u_j, y_j)                        # (N, 2) each, once per trial

See docs/api.md. The names below are imported on first use, so that ``import gcs`` (the
command line, the mock drone's process) stays light.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

#: Public name -> module that defines it.
_API = {
    "Learner": "gcs.api",
    "learner_settings": "gcs.api",
    "profile_of": "gcs.api",
    "LearnerBatch": "gcs.core.learner",
    "LearnerStep": "gcs.core.learner",
    "Trial": "gcs.core.learner",
    "AdaptiveSettings": "gcs.core.learning",
    "LearnerSettings": "gcs.core.learning",
    "LearningRecord": "gcs.core.learning",
    "KilcSettings": "gcs.core.estimators",
    "KilcState": "gcs.core.estimators",
    "SmootherSettings": "gcs.core.estimators",
    "DiscreteModel": "gcs.core.model",
    "from_state_space": "gcs.core.model",
    "from_transfer_function": "gcs.core.model",
    "Box": "gcs.core.trajectory",
    "UpdateWeights": "gcs.core.update",
}

__all__ = sorted(_API)


def __getattr__(name: str) -> Any:
    if name in _API:
        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'gcs' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_API])
