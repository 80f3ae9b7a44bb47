"""A loopback UDP relay between a driver and its test peer, with the link's faults as knobs.

The driver is pointed at the relay's port; the relay forwards each datagram to the peer
(CRTP responder, MAVLink double) and the peer's answers back, after `delay_s` [s] each way.
mute() drops the peer's answers (a vehicle that stops answering), pause()/resume() drop
everything both ways (a link that goes away and comes back).
"""

from __future__ import annotations

import heapq
import itertools
import socket
import threading
import time


class UdpRelay:
    def __init__(self, peer_port: int, delay_s: float = 0.0) -> None:
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind(("127.0.0.1", 0))
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.bind(("127.0.0.1", 0))
        self.back.connect(("127.0.0.1", peer_port))
        self.port = self.front.getsockname()[1]
        for s in (self.front, self.back):
            s.settimeout(0.05)  # the threads look at _alive this often
        self.delay_s = delay_s
        self.muted = self.paused = False
        self.forwarded = {"up": 0, "down": 0}
        self._client: tuple[str, int] | None = None
        self._due: list[tuple[float, int, str, bytes]] = []
        self._order = itertools.count()
        self._wake = threading.Condition()
        self._alive = True
        self._threads = [
            threading.Thread(target=fn, daemon=True, name=f"relay-{n}")
            for n, fn in (("up", self._up), ("down", self._down), ("out", self._out))
        ]
        for t in self._threads:
            t.start()

    def inject(self, data: bytes) -> None:
        """A datagram down to the driver as if from the peer's side: another component behind
        a router, whose traffic reaches every link."""
        self._queue("down", data)

    def mute(self) -> None:
        self.muted = True

    def pause(self) -> None:
        self.paused = True

    def resume(self) -> None:
        self.paused = self.muted = False

    def _queue(self, way: str, data: bytes) -> None:
        with self._wake:
            due = time.monotonic() + self.delay_s
            heapq.heappush(self._due, (due, next(self._order), way, data))
            self._wake.notify()

    def _up(self) -> None:
        while self._alive:
            try:
                data, addr = self.front.recvfrom(2048)
            except TimeoutError:
                continue
            except OSError:
                return
            self._client = addr
            if not self.paused:
                self._queue("up", data)

    def _down(self) -> None:
        while self._alive:
            try:
                data = self.back.recv(2048)
            except (TimeoutError, ConnectionRefusedError):
                continue  # the peer is gone; keep relaying whatever comes
            except OSError:
                return
            if not (self.paused or self.muted):
                self._queue("down", data)

    def _out(self) -> None:
        while self._alive:
            with self._wake:
                while self._alive and (not self._due or self._due[0][0] > time.monotonic()):
                    wait = self._due[0][0] - time.monotonic() if self._due else None
                    self._wake.wait(wait)
                if not self._alive:
                    return
                _, _, way, data = heapq.heappop(self._due)
            try:
                if way == "up":
                    self.back.send(data)
                elif self._client is not None:
                    self.front.sendto(data, self._client)
                self.forwarded[way] += 1
            except OSError:
                pass  # the far end is closed: the datagram is lost, as on a real link

    def close(self) -> None:
        self._alive = False
        with self._wake:
            self._wake.notify()
        for t in self._threads:
            t.join(timeout=1.0)
        for s in (self.front, self.back):
            s.close()
