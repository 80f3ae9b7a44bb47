"""Carry a pose source's poses over a real socket path and read them back.

    relay = RelayedSource(sim_mocap, open_pose_output("natnet://127.0.0.1:0", ["cf1"], clock),
                          runtime)
    relay.start(); ...; relay.latest()  # the Pose as the NatNet client decoded it

Used to fly the simulator with its mocap going simulator -> NatNet emulator -> NatNet client
(or -> ZMQ publisher -> ZMQ source) inside one process. Each read forwards any new upstream
pose and then blocks, in wall time and at most `timeout_s`, until the socket source has
decoded it: a simulated clock never outruns the sockets, and the flight sees exactly what
the socket source made of the packet (float32 positions, its own latency estimate).
"""

from __future__ import annotations

from typing import Any

from perchd.core.ports import PoseSource, SourceStats
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.mocap.base import open_source
from perchd.mocap.outputs import PoseOutput


class RelayedSource:
    """PoseSource: upstream -> output (sockets) -> the source that output's URI names."""

    def __init__(
        self, upstream: PoseSource, output: PoseOutput, runtime: Runtime, timeout_s: float = 1.0
    ) -> None:
        self.upstream, self.output = upstream, output
        self.body = upstream.body
        self.downstream: Any = open_source(output.uri(upstream.body), runtime)
        self.timeout_s = timeout_s
        self._forwarded = -1

    def start(self) -> None:
        self.upstream.start()
        self.downstream.start()
        waiter = getattr(self.output, "wait_for_subscriber", None)
        if waiter is not None:
            waiter(self.timeout_s)  # a ZMQ subscriber joins asynchronously

    def latest(self) -> Pose | None:
        self._forward(self.upstream.latest())
        return self.downstream.latest()

    def wait(self, after_seq: int, timeout: float) -> Pose | None:
        self._forward(self.upstream.wait(self._forwarded, timeout))
        return self.downstream.wait(after_seq, 0.0)

    def stats(self) -> SourceStats:
        return self.downstream.stats()

    def close(self) -> None:
        self.downstream.close()
        self.output.close()
        self.upstream.close()

    def _forward(self, pose: Pose | None) -> None:
        if pose is None or pose.seq == self._forwarded:
            return
        before = self.downstream.latest()
        self.output.publish(pose)
        self._forwarded = pose.seq
        self.downstream.wait(before.seq if before else -(2**63), self.timeout_s)
