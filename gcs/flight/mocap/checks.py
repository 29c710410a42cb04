"""Pre-flight agreement of the motion capture and the vehicle (pure).

Two checks catch a wrong frame mapping before the manoeuvre does:

- :func:`pose_agreement_problem`: the vehicle's position estimate and the mocap position,
  mapped to NED, agree within a tolerance (catches a wrong origin, a wrong up axis, a wrong
  scale, or a vehicle whose estimate is not fed by this mocap);
- :func:`move_direction_problem`: a small commanded move went the commanded way in both the
  vehicle's estimate and the mocap. It catches what the first check cannot when the vehicle
  sits at the origin: a mirrored axis (left-handed mapping, east and west swapped), swapped
  axes or a yaw offset off by 90 or 180 degrees. A mirror along one axis is invisible to a
  move along the other, so fly one move per horizontal axis (north, then east).

A hovering vehicle wanders (PX4 SIH on vision: +-0.2-0.3 m), so single positions before and
after a move can show a 0.3 m move as 0.07 m. The move check therefore compares the means of a
window before and one after (:func:`window_mean`), and the move is made long enough to stand
out of the wander measured in the first window (:func:`move_length`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "pose_agreement_problem",
    "move_direction_problem",
    "moved_as_commanded",
    "window_mean",
    "move_length",
]

#: A move is at least this many times the hover's measured wander.
WANDER_FACTOR = 4.0


def _vec(value: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers (north, east, down), got {value!r}")
    return v


def pose_agreement_problem(
    est_pos_ned_m: np.ndarray, mocap_pos_ned_m: np.ndarray, tolerance_m: float = 0.1
) -> str | None:
    """Whether estimate and mocap disagree on where the vehicle is.

    Parameters
    ----------
    est_pos_ned_m : numpy.ndarray
        Vehicle's position estimate, shape (3,) [m, NED].
    mocap_pos_ned_m : numpy.ndarray
        Mocap position mapped to NED, shape (3,) [m].
    tolerance_m : float
        Largest accepted distance [m].

    Returns
    -------
    str or None
        Reason naming the distance and the largest axis, or None.
    """
    diff = _vec(mocap_pos_ned_m, "mocap_pos_ned_m") - _vec(est_pos_ned_m, "est_pos_ned_m")
    dist = float(np.linalg.norm(diff))
    if dist <= tolerance_m:
        return None
    axis = ("north", "east", "down")[int(np.argmax(np.abs(diff)))]
    return (
        f"mocap and vehicle estimate {dist:.2f} m apart (mostly {axis}; tolerance "
        f"{tolerance_m:.2f} m): check the mocap origin, up axis and that the vehicle uses it"
    )


def _went_wrong(
    cmd: np.ndarray, delta: np.ndarray, who: str, min_fraction: float, max_angle_deg: float
) -> str | None:
    size = float(np.linalg.norm(cmd))
    along = float(delta @ cmd) / size
    if along < min_fraction * size:
        if along < 0:
            return f"{who} moved {-along:.2f} m the opposite way"
        return f"{who} moved only {along:.2f} m of {size:.2f} m commanded"
    moved = float(np.linalg.norm(delta))
    angle = math.degrees(math.acos(min(1.0, along / moved)))
    if angle > max_angle_deg:
        return f"{who} moved {angle:.0f} deg off the commanded direction"
    return None


def moved_as_commanded(
    cmd_ned_m: np.ndarray,
    delta_ned_m: np.ndarray,
    min_fraction: float = 0.5,
    max_angle_deg: float = 45.0,
) -> bool:
    """Whether one displacement went the commanded way (the test of
    :func:`move_direction_problem` for one side).

    Parameters
    ----------
    cmd_ned_m : numpy.ndarray
        Commanded displacement, shape (3,) [m, NED].
    delta_ned_m : numpy.ndarray
        Displacement seen, shape (3,) [m, NED].
    min_fraction : float
        Least fraction of the command covered along it.
    max_angle_deg : float
        Largest angle to the command [deg].

    Returns
    -------
    bool
    """
    cmd = _vec(cmd_ned_m, "cmd_ned_m")
    delta = _vec(delta_ned_m, "delta_ned_m")
    return _went_wrong(cmd, delta, "", min_fraction, max_angle_deg) is None


def move_direction_problem(
    cmd_ned_m: np.ndarray,
    est_delta_ned_m: np.ndarray,
    mocap_delta_ned_m: np.ndarray,
    min_fraction: float = 0.5,
    max_angle_deg: float = 45.0,
) -> str | None:
    """Whether a commanded move went the commanded way in the estimate and in the mocap.

    Parameters
    ----------
    cmd_ned_m : numpy.ndarray
        Commanded displacement, shape (3,) [m, NED], e.g. 0.3 m north.
    est_delta_ned_m : numpy.ndarray
        Displacement seen by the vehicle's estimate, shape (3,) [m, NED].
    mocap_delta_ned_m : numpy.ndarray
        Displacement seen by the mocap after frame mapping, shape (3,) [m, NED].
    min_fraction : float
        Each must have covered at least this fraction of the command along it.
    max_angle_deg : float
        Largest accepted angle between a displacement and the command [deg].

    Returns
    -------
    str or None
        Reason (which side went wrong, and the likely cause), or None.
    """
    cmd = _vec(cmd_ned_m, "cmd_ned_m")
    if float(np.linalg.norm(cmd)) <= 0:
        raise ValueError("cmd_ned_m must be a non-zero move")
    est = _went_wrong(
        cmd, _vec(est_delta_ned_m, "est_delta_ned_m"), "vehicle estimate", min_fraction,
        max_angle_deg,
    )  # fmt: skip
    mocap = _went_wrong(
        cmd, _vec(mocap_delta_ned_m, "mocap_delta_ned_m"), "mocap", min_fraction, max_angle_deg
    )
    if mocap is not None and est is None:
        return (
            f"commanded move {_fmt(cmd)}: {mocap}, the vehicle estimate did not: "
            "the mocap frame mapping is wrong (mirrored or swapped axis, or yaw offset)"
        )
    if est is not None and mocap is None:
        return (
            f"commanded move {_fmt(cmd)}: {est}, the mocap did not: the vehicle's "
            "estimate is wrong (vision fed with another frame, or not fused)"
        )
    if est is not None:
        return f"commanded move {_fmt(cmd)}: {est}; {mocap}: the vehicle did not follow"
    return None


def _fmt(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:+.2f}" for x in v) + ") m NED"


def window_mean(pos_ned_m: np.ndarray) -> tuple[np.ndarray, float]:
    """Mean position of a window and its horizontal wander.

    Parameters
    ----------
    pos_ned_m : numpy.ndarray
        Positions, shape (N, 3) [m, NED]; rows with NaN are left out.

    Returns
    -------
    tuple
        Mean, shape (3,) [m], and the RMS horizontal distance from it [m].

    Raises
    ------
    ValueError
        No finite row.
    """
    pos = np.asarray(pos_ned_m, dtype=float).reshape(-1, 3)
    pos = pos[np.all(np.isfinite(pos), axis=1)]
    if pos.shape[0] == 0:
        raise ValueError("no finite position in the window")
    mean = pos.mean(axis=0)
    wander = float(np.sqrt(np.mean(np.sum((pos[:, :2] - mean[:2]) ** 2, axis=1))))
    return mean, wander


def move_length(check_move_m: float, wander_m: float, max_m: float = 1.0) -> float:
    """Length of the check move: the profile's, or :data:`WANDER_FACTOR` times the wander.

    Parameters
    ----------
    check_move_m : float
        The profile's ``mocap.check_move_m`` [m] (> 0).
    wander_m : float
        The hover's measured horizontal wander [m].
    max_m : float
        Longest move [m].

    Returns
    -------
    float
        ``min(max(check_move_m, WANDER_FACTOR * wander_m), max(max_m, check_move_m))`` [m].
    """
    return min(max(check_move_m, WANDER_FACTOR * wander_m), max(max_m, check_move_m))
