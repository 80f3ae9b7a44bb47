"""The mocap kept flowing to the autopilot after the agent dies (docs/safety.md, "When the
agent dies").

An EKF on mocap alone (PX4 EKF2_EV_CTRL, ArduPilot ExternalNav) loses its only position
source with the agent: the sentinel's brake stops the vehicle, and then the autopilot's
Land holds a dead-reckoned position that drifts (PX4 SIH: 1.0-1.4 m further toward the
wall, creeping at ~0.2 m/s). So the sentinel (sentinel.py) opens the flight's
own mocap URI when it starts (through the PoseOpener its process entry point injects:
perchd/service/mavsentinel_main.py) (its sockets only once the agent has died: the agent's own
source is never competed with) and from the death on sends each pose as
VISION_POSITION_ESTIMATE, as the driver did (vision.py: the same frame, yaw0 as
the driver last told it, the same stamps on the same monotonic clock, whose TIMESYNC the
sentinel answers), until the landing is over (sentinel.follow_landing).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Protocol

from perchd.core.childproc import say
from perchd.core.types import Pose
from perchd.drivers.mavlink.vision import vision_estimate, vision_message

RELAY_MAX_S = 120.0
"""[s] the longest the mocap is relayed after the agent's death (a landing takes seconds;
a vehicle still armed after this is someone else's)."""
DISARMED_GRACE_S = 1.0
"""[s] relayed on after the vehicle is seen disarmed (its EKF may log or settle)."""
WAIT_S = 0.1
"""[s] the relay thread looks for its stop this often when no pose comes."""


class PoseStream(Protocol):
    """The flight's mocap as the relay reads it: start() opens its sockets; next(after_seq,
    timeout_s) -> (the next pose after after_seq within timeout_s [s] or None, the seq to
    wait after next); close()."""

    def start(self) -> None: ...

    def next(self, after_seq: int, timeout_s: float) -> tuple[Pose | None, int]: ...

    def close(self) -> None: ...


PoseOpener = Callable[[str], PoseStream]
"""Opens a mocap URI as a PoseStream, not started (the mocap is no driver's to import)."""


class VisionRelay:
    """Poses of `poses` (opened, not started: a death then costs no imports) to `send` as
    VISION_POSITION_ESTIMATE frames from `source` (system, component), in NED by yaw0 [rad]
    (vision.py); start() begins the relay on its own thread, stop() ends it and closes the
    poses."""

    def __init__(
        self, poses: PoseStream, source: tuple[int, int], send: Callable[[bytes], None]
    ) -> None:
        from pymavlink import mavutil

        self.poses = poses
        self._mav = mavutil.mavlink.MAVLink(None, *source)
        self._send = send
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.sent = 0

    def start(self, yaw0: float) -> None:
        self._thread = threading.Thread(
            target=self._run, args=(yaw0,), name="vision-relay", daemon=True
        )
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def frame(self, pose: Pose, yaw0: float) -> bytes:
        return vision_message(self._mav, vision_estimate(pose, yaw0)).pack(self._mav)

    def _run(self, yaw0: float) -> None:
        try:
            self.poses.start()
        except Exception as err:  # noqa: BLE001 - the brake and LAND go on without it
            say("mavsentinel", f"the mocap cannot be relayed: {err}")
            return
        seq = -1
        try:
            while not self._stop.is_set():
                pose, seq = self.poses.next(seq, WAIT_S)
                if pose is not None and pose.valid:
                    self._relay(self.frame(pose, yaw0))
        except OSError as err:  # the link is gone: nothing more to relay to
            say("mavsentinel", f"mocap relay ended: {err}")
        finally:
            self.poses.close()
            say("mavsentinel", f"relayed {self.sent} mocap poses")

    def _relay(self, frame: bytes) -> None:
        try:
            self._send(frame)
            self.sent += 1
        except (BlockingIOError, InterruptedError):
            pass  # a full send buffer costs this pose, not the relay
