"""Between a service's flights, the mocap still reaches the driver (docs/safety.md,
"Between flights").

During a flight the control loop hands each pose to Driver.observe_pose; that is how an
autopilot whose EKF runs on the mocap alone (MAVLink, `vision` on) keeps its position. A
service keeps its links between flights, and the vehicle does not stop needing the mocap
there: a failsafe's LAND descends for seconds after the flight has ended, and a pilot may
fly it. A stream that pauses is worse than a late one: EKF2 resets its position when an
external source comes back after a gap, under a vehicle that may be hovering. So this
thread hands the poses over whenever no flight does, and steps aside for each flight.
"""

from __future__ import annotations

import logging
import threading

from perchd.core.ports import Driver, PoseSource
from perchd.mocap.base import next_pose

log = logging.getLogger(__name__)

WAIT_S = 0.05
"""[s] longest wait for a pose; pause() returns within it and one observe_pose call."""


class IdleFeed:
    """A thread feeding `source`'s poses to `driver.observe_pose` while resumed. It starts
    paused; pause() returns once no pose is being read or handed over, so the flight that
    follows is the driver's only feeder."""

    def __init__(self, source: PoseSource, driver: Driver) -> None:
        self.source, self.driver = source, driver
        self.fed = 0  # poses handed over
        self._idle = threading.Event()
        self._closed = threading.Event()
        self._turn = threading.Lock()  # held while reading and handing over one pose
        self._seq = -1
        self._failed = ""
        self._thread = threading.Thread(target=self._run, name="perchd-idle-feed", daemon=True)
        self._thread.start()

    def resume(self) -> None:
        self._idle.set()

    def pause(self) -> None:
        self._idle.clear()
        with self._turn:
            pass

    def close(self) -> None:
        self._closed.set()
        self._idle.set()  # wakes the thread to see it closed (it feeds nothing once closed)
        with self._turn:
            pass
        self._thread.join(1.0)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        while not self._closed.is_set():
            self._idle.wait()  # paused through a flight: no wake-ups beside its loop
            with self._turn:
                if self._idle.is_set() and not self._closed.is_set():
                    self._feed_one()

    def _feed_one(self) -> None:
        try:
            pose, self._seq = next_pose(self.source, self._seq, WAIT_S)
            if pose is None:
                return
            self.driver.observe_pose(pose)
        except Exception as err:  # noqa: BLE001 - the next pose tries again; said once per kind
            why = f"{type(err).__name__}: {err}"
            if why != self._failed:
                log.warning("between flights, a pose did not reach the driver: %s", why)
            self._failed = why
            return
        self.fed, self._failed = self.fed + 1, ""
