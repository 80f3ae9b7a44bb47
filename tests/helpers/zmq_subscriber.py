"""A ZMQ subscriber standing in for `perchd sim --setpoint-in` or a HIL rig: binds an
ephemeral port, subscribes to `setpoint` and `stop`, and records what arrives."""

from __future__ import annotations

import json
import threading
import time

import zmq
from ticks import wait_for


class SetpointSubscriber:
    def __init__(self) -> None:
        self.sock = zmq.Context.instance().socket(zmq.SUB)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.bind("tcp://127.0.0.1:*")
        self.port = int(self.sock.getsockopt(zmq.LAST_ENDPOINT).decode().rsplit(":", 1)[1])
        self.uri = f"zmq://127.0.0.1:{self.port}"
        for topic in (b"setpoint", b"stop"):
            self.sock.setsockopt(zmq.SUBSCRIBE, topic)
        self.received: list[tuple[str, dict, float]] = []  # topic, body, arrival [s]
        self._alive = True
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._serve, name="zmq-subscriber", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while self._alive:
            if not self.sock.poll(5):
                continue
            topic, body = self.sock.recv_multipart()
            with self._lock:
                self.received.append((topic.decode(), json.loads(body), time.monotonic()))

    def of(self, topic: str) -> list[dict]:
        with self._lock:
            return [body for t, body, _ in self.received if t == topic]

    def arrivals(self, topic: str) -> list[float]:
        with self._lock:
            return [at for t, _, at in self.received if t == topic]

    wait_for = staticmethod(wait_for)

    def die(self) -> None:
        if self._alive:
            self._alive = False
            self._thread.join(timeout=1.0)
            self.sock.close(0)

    close = die
