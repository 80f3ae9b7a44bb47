"""Setpoints published on ZMQ (docs/contracts.md §3) for external simulators and HIL rigs.

`zmq://HOST:PORT[?vehicle=cf1&bind=1&wait=2]`: by default the driver connects to a
subscriber that has bound the port (`perchd sim --setpoint-in` binds, like a mocap bridge
binds its pose port); bind=1 binds instead, on loopback only unless public=1 is added
(perchd.core.netbind). The socket is an XPUB, so the driver sees its
subscribers come and go: connect() waits up to `wait` seconds for one to subscribe to
`setpoint` (nothing is sent into the void), and health() is not ok once none is left.
"""

from __future__ import annotations

import json
import math
import os
import secrets
import time
from typing import Any

import zmq

from perchd.core.errors import LinkError, UriError
from perchd.core.netbind import check_bind, port_error
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, LinkHealth, Phase, Setpoint
from perchd.core.uri import Uri
from perchd.core.uriparams import bool_param, float_param
from perchd.drivers.base import DriverBase, PoseFeed, no_poses
from perchd.drivers.targetlock import TargetLock, connect_holding

SETPOINT, STOP = b"setpoint", b"stop"


def open_zmq_driver(uri: Uri, runtime: Runtime) -> ZmqSetpointDriver:
    if not uri.host or uri.port is None:
        raise UriError(f"{uri.raw}: a zmq driver needs host and port, e.g. zmq://127.0.0.1:5556")
    if bool_param(uri, "bind"):
        check_bind(uri.host, bool_param(uri, "public"), uri.raw)
    return ZmqSetpointDriver(
        uri.raw,
        f"tcp://{uri.host}:{uri.port}",
        runtime,
        vehicle=uri.param("vehicle", "cf1") or "cf1",
        bind=bool_param(uri, "bind"),
        wait=float_param(uri, "wait", 2.0, 0.0, 60.0, " s"),
    )


def setpoint_message(vehicle: str, seq: int, sp: Setpoint, sender: str = "") -> dict[str, Any]:
    """The docs/contracts.md §3 setpoint body: radians, newtons, world-frame Z-Y-X attitude."""
    return {
        "vehicle": vehicle,
        "seq": seq,
        "t": sp.t,
        "pose_seq": sp.pose_seq,
        "roll": sp.roll,
        "pitch": sp.pitch,
        "yaw": sp.yaw,
        "thrust": sp.thrust,
        "phase": sp.phase.value,
        "sender": sender,
    }


def new_sender_id() -> str:
    """This driver on the wire: the pid, and random bits for a pid reused or a second driver."""
    return f"{os.getpid()}-{secrets.token_hex(4)}"


def sender_of(body: bytes) -> str:
    """The sender id of a `setpoint` or `stop` body ("" when it names none: a sender older
    than the field, or not JSON at all)."""
    try:
        msg = json.loads(body)
    except (ValueError, UnicodeDecodeError, RecursionError):
        return ""
    sender = msg.get("sender", "") if isinstance(msg, dict) else ""
    return sender if isinstance(sender, str) else ""


class BadSetpoint(ValueError):
    """A setpoint message that does not follow docs/contracts.md §3; the message names the field."""


def parse_setpoint_message(body: bytes) -> tuple[str, int, Setpoint]:
    """(vehicle, seq, Setpoint) from a `setpoint` body, the receiving end of setpoint_message."""
    try:
        msg = json.loads(body)
    except (ValueError, UnicodeDecodeError) as err:
        raise BadSetpoint(f"setpoint message is not JSON: {err}") from None
    except RecursionError:
        raise BadSetpoint("setpoint message is not JSON: nested too deeply") from None
    if not isinstance(msg, dict):
        raise BadSetpoint("setpoint message is not a JSON object")
    values = {}
    for key in ("t", "roll", "pitch", "yaw", "thrust"):
        v = msg.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise BadSetpoint(f"setpoint field {key!r} must be a finite number, got {v!r}")
        values[key] = float(v)
    try:
        phase = Phase(msg.get("phase", Phase.STAGE1.value))
    except ValueError:
        raise BadSetpoint(f"setpoint field 'phase' is not a phase: {msg.get('phase')!r}") from None
    seq, pose_seq = msg.get("seq", -1), msg.get("pose_seq", -1)
    if not isinstance(seq, int) or not isinstance(pose_seq, int):
        raise BadSetpoint("setpoint fields 'seq' and 'pose_seq' must be integers")
    sp = Setpoint(
        values["t"],
        values["roll"],
        values["pitch"],
        values["yaw"],
        values["thrust"],
        pose_seq,
        phase,
    )
    return str(msg.get("vehicle", "")), seq, sp


class ZmqSetpointDriver(DriverBase):
    def __init__(
        self, uri: str, endpoint: str, runtime: Runtime, vehicle: str, bind: bool, wait: float
    ) -> None:
        self.uri = uri
        self.endpoint = endpoint
        self.clock = runtime.clock
        self.vehicle = vehicle
        self.bind = bind
        self.wait = wait
        self._sock: Any = None
        self._subscribers = 0
        self._seq = 0
        self._stopped = False
        self._lock = TargetLock(uri)
        self.sender = new_sender_id()
        self.failsafe_reasons: list[EndReason] = []

    def connect(self) -> None:
        connect_holding(self._lock, self._open, self._release)

    def _open(self) -> None:
        sock = zmq.Context.instance().socket(zmq.XPUB)
        sock.setsockopt(zmq.LINGER, 500)  # let a final stop reach the subscriber
        sock.setsockopt(zmq.XPUB_VERBOSER, 1)  # every (un)subscription, for the count
        sock.setsockopt(zmq.IMMEDIATE, 1)  # a lost peer drops its pipe: we see it unsubscribe
        try:
            (sock.bind if self.bind else sock.connect)(self.endpoint)
        except zmq.ZMQError as err:
            sock.close(0)
            if self.bind:  # a taken port is bad input (exit 2), as for every listener
                raise port_error(self.uri, err) from None
            raise LinkError(f"{self.uri}: cannot open {self.endpoint}: {err}") from None
        self._sock, self._stopped, self._subscribers = sock, False, 0
        deadline = time.monotonic() + self.wait
        while self._subscribers <= 0:
            left = deadline - time.monotonic()
            if left <= 0 or not sock.poll(int(left * 1000) + 1):
                raise LinkError(f"{self.uri}: no subscriber to 'setpoint' within {self.wait:g} s")
            self._drain()

    def send(self, setpoint: Setpoint) -> None:
        if self._stopped or self._sock is None:
            return
        body = setpoint_message(self.vehicle, self._seq, setpoint, self.sender)
        self._seq += 1
        self._publish(SETPOINT, body)

    def engage(self, poses: PoseFeed = no_poses) -> None:
        """A flight after a failsafe on the same link (perchd serve) streams again; the last
        flight's `stop` was its end."""
        self._stopped = False

    def failsafe(self, reason: EndReason) -> None:
        self.failsafe_reasons.append(reason)
        self._stop(reason.value, reason.name)

    def health(self) -> LinkHealth:
        if self._sock is None:
            return LinkHealth(False, 0.0, "not connected")
        self._drain()
        if self._subscribers <= 0:
            return LinkHealth(False, 0.0, "connection lost: no subscriber to 'setpoint' left")
        return LinkHealth(True, 0.0)

    def close(self, hand_over: bool = True) -> None:  # nothing outlives the link
        if self._sock is None:
            return
        if not self._stopped:
            self._stop("driver closed while the vehicle was flying", "CLOSED")
        self._release()

    def _stop(self, reason: str, code: str) -> None:
        self._stopped = True
        if self._sock is not None:
            self._publish(
                STOP,
                {
                    "vehicle": self.vehicle,
                    "reason": reason,
                    "code": code,
                    "t": self.clock.now(),
                    "sender": self.sender,
                },
            )

    def _publish(self, topic: bytes, body: dict[str, Any]) -> None:
        try:
            self._sock.send_multipart([topic, json.dumps(body).encode()], zmq.NOBLOCK)
        except zmq.Again:
            pass  # a PUB never blocks the control loop; a slow subscriber loses messages

    def _drain(self) -> None:
        """Count subscriptions to 'setpoint' (or to everything) from XPUB's notices."""
        # Asking EVENTS first: an empty recv would raise zmq.Again on nearly every tick.
        while self._sock.getsockopt(zmq.EVENTS) & zmq.POLLIN:
            note = self._sock.recv(zmq.NOBLOCK)
            if note[:1] in (b"\x00", b"\x01") and SETPOINT.startswith(note[1:]):
                self._subscribers += 1 if note[:1] == b"\x01" else -1

    def _release(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()
        self._lock.release()
