"""NatNet messages other than frames and model definitions: header, server info, requests.

Every UDP payload is `u16 message id, u16 payload length`, then the payload, little endian.
The client talks to the server's command port (1510): connect (0) -> server info (1), request
model definitions (4) -> model definitions (5), echo (12) -> echo response (13) for clock
sync, string requests (2) -> responses (3), keep-alive (10) in unicast. Frames (7) come on
the data port by multicast, or in unicast to the socket the client connected from.
"""

from __future__ import annotations

import socket
import struct
from dataclasses import dataclass

from perchd.mocap.natnet.wire import MalformedPacket, Reader, Truncated, Version, Writer

NAT_CONNECT = 0
NAT_SERVERINFO = 1
NAT_REQUEST = 2
NAT_RESPONSE = 3
NAT_REQUEST_MODELDEF = 4
NAT_MODELDEF = 5
NAT_REQUEST_FRAMEOFDATA = 6
NAT_FRAMEOFDATA = 7
NAT_MESSAGESTRING = 8
NAT_DISCONNECT = 9
NAT_KEEPALIVE = 10
NAT_ECHOREQUEST = 12
NAT_ECHORESPONSE = 13
NAT_DISCOVERY = 14
NAT_UNRECOGNIZED_REQUEST = 100

KNOWN_IDS = frozenset(range(15)) | {NAT_UNRECOGNIZED_REQUEST}
MAX_PACKET = 65_535 + 4  # the u16 length field bounds every payload
SENDER_NAME_BYTES = 256
DEFAULT_COMMAND_PORT = 1510
DEFAULT_DATA_PORT = 1511
DEFAULT_MULTICAST = "239.255.42.99"
SUPPORTED = ((2, 0), (4, 1))  # oldest and newest bitstream this module reads

_HEADER = struct.Struct("<HH")
_ECHO_RESPONSE = struct.Struct("<QQ")


class Oversized(MalformedPacket):
    """A datagram longer than its header says."""


def pack(message_id: int, payload: bytes = b"") -> bytes:
    if len(payload) > 0xFFFF:
        raise ValueError(f"NatNet payload of {len(payload)} bytes exceeds 65535")
    return _HEADER.pack(message_id, len(payload)) + payload


def unpack(datagram: bytes, strict: bool = True) -> tuple[int, bytes]:
    """(message id, payload). MalformedPacket for no header or an unknown message id,
    Truncated or Oversized when the length field disagrees with the datagram. Not `strict`,
    bytes past the stated length are ignored (NatNet clients pad requests with a NUL)."""
    if len(datagram) < 4:
        raise MalformedPacket(f"datagram of {len(datagram)} bytes has no NatNet header")
    message_id, size = _HEADER.unpack_from(datagram)
    if message_id not in KNOWN_IDS:
        raise MalformedPacket(f"unknown message id {message_id}")
    if len(datagram) - 4 < size:
        raise Truncated(f"header says {size} payload bytes, datagram has {len(datagram) - 4}")
    if len(datagram) - 4 > size and strict:
        raise Oversized(f"header says {size} payload bytes, datagram has {len(datagram) - 4}")
    return message_id, datagram[4 : 4 + size]


# ---------------------------------------------------------------- server info


@dataclass(frozen=True, slots=True)
class ServerInfo:
    """What the server says about itself (message 1).

    natnet_version: bitstream version (major, minor, build, revision) the frames use.
    clock_hz: [ticks/s] of the camera/transmit stamps (3.0+; None before).
    data_port, multicast, multicast_group: streaming setup (3.0+; None before).
    """

    app_name: str
    app_version: tuple[int, int, int, int]
    natnet_version: tuple[int, int, int, int]
    clock_hz: int | None = None
    data_port: int | None = None
    multicast: bool | None = None
    multicast_group: str | None = None

    @property
    def version(self) -> Version:
        return self.natnet_version[0], self.natnet_version[1]


def decode_server_info(payload: bytes) -> ServerInfo:
    r = Reader(payload)
    name = r.fixed_string(SENDER_NAME_BYTES)
    app, natnet = _four(r), _four(r)
    if r.remaining() < 15:  # NatNet 2.x: sender block only
        return ServerInfo(name, app, natnet)
    clock_hz, data_port, multicast = r.u64(), r.u16(), bool(r.buf[r.pos])
    r.skip(1)
    at = r.pos
    r.skip(4)
    group = socket.inet_ntoa(bytes(payload[at : at + 4]))
    return ServerInfo(name, app, natnet, clock_hz, data_port, multicast, group)


def encode_server_info(info: ServerInfo) -> bytes:
    w = _sender(info.app_name, info.app_version, info.natnet_version)
    if info.version >= (3, 0):
        w.u64(info.clock_hz or 0)
        w.u16(info.data_port or 0)
        w.out.append(1 if info.multicast else 0)
        w.out += socket.inet_aton(info.multicast_group or "0.0.0.0")
    return w.bytes()


def _four(r: Reader) -> tuple[int, int, int, int]:
    at = r.pos
    r.skip(4)
    a, b, c, d = r.buf[at : at + 4]
    return a, b, c, d


def _sender(name: str, app: tuple[int, ...], natnet: tuple[int, ...]) -> Writer:
    w = Writer()
    w.fixed_string(name, SENDER_NAME_BYTES)
    w.out += bytes(app) + bytes(natnet)
    return w


# ---------------------------------------------------------------- requests


def connect_request(natnet: tuple[int, int, int, int] = (4, 1, 0, 0)) -> bytes:
    """What NatNetLib sends to connect: its sender block with the version it speaks."""
    return pack(NAT_CONNECT, _sender("NatNetLib", natnet, natnet).bytes())


def echo_request(client_stamp: int) -> bytes:
    return pack(NAT_ECHOREQUEST, struct.pack("<Q", client_stamp))


def echo_response(request_payload: bytes, server_ticks: int) -> bytes:
    """Echo the client's 8-byte stamp with the server's clock when the request arrived."""
    stamp = struct.unpack_from("<Q", request_payload)[0] if len(request_payload) >= 8 else 0
    return pack(NAT_ECHORESPONSE, _ECHO_RESPONSE.pack(stamp, server_ticks))


def decode_echo_response(payload: bytes) -> tuple[int, int]:
    """(the client's stamp echoed, server ticks at reception)."""
    if len(payload) < 16:
        raise Truncated(f"echo response of {len(payload)} bytes, needs 16")
    return _ECHO_RESPONSE.unpack_from(payload)


def string_request(command: str) -> bytes:
    return pack(NAT_REQUEST, command.encode("utf-8") + b"\0")
