"""Setpoints into a simulated world over ZMQ (docs/contracts.md §3 topics `setpoint` and
`stop`): the vehicle side of `perchd sim` and of the loop benchmark's rig."""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import zmq

from perchd.core.errors import LinkError, UriError
from perchd.core.netbind import check_bind
from perchd.core.types import Setpoint
from perchd.core.uri import parse_uri
from perchd.core.uriparams import bool_param
from perchd.drivers.zmq import BadSetpoint, parse_setpoint_message, sender_of
from perchd.sim.onesender import SenderGate
from perchd.sim.watchdog import SetpointWatchdog, WatchdogParams
from perchd.sim.world import SimWorld


def bind_setpoint_socket(host: str, port: int, where: str) -> tuple[zmq.Socket, int]:
    """A SUB socket bound at host:port (0: a free port) for the setpoint and stop topics,
    and the port it got; a port in use is one LinkError naming `where`."""
    sock = zmq.Context.instance().socket(zmq.SUB)
    sock.setsockopt(zmq.LINGER, 0)
    try:
        sock.bind(f"tcp://{host}:{port or '*'}")
    except zmq.ZMQError as err:
        sock.close()
        raise LinkError(f"{where}: cannot bind: {err}") from None
    for topic in (b"setpoint", b"stop"):
        sock.setsockopt(zmq.SUBSCRIBE, topic)
    return sock, int(sock.getsockopt(zmq.LAST_ENDPOINT).decode().rsplit(":", 1)[1])


@dataclass
class Counts:
    setpoints: int = 0
    stops: int = 0
    rejected: int = 0
    foreign: int = 0  # setpoints and stops from a second sender while the first is live
    poses: int = 0
    stop_at: float | None = None  # time.monotonic() of the first stop


NAMED_MAX = 64
"""Refused senders named in a line each; more are only counted (a flood of ids stays bounded)."""


def say(line: str) -> None:
    print(f"perchd sim: {line}", file=sys.stderr, flush=True)


class SetpointInbox:
    """SUB bound at --setpoint-in: setpoints and stops for `body` go to the world, through
    the vehicle's setpoint watchdog (checked on this thread, between messages), from one
    sender at a time (sim/onesender.py); a second is counted and named once in a line."""

    def __init__(
        self,
        text: str,
        world: SimWorld,
        body: str,
        counts: Counts,
        watchdog: WatchdogParams | None = None,
        log: Callable[[str], None] = say,
        gate: SenderGate | None = None,
    ) -> None:
        uri = parse_uri(text)
        if uri.scheme != "zmq" or not uri.host or uri.port is None:
            raise UriError(f"--setpoint-in {text}: expected zmq://HOST:PORT")
        check_bind(uri.host, bool_param(uri, "public"), f"--setpoint-in {text}")
        self.world, self.body, self.counts, self.log = world, body, counts, log
        self.gate = gate or SenderGate()
        self._named: set[str] = set()  # refused senders already named in a line
        self.watchdog = SetpointWatchdog(watchdog or WatchdogParams(), world.command)
        self.sock, port = bind_setpoint_socket(uri.host, uri.port, f"--setpoint-in {text}")
        self.uri = f"zmq://{uri.host}:{port}?vehicle={body}"
        self._alive = True
        self._thread = threading.Thread(target=self._serve, name="sim-setpoints", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while self._alive:
            due = self.watchdog.check(self.world.clock.now())
            wait_ms = 50 if due is None else max(1, min(50, math.ceil(1000 * due)))
            if self.sock.poll(wait_ms):
                frames = self.sock.recv_multipart()
                if len(frames) != 2:  # not [topic, JSON]: counted, never fatal
                    self.counts.rejected += 1
                    continue
                self.handle(*frames)

    def handle(self, topic: bytes, body: bytes) -> None:
        if topic == b"stop":
            self._stop(body)
        else:
            self._setpoint(body)

    def _stop(self, body: bytes) -> None:
        if not self._admitted(self.gate.stop, body):
            return
        self.counts.stops += 1
        self.counts.stop_at = self.counts.stop_at or time.monotonic()
        self.world.command(Setpoint.stop(self.world.clock.now()))
        self.watchdog.stopped()

    def _setpoint(self, body: bytes) -> None:
        try:
            vehicle, _, sp = parse_setpoint_message(body)
        except BadSetpoint:
            self.counts.rejected += 1  # counted, never fatal: the sim outlives a bad sender
            return
        if vehicle in ("", self.body) and self._admitted(self.gate.admit, body):
            self.counts.setpoints += 1  # received; the thrust lock may refuse it
            self.watchdog.feed(sp, self.world.clock.now())

    def _admitted(self, gate: Callable[[str, float], bool], body: bytes) -> bool:
        """The gate's word on this message's sender; a refusal counted, and named once."""
        sender = sender_of(body)
        if gate(sender, self.world.clock.now()):
            return True
        self.counts.foreign += 1
        if sender not in self._named and len(self._named) < NAMED_MAX:
            self._named.add(sender)
            self.log(
                f"refusing sender {sender or '(unnamed)'}: sender "
                f"{self.gate.holder or '(unnamed)'} is steering the vehicle"
            )
        return False

    def close(self) -> None:
        self._alive = False
        self._thread.join(timeout=1.0)
        self.sock.close()
