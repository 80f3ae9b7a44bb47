"""The attitude and thrust stream to the autopilot: SET_ATTITUDE_TARGET, an attitude
quaternion (w first) and a normalised thrust, the last one repeated levelled whenever the
loop falls silent.

Frames: perchd's world is Z-up with Z-Y-X Euler angles; autopilots want the body FRD
attitude in NED. Rotating by pi about X maps one onto the other: roll stays, pitch and yaw
change sign (yaw then measured from yaw0, the autopilot's heading of world X). Yaw is
relative to the autopilot's own heading reference, so its yaw zero must face the mocap X
axis (as the paper's does) or yaw0 say where it is.
"""

from __future__ import annotations

import time

from perchd.core.clock import Clock
from perchd.core.ned import quaternion_wxyz
from perchd.core.types import Setpoint
from perchd.drivers.mavlink.link import Connection
from perchd.drivers.mavlink.tilt import NO_TILT, Tilt

Quaternion = tuple[float, float, float, float]

IGNORE_BODY_RATES = 0b0000_0111  # SET_ATTITUDE_TARGET: the attitude alone
KEEPALIVE_S = 0.1
"""[s] a silent loop gets its last attitude target repeated after this long (PX4 leaves
OFFBOARD after COM_OF_LOSS_T = 0.5 s without one; ArduPilot levels after 1 s)."""


def ned_attitude(sp: Setpoint, yaw0: float = 0.0, tilt: Tilt = NO_TILT) -> Quaternion:
    """perchd's Z-up attitude as the FRD-in-NED quaternion an autopilot takes, its roll and
    pitch moved by `tilt` (FRD in NED)."""
    return quaternion_wxyz(
        sp.roll + tilt.roll_rad, -sp.pitch + tilt.pitch_rad, ned_yaw(sp.yaw, yaw0)
    )


def ned_yaw(yaw: float, yaw0: float) -> float:
    """[rad] autopilot heading of a world (Z-up) yaw, yaw0 the heading of world X."""
    return yaw0 - yaw


def level_ned(yaw_ned: float) -> Quaternion:
    """Roll 0, pitch 0 at an autopilot heading: level, never "level facing north"."""
    return quaternion_wxyz(0.0, 0.0, yaw_ned)


def attitude_target(
    mav: object, boot_ms: int, target: tuple[int, int], q: Quaternion, thrust: float
) -> object:
    """SET_ATTITUDE_TARGET from pymavlink's encoder `mav`."""
    return mav.set_attitude_target_encode(
        boot_ms, *target, IGNORE_BODY_RATES, list(q), 0.0, 0.0, 0.0, thrust
    )


class SetpointStream:
    """Attitude targets to the vehicle `target` (system, component) on `link`, stamped on
    `clock`; keep_alive() repeats the last thrust, level at level_yaw [rad, NED], when none
    went out for KEEPALIVE_S."""

    def __init__(self, link: Connection, target: tuple[int, int], clock: Clock) -> None:
        self.link, self.target, self.clock = link, target, clock
        self.last_thrust: float | None = None  # None: nothing streamed yet
        self._sent_s = 0.0  # time.monotonic() of the last target
        self.level_yaw: float | None = None  # None: north, the vehicle's heading unknown

    def send(self, q: Quaternion, thrust: float) -> None:
        self.last_thrust, self._sent_s = thrust, time.monotonic()
        boot_ms = int(self.clock.now() * 1000) & 0xFFFFFFFF
        self.link.send(attitude_target(self.link.mav, boot_ms, self.target, q, thrust))

    def level(self, heading: float, thrust: float) -> None:
        """Level at `heading` [rad, NED], which keep_alive() levels at from now on."""
        self.level_yaw = heading
        self.send(level_ned(heading), thrust)

    def keep_alive(self) -> None:
        """The last thrust, level, if the stream has fallen silent."""
        if self.last_thrust is not None and time.monotonic() - self._sent_s >= KEEPALIVE_S:
            self.send(level_ned(self.level_yaw or 0.0), self.last_thrust)
