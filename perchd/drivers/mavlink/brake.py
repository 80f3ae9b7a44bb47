"""The brake a dead agent leaves behind (docs/safety.md, "When the agent dies").

Killed mid-approach, the vehicle leans toward the wall at speed, and an autopilot's LAND
does not brake it well: PX4's is jerk-limited from the acceleration it finds (SIH killed at
0.45-0.50 m/s went on 0.36-0.63 m), and lands where its own braking from the speed it has
would end (navigator's preproject_stop_point: 1.3-2.4 m further from 1.2 m/s). While perchd
flies, the driver keeps the sentinel (sentinel.py) supplied with a brake,
renewed from the mocap every WILL_PERIOD_S: lean against the velocity at BRAKE_ACCEL_MPS2
for |v| / a (the attitude's lag delays the stop but not the velocity the lean takes off),
then level at hover thrust until the autopilot's own velocity (LOCAL_POSITION_NED) says
the vehicle has stopped, at most LEVEL_MAX_S; still moving, the same again against the
velocity the autopilot reports (BRAKE_ROUNDS in all); then LAND: the vehicle is still and
level when the autopilot takes it. A brake older than WILL_MAX_AGE_S is not flown (the agent's
mocap had stopped: its velocity is not known).
"""

from __future__ import annotations

import collections
import math
import struct
from dataclasses import dataclass

from perchd.core.ned import quaternion_wxyz
from perchd.core.types import Pose, Vec3

G = 9.81
BRAKE_ACCEL_MPS2 = 3.0
"""[m/s^2] the brake's horizontal deceleration: 17 deg of lean."""
LEVEL_MAX_S = 0.5
"""[s] longest level phase: the attitude follows 0.25-0.35 s late (docs/firmware.md)."""
BRAKE_DONE_MPS = 0.1
"""[m/s] stopped: the autopilot's velocity along the one braked no faster than this."""
BRAKE_ROUNDS = 3
"""lean-and-level rounds at most: the first against the mocap's velocity, the others
against the autopilot's, should the first leave the vehicle moving."""
BRAKE_MIN_MPS = 0.1
"""[m/s] slower than this, no brake: LAND at once."""
VELOCITY_WINDOW_S = 0.05
"""[s] the velocity is the mocap's displacement over at least this long."""
WILL_PERIOD_S = 0.02
"""[s] how often the driver renews the brake."""
WILL_MAX_AGE_S = 0.15
"""[s] an older brake is not flown."""


@dataclass(frozen=True)
class Brake:
    """An attitude target (w, x, y, z; FRD in NED) and normalised thrust to hold for
    duration_s [s] against the horizontal velocity v_ne [m/s, north, east] at the heading
    heading_ned [rad] (hover: the hover thrust), measured (time.monotonic()) at t_s [s]."""

    q_ned: tuple[float, float, float, float]
    thrust: float
    duration_s: float
    v_ne: tuple[float, float]
    heading_ned: float
    hover: float
    t_s: float

    @property
    def level(self) -> tuple[tuple[float, float, float, float], float]:
        """(attitude, thrust) level at the heading, at hover thrust."""
        return quaternion_wxyz(0.0, 0.0, self.heading_ned), self.hover

    def again(self, v_ned: Vec3) -> Brake:
        """The brake against a velocity [m/s, NED] still left: the autopilot's own."""
        return brake_for(v_ned, self.heading_ned, self.hover, self.t_s)

    def pack(self) -> bytes:
        return struct.pack(
            WIRE,
            *self.q_ned,
            self.thrust,
            self.duration_s,
            *self.v_ne,
            self.heading_ned,
            self.hover,
            self.t_s,
        )

    @classmethod
    def unpack(cls, data: bytes) -> Brake:
        *q, thrust, duration, vn, ve, heading, hover, t = struct.unpack(WIRE, data)
        return cls(tuple(q), thrust, duration, (vn, ve), heading, hover, t)

    def stopped(self, v_ned: Vec3) -> bool:
        """Is a velocity [m/s, NED] down to BRAKE_DONE_MPS along the one braked?"""
        speed = math.hypot(*self.v_ne)
        along = (v_ned[0] * self.v_ne[0] + v_ned[1] * self.v_ne[1]) / speed if speed else 0.0
        return along <= BRAKE_DONE_MPS


WIRE = "<10fd"  # q (4), thrust, duration, v_ne (2), heading, hover; t_s
PACKED_SIZE = struct.calcsize(WIRE)


def lean_for(v_ned: Vec3, heading_ned: float) -> tuple[float, float, float]:
    """(roll, pitch [rad], FRD in NED; duration [s]) of the lean that decelerates the
    horizontal NED velocity v_ned [m/s] at BRAKE_ACCEL_MPS2 at the heading [rad]; level for
    no time when slower than BRAKE_MIN_MPS."""
    speed = math.hypot(v_ned[0], v_ned[1])
    if speed < BRAKE_MIN_MPS:
        return 0.0, 0.0, 0.0
    a_n, a_e = (-BRAKE_ACCEL_MPS2 * c / speed for c in v_ned[:2])
    cy, sy = math.cos(heading_ned), math.sin(heading_ned)
    forward, right = a_n * cy + a_e * sy, -a_n * sy + a_e * cy
    pitch = -math.atan2(forward, G)  # FRD: nose down (negative) accelerates forward
    return math.atan2(right * math.cos(pitch), G), pitch, speed / BRAKE_ACCEL_MPS2


def brake_for(v_ned: Vec3, heading_ned: float, hover_fraction: float, t_s: float) -> Brake:
    """The lean that decelerates the horizontal NED velocity v_ned [m/s] at the heading
    [rad] (lean_for), thrust holding height."""
    roll, pitch, duration = lean_for(v_ned, heading_ned)
    thrust = min(hover_fraction / (math.cos(roll) * math.cos(pitch)), 1.0)
    return Brake(
        quaternion_wxyz(roll, pitch, heading_ned),
        thrust,
        duration,
        (v_ned[0], v_ned[1]),
        heading_ned,
        hover_fraction,
        t_s,
    )


class WillSchedule:
    """When a driver's helper (the MAVLink sentinel, the Crazyflie keeper) is due a fresh
    brake: fed every pose, it gives the mocap's velocity once per WILL_PERIOD_S."""

    def __init__(self) -> None:
        self._velocity = VelocityTracker()
        self._at = 0.0  # time.monotonic() of the last will

    def due(self, pose: Pose, now: float) -> Vec3 | None:
        """[m/s] the velocity to brake against when a will is due at `now` [s], else None."""
        v = self._velocity.update(pose.t, pose.p)
        if v is None or now - self._at < WILL_PERIOD_S:
            return None
        self._at = now
        return v


class VelocityTracker:
    """World velocity [m/s] from mocap positions: the displacement from the oldest pose
    kept (at least VELOCITY_WINDOW_S back) to the newest."""

    def __init__(self) -> None:
        self._poses: collections.deque[tuple[float, Vec3]] = collections.deque()

    def update(self, t: float, p: Vec3) -> Vec3 | None:
        poses = self._poses
        if poses and t <= poses[-1][0]:
            return None  # a repeat or out of order: no new information
        poses.append((t, p))
        while len(poses) > 2 and t - poses[1][0] >= VELOCITY_WINDOW_S:
            poses.popleft()
        t0, p0 = poses[0]
        if t - t0 < VELOCITY_WINDOW_S:
            return None
        return tuple((b - a) / (t - t0) for a, b in zip(p0, p, strict=True))
