"""Autopilot frames to perchd's: NED world and FRD body (MAVLink's) to a Z-up world and an
FLU body (docs/architecture.md, frames). Shared by the ArduPilot and PX4 harnesses."""

from __future__ import annotations

import math

from perchd.core.types import Quat, Vec3

QuatWXYZ = tuple[float, float, float, float]

_H = math.sqrt(0.5)
WORLD_FROM_NED: dict[str, QuatWXYZ] = {"nwu": (0.0, 1.0, 0.0, 0.0), "enu": (0.0, _H, _H, 0.0)}
"""(w, x, y, z): NWU is pi about X; ENU is pi about (1, 1, 0)/sqrt 2 (swap N/E, negate D)."""
FRD_FROM_FLU: QuatWXYZ = (0.0, 1.0, 0.0, 0.0)
"""perchd's body is FLU (Z up), the autopilots' FRD: pi about X."""


def quat_mul(a: QuatWXYZ, b: QuatWXYZ) -> QuatWXYZ:
    """Hamilton product of (w, x, y, z) quaternions."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def world_vec(ned: Vec3, frame: str) -> Vec3:
    """A NED vector in the world frame `frame` ("nwu" or "enu")."""
    n, e, d = ned
    return (n, -e, -d) if frame == "nwu" else (e, n, -d)


def world_quat(q_ned_wxyz: QuatWXYZ, frame: str) -> Quat:
    """An autopilot attitude (w, x, y, z; body FRD -> NED) as perchd's (x, y, z, w), body
    FLU -> world, normalised and with w >= 0 (one sign for one attitude: PX4 often sends -q)."""
    w, x, y, z = quat_mul(quat_mul(WORLD_FROM_NED[frame], tuple(q_ned_wxyz)), FRD_FROM_FLU)
    n = math.sqrt(w * w + x * x + y * y + z * z) or 1.0
    s = (1.0 if w >= 0 else -1.0) / n
    return (x * s, y * s, z * s, w * s)
