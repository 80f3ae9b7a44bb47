"""The PoseSource protocol and the explicit registry of mocap URI schemes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.core.uri import Registry


@dataclass(frozen=True, slots=True)
class SourceStats:
    """Counters a source keeps; dropped packets are counted, never raised."""

    received: int = 0
    poses: int = 0
    dropped: int = 0


class PoseSource(Protocol):
    """A stream of poses for one body, converted to the world frame (Z up, metres)."""

    body: str

    def start(self) -> None:
        """Open sockets / threads; raises LinkError if the source cannot be reached."""

    def latest(self) -> Pose | None:
        """The newest pose received so far (None before the first); never blocks."""

    def wait(self, after_seq: int, timeout: float) -> Pose | None:
        """Block up to `timeout` [s] for a pose newer than `after_seq` (mocap-synchronous mode)."""

    def stats(self) -> SourceStats:
        ...

    def close(self) -> None:
        ...


SOURCES: Registry[PoseSource] = Registry("mocap", {
    "sim": "perchd.sim.world:open_sim_mocap",
    "natnet": "perchd.mocap.natnet.uris:open_natnet",
    "zmq": "perchd.mocap.zmq:open_zmq",
    "motioncapture": "perchd.mocap.motioncapture:open_motioncapture",
})


def open_source(uri: str, runtime: Runtime) -> PoseSource:
    """Build the pose source a URI names (not started yet)."""
    return SOURCES.open(uri, runtime)


def next_pose(source: PoseSource, after_seq: int, timeout: float) -> tuple[Pose | None, int]:
    """The next pose after `after_seq` within `timeout` [s], and the seq to wait after
    next. A sender that restarted numbers from below `after_seq` (Motive, a bridge) is
    followed from its newest pose, not waited for until it passes the old numbers."""
    pose = source.wait(after_seq, timeout)
    if pose is not None:
        return pose, pose.seq
    newest = source.latest()
    return None, -1 if newest is not None and newest.seq < after_seq else after_seq
