"""`zmq://` pose source and the pose publisher (docs/contracts.md §3, topic `pose`).

    zmq://HOST:PORT?body=NAME[&bind=1[&public=1]][&clock=local|remote][&max_age=0.5]

Messages are multipart `[b"pose", JSON]` with body, seq, t, p (world, Z up, metres),
q (x, y, z, w) and valid. The source SUBscribes, by default connecting to a publisher that
bound the port (a mocap bridge, `perchd sim --pose-out`). `clock=local` (default) says the
sender's `t` is on this machine's clock (the simulator, a bridge on this host using
time.monotonic), so latency = arrival - t; `clock=remote` takes t for ordering only
(latency 0, the pose measured on arrival). Validation and staleness are those of every socket
source (perchd.mocap.stream): malformed, non-finite, huge, stale, out-of-order and
other-body messages are counted and dropped, never raised. Binding (the source with bind=1,
the publisher) is on loopback only unless public=1 / public=True opts in (perchd.core.netbind).

    pub = ZmqPosePublisher("tcp://127.0.0.1:0")     # ephemeral port; pub.uri("cf1")
    pub.wait_for_subscriber(2.0)
    pub.publish(pose)
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from typing import Any

import zmq

from perchd.core.clock import Clock
from perchd.core.errors import LinkError, UriError
from perchd.core.netbind import check_bind, port_error
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.core.uri import Uri
from perchd.core.uriparams import bool_param, float_param
from perchd.mocap.stream import (
    Drop,
    PoseLimits,
    PoseStream,
    RateLimitedWarning,
    ThreadedSource,
)

log = logging.getLogger("perchd.mocap.zmq")

TOPIC = b"pose"
MAX_MESSAGE = 64 * 1024  # a pose is ~150 bytes; anything this big is not one
CLOCK_SKEW_S = 0.005  # [s] a local-clock t this far in the future is rounding, not an error
_PARAMS = ("body", "bind", "clock", "max_age", "public")


def open_zmq(uri: Uri, runtime: Runtime) -> ZmqPoseSource:
    """Registry factory for `zmq://` (not started yet)."""
    unknown = sorted(set(uri.query) - set(_PARAMS))
    if unknown:
        raise UriError(f"{uri.raw}: unknown parameter {unknown[0]!r}; known: {', '.join(_PARAMS)}")
    if not uri.host or uri.port is None:
        raise UriError(
            f"{uri.raw}: a zmq pose source needs host and port, e.g. zmq://127.0.0.1:5555?body=cf1"
        )
    body = uri.param("body") or ""
    if not body:
        raise UriError(f"{uri.raw}: body=NAME is required")
    clock = uri.param("clock", "local")
    if clock not in ("local", "remote"):
        raise UriError(f"{uri.raw}: clock={clock!r} must be local or remote")
    max_age = float_param(uri, "max_age", 0.5, 0.001, 10.0, " s")
    if bool_param(uri, "bind"):
        check_bind(uri.host, bool_param(uri, "public"), uri.raw)
    return ZmqPoseSource(
        f"tcp://{uri.host}:{uri.port}",
        body,
        runtime.clock,
        bind=bool_param(uri, "bind"),
        local_clock=clock == "local",
        limits=PoseLimits(max_age_s=max_age),
        name=uri.raw,
    )


# ---------------------------------------------------------------- message codec


def pose_message(pose: Pose) -> bytes:
    """The docs/contracts.md §3 JSON body of a pose."""
    return json.dumps(
        {
            "body": pose.body,
            "seq": pose.seq,
            "t": pose.t,
            "p": list(pose.p),
            "q": list(pose.q),
            "valid": pose.valid,
        }
    ).encode()


class BadMessage(ValueError):
    """A message that is not a docs/contracts.md §3 pose."""


def parse_pose_message(body: bytes) -> tuple[str, int, float, tuple, tuple, bool]:
    """(body, seq, t, p, q, valid) of a pose message; BadMessage naming the faulty field."""
    try:
        msg = json.loads(body)
    except (UnicodeDecodeError, ValueError) as err:
        raise BadMessage(f"not JSON: {err}") from None
    if not isinstance(msg, dict):
        raise BadMessage(f"not a JSON object but {type(msg).__name__}")
    name, seq, t, valid = msg.get("body"), msg.get("seq"), msg.get("t"), msg.get("valid", True)
    if not isinstance(name, str):
        raise BadMessage("body must be a string")
    if not isinstance(seq, int) or isinstance(seq, bool):
        raise BadMessage(f"seq must be an integer, got {seq!r}")
    if not _is_number(t):
        raise BadMessage(f"t must be a number, got {t!r}")
    if not isinstance(valid, bool):
        raise BadMessage(f"valid must be true or false, got {valid!r}")
    return name, seq, float(t), _vector(msg, "p", 3), _vector(msg, "q", 4), valid


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _vector(msg: dict, key: str, n: int) -> tuple[float, ...]:
    value = msg.get(key)
    if not isinstance(value, list) or len(value) != n or not all(map(_is_number, value)):
        raise BadMessage(f"{key} must be a list of {n} numbers, got {value!r}"[:200])
    return tuple(float(v) for v in value)


# ---------------------------------------------------------------- source


class ZmqPoseSource(ThreadedSource):
    """PoseSource over a ZMQ SUB socket; a thread receives, validates and publishes."""

    def __init__(
        self,
        endpoint: str,
        body: str,
        clock: Clock,
        *,
        bind: bool = False,
        local_clock: bool = True,
        limits: PoseLimits | None = None,
        name: str = "",
    ) -> None:
        super().__init__()
        self.body = body
        self.endpoint = endpoint
        self._clock = clock
        self._bind = bind
        self._local_clock = local_clock
        self._name = name or endpoint
        self._stream = PoseStream(body, limits or PoseLimits(), RateLimitedWarning(log, self._name))
        self._sock: Any = None

    def start(self) -> None:
        sock = zmq.Context.instance().socket(zmq.SUB)
        sock.setsockopt(zmq.SUBSCRIBE, TOPIC)
        sock.setsockopt(zmq.LINGER, 0)
        try:
            (sock.bind if self._bind else sock.connect)(self.endpoint)
        except zmq.ZMQError as err:
            sock.close(0)
            if self._bind:  # a taken port is bad input (exit 2), as for every listener
                raise port_error(self._name, err) from None
            raise LinkError(f"{self._name}: cannot open {self.endpoint}: {err}") from None
        if self._bind:  # port 0 binds an ephemeral port: say which
            self.endpoint = sock.getsockopt(zmq.LAST_ENDPOINT).decode()
        self._sock = sock
        self._start_thread("zmq-pose-rx")

    def close(self) -> None:
        self._stop_thread()
        if self._sock is not None:
            self._sock.close(0)
            self._sock = None

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                if not self._sock.poll(50):
                    continue
                frames = self._sock.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                continue
            except zmq.ZMQError as err:
                if self._stop.is_set():
                    return
                log.warning("%s: receive error: %s", self._name, err)
                continue
            self.handle_message(frames, self._clock.now())

    def handle_message(self, frames: list[bytes], arrival: float) -> None:
        """Turn one multipart message that arrived at agent time `arrival` into a pose;
        never raises."""
        self._stream.packet()
        try:
            self._accept(frames, arrival)
        except BadMessage as err:
            self._stream.drop(Drop.GARBAGE, str(err))
        except Exception as err:  # noqa: BLE001 - the receive loop must survive anything
            self._stream.drop(Drop.GARBAGE, f"{type(err).__name__}: {err}")

    def _accept(self, frames: list[bytes], arrival: float) -> None:
        if len(frames) != 2 or frames[0] != TOPIC:
            raise BadMessage(f"expected [b'pose', JSON], got {len(frames)} frames")
        if len(frames[1]) > MAX_MESSAGE:
            self._stream.drop(Drop.OVERSIZED, f"{len(frames[1])} bytes")
            return
        body, seq, t, p, q, valid = parse_pose_message(frames[1])
        if body != self.body:
            self._stream.drop(Drop.WRONG_BODY, f"pose of {body!r}, following {self.body!r}")
            return
        latency = 0.0
        if self._local_clock and math.isfinite(t):
            latency = arrival - t
            if -CLOCK_SKEW_S <= latency < 0.0:
                latency = 0.0
        self._stream.offer(Pose(body, seq, arrival - latency, p, q, valid, latency))


# ---------------------------------------------------------------- publisher


class ZmqPosePublisher:
    """Publishes docs/contracts.md §3 poses; binds by default (the source connects).

    endpoint: "tcp://HOST:PORT" or "zmq://HOST:PORT"; port 0 picks a free port (read it back
    from `endpoint`). An XPUB underneath lets `wait_for_subscriber` avoid sending into the void.
    A bind on anything but loopback needs public=True.
    """

    def __init__(
        self, endpoint: str = "tcp://127.0.0.1:0", *, bind: bool = True, public: bool = False
    ) -> None:
        address = endpoint.replace("zmq://", "tcp://", 1).split("?", 1)[0]
        if bind:
            check_bind(
                address.split("://", 1)[-1].rsplit(":", 1)[0], public, f"pose publisher {address}"
            )
        if address.endswith(":0"):
            address = address[:-2] + ":*"
        self._sock = zmq.Context.instance().socket(zmq.XPUB)
        self._sock.setsockopt(zmq.LINGER, 200)
        try:
            (self._sock.bind if bind else self._sock.connect)(address)
        except zmq.ZMQError as err:
            self._sock.close(0)
            raise LinkError(f"cannot open pose publisher on {address}: {err}") from None
        self.endpoint = self._sock.getsockopt(zmq.LAST_ENDPOINT).decode() if bind else address
        self._subscribers = 0
        self._lock = threading.Lock()

    def uri(self, body: str) -> str:
        """The zmq:// URI a perchd source uses to follow `body` from this publisher."""
        return f"zmq://{self.endpoint.split('://', 1)[1]}?body={body}"

    def publish(self, pose: Pose) -> None:
        self.send_raw([TOPIC, pose_message(pose)])

    def send_raw(self, frames: list[bytes]) -> None:
        """Send any multipart message (tests use it for malformed ones); never blocks."""
        with self._lock:
            try:
                self._sock.send_multipart(frames, zmq.NOBLOCK)
            except zmq.Again:
                pass  # no room for a slow subscriber: it loses this pose, the flight goes on

    def wait_for_subscriber(self, timeout: float) -> bool:
        """Block until some subscriber has subscribed to `pose` (True) or `timeout` [s]."""
        deadline = time.monotonic() + timeout
        with self._lock:
            while self._subscribers <= 0:
                left = deadline - time.monotonic()
                if left <= 0 or not self._sock.poll(int(left * 1000) + 1):
                    return False
                note = self._sock.recv()
                if note[:1] == b"\x01" and TOPIC.startswith(note[1:]):
                    self._subscribers += 1
            return True

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> ZmqPosePublisher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
