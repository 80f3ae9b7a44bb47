"""The perching frame: origin on the surface, X along the approach normal, Z as near up as
a wall allows, Y = Z x X. World vectors map in and out of it (ARCHITECTURE, Frames)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from perchd.core.types import Vec3


def body_z(roll: float, pitch: float, yaw: float) -> Vec3:
    """World-frame direction of the body z axis for Z-Y-X angles (eq. 19's thrust direction)."""
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    sy, cy = math.sin(yaw), math.cos(yaw)
    return (cy * sp * cr + sy * sr, sy * sp * cr - cy * sr, cp * cr)


def _unit(v: Vec3) -> Vec3:
    n = math.sqrt(sum(c * c for c in v))
    return (v[0] / n, v[1] / n, v[2] / n)


@dataclass(frozen=True, slots=True)
class PerchFrame:
    """point [m] on the surface, world frame; ex, ey, ez: unit axes in world coordinates."""

    point: Vec3
    ex: Vec3
    ey: Vec3
    ez: Vec3

    @classmethod
    def from_surface(cls, point: Vec3, normal: Vec3) -> PerchFrame:
        ex = _unit(normal)
        up_dot = ex[2]
        ez = _unit((-up_dot * ex[0], -up_dot * ex[1], 1.0 - up_dot * ex[2]))
        ey = (
            ez[1] * ex[2] - ez[2] * ex[1],
            ez[2] * ex[0] - ez[0] * ex[2],
            ez[0] * ex[1] - ez[1] * ex[0],
        )
        return cls(tuple(point), ex, ey, ez)

    @property
    def yaw_facing(self) -> float:
        """[rad] world yaw that points the body x axis at the surface."""
        return math.atan2(self.ex[1], self.ex[0])

    def to_frame(self, p: Vec3) -> Vec3:
        """World position [m] -> perching-frame position [m]."""
        d = (p[0] - self.point[0], p[1] - self.point[1], p[2] - self.point[2])
        return self.rotate_in(d)

    # Written out, not as generators: these run several times in every control tick.
    def rotate_in(self, v: Vec3) -> Vec3:
        """World vector -> perching-frame components."""
        ex, ey, ez = self.ex, self.ey, self.ez
        return (
            v[0] * ex[0] + v[1] * ex[1] + v[2] * ex[2],
            v[0] * ey[0] + v[1] * ey[1] + v[2] * ey[2],
            v[0] * ez[0] + v[1] * ez[1] + v[2] * ez[2],
        )

    def rotate_out(self, v: Vec3) -> Vec3:
        """Perching-frame components -> world vector."""
        ex, ey, ez = self.ex, self.ey, self.ez
        return (
            v[0] * ex[0] + v[1] * ey[0] + v[2] * ez[0],
            v[0] * ex[1] + v[1] * ey[1] + v[2] * ez[1],
            v[0] * ex[2] + v[1] * ey[2] + v[2] * ez[2],
        )
