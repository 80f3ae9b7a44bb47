"""Autopilot frames to perchd's and back: NED world and FRD body (MAVLink's) against a Z-up
world and an FLU body (docs/architecture.md, frames). One rotation, used both ways: the
ArduPilot and PX4 harnesses (perchd/sim/firmware) turn truth into mocap with it, the
MAVLink driver turns mocap into the autopilot's vision input (drivers/mavlink/vision.py).

A Z-up world is placed on NED by yaw0 [rad], the NED heading (from north, clockwise) of
world X: pi about X (NED -> NWU), then yaw0 about Z. NWU is yaw0 = 0, ENU yaw0 = pi/2."""

from __future__ import annotations

import math

from perchd.core.types import Quat, Vec3

QuatWXYZ = tuple[float, float, float, float]

FRAME_YAW0: dict[str, float] = {"nwu": 0.0, "enu": math.pi / 2}
"""[rad] the NED heading of world X in the named world frames."""
FRD_FROM_FLU: QuatWXYZ = (0.0, 1.0, 0.0, 0.0)
"""perchd's body is FLU (Z up), the autopilots' FRD: pi about X."""


def world_from_ned(yaw0: float) -> QuatWXYZ:
    """(w, x, y, z) rotating NED vectors into the world whose X is at heading yaw0: the
    product of yaw0 about Z and pi about X."""
    return (0.0, math.cos(yaw0 / 2), math.sin(yaw0 / 2), 0.0)


def yaw0_of(frame: str | float) -> float:
    """[rad] a frame name ("nwu", "enu") or a heading yaw0 itself."""
    return FRAME_YAW0[frame] if isinstance(frame, str) else float(frame)


def quat_mul(a: QuatWXYZ, b: QuatWXYZ) -> QuatWXYZ:
    """Hamilton product of (w, x, y, z) quaternions."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def conj(q: QuatWXYZ) -> QuatWXYZ:
    return (q[0], -q[1], -q[2], -q[3])


def rotate(q: QuatWXYZ, v: Vec3) -> Vec3:
    """v rotated by the unit (w, x, y, z) quaternion q."""
    _, x, y, z = quat_mul(quat_mul(q, (0.0, *v)), conj(q))
    return (x, y, z)


def world_vec(ned: Vec3, frame: str | float) -> Vec3:
    """A NED vector in the world frame `frame` ("nwu", "enu" or yaw0 [rad])."""
    return rotate(world_from_ned(yaw0_of(frame)), ned)


def ned_vec(world: Vec3, frame: str | float) -> Vec3:
    """A world vector in NED: world_vec's inverse."""
    return rotate(conj(world_from_ned(yaw0_of(frame))), world)


def _canonical(q: QuatWXYZ) -> QuatWXYZ:
    """Normalised, w >= 0: one sign for one attitude (PX4 often sends -q)."""
    n = math.sqrt(sum(c * c for c in q)) or 1.0
    s = (1.0 if q[0] >= 0 else -1.0) / n
    return (q[0] * s, q[1] * s, q[2] * s, q[3] * s)


def world_quat(q_ned_wxyz: QuatWXYZ, frame: str | float) -> Quat:
    """An autopilot attitude (w, x, y, z; body FRD -> NED) as perchd's (x, y, z, w), body
    FLU -> world."""
    w0, x0, y0, z0 = q_ned_wxyz
    q = quat_mul(quat_mul(world_from_ned(yaw0_of(frame)), (w0, x0, y0, z0)), FRD_FROM_FLU)
    w, x, y, z = _canonical(q)
    return (x, y, z, w)


def ned_quat(q_world_xyzw: Quat, frame: str | float) -> QuatWXYZ:
    """perchd's attitude (x, y, z, w; body FLU -> world) as the autopilot's (w, x, y, z;
    body FRD -> NED): world_quat's inverse."""
    x, y, z, w = q_world_xyzw
    q = quat_mul(quat_mul(conj(world_from_ned(yaw0_of(frame))), (w, x, y, z)), conj(FRD_FROM_FLU))
    return _canonical(q)


def quaternion_wxyz(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of Z-Y-X Euler angles [rad]."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def euler_zyx(q: Quat) -> Vec3:
    """(roll, pitch, yaw) [rad] of an (x, y, z, w) quaternion, Z-Y-X order (docs/contracts.md §3)."""
    x, y, z, w = q
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw
