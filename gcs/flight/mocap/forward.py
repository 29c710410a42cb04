"""Motion capture to PX4 as external vision, through MAVSDK's Mocap plugin.

Each tracked sample is mapped to NED/FRD and sent as MAVLink ``VISION_POSITION_ESTIMATE``
(roll, pitch, yaw, pose covariance) or ``ODOMETRY`` (frame ``LOCAL_FRD``, estimator type
``VISION``, quality 100, the same covariance; velocity unknown: NaN), stamped with the
sample's receipt time on the monotonic clock in microseconds (MAVSDK's ``steady_clock``).
PX4's receiver maps a stamp to its own clock only once its time synchronisation with the
sender has converged, and MAVSDK answers PX4's TIMESYNC requests only after
``enable_timesync()``, which gcs does not call: so PX4 stamps each pose when it arrives, and
``EKF2_EV_DELAY`` holds the latency from the body's motion to PX4 (the mocap's cameras and
solve, the network, gcs, the link to the vehicle). Untracked samples are not sent: PX4 then
sees vision stop, which is what it must see.

Which message. ``VISION_POSITION_ESTIMATE`` (the default) reaches EKF2 in frame NED: PX4 aligns
its heading to the vision yaw, with no magnetometer or GPS. ``ODOMETRY`` goes out in
``LOCAL_FRD`` with estimator type ``VISION``: PX4's ``mavlink_receiver`` (v1.14-v1.16) passes
``ODOMETRY`` to EKF2 only in a local frame and not with estimator ``MOCAP``, and MAVSDK offers
only ``MOCAP_NED`` (dropped by PX4) and ``LOCAL_FRD``. An FRD vision yaw is relative for PX4
v1.16: without a magnetometer or GPS heading it never aligns to north and arming is denied
(flown on the SIH firmware; :mod:`gcs.flight.mocap.preflight` refuses that combination).

The path. :class:`VisionForwarder.send` runs in the mocap client's thread (its ``on_sample``)
and calls the *blocking* MAVSDK plugin there: no asyncio task, no executor, nothing on the
event loop that streams the setpoints, so forwarding at the mocap rate can never delay a
setpoint (``benchmarks/mocap_forwarding.py`` measures the setpoint jitter with and without).
A failing send is counted, never raised (it would end the mocap stream, which the safety
watch needs); :meth:`VisionForwarder.stop` waits for a send in progress before the plugin is
released.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from gcs.core.frames import FrameMapping, quat_to_matrix
from gcs.flight.mocap.client import MocapSample

__all__ = ["VisionPose", "vision_pose", "pose_covariance", "VisionForwarder", "ForwardStats"]

#: Indices of the diagonal in MAVLink's 21-entry upper-right triangle of a 6x6 covariance.
_DIAGONAL = (0, 6, 11, 15, 18, 20)


@dataclass(frozen=True)
class VisionPose:
    """One sample as PX4 gets it.

    Parameters
    ----------
    time_usec : int
        Receipt time on the monotonic clock [us].
    pos_ned_m : tuple of float
        Position, local NED [m].
    quat_wxyz : tuple of float
        Attitude FRD to NED, ``w, x, y, z``.
    euler_rad : tuple of float
        Roll, pitch, yaw of the same attitude [rad] (ZYX).
    covariance : tuple of float
        21 entries: the upper-right triangle of the 6x6 pose covariance, row-major.
    """

    time_usec: int
    pos_ned_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    euler_rad: tuple[float, float, float]
    covariance: tuple[float, ...]


def pose_covariance(position_std_m: float, angle_std_rad: float) -> tuple[float, ...]:
    """The 21-entry pose covariance of independent axes.

    Parameters
    ----------
    position_std_m : float
        Standard deviation of each position coordinate [m].
    angle_std_rad : float
        Standard deviation of each angle [rad].

    Returns
    -------
    tuple of float
        Length 21: variances on the diagonal, zeros elsewhere.
    """
    cov = [0.0] * 21
    for i, k in enumerate(_DIAGONAL):
        cov[k] = (position_std_m if i < 3 else angle_std_rad) ** 2
    return tuple(cov)


def vision_pose(
    sample: MocapSample, mapping: FrameMapping, covariance: tuple[float, ...]
) -> VisionPose | None:
    """Map one mocap sample to what PX4 is sent (None if the body was not tracked).

    Parameters
    ----------
    sample : MocapSample
        As delivered, in the system's axes.
    mapping : FrameMapping
        System to NED.
    covariance : tuple of float
        From :func:`pose_covariance`.

    Returns
    -------
    VisionPose or None
    """
    if not sample.tracked:
        return None
    pos = mapping.position_to_ned(np.asarray(sample.pos_m))
    q = mapping.attitude_to_ned(np.asarray(sample.quat_wxyz))
    r = quat_to_matrix(q)
    roll = math.atan2(r[2, 1], r[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, r[2, 0])))
    yaw = math.atan2(r[1, 0], r[0, 0])
    return VisionPose(
        time_usec=int(round(sample.t_receipt_s * 1e6)),
        pos_ned_m=(float(pos[0]), float(pos[1]), float(pos[2])),
        quat_wxyz=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        euler_rad=(roll, pitch, yaw),
        covariance=covariance,
    )


@dataclass(frozen=True)
class ForwardStats:
    """What the forwarder did.

    Parameters
    ----------
    sent : int
        Poses sent.
    skipped : int
        Samples not sent (body not tracked).
    failed : int
        Sends MAVSDK refused or that raised.
    last_error : str or None
        The newest failure.
    send_s_p50 : float
        Median duration of one send [s] (NaN before any).
    """

    sent: int
    skipped: int
    failed: int
    last_error: str | None
    send_s_p50: float


class VisionForwarder:
    """Sends mapped mocap samples to PX4 from the mocap client's thread.

    Parameters
    ----------
    plugin : object
        MAVSDK's blocking ``mavsdk.plugins.mocap.Mocap`` of the vehicle's system.
    mapping : FrameMapping
        System to NED.
    message : str
        ``odometry`` or ``vision_position_estimate``.
    position_std_m : float
        Position standard deviation sent [m].
    angle_std_rad : float
        Angle standard deviation sent [rad].
    """

    def __init__(
        self,
        plugin: object,
        mapping: FrameMapping,
        message: str,
        position_std_m: float,
        angle_std_rad: float,
    ) -> None:
        if message not in ("odometry", "vision_position_estimate"):
            raise ValueError(f"message must be odometry or vision_position_estimate: {message!r}")
        self._plugin = plugin
        self.mapping = mapping
        self.message = message
        self.covariance = pose_covariance(position_std_m, angle_std_rad)
        self._lock = threading.Lock()
        self._sent = self._skipped = self._failed = 0
        self._last_error: str | None = None
        self._durations: list[float] = []

    def send(self, sample: MocapSample) -> None:
        """Forward one sample (the mocap client's ``on_sample``); never raises.

        Parameters
        ----------
        sample : MocapSample
            As delivered.
        """
        try:
            pose = vision_pose(sample, self.mapping, self.covariance)
        except ValueError as exc:  # a malformed quaternion: not sent, counted
            pose, self._last_error = None, f"sample {sample.seq}: {exc}"
            self._failed += 1
        if pose is None:
            self._skipped += 1
            return
        with self._lock:
            if self._plugin is None:
                return
            started = time.perf_counter()
            try:
                self._send(pose)
                self._sent += 1
            except Exception as exc:  # refused or plugin gone: counted, the stream goes on
                self._failed += 1
                self._last_error = f"{type(exc).__name__}: {exc}"
            if len(self._durations) < 100_000:
                self._durations.append(time.perf_counter() - started)

    def _send(self, pose: VisionPose) -> None:
        from mavsdk.plugins.mocap import (
            AngleBody,
            AngularVelocityBody,
            Covariance,
            Odometry,
            PositionBody,
            Quaternion,
            SpeedBody,
            VisionPositionEstimate,
        )

        position = PositionBody(*pose.pos_ned_m)
        covariance = Covariance(list(pose.covariance))
        if self.message == "vision_position_estimate":
            message = VisionPositionEstimate(
                pose.time_usec, position, AngleBody(*pose.euler_rad), covariance, 0
            )
            self._plugin.set_vision_position_estimate(message)  # type: ignore[attr-defined]
            return
        nan = math.nan
        odometry = Odometry(
            time_usec=pose.time_usec,
            frame_id=Odometry.MavFrame.LOCAL_FRD,
            position_body=position,
            q=Quaternion(*pose.quat_wxyz),
            speed_body=SpeedBody(nan, nan, nan),
            angular_velocity_body=AngularVelocityBody(nan, nan, nan),
            pose_covariance=covariance,
            velocity_covariance=Covariance([nan]),
            reset_counter=0,
            estimator_type=Odometry.MavEstimatorType.VISION,
            quality_percent=100,
        )
        self._plugin.set_odometry(odometry)  # type: ignore[attr-defined]

    def stop(self) -> None:
        """Stop sending (waits for a send in progress); the plugin may be released after."""
        with self._lock:
            self._plugin = None

    def stats(self) -> ForwardStats:
        """Counters so far.

        Returns
        -------
        ForwardStats
        """
        with self._lock:
            durations = list(self._durations)
        p50 = float(np.median(durations)) if durations else math.nan
        return ForwardStats(self._sent, self._skipped, self._failed, self._last_error, p50)
