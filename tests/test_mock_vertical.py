"""The mock's vertical loop: PX4's cascade with its thrust and speed limits, calibrated on the
shared PX4 capture (``benchmarks/mock_vertical_calibration.py``); horizontal flight unchanged.
"""

from __future__ import annotations

import hashlib
import math
import struct
from pathlib import Path

from gcs.mock.config import MockConfig, load_mock_config
from gcs.mock.vehicle import Mode, Vehicle

ROOT = Path(__file__).resolve().parents[1]

# sha256 of horizontal_digest(cfg, seed=3) computed with the mock as it was before its vertical
# loop was calibrated: with the altitude held, the horizontal flight must not change by a bit.
HORIZONTAL_BEFORE = {
    "mock.yaml": "ce0aed09780245c3d1688c8341011e48d2e2ec00bcc788220fdb221f1a8367a2",
    "mock-gps.yaml": "740af97ee738d55cebf0f513933d51af13a49f03e0dd9641b931fd09153ded17",
}


def horizontal_digest(cfg: MockConfig, seed: int) -> str:
    """Arm, take off, fly an eight at a held altitude in OFFBOARD, land: north and east only."""
    v = Vehicle(cfg, seed)
    h = hashlib.sha256()
    v.arm(True)
    v.takeoff()
    for k in range(1, 2001):  # 40 s at 50 Hz
        t = k * 0.02
        if t >= 8.0 and k < 1900:
            if v.mode is not Mode.OFFBOARD:
                v.on_setpoint(t, (0.0, 0.0, -2.0), 0.0)
                v.set_mode(Mode.OFFBOARD)
            s = t - 8.0
            v.on_setpoint(t, (1.2 * math.sin(0.6 * s), 0.8 * math.sin(1.2 * s), -2.0), 0.0)
        if k == 1900:
            v.land()
        v.update(t)
        pos, vel = v.physics.measure()
        p, u = v.physics.pos, v.physics.vel
        h.update(struct.pack("<9d", v.t_s, p[0], p[1], u[0], u[1], pos[0], pos[1], vel[0], vel[1]))
    return h.hexdigest()


def test_horizontal_flight_at_a_held_altitude_is_bit_for_bit_as_before() -> None:
    for name, digest in HORIZONTAL_BEFORE.items():
        cfg = load_mock_config(ROOT / "profiles" / name)
        assert horizontal_digest(cfg, 3) == digest, name
