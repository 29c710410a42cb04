"""Pre-flight agreement of the motion capture and the vehicle (pure).

What a wrong frame mapping does in the air. gcs forwards the mocap, mapped to NED by the
profile's ``mocap:`` section, to the vehicle as external vision; EKF2 fuses it, so the
vehicle's position estimate *is* the mapped mocap (within centimetres), whatever the mapping.
So before arming the estimate agrees with the mocap under any mapping once EKF2 has settled,
and in the air, every commanded move shows alike in both. What a wrong mapping ``Q`` (mocap in
gcs's NED = ``Q`` times the truth) changes depends on where the vehicle's heading comes from:

- heading from the vision too (EKF2_EV_CTRL bit 3, no magnetometer or GPS: the usual indoor
  set-up, and the real-firmware lab here): a rotation about down (``yaw_offset_deg`` off by 90
  or 180 degrees, ``north_axis`` set to the other horizontal axis) rotates position and heading
  alike: the vehicle flies every command correctly *in the rotated frame*. Nothing on board or
  in the mocap contradicts it (a rotation about gravity is unobservable without a heading
  reference); what is wrong is only where the arena lies in the room. No check here can
  catch it, and none pretends to (docs/mocap.md says what was flown of it on PX4 v1.16 SIH);
- heading from the vehicle's own compass (the mock drone, or a vehicle with EKF2_MAG_TYPE on
  and no vision yaw): the position loop is rotated by ``Q``: at 180 degrees it pushes away
  from the setpoint, at 90 degrees it spirals out; the estimate then runs against the vehicle's
  own velocity and the fence's consistency watch ends the flight while the vehicle settles for
  this check, before any move;
- a mirror (``right_handed: false``, or north and east swapped, which is a mirror) is refused
  by the configuration before anything starts (every supported system is right-handed);
- a wrong up axis puts the height on a horizontal axis: the estimate, fed from it, is
  contradicted by the accelerometers; the agreement check catches it when the vehicle stands
  away from the mocap origin, and this check (the mocap against the estimate, in 3-D) when
  another bridge feeds the vision.

What a flight check *can* judge is therefore (1) whether the mocap, as gcs maps it, moves with
the vehicle's estimate (the frame the vehicle flies in): it differs when another bridge feeds
the vision (``mocap.forward: false``) with another mapping, or the estimate is not fed by this
mocap; and (2) whether the vehicle follows the commands in its own estimate. Both are judged by
:func:`frame_check` from hover windows at home, a move north, home, a move east, home:

- (1) the mocap regressed on the estimate, sample by sample (``mocap = c + d t + G est``):
  the hover's wander moves both alike, so it is excitation here, not noise; each horizontal
  column of ``G`` must point along its axis (within :data:`MAX_MAPPING_ANGLE_DEG`, gain at
  least :data:`MIN_GAIN`). This is what refuses a wrong mapping; wander cannot imitate it as
  long as both sources are placed on one clock. Known limit: the estimate's samples carry
  their receipt times, which a loaded machine delays by up to hundreds of milliseconds; on
  PX4 SIH at load 8-20 that turned the wander into 10-45 degrees between the sources and a
  false refusal (docs/mocap.md). When gcs itself forwards the mocap (``mocap.forward``, the
  default) the estimate *is* the mapped mocap, so (1) can refuse no wrong mapping there, only
  a right one on that timing: it is then computed for the record and not judged
  (``judge_mapping=False``).
- (2) the estimate regressed on the commanded displacement, with an offset and a drift term
  (the three home windows bracket the moves, so a slow linear drift of the hover cancels):
  the fitted displacement per commanded move must cover :data:`MIN_GAIN` of it within
  :data:`MAX_FOLLOW_ANGLE_DEG`. A hover that wanders by decimetres around a linear drift can
  imitate a failure of a move of the same size: with a wander bounded by a quarter of the move
  the fit is never off by more than half of it (tested), and when the wander left about the fit
  (RMS) is above a quarter of the move a failure is not conclusive (``following`` is
  ``"unjudged"``): the caller flies it again with a longer move rather than abort a good
  vehicle on its wander.

:func:`move_direction_problem` (two windows, one move) is the earlier judgement, kept for the
live tests of the NatNet path; :func:`window_mean` and :func:`move_length` serve both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "pose_agreement_problem",
    "origin_shift_problem",
    "ORIGIN_SHIFT_TOLERANCE_M",
    "move_direction_problem",
    "moved_as_commanded",
    "window_mean",
    "move_length",
    "Response",
    "FrameCheck",
    "frame_check",
    "MIN_GAIN",
    "MAX_FOLLOW_ANGLE_DEG",
    "MAX_MAPPING_ANGLE_DEG",
]

#: A move is at least this many times the hover's measured wander.
WANDER_FACTOR = 4.0
#: Least fitted displacement along a commanded move (or along the estimate's motion), per metre.
MIN_GAIN = 0.5
#: Largest angle between the estimate's fitted displacement and the commanded one [deg].
MAX_FOLLOW_ANGLE_DEG = 45.0
#: Largest angle between the mocap's fitted motion and the estimate's, per axis [deg].
MAX_MAPPING_ANGLE_DEG = 30.0
#: Least spread [m] of the estimate along each horizontal axis for the mapping to be judged.
MIN_EXCITATION_M = 0.05
#: How close to the global origin's altitude the estimate's height error must be for the
#: origin to be named as its cause [m] (the jump comes with EKF2's own height error before
#: vision is fused: 1.5 m on the SIH firmware).
ORIGIN_SHIFT_TOLERANCE_M = 2.0


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


def origin_shift_problem(
    est_pos_ned_m: np.ndarray, mocap_pos_ned_m: np.ndarray, origin_alt_m: float
) -> str | None:
    """Whether the estimate's height is off by the global origin's altitude.

    PX4 v1.16's EKF2 moves its local height by the origin's altitude when it takes the origin
    before it has a valid height, and again at a start or reset of its vision height under an
    origin above 0 m (docs/mocap.md); the local position then stays that far down for good.

    Parameters
    ----------
    est_pos_ned_m : numpy.ndarray
        Vehicle's position estimate, shape (3,) [m, NED].
    mocap_pos_ned_m : numpy.ndarray
        Mocap position mapped to NED, shape (3,) [m].
    origin_alt_m : float
        Altitude of the vehicle's global origin, AMSL [m].

    Returns
    -------
    str or None
        Reason naming the offset, the origin and what to do, or None (the offset is not the
        origin's altitude, or that altitude is too small to tell).
    """
    below_m = float(_vec(est_pos_ned_m, "est_pos_ned_m")[2] - _vec(mocap_pos_ned_m, "mocap")[2])
    if abs(origin_alt_m) <= 2 * ORIGIN_SHIFT_TOLERANCE_M:
        return None
    if abs(below_m - origin_alt_m) > ORIGIN_SHIFT_TOLERANCE_M:
        return None
    return (
        f"the vehicle's estimate is {below_m:.1f} m below the mocap, its global origin's "
        f"altitude ({origin_alt_m:g} m): PX4 moved its local height by the origin's altitude "
        "(origin taken before EKF2 had a vision height, or a vision height reset since) and "
        "does not recover: restart PX4 and let gcs set the origin (at 0 m)"
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


@dataclass(frozen=True)
class Response:
    """A fitted displacement against the one it should follow.

    Parameters
    ----------
    gain : float
        Fitted displacement along the reference, per metre of the reference.
    angle_deg : float
        Angle between the fitted 3-D displacement and the reference's direction [deg].
    """

    gain: float
    angle_deg: float


@dataclass(frozen=True)
class FrameCheck:
    """What :func:`frame_check` found.

    Parameters
    ----------
    cmd_ned_m : tuple of tuple of float
        The commanded displacements from home, one per move [m, NED].
    estimate : tuple of Response
        The estimate's fitted displacement against each commanded one.
    mocap : tuple of Response
        The mocap's fitted displacement against each commanded one (for the record).
    mapping : tuple of Response
        The mocap's fitted motion against the estimate's along north and along east.
    rotation_deg : float
        Horizontal rotation of the mocap's motion against the estimate's [deg], from north
        towards east.
    mirrored : bool
        The mocap's horizontal motion is a mirror image of the estimate's.
    wander_m : float
        The hover's wander [m]: the estimate's largest horizontal distance from the drift
        line of the windows at home, or from its own window's mean.
    following : str
        ``"ok"``, ``"failed"`` (conclusively) or ``"unjudged"`` (the estimate's fit failed
        but the wander is above a quarter of the shortest move: not conclusive).
    problem : str or None
        The reason to refuse the flight, or None.
    mapping_judged : bool
        Whether the mapping was judged in both horizontal directions. False when it was not
        to be judged (``judge_mapping=False``), and when the estimate moved along one
        direction only (less than :data:`MIN_EXCITATION_M` RMS across it) inside a wander
        too large for the following to be judged: the mapping was then judged along that
        direction alone, and a mirror or a swap across it cannot show (the campaign flies
        the check once more with longer moves, then refuses).
    """

    cmd_ned_m: tuple[tuple[float, float, float], ...]
    estimate: tuple[Response, ...]
    mocap: tuple[Response, ...]
    mapping: tuple[Response, ...]
    rotation_deg: float
    mirrored: bool
    wander_m: float
    following: str
    problem: str | None
    mapping_judged: bool = True

    def as_record(self) -> dict:
        """The figures as plain numbers (for the session record).

        Returns
        -------
        dict
        """

        def rows(rs: tuple[Response, ...]) -> list[dict]:
            return [{"gain": round(r.gain, 4), "angle_deg": round(r.angle_deg, 2)} for r in rs]

        return {
            "cmd_ned_m": [list(c) for c in self.cmd_ned_m],
            "estimate": rows(self.estimate),
            "mocap": rows(self.mocap),
            "mapping": rows(self.mapping),
            "rotation_deg": round(self.rotation_deg, 2),
            "mirrored": self.mirrored,
            "wander_m": round(self.wander_m, 4),
            "following": self.following,
            "problem": self.problem,
            "mapping_judged": self.mapping_judged,
        }


def _response(displacement: np.ndarray, reference: np.ndarray) -> Response:
    size = float(np.linalg.norm(reference))
    along = float(displacement @ reference) / size
    moved = float(np.linalg.norm(displacement))
    cos = along / moved if moved > 0 else 0.0
    return Response(along / size, math.degrees(math.acos(max(-1.0, min(1.0, cos)))))


def _in_windows(t_s: np.ndarray, windows_t_s: np.ndarray) -> np.ndarray:
    """Index of the window each time falls in, -1 outside every window."""
    which = np.full(t_s.shape, -1)
    for k, (a, b) in enumerate(windows_t_s):
        which[(t_s >= a) & (t_s <= b)] = k
    return which


def _design(t_s: np.ndarray, which: np.ndarray, cmd: np.ndarray, moves: list[int]) -> np.ndarray:
    """Columns: 1, drift (when two windows at home bracket the moves), one per move."""
    home = [k for k in range(len(cmd)) if not np.any(cmd[k])]
    cols = [np.ones_like(t_s)]
    if len(home) >= 2:
        span = max(float(np.ptp(t_s)), 1e-9)
        cols.append((t_s - float(np.mean(t_s))) / span)
    for m in moves:
        cols.append(np.all(cmd[which] == cmd[m], axis=1).astype(float))
    return np.column_stack(cols)


def _wander(t_s: np.ndarray, est: np.ndarray, which: np.ndarray, cmd: np.ndarray) -> float:
    """The hover's wander: the largest horizontal distance of a sample at home from the home
    windows' drift line, or of any sample from its own window's mean [m]."""
    home = ~np.any(cmd[which] != 0, axis=1)
    x = _design(t_s[home], which[home], cmd, [])
    coef, *_ = np.linalg.lstsq(x, est[home, :2], rcond=None)
    worst = float(np.max(np.linalg.norm(est[home, :2] - x @ coef, axis=1)))
    for k in np.unique(which):
        pos = est[which == k, :2]
        worst = max(worst, float(np.max(np.linalg.norm(pos - pos.mean(axis=0), axis=1))))
    return worst


def _finite(t_s: np.ndarray, pos: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(t_s, dtype=float).reshape(-1)
    p = np.asarray(pos, dtype=float).reshape(-1, 3)
    if t.shape[0] != p.shape[0]:
        raise ValueError(f"{name}: {t.shape[0]} times for {p.shape[0]} positions")
    ok = np.isfinite(t) & np.all(np.isfinite(p), axis=1)
    return t[ok], p[ok]


def frame_check(
    t_est_s: np.ndarray,
    est_ned_m: np.ndarray,
    t_mocap_s: np.ndarray,
    mocap_ned_m: np.ndarray,
    windows_t_s: np.ndarray,
    cmd_ned_m: np.ndarray,
    judge_mapping: bool = True,
) -> FrameCheck:
    """Judge the frame from hover windows at home and at commanded moves (module docstring).

    Parameters
    ----------
    t_est_s : numpy.ndarray
        Times of the estimate's samples, shape (N,) [s] (the same clock as the windows').
    est_ned_m : numpy.ndarray
        The vehicle's position estimate, shape (N, 3) [m, NED].
    t_mocap_s : numpy.ndarray
        Times of the mocap's samples, shape (M,) [s].
    mocap_ned_m : numpy.ndarray
        The mocap mapped to NED, shape (M, 3) [m]; NaN rows (untracked) are left out.
    windows_t_s : numpy.ndarray
        Start and end of each hover window, shape (K, 2) [s]; samples outside every window
        are not used.
    cmd_ned_m : numpy.ndarray
        Commanded displacement from home during each window, shape (K, 3) [m]: zero at home.
        At least one window at home and one move; two windows at home or more add a drift term.
    judge_mapping : bool
        Judge (1), the mocap against the estimate. False when gcs forwards this mocap to the
        vehicle: the estimate is then the mapped mocap under any mapping, so (1) can find no
        wrong mapping and only a false one from the sources' receipt times on a loaded
        machine; its figures are still computed for the record.

    Returns
    -------
    FrameCheck

    Raises
    ------
    ValueError
        Shapes, no window at home, no move, or a window without samples of either source.
    """
    windows = np.asarray(windows_t_s, dtype=float).reshape(-1, 2)
    cmd = np.asarray(cmd_ned_m, dtype=float).reshape(-1, 3)
    if windows.shape[0] != cmd.shape[0]:
        raise ValueError(f"{windows.shape[0]} windows for {cmd.shape[0]} commands")
    if not np.all(np.isfinite(windows)) or not np.all(np.isfinite(cmd)):
        raise ValueError("windows_t_s and cmd_ned_m must be finite")
    at_home = ~np.any(cmd != 0, axis=1)
    moves: list[int] = []
    for k in np.flatnonzero(~at_home):
        if not any(np.array_equal(cmd[k], cmd[m]) for m in moves):
            moves.append(int(k))
    if not at_home.any() or not moves:
        raise ValueError("the windows need one at home (zero command) and one move")
    t_e, est = _finite(t_est_s, est_ned_m, "est_ned_m")
    t_m, moc = _finite(t_mocap_s, mocap_ned_m, "mocap_ned_m")
    w_e, w_m = _in_windows(t_e, windows), _in_windows(t_m, windows)
    for name, w in (("estimate", w_e), ("mocap", w_m)):
        empty = sorted(set(range(len(windows))) - set(w[w >= 0].tolist()))
        if empty:
            raise ValueError(f"no {name} sample in window {empty[0]}")
    t_e, est, w_e = t_e[w_e >= 0], est[w_e >= 0], w_e[w_e >= 0]
    t_m, moc, w_m = t_m[w_m >= 0], moc[w_m >= 0], w_m[w_m >= 0]
    n_moves = len(moves)

    # (2) each source on the commanded displacement, with an offset and a drift term
    x_e = _design(t_e, w_e, cmd, moves)
    coef_e, *_ = np.linalg.lstsq(x_e, est, rcond=None)
    wander = _wander(t_e, est, w_e, cmd)
    x_m = _design(t_m, w_m, cmd, moves)
    coef_m, *_ = np.linalg.lstsq(x_m, moc, rcond=None)
    est_r = tuple(_response(coef_e[-n_moves + i], cmd[m]) for i, m in enumerate(moves))
    moc_r = tuple(_response(coef_m[-n_moves + i], cmd[m]) for i, m in enumerate(moves))

    # (1) the mocap on the estimate, at the estimate's times (the wander is excitation here)
    order = np.argsort(t_m)
    t_m, moc = t_m[order], moc[order]
    inside = (t_e >= t_m[0]) & (t_e <= t_m[-1])
    moc_at = np.column_stack([np.interp(t_e[inside], t_m, moc[:, i]) for i in range(3)])
    est_h = est[inside, :2] - est[inside, :2].mean(axis=0)
    span = max(float(np.ptp(t_e[inside])), 1e-9)
    drift = (t_e[inside] - float(np.mean(t_e[inside]))) / span
    x_g = np.column_stack([np.ones(len(drift)), drift, est_h])
    coef_g, *_ = np.linalg.lstsq(x_g, moc_at, rcond=None)
    g = coef_g[2:].T  # (3, 2): the mocap's displacement per metre of the estimate's N, E
    excitation = np.linalg.svd(est_h, compute_uv=False) / math.sqrt(max(len(est_h), 1))
    map_r = tuple(_response(g[:, i], np.eye(3)[i]) for i in range(2))
    h = g[:2, :2]
    rotation = math.degrees(math.atan2(h[1, 0] - h[0, 1], h[0, 0] + h[1, 1]))
    mirrored = bool(np.linalg.det(h) < -(MIN_GAIN**2))

    problem, mapping_judged = None, judge_mapping
    failed = [
        i for i, r in enumerate(est_r) if r.gain < MIN_GAIN or r.angle_deg > MAX_FOLLOW_ANGLE_DEG
    ]
    shortest = min(float(np.linalg.norm(cmd[m])) for m in moves)
    conclusive = WANDER_FACTOR * wander <= shortest + 1e-12
    following = "ok" if not failed else ("failed" if conclusive else "unjudged")
    bad_map = [
        i for i, r in enumerate(map_r) if r.gain < MIN_GAIN or r.angle_deg > MAX_MAPPING_ANGLE_DEG
    ]
    if not judge_mapping:
        pass  # forwarded: (1) cannot tell a wrong mapping (module docstring); (2) alone
    elif float(np.min(excitation)) < MIN_EXCITATION_M and not conclusive:
        # too still across one direction to compare there, but inside its own wander: judge
        # the mapping along the direction the estimate did move
        following, mapping_judged = "unjudged", False
        along = np.linalg.svd(est_h, full_matrices=False)[2][0]
        seen = _response(g @ along, np.append(along, 0.0))
        if seen.gain < MIN_GAIN or seen.angle_deg > MAX_MAPPING_ANGLE_DEG:
            bearing = math.degrees(math.atan2(along[1], along[0])) % 180.0
            problem = (
                f"the mocap saw the vehicle's motion along {bearing:.0f} deg from north "
                f"{seen.angle_deg:.0f} deg off (gain {seen.gain:.2f}) against its own "
                "estimate: the mocap mapping (yaw_offset_deg, north_axis, up_axis, "
                "handedness) is not the frame the vehicle flies in, or its estimate is not fed "
                "by this mocap"
            )
    elif float(np.min(excitation)) < MIN_EXCITATION_M:
        following = "failed"  # too still to compare with the mocap: it did not follow
        problem = (
            f"the vehicle estimate moved {float(np.min(excitation)):.3f} m (RMS) along one "
            "axis over the moves: too little to compare it with the mocap: the vehicle did "
            "not follow"
        )
    elif bad_map:
        i = bad_map[0]
        axis = ("north", "east")[i]
        if mirrored:
            how = "mirrored"
        elif abs(float(np.linalg.det(h))) < MIN_GAIN**2:
            how = "out of the horizontal plane"
        else:
            how = f"rotated {rotation:+.0f} deg"
        problem = (
            f"the mocap saw the vehicle's {axis} motion {map_r[i].angle_deg:.0f} deg off "
            f"(gain {map_r[i].gain:.2f}, {how}) against its own "
            "estimate: the mocap mapping (yaw_offset_deg, north_axis, up_axis, handedness) is "
            "not the frame the vehicle flies in, or its estimate is not fed by this mocap"
        )
    if problem is None and following == "failed":
        i = failed[0]
        problem = (
            f"commanded move {_fmt(cmd[moves[i]])}: the vehicle estimate moved "
            f"{est_r[i].gain:.2f} of it at {est_r[i].angle_deg:.0f} deg off its direction "
            f"(hover wander {wander:.3f} m): the vehicle did not follow"
        )
    return FrameCheck(
        tuple(tuple(float(x) for x in cmd[m]) for m in moves),  # type: ignore[misc]
        est_r, moc_r, map_r, rotation, mirrored, wander, following, problem, mapping_judged,
    )  # fmt: skip
