"""A vehicle standing still (or moving at a constant `velocity` [m/s] from its first pose),
as mocap: a ZMQ pose publisher (docs/contracts.md §3), or with natnet=True perchd's NatNet
server emulator (unicast, as Motive serves several clients), sending one body's pose at
100 Hz on the monotonic clock, with 0.5 mm of noise (a real tracker is never bit-still),
until close(); snapshot() maps each pose's stamp [us] to its position."""

from __future__ import annotations

import random
import threading
import time

from perchd.core.types import Pose
from perchd.mocap.natnet.server import NatNetServer
from perchd.mocap.zmq import ZmqPosePublisher


class StillPoses:
    def __init__(
        self,
        p: tuple[float, float, float] = (-4.5, 0.0, 1.0),
        body: str = "cf1",
        rate_hz: float = 100.0,
        velocity: tuple[float, float, float] = (0.0, 0.0, 0.0),
        natnet: bool = False,
    ) -> None:
        if natnet:
            self.pub = NatNetServer([body]).start()
            self.uri = f"{self.pub.uri}&body={body}"
        else:
            self.pub = ZmqPosePublisher("tcp://127.0.0.1:0")
            self.uri = self.pub.uri(body)
        self.p, self.body, self.period = p, body, 1.0 / rate_hz
        self.sent = 0
        self.velocity = velocity
        self._published: dict[int, tuple[float, ...]] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="still-poses", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        rng, t0 = random.Random(0), time.monotonic()
        while not self._stop.wait(self.period):
            self.sent, t = self.sent + 1, time.monotonic()
            p = tuple(
                c + v * (t - t0) + rng.gauss(0.0, 0.0005)
                for c, v in zip(self.p, self.velocity, strict=True)
            )
            with self._lock:
                self._published[round(t * 1e6)] = p
            self.pub.publish(Pose(self.body, self.sent, t, p, (0.0, 0.0, 0.0, 1.0)))

    def snapshot(self) -> dict[int, tuple[float, ...]]:
        """{stamp [us]: position [m]} of every pose published so far."""
        with self._lock:
            return dict(self._published)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        self.pub.close()
