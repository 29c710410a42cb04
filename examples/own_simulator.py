"""A learner driving your own simulator: three axes, a plain Python plant, no files.

The "vehicle" is a second-order discrete loop per axis (setpoint -> position) that the model
describes only roughly, pushed by a wind that repeats every trial, with measurement noise.
The learner knows the model and the reference; after each trial it gets the setpoints flown
and the positions measured, and returns the next setpoints. e_pos (eq. 10, here over three
axes) falls trial by trial down to the noise.

Run: ``python examples/own_simulator.py``
"""

from __future__ import annotations

import numpy as np

from gcs import Box, Learner, LearnerSettings, from_transfer_function

DT_S = 0.05  # the learning grid [s]
N = 200  # samples per trial (10 s)


#: The vehicle's true loops per axis (natural frequency [rad/s], damping), which the learner
#: does not know: its model has wn = 1.4 rad/s, zeta = 0.7 on every axis.
TRUE_LOOPS = [(1.55, 0.65), (1.3, 0.8), (1.6, 0.75)]


def plant(u_m: np.ndarray, start_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Your simulator: positions y(1..N), shape (N, 3), for setpoints u(0..N-1) [m].

    Per axis a second-order loop (:data:`TRUE_LOOPS`, stepped exactly over each sample with
    the setpoint held), a repeatable disturbance (the same wind every trial) and 5 mm of white
    measurement noise.
    """
    t = np.arange(1, N + 1) * DT_S
    wind = np.column_stack([0.3 * np.sin(0.6 * t), -0.2 * np.cos(0.4 * t), 0.1 * np.sin(t)])
    y = np.empty((N, 3))
    for axis, (wn, zeta) in enumerate(TRUE_LOOPS):
        loop = from_transfer_function([wn**2], [1.0, 2 * zeta * wn, wn**2], 0.0, DT_S)
        x = np.zeros(loop.order)
        for k in range(N):
            x = loop.A @ x + loop.B[:, 0] * (u_m[k, axis] - start_m[axis])
            y[k, axis] = start_m[axis] + loop.C[0] @ x + wind[k, axis]
    return y + 0.005 * rng.standard_normal((N, 3))


def reference() -> np.ndarray:
    """yd(0..N), shape (N+1, 3), local NED [m]: a climbing circle from rest at (0, 0, -1)."""
    t = np.arange(N + 1) * DT_S
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / 2.0, 0.0, 1.0))  # starts at rest
    phase = 2 * np.pi * t / 10.0
    return np.column_stack(
        [ramp * np.sin(phase), ramp * (1.0 - np.cos(phase)), -1.0 - 0.5 * ramp * t / t[-1]]
    )


def main(trials: int = 8, seed: int = 0) -> list[float]:
    """Learn for ``trials`` trials; return e_pos [m] of each."""
    model = from_transfer_function([1.96], [1.0, 2.0, 1.96], 0.0, DT_S)  # wn 1.4, zeta 0.7
    settings = LearnerSettings(
        models=(model, model, model),
        axes=(0, 1, 2),  # north, east, down
        arena=Box(north_m=(-3.0, 3.0), east_m=(-3.0, 3.0), down_m=(-3.0, 0.0)),
        max_step_m=0.5,
    )
    ref = reference()
    learner = Learner(settings, ref)
    rng = np.random.default_rng(seed)
    u = ref[:-1].copy()  # trial 0 flies the reference itself
    errors = []
    for j in range(trials):
        y = plant(u, ref[0], rng)
        errors.append(float(np.mean(np.linalg.norm(y - ref[1:], axis=1))))
        print(f"trial {j}: e_pos = {errors[-1]:.4f} m")
        u = learner.step(u, y)
    return errors


if __name__ == "__main__":
    main()
