"""Mocap axes to perchd's world frame (right-handed, Z up).

Motive streams Y-up by default (X, Y up, Z toward the viewer) or Z-up when set so. Y-up is
turned into Z-up by +90 degrees about X: (x, y, z) -> (x, -z, y). Orientations are conjugated
by the same rotation, which for a quaternion rotates its vector part the same way and keeps w:
a body defined level in Motive (its Y up) stays the identity, now with its Z up.
"""

from __future__ import annotations

import enum

from perchd.core.errors import UriError
from perchd.core.types import Quat, Vec3


class UpAxis(enum.Enum):
    Y = "y"
    Z = "z"

    @classmethod
    def parse(cls, text: str, where: str) -> UpAxis:
        try:
            return cls(text.lower())
        except ValueError:
            raise UriError(f"{where}: up={text!r} must be y (Motive default) or z") from None


def to_world(p: Vec3, q: Quat, up: UpAxis) -> tuple[Vec3, Quat]:
    """Position [m] and quaternion (x, y, z, w) from the mocap axes to the world frame."""
    if up is UpAxis.Z:
        return p, q
    return (p[0], 0.0 - p[2], p[1]), (q[0], 0.0 - q[2], q[1], q[3])  # 0.0 - x: no -0.0


def from_world(p: Vec3, q: Quat, up: UpAxis) -> tuple[Vec3, Quat]:
    """The inverse of to_world: what a mocap system with `up` axes would stream."""
    if up is UpAxis.Z:
        return p, q
    return (p[0], p[2], 0.0 - p[1]), (q[0], q[2], 0.0 - q[1], q[3])
