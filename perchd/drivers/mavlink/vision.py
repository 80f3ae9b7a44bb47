"""Mocap to the autopilot: each pose the flight uses goes to the vehicle's EKF as
VISION_POSITION_ESTIMATE, so the autopilot knows where it is without GPS and its own
failsafe can hold or land in place (docs/firmware.md, "Mocap to the autopilot").

VISION_POSITION_ESTIMATE rather than ODOMETRY: ArduPilot takes ODOMETRY only in
LOCAL_FRD/BODY_FRD and with a velocity perchd does not measure; both autopilots take
VISION_POSITION_ESTIMATE as a NED position with Z-Y-X angles and a covariance.
- Frame: the world (Z up) placed on NED by yaw0, the heading of world X
  (perchd.core.ned, the same rotation the harnesses use the other way).
- Time: `usec` is the pose's measurement time on perchd's clock. ArduPilot fits any remote
  clock to its own (jitter correction); PX4 converts through TIMESYNC, which the driver
  answers on the same clock (timesync_reply), and stamps on receipt until that converged.
- Covariance: the diagonal of position and angle variances; the autopilots take the larger
  of it and their own noise floor (VISO_POS_M_NSE, EKF2_EVP_NOISE).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from perchd.core.ned import euler_zyx, ned_quat, ned_vec
from perchd.core.types import Pose, Vec3

POS_STD_M = 0.01
"""[m] a mocap position's standard deviation (a rigid body in a tuned room: ~1 mm; kept
above it so the EKF still weighs its IMU)."""
ANG_STD_RAD = 0.02
"""[rad] a mocap attitude's standard deviation."""
MAVLINK2_MARKER = 253  # a MAVLink 2 frame's first byte
COV_DIAGONAL = (0, 6, 11, 15, 18, 20)
"""Indices of x, y, z, roll, pitch, yaw in MAVLink's upper-triangle 6 x 6 covariance."""


@dataclass(frozen=True, slots=True)
class VisionEstimate:
    """One VISION_POSITION_ESTIMATE: usec [us] perchd's clock; ned [m]; rpy [rad] body FRD
    in NED, Z-Y-X; covariance (21 values, upper triangle, row-major)."""

    usec: int
    ned: Vec3
    rpy: Vec3
    covariance: tuple[float, ...]


def covariance(pos_std_m: float = POS_STD_M, ang_std_rad: float = ANG_STD_RAD) -> tuple[float, ...]:
    cov = [0.0] * 21
    for k, i in enumerate(COV_DIAGONAL):
        cov[i] = (pos_std_m if k < 3 else ang_std_rad) ** 2
    return tuple(cov)


COVARIANCE = covariance()


def vision_estimate(pose: Pose, yaw0: float) -> VisionEstimate:
    """A world pose (Z up, FLU body) as the autopilot's NED position and FRD attitude."""
    w, x, y, z = ned_quat(pose.q, yaw0)
    return VisionEstimate(
        int(round(pose.t * 1e6)), ned_vec(pose.p, yaw0), euler_zyx((x, y, z, w)), COVARIANCE
    )


def vision_message(mav: Any, v: VisionEstimate) -> Any:
    """VISION_POSITION_ESTIMATE of `v` from pymavlink's encoder `mav`, in the protocol it
    speaks: MAVLink 1 has no covariance (an extension field)."""
    fields = (v.usec, *v.ned, *v.rpy)
    if mav.protocol_marker == MAVLINK2_MARKER:
        return mav.vision_position_estimate_encode(*fields, list(v.covariance))
    return mav.vision_position_estimate_encode(*fields)


def timesync_reply(ts1_ns: int, now_s: float) -> tuple[int, int]:
    """(tc1, ts1) answering an autopilot's TIMESYNC request (tc1 = 0): our clock [ns] and
    its own stamp back, from which it learns the offset of the clock `usec` is on."""
    return int(now_s * 1e9), ts1_ns
