"""The truth behind the mock's position estimate, recorded for its statistics.

One record for the mock drone's MAVLink server (:mod:`gcs.mock.server`) and the simulated drone
of the virtual-clock tests (:mod:`gcs.sim.drone`): every :data:`TRUTH_PERIOD_S` of vehicle time,
the true position and velocity and the estimator's errors.
"""

from __future__ import annotations

from typing import Any

__all__ = ["TRUTH_PERIOD_S", "TruthRecord"]

TRUTH_PERIOD_S = 0.02
"""Period of the truth-and-error record in the statistics (vehicle time) [s]."""
_KEYS = (
    "t_vehicle_s", "north_m", "east_m", "down_m", "err_north_m", "err_east_m", "err_down_m",
    "err_vn_m_s", "err_ve_m_s", "err_vd_m_s", "vn_m_s", "ve_m_s", "vd_m_s",
)  # fmt: skip


class TruthRecord:
    """Rows of truth and estimator error of ``physics`` (none when it has no estimator)."""

    def __init__(self, physics: Any) -> None:
        self.physics = physics
        self.rows: dict[str, list[float]] | None = None
        if physics.estimator is not None:
            self.rows = {key: [] for key in _KEYS}
        self._next_t_s = 0.0

    def record(self) -> None:
        """Add a row when a period of vehicle time has passed since the last one."""
        ph = self.physics
        est = ph.estimator
        if self.rows is None or est is None or ph.t_s < self._next_t_s - 1e-9:
            return
        self._next_t_s = ph.t_s + TRUTH_PERIOD_S
        row = (ph.t_s, *ph.pos, *est.pos_err_m, *est.vel_err_m_s, *ph.vel)
        for key, value in zip(_KEYS, row, strict=True):
            self.rows[key].append(value)

    def stats(self, **extra: Any) -> dict[str, Any] | None:
        """The record for the statistics (None without an estimator), with ``extra`` keys."""
        if self.rows is None:
            return None
        return {"period_s": TRUTH_PERIOD_S, **extra, **self.rows}
