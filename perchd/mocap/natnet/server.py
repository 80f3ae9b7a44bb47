"""A NatNet server emulator: stands in for Motive in tests and hardware-in-the-loop runs.

    server = NatNetServer(bodies={"cf1": 1}, version=(4, 1), host="127.0.0.1").start()
    server.publish(pose)          # a world-frame perchd Pose (Z up); sent as Motive would
    ...
    server.close()

It answers connect and discovery with server info, model-definition requests, echo requests
(with its clock, for the client's clock sync), keep-alives, frame requests and the common
string requests (FrameRate, UnitsToMillimeters, CurrentMode, Bitstream, ...), and streams
frames of data by multicast (group 239.255.42.99 on the data port, out of `host`'s
interface) or by unicast to every client that connected (to the socket it connected from, as
Motive does, once it has sent it the server info, which tells the client how to read frames).
With `rate_hz` it sends a frame at that rate carrying each body's newest pose; without, every
`publish` sends one frame at once. Every frame carries every pose published before it was
built: a pose published before `start` is in the first frame.

The data port is, as in Motive, a port the server advertises and sends to but does not hold:
clients (OptiTrack's samples, libmotioncapture) bind it themselves, so a server holding it
would make their bind fail. Frames leave from an ephemeral socket of the server's own.

Stamps: the server's high-resolution clock is `clock` (the agent's injected clock, so a
simulated world and its mocap share one time base) at `clock_hz` ticks/s; a pose's `t` is its
camera mid-exposure, the publish time its data-received stamp, the send time its transmit.
The command port defaults to 0 (ephemeral); the data port to Motive's 1511, or with an
ephemeral command port to a port free at start-up, so servers of parallel tests do not
share one. Read them back from `command_port` and `data_port`.
"""

from __future__ import annotations

import logging
import select
import socket
import struct
import threading
import time
from dataclasses import replace

from perchd.core.clock import Clock, MonotonicClock
from perchd.core.types import Pose
from perchd.mocap.frames import UpAxis, from_world
from perchd.mocap.natnet import models as natdefs
from perchd.mocap.natnet import protocol as proto
from perchd.mocap.natnet.frame import Frame, RigidBodySample, Timing, encode_frame
from perchd.mocap.natnet.wire import MalformedPacket, Version

log = logging.getLogger("perchd.mocap.natnet.server")

CLIENT_TIMEOUT_S = 10.0  # a unicast client silent this long is forgotten, as Motive does


class NatNetServer:
    """See the module docstring. Thread-safe: publish from any thread."""

    def __init__(
        self,
        bodies: dict[str, int] | list[str],
        version: Version = (4, 1),
        *,
        host: str = "127.0.0.1",
        command_port: int = 0,
        data_port: int | None = None,
        multicast: bool = False,
        group: str = proto.DEFAULT_MULTICAST,
        rate_hz: float | None = None,
        up: str = "y",
        clock: Clock | None = None,
        clock_hz: int = 10_000_000,
        app: tuple[str, tuple[int, int, int, int]] = ("Motive", (3, 1, 0, 0)),
    ) -> None:
        if not proto.SUPPORTED[0] <= tuple(version) <= proto.SUPPORTED[1]:
            raise ValueError(f"NatNet version {version} outside 2.0..4.1")
        self.bodies = (
            dict(bodies)
            if isinstance(bodies, dict)
            else {name: i + 1 for i, name in enumerate(bodies)}
        )
        self.version: Version = (int(version[0]), int(version[1]))
        self.host, self.multicast, self.group = host, multicast, group
        self.rate_hz, self.clock_hz = rate_hz, clock_hz
        self.up = UpAxis.parse(up, "NatNetServer")
        self._clock = clock or MonotonicClock()
        self._epoch = self._clock.now() - 1.0  # server ticks start near 1 s, never negative
        self._app = app
        self._lock = threading.Lock()
        self._latest: dict[int, tuple[RigidBodySample, float, float]] = {}
        self._clients: dict[tuple[str, int], float] = {}
        self._frame_number = 0
        self._models_changed = False
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._command = self._bind(command_port)
        self._data = self._bind(0)
        self._data_port = _advertised_data_port(data_port, command_port, host)
        if multicast:
            self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(host))
            self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
        self.frames_sent = 0
        self.keepalives = 0

    # ------------------------------------------------------------ public API

    @property
    def command_port(self) -> int:
        return self._command.getsockname()[1]

    @property
    def data_port(self) -> int:
        """The port frames are sent to (multicast) and the server info announces."""
        return self._data_port

    @property
    def uri(self) -> str:
        """A natnet:// URI a perchd client can open (add &body=NAME). NatNet 2.x server info
        does not announce the transport, group and data port, so the URI carries them."""
        uri = f"natnet://{self.host}:{self.command_port}?local={self.host}"
        if self.up is UpAxis.Z:
            uri += "&up=z"
        if self.version >= (3, 0):
            return uri
        if self.multicast:
            return uri + f"&multicast={self.group}&data_port={self.data_port}"
        return uri + "&transport=unicast"

    def start(self) -> NatNetServer:
        self._spawn(self._serve_commands, "natnet-server-cmd")
        if self.rate_hz:
            self._spawn(self._stream_frames, "natnet-server-frames")
        return self

    def publish(self, pose: Pose) -> None:
        """Take a world-frame pose of a known body; sent now, or with the next frame."""
        body_id = self.bodies.get(pose.body)
        if body_id is None:
            raise KeyError(f"NatNetServer has no body {pose.body!r}: {sorted(self.bodies)}")
        p, q = from_world(pose.p, pose.q, self.up)
        sample = RigidBodySample(body_id, p, q, 0.0002, pose.valid)
        with self._lock:
            self._latest[body_id] = (sample, pose.t, self._clock.now())
        if not self.rate_hz:
            self.send_frame()

    def redefine(self, bodies: dict[str, int]) -> None:
        """Change the rigid bodies (as when a Motive user edits assets); the next frame
        carries the "tracked models changed" flag so clients ask for the new definitions."""
        with self._lock:
            self.bodies = dict(bodies)
            self._latest.clear()
            self._models_changed = True

    def send_frame(self) -> Frame:
        """Build a frame from the newest poses and send it to every client."""
        frame = self._next_frame()
        self.send_raw(proto.pack(proto.NAT_FRAMEOFDATA, encode_frame(frame, self.version)))
        self.frames_sent += 1
        return frame

    def send_raw(self, datagram: bytes) -> None:
        """Send any datagram down the data path (tests use this for malformed packets)."""
        for address in self._destinations():
            try:
                self._data.sendto(datagram, address)
            except OSError as err:
                log.warning("natnet server: cannot send to %s: %s", address, err)

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._command.close()
        self._data.close()

    def __enter__(self) -> NatNetServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def ticks(self, t: float) -> int:
        """Server clock ticks of agent time `t` [s]."""
        return max(0, int(round((t - self._epoch) * self.clock_hz)))

    @property
    def clients(self) -> list[tuple[str, int]]:
        with self._lock:
            return list(self._clients)

    def server_info(self) -> proto.ServerInfo:
        return proto.ServerInfo(
            self._app[0],
            self._app[1],
            (*self.version, 0, 0),
            self.clock_hz,
            self.data_port,
            self.multicast,
            self.group,
        )

    def model_defs(self) -> natdefs.ModelDefs:
        with self._lock:
            named = list(self.bodies.items())
        bodies = tuple(natdefs.RigidBodyDef(name, body_id) for name, body_id in named)
        return natdefs.ModelDefs((("all", ()),), bodies)

    # ------------------------------------------------------------ internals

    def _bind(self, port: int) -> socket.socket:
        # Exclusive: no SO_REUSEADDR/SO_REUSEPORT, so a second server on a taken command port
        # fails here instead of sharing it and stealing clients (the ZMQ path refuses too).
        # The data socket is an ephemeral sender; clients bind the advertised data port.
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.host, port))
        except OSError:
            sock.close()
            raise
        return sock

    def _spawn(self, target, name: str) -> None:
        thread = threading.Thread(target=target, name=name, daemon=True)
        thread.start()
        self._threads.append(thread)

    def _next_frame(self) -> Frame:
        now = self._clock.now()
        with self._lock:
            self._frame_number += 1
            number = self._frame_number
            latest = sorted(self._latest.items())
            params, self._models_changed = (0x02 if self._models_changed else 0), False
        bodies = tuple(sample for _, (sample, _, _) in latest)
        measured = max((t for _, (_, t, _) in latest), default=now)
        received = max((r for _, (_, _, r) in latest), default=now)
        timing = Timing(
            timestamp=now - self._epoch,
            camera_mid_exposure=self.ticks(measured),
            data_received=self.ticks(received),
            transmit=self.ticks(now),
        )
        if self.version < (3, 0):
            timing = replace(timing, camera_mid_exposure=None, data_received=None, transmit=None)
        return Frame(number, bodies, timing, marker_sets=(("all", ()),), params=params)

    def _destinations(self) -> list[tuple[str, int]]:
        if self.multicast:
            return [(self.group, self.data_port)]
        now = time.monotonic()
        with self._lock:
            for address, seen in list(self._clients.items()):
                if now - seen > CLIENT_TIMEOUT_S:
                    del self._clients[address]
            return list(self._clients)

    def _stream_frames(self) -> None:
        period = 1.0 / float(self.rate_hz or 1.0)
        next_at = time.monotonic()
        while not self._stop.is_set():
            self.send_frame()
            next_at += period
            self._stop.wait(max(0.0, next_at - time.monotonic()))

    def _serve_commands(self) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._command], [], [], 0.05)
                if ready:
                    datagram, address = self._command.recvfrom(proto.MAX_PACKET + 1)
                    self._answer(datagram, address)
            except OSError as err:
                if self._stop.is_set():
                    return
                log.warning("natnet server: command socket: %s", err)

    def _answer(self, datagram: bytes, address: tuple[str, int]) -> None:
        arrival_ticks = self.ticks(self._clock.now())
        try:
            message_id, payload = proto.unpack(datagram, strict=False)
        except MalformedPacket:
            return
        reply = self._reply(message_id, payload, address, arrival_ticks)
        if reply is not None:
            self._command.sendto(reply, address)
        if message_id == proto.NAT_CONNECT:
            # Frames only after the server info: a client learns from it the NatNet version
            # to read frames with, and OptiTrack's reads one that comes first as version 0.0.
            self._remember(address)

    def _reply(
        self, message_id: int, payload: bytes, address: tuple[str, int], arrival_ticks: int
    ) -> bytes | None:
        if message_id in (proto.NAT_CONNECT, proto.NAT_DISCOVERY):
            return proto.pack(proto.NAT_SERVERINFO, proto.encode_server_info(self.server_info()))
        self._touch(address)
        if message_id == proto.NAT_REQUEST_MODELDEF:
            return proto.pack(
                proto.NAT_MODELDEF, natdefs.encode_model_defs(self.model_defs(), self.version)
            )
        if message_id == proto.NAT_ECHOREQUEST:
            return proto.echo_response(payload, arrival_ticks)
        if message_id == proto.NAT_REQUEST_FRAMEOFDATA:
            return proto.pack(proto.NAT_FRAMEOFDATA, encode_frame(self._next_frame(), self.version))
        if message_id == proto.NAT_REQUEST:
            return self._string_reply(payload.split(b"\0", 1)[0].decode("utf-8", "replace"))
        if message_id == proto.NAT_DISCONNECT:
            with self._lock:
                self._clients.pop(address, None)
        if message_id == proto.NAT_KEEPALIVE:
            self.keepalives += 1
        if message_id in (proto.NAT_KEEPALIVE, proto.NAT_DISCONNECT):
            return None
        return proto.pack(proto.NAT_UNRECOGNIZED_REQUEST)

    def _string_reply(self, command: str) -> bytes:
        name = command.split(",", 1)[0]
        if name == "FrameRate":
            return proto.pack(proto.NAT_RESPONSE, struct.pack("<f", float(self.rate_hz or 0.0)))
        if name == "UnitsToMillimeters":
            return proto.pack(proto.NAT_RESPONSE, struct.pack("<f", 1000.0))
        if name == "Bitstream" and name == command:
            text = f"Bitstream,{self.version[0]}.{self.version[1]}"
            return proto.pack(proto.NAT_RESPONSE, text.encode() + b"\0")
        if name in _ACKNOWLEDGED:
            return proto.pack(proto.NAT_RESPONSE, struct.pack("<i", 0))
        return proto.pack(proto.NAT_UNRECOGNIZED_REQUEST)

    def _remember(self, address: tuple[str, int]) -> None:
        with self._lock:
            self._clients[address] = time.monotonic()

    def _touch(self, address: tuple[str, int]) -> None:
        with self._lock:
            if address in self._clients:
                self._clients[address] = time.monotonic()


def _advertised_data_port(data_port: int | None, command_port: int, host: str) -> int:
    """`data_port`, else Motive's 1511, else (ephemeral command port) one free right now."""
    if data_port:
        return data_port
    if data_port is None and command_port:
        return proto.DEFAULT_DATA_PORT
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind((host, 0))
        return probe.getsockname()[1]


# requests Motive answers with an integer 0 ("ok", or "0" for counts and modes)
_ACKNOWLEDGED = {
    "CurrentMode",
    "AnalogSamplesPerMocapFrame",
    "LiveMode",
    "EditMode",
    "TimelinePlay",
    "TimelineStop",
    "StartRecording",
    "StopRecording",
    "SetPlaybackCurrentFrame",
    "SubscribeToData",
    "SubscribeByID",
}
