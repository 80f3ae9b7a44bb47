"""The MAVLink sentinel's process (drivers/mavlink/sentinel.py), started by the driver as
`python -m perchd.service.mavsentinel_main ARGS`. The drivers import no mocap: here the
flight's mocap is opened by its URI for the relay (drivers/mavlink/relay.py)."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

from perchd.core.types import Pose
from perchd.drivers.mavlink.sentinel import main

if TYPE_CHECKING:
    from perchd.mocap.base import PoseSource


class MocapStream:
    """A mocap PoseSource as the relay reads it (relay.PoseStream)."""

    def __init__(self, source: PoseSource) -> None:
        self.source = source

    def start(self) -> None:
        self.source.start()

    def next(self, after_seq: int, timeout_s: float) -> tuple[Pose | None, int]:
        from perchd.mocap.base import next_pose

        return next_pose(self.source, after_seq, timeout_s)

    def close(self) -> None:
        self.source.close()


def open_mocap(uri: str) -> MocapStream:
    """The mocap URI's source, opened (its own modules imported) and not started; the mocap
    is imported here, not at start-up: a sentinel without one to relay starts sooner."""
    from perchd.core.runtime import Runtime
    from perchd.mocap.base import open_source

    return MocapStream(open_source(uri, Runtime.real()))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:], open_mocap))
