"""NatNet client: a PoseSource reading one rigid body from an OptiTrack Motive server.

Start-up (on the caller's thread, so a missing server is a LinkError): connect on the
command port and read the server info (NatNet version, clock, streaming setup), synchronise
clocks by echo, request the model definitions to turn the body's name into its id, then join
the multicast group on the data port, or in unicast take frames on the command socket (where
Motive sends them) and keep the server's client entry alive. A receive thread then turns
frames into Poses; it never raises: every bad datagram is counted and dropped.

Latency per pose: camera mid-exposure to arrival, from the frame's high-resolution stamps
mapped onto the agent's clock by the echo clock sync (NatNet 3.0+). Without a sync it is the
server's own exposure-to-transmit time; NatNet 2.x frames carry no stamps, so 0.0.
"""

from __future__ import annotations

import logging
import select
import socket
import time
from dataclasses import dataclass, field

from perchd.core.clock import Clock
from perchd.core.errors import LinkError, UriError
from perchd.core.types import Pose
from perchd.mocap.frames import UpAxis, to_world
from perchd.mocap.natnet import models as natdefs
from perchd.mocap.natnet import protocol as proto
from perchd.mocap.natnet.clock import ClockSync
from perchd.mocap.natnet.frame import Frame, Timing, decode_frame
from perchd.mocap.natnet.wire import MalformedPacket, Truncated
from perchd.mocap.stream import (
    Drop,
    PoseLimits,
    PoseStream,
    RateLimitedWarning,
    ThreadedSource,
)

log = logging.getLogger("perchd.mocap.natnet")

MODELS_CHANGED = 0x02  # frame params bit: Motive's list of tracked models changed


@dataclass(frozen=True)
class NatNetConfig:
    """How to reach the server and which body to follow.

    body: rigid-body name as defined in Motive, or its numeric id.
    transport: "auto" (what the server info says), "multicast" or "unicast".
    multicast_group, data_port: override the server info (needed for NatNet 2.x servers
        that do not announce them; default 239.255.42.99 and 1511).
    local: address of this machine's interface on the mocap network (multicast membership
        and the command socket's bind address); 0.0.0.0 lets the OS choose.
    up: the axis Motive streams as up (perchd's world is Z up).
    """

    server: str
    body: str
    command_port: int = proto.DEFAULT_COMMAND_PORT
    transport: str = "auto"
    multicast_group: str | None = None
    data_port: int | None = None
    local: str = "0.0.0.0"
    up: UpAxis = UpAxis.Y
    connect_timeout_s: float = 2.0
    keepalive_s: float = 1.0
    sync_interval_s: float = 1.0
    limits: PoseLimits = field(default_factory=PoseLimits)


class NatNetSource(ThreadedSource):
    """PoseSource over NatNet; see the module docstring for the protocol steps."""

    def __init__(self, config: NatNetConfig, clock: Clock) -> None:
        super().__init__()
        self.config = config
        self.body = config.body
        self._clock = clock
        self._stream = PoseStream(
            config.body, config.limits, RateLimitedWarning(log, f"natnet {config.server}")
        )
        self._server = (config.server, config.command_port)
        self._command: socket.socket | None = None
        self._data: socket.socket | None = None
        self.info: proto.ServerInfo | None = None
        self.models = natdefs.ModelDefs()
        self.multicast = True
        self._body_id: int | None = int(config.body) if config.body.isdigit() else None
        self._sync: ClockSync | None = None
        self._next_keepalive = self._next_echo = self._next_models = 0.0
        self._want_models = False

    # ------------------------------------------------------------ PoseSource

    def start(self) -> None:
        try:
            self._command = self._open_command_socket()
            self.info = self._handshake()
            self._resolve_body()
            if self.multicast:
                self._data = self._open_data_socket()
        except (OSError, MalformedPacket) as err:
            self.close()
            raise LinkError(f"natnet {self.config.server}: {err}") from None
        except (LinkError, UriError):
            self.close()
            raise
        self._start_thread("natnet-rx")

    def close(self) -> None:
        self._stop_thread()
        for sock in (self._command, self._data):
            if sock is not None:
                sock.close()
        self._command = self._data = None

    @property
    def version(self) -> tuple[int, int]:
        return self.info.version if self.info else (0, 0)

    @property
    def clock_sync(self) -> ClockSync | None:
        return self._sync

    # ------------------------------------------------------------ start-up

    def _open_command_socket(self) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        sock.bind((self.config.local, 0))
        return sock

    def _handshake(self) -> proto.ServerInfo:
        payload = self._ask(proto.connect_request(), proto.NAT_SERVERINFO)
        info = proto.decode_server_info(payload)
        if not proto.SUPPORTED[0] <= info.version <= proto.SUPPORTED[1]:
            raise LinkError(
                f"natnet {self.config.server}: server speaks NatNet "
                f"{info.version[0]}.{info.version[1]}, perchd reads 2.0 to 4.1"
            )
        self.multicast = self._choose_transport(info)
        if info.clock_hz:
            self._sync = ClockSync(info.clock_hz)
            self._initial_sync()
        self.info = info
        self.models = natdefs.decode_model_defs(
            self._ask(proto.pack(proto.NAT_REQUEST_MODELDEF), proto.NAT_MODELDEF), info.version
        )
        return info

    def _choose_transport(self, info: proto.ServerInfo) -> bool:
        if self.config.transport == "auto":
            return info.multicast is not False
        return self.config.transport == "multicast"

    def _ask(self, packet: bytes, want: int, tries: int = 3) -> bytes:
        """Send `packet` to the command port until a reply of type `want` arrives."""
        assert self._command is not None
        per_try = self.config.connect_timeout_s / tries
        for _ in range(tries):
            self._command.sendto(packet, self._server)
            deadline = time.monotonic() + per_try
            while (left := deadline - time.monotonic()) > 0:
                ready, _, _ = select.select([self._command], [], [], left)
                if not ready:
                    break
                datagram = self._command.recv(proto.MAX_PACKET + 1)
                try:
                    message_id, payload = proto.unpack(datagram)
                except MalformedPacket:
                    continue
                if message_id == want:
                    return payload
        raise LinkError(
            f"no NatNet server answered at {self._server[0]}:{self._server[1]} "
            f"within {self.config.connect_timeout_s} s"
        )

    def _initial_sync(self, echoes: int = 8) -> None:
        """A few echoes so the first poses already have their full latency."""
        for _ in range(echoes):
            try:
                self._on_echo(self._ask(self._echo_packet(), proto.NAT_ECHORESPONSE, tries=1))
            except LinkError:
                return  # a server without echo support: latency falls back to its own stamps

    def _resolve_body(self) -> None:
        by_name = self.models.body_ids()
        if self._body_id is not None:
            names = {v: k for k, v in by_name.items()}
            self.body = names.get(self._body_id, self.config.body)
            return
        if self.config.body not in by_name:
            known = ", ".join(f"{n} ({i})" for n, i in by_name.items()) or "none"
            raise UriError(
                f"natnet {self.config.server}: no rigid body named "
                f"{self.config.body!r}; the server defines: {known}"
            )
        self._body_id = by_name[self.config.body]

    def _open_data_socket(self) -> socket.socket:
        group = (
            self.config.multicast_group
            or (self.info and self.info.multicast_group)
            or proto.DEFAULT_MULTICAST
        )
        port = (
            self.config.data_port or (self.info and self.info.data_port) or proto.DEFAULT_DATA_PORT
        )
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        try:
            sock.bind((group, port))  # Linux: receive only this group's datagrams
        except OSError:
            sock.bind(("", port))
        membership = socket.inet_aton(group) + socket.inet_aton(self.config.local)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
        return sock

    # ------------------------------------------------------------ receive thread

    def _run(self) -> None:
        sockets = [s for s in (self._command, self._data) if s is not None]
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select(sockets, [], [], 0.05)
                for sock in ready:
                    datagram = sock.recv(proto.MAX_PACKET + 1)
                    self.handle_datagram(datagram, self._clock.now())
                self._housekeeping()
            except (OSError, ValueError) as err:  # socket closed under us, network gone
                if self._stop.is_set():
                    return
                log.warning("natnet %s: receive error: %s", self.config.server, err)
                time.sleep(0.05)

    def handle_datagram(self, datagram: bytes, arrival: float) -> None:
        """Decode one datagram that arrived at agent time `arrival`; never raises."""
        self._stream.packet()
        try:
            message_id, payload = proto.unpack(datagram)
            if message_id == proto.NAT_FRAMEOFDATA:
                self._on_frame(decode_frame(payload, self.version), arrival)
            elif message_id == proto.NAT_ECHORESPONSE:
                self._on_echo(payload, arrival)
            elif message_id == proto.NAT_MODELDEF:
                self._on_models(natdefs.decode_model_defs(payload, self.version))
        except Truncated as err:
            self._stream.drop(Drop.TRUNCATED, str(err))
        except proto.Oversized as err:
            self._stream.drop(Drop.OVERSIZED, str(err))
        except MalformedPacket as err:
            self._stream.drop(Drop.GARBAGE, str(err))
        except Exception as err:  # noqa: BLE001 - the receive loop must survive anything
            self._stream.drop(Drop.GARBAGE, f"{type(err).__name__}: {err}")

    def _on_models(self, models: natdefs.ModelDefs) -> None:
        """New definitions (asked for after Motive flagged a change): follow the body's id."""
        self.models = models
        self._want_models = False
        new_id = models.body_ids().get(self.config.body)
        if new_id is not None and new_id != self._body_id:
            log.warning(
                "natnet %s: rigid body %r is now id %d (was %s)",
                self.config.server,
                self.config.body,
                new_id,
                self._body_id,
            )
            self._body_id = new_id

    def _on_frame(self, frame: Frame, arrival: float) -> None:
        if frame.params & MODELS_CHANGED and not self.config.body.isdigit():
            self._want_models = True  # ids may have moved: no pose until the names are known
        if self._want_models:
            self._stream.drop(
                Drop.NO_BODY,
                f"frame {frame.number}: awaiting the new model definitions Motive announced",
            )
            return
        sample = next((b for b in frame.rigid_bodies if b.id == self._body_id), None)
        if sample is None:
            self._stream.drop(
                Drop.NO_BODY,
                f"frame {frame.number} has no rigid body {self._body_id} ({self.body})",
            )
            return
        latency = self._latency(frame.timing, arrival)
        p, q = to_world(sample.p, sample.q, self.config.up)
        self._stream.offer(
            Pose(self.body, frame.number, arrival - latency, p, q, sample.tracking_valid, latency)
        )

    def _latency(self, timing: Timing, arrival: float) -> float:
        exposure, transmit = timing.camera_mid_exposure, timing.transmit
        if not exposure or transmit is None or self._sync is None:
            return 0.0  # no stamps (NatNet 2.x, or a server that leaves them 0)
        in_server = max(0.0, (transmit - exposure) / self._sync.clock_hz)
        if not self._sync.synced:
            return in_server
        return max(in_server, arrival - self._sync.to_agent(exposure))

    def _on_echo(self, payload: bytes, arrival: float | None = None) -> None:
        stamp, ticks = proto.decode_echo_response(payload)
        if self._sync is not None:
            self._sync.response(stamp, ticks, self._clock.now() if arrival is None else arrival)

    def _echo_packet(self) -> bytes:
        assert self._sync is not None
        return proto.echo_request(self._sync.request(self._clock.now()))

    def _housekeeping(self) -> None:
        """Keep-alive (unicast), clock-sync echoes and model-definition refreshes, paced in
        wall time: they serve the network, not the flight."""
        now = time.monotonic()
        if not self.multicast and now >= self._next_keepalive:
            self._send(proto.pack(proto.NAT_KEEPALIVE))
            self._next_keepalive = now + self.config.keepalive_s
        if self._sync is not None and now >= self._next_echo:
            self._send(self._echo_packet())
            self._next_echo = now + self.config.sync_interval_s
        if self._want_models and now >= self._next_models:
            self._send(proto.pack(proto.NAT_REQUEST_MODELDEF))
            self._next_models = now + 0.5

    def _send(self, packet: bytes) -> None:
        if self._command is not None:
            self._command.sendto(packet, self._server)
