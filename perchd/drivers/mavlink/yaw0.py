"""yaw0, the autopilot's heading (NED yaw, from north) of the world X axis: given, or
(yaw0=auto) measured from every pose, the autopilot's heading from ATTITUDE plus the mocap
yaw, low-passed over YAW0_TRACK_S, for an autopilot whose heading comes from its compass and
drifts off the mocap's (PX4 SIH: degrees per second in hover). Tracking the offset closes the
heading loop on the mocap."""

from __future__ import annotations

import logging
import math

from perchd.core.types import Pose, Quat

log = logging.getLogger(__name__)

YAW0_TRACK_S = 0.1
"""[s] time constant of yaw0=auto's offset tracking: ten mocap frames, against one frame's
jitter; and fast, because the autopilot steers its own heading estimate, which PX4 SIH's
EKF2 moves by 10-14 deg within a perch: at 0.5 s the true heading strayed 3.7-13 deg over
eight flights, at 0.1 s at most 2.2 deg over six (docs/firmware.md)."""


def pose_yaw(q: Quat) -> float:
    """[rad] Z-Y-X yaw of an (x, y, z, w) quaternion."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class Yaw0:
    """value [rad]: yaw0, None while yaw0=auto has measured nothing yet (`auto`)."""

    def __init__(self, value: float | None, uri: str) -> None:
        self.value, self.uri = value, uri
        self.auto = value is None
        self._t: float | None = None  # [s] pose time of the last tracked update

    def track(self, heading_ned: float | None, pose: Pose) -> None:
        """yaw0=auto: the offset between the autopilot's heading [rad] and the pose's yaw,
        followed through a first-order lag."""
        if not self.auto or heading_ned is None:
            return
        measured = heading_ned + pose_yaw(pose.q)
        if self.value is None or self._t is None:
            self.align(measured)
        else:
            gain = min(1.0, max(0.0, pose.t - self._t) / YAW0_TRACK_S)
            self.value += gain * math.remainder(measured - self.value, math.tau)
        self._t = pose.t

    def align(self, value: float) -> None:
        self.value = value
        log.info(
            "%s: yaw0=auto: world X is at autopilot heading %.1f deg", self.uri, math.degrees(value)
        )
