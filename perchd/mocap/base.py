"""The explicit registry of mocap URI schemes (the PoseSource protocol itself: core/ports.py)."""

from __future__ import annotations

from perchd.core.ports import PoseSource
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.core.uri import Registry

SOURCES: Registry[PoseSource] = Registry(
    "mocap",
    {
        "sim": "perchd.sim.world:open_sim_mocap",
        "natnet": "perchd.mocap.natnet.uris:open_natnet",
        "zmq": "perchd.mocap.zmq:open_zmq",
        "motioncapture": "perchd.mocap.motioncapture:open_motioncapture",
    },
)


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
