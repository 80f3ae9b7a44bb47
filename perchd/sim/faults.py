"""Mocap faults the simulated world can inject, frame by frame (SimWorld.faults.mocap).

Each fault is a small object with a window [t0, t1) on the frame's *measurement* time and an
`apply(arrive, pose) -> [(arrive, pose), ...]` that may drop the frame (empty list), change
it, delay its arrival [s, on the world's clock] or send it more than once. The world passes
every measured frame through its faults in order and delivers what comes out by arrival
time, so a delayed frame can arrive after a newer one (out of order). A frame's `latency`
field is what the mocap system *claims*; a fault that delays arrival leaves it alone (the
network delay is unknown to the sender), as it would be on a real link.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

from perchd.core.types import Pose

Arrival = tuple[float, Pose]
"""([s] when the frame reaches the agent, the frame)."""


class MocapFault(Protocol):
    def apply(self, arrive: float, pose: Pose) -> list[Arrival]: ...


def shape(faults: Sequence[MocapFault], arrive: float, pose: Pose) -> list[Arrival]:
    """Pass one measured frame through every fault in order."""
    out = [(arrive, pose)]
    for fault in faults:
        out = [item for a, p in out for item in fault.apply(a, p)]
    return out


@dataclass(frozen=True)
class Window:
    """[t0, t1) [s] of measurement time in which a fault acts (t1 = inf: for good)."""

    t0: float = 0.0
    t1: float = math.inf

    def holds(self, pose: Pose) -> bool:
        return self.t0 <= pose.t < self.t1


@dataclass(frozen=True)
class Stop(Window):
    """Frames stop: nothing measured in the window reaches the agent."""

    def apply(self, arrive: float, pose: Pose) -> list[Arrival]:
        return [] if self.holds(pose) else [(arrive, pose)]


@dataclass(frozen=True)
class Late(Window):
    """Frames arrive delay_s [s] late (network or host delay the sender cannot see)."""

    delay_s: float = 0.05

    def apply(self, arrive: float, pose: Pose) -> list[Arrival]:
        return [(arrive + self.delay_s, pose)] if self.holds(pose) else [(arrive, pose)]


@dataclass(frozen=True)
class Reorder(Window):
    """Every second frame (even seq) is held back delay_s [s], more than a frame period, so
    it arrives after its successor: pairs arrive swapped."""

    delay_s: float = 0.0125

    def apply(self, arrive: float, pose: Pose) -> list[Arrival]:
        late = self.holds(pose) and pose.seq % 2 == 0
        return [(arrive + self.delay_s if late else arrive, pose)]


@dataclass(frozen=True)
class Repeat(Window):
    """Each frame arrives `times` times (the copies gap_s [s] apart), same seq and stamp."""

    times: int = 2
    gap_s: float = 0.001

    def apply(self, arrive: float, pose: Pose) -> list[Arrival]:
        n = self.times if self.holds(pose) else 1
        return [(arrive + i * self.gap_s, pose) for i in range(n)]


@dataclass
class Freeze:
    """A stuck tracker: in [t0, t1) [s] every frame is the last one before the window,
    re-sent with a fresh seq; restamp=True also gives it the fresh measurement time (old
    position, new time), restamp=False keeps the old time (a replayed frame)."""

    t0: float = 0.0
    t1: float = math.inf
    restamp: bool = False
    _held: Pose | None = field(default=None, init=False, repr=False)

    def apply(self, arrive: float, pose: Pose) -> list[Arrival]:
        if not self.t0 <= pose.t < self.t1:
            self._held = pose
            return [(arrive, pose)]
        if self._held is None:
            return [(arrive, pose)]
        t = pose.t if self.restamp else self._held.t
        return [(arrive, replace(self._held, seq=pose.seq, t=t))]


@dataclass(frozen=True)
class Outliers(Window):
    """Every `every`-th frame (by seq) jumps jump_m [m] along world x, y and z (a marker
    swap or a reflection tracked as the body)."""

    every: int = 10
    jump_m: float = 0.5

    def apply(self, arrive: float, pose: Pose) -> list[Arrival]:
        if self.holds(pose) and pose.seq % self.every == 0:
            pose = replace(pose, p=tuple(c + self.jump_m for c in pose.p))
        return [(arrive, pose)]


@dataclass(frozen=True)
class Invalid(Window):
    """Tracking lost: frames keep coming, flagged invalid, with a zero position."""

    def apply(self, arrive: float, pose: Pose) -> list[Arrival]:
        if self.holds(pose):
            pose = replace(pose, p=(0.0, 0.0, 0.0), q=(0.0, 0.0, 0.0, 1.0), valid=False)
        return [(arrive, pose)]


@dataclass(frozen=True)
class RateDrop(Window):
    """Only one frame in `keep_every` (by seq) gets through: 5 = 20 % of the rate."""

    keep_every: int = 5

    def apply(self, arrive: float, pose: Pose) -> list[Arrival]:
        drop = self.holds(pose) and pose.seq % self.keep_every != 0
        return [] if drop else [(arrive, pose)]


@dataclass(frozen=True)
class Corrupt(Window):
    """Every `every`-th frame (by seq) carries `value` (NaN, inf, 1e12) in every position
    and orientation component, still flagged valid."""

    value: float = math.nan
    every: int = 1

    def apply(self, arrive: float, pose: Pose) -> list[Arrival]:
        if self.holds(pose) and pose.seq % self.every == 0:
            pose = replace(pose, p=(self.value,) * 3, q=(self.value,) * 4)
        return [(arrive, pose)]
