"""NatNet messages other than frames: header, server info, model definitions, requests.

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

from perchd.mocap.natnet_wire import (
    MalformedPacket, Reader, Truncated, Version, Writer, has_section_sizes)

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
    return message_id, datagram[4:4 + size]


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
    group = socket.inet_ntoa(bytes(payload[at:at + 4]))
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
    a, b, c, d = r.buf[at:at + 4]
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


# ---------------------------------------------------------------- model definitions

@dataclass(frozen=True, slots=True)
class RigidBodyDef:
    """A rigid body as Motive defines it. offset: [m] from parent; markers: (offset [m],
    active label, name) per marker (3.0+; names 4.0+)."""

    name: str
    id: int
    parent_id: int = -1
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    markers: tuple[tuple[tuple[float, float, float], int, str], ...] = ()


@dataclass(frozen=True, slots=True)
class ModelDefs:
    """Model definitions (message 5). others: names of cameras, force plates, devices
    and assets, which perchd does not use."""

    marker_sets: tuple[tuple[str, tuple[str, ...]], ...] = ()
    rigid_bodies: tuple[RigidBodyDef, ...] = ()
    skeletons: tuple[tuple[str, int, tuple[RigidBodyDef, ...]], ...] = ()
    others: tuple[str, ...] = ()

    def body_ids(self) -> dict[str, int]:
        return {body.name: body.id for body in self.rigid_bodies}


MARKER_SET, RIGID_BODY, SKELETON, FORCE_PLATE, DEVICE, CAMERA, ASSET = range(7)


def decode_model_defs(payload: bytes, version: Version) -> ModelDefs:
    r = Reader(payload)
    sets, bodies, skeletons, others = [], [], [], []
    for _ in range(r.count("data description")):
        kind = r.i32()
        if has_section_sizes(version):
            size = r.i32()
            if size < 0 or size > r.remaining():
                raise MalformedPacket(f"description says {size} bytes, {r.remaining()} left")
            item = Reader(r.buf, r.pos, r.pos + size)
            r.pos += size
        else:
            item = r
        if kind == MARKER_SET:
            sets.append((item.cstring(), tuple(item.cstring() for _ in range(item.count("name")))))
        elif kind == RIGID_BODY:
            bodies.append(_read_body_def(item, version))
        elif kind == SKELETON:
            skeletons.append(_read_skeleton_def(item, version))
        elif kind in _SKIPPERS:
            others.append(_SKIPPERS[kind](item, version))
        else:
            raise MalformedPacket(f"unknown data description type {kind}")
    return ModelDefs(tuple(sets), tuple(bodies), tuple(skeletons), tuple(others))


def _read_body_def(r: Reader, version: Version) -> RigidBodyDef:
    name = r.cstring() if version >= (2, 0) else ""
    body_id, parent, offset = r.i32(), r.i32(), r.vec3()
    markers: tuple = ()
    if version >= (3, 0):
        n = r.count("rigid body marker")
        offsets = [r.vec3() for _ in range(n)]
        labels = [r.i32() for _ in range(n)]
        names = [r.cstring() for _ in range(n)] if version >= (4, 0) else [""] * n
        markers = tuple(zip(offsets, labels, names))
    return RigidBodyDef(name, body_id, parent, offset, markers)


def _read_skeleton_def(r: Reader, version: Version) -> tuple[str, int, tuple[RigidBodyDef, ...]]:
    name, skel_id = r.cstring(), r.i32()
    return name, skel_id, tuple(_read_body_def(r, version) for _ in range(r.count("bone")))


def _skip_force_plate(r: Reader, version: Version) -> str:
    if version < (3, 0):
        raise MalformedPacket("force plate descriptions before NatNet 3.0 are not supported")
    r.i32()
    serial = r.cstring()
    r.skip(4 * (2 + 3 + 144 + 12))  # width, length, origin, calibration matrix, corners
    r.i32(), r.i32()  # plate type, channel data type
    for _ in range(r.count("channel")):
        r.cstring()
    return f"force plate {serial}"


def _skip_device(r: Reader, version: Version) -> str:
    if version < (3, 0):
        raise MalformedPacket("device descriptions before NatNet 3.0 are not supported")
    r.i32()
    name = r.cstring()
    r.cstring()
    r.i32(), r.i32()
    for _ in range(r.count("channel")):
        r.cstring()
    return f"device {name}"


def _skip_camera(r: Reader, version: Version) -> str:
    name = r.cstring()
    r.skip(12 + 16)
    return f"camera {name}"


def _skip_asset(r: Reader, version: Version) -> str:
    name = r.cstring()
    r.i32(), r.i32()  # asset type, id
    for _ in range(r.count("asset body")):
        _read_body_def(r, version)
    for _ in range(r.count("asset marker")):
        r.cstring()
        r.skip(4 + 12 + 4 + 2)  # id, position, size, params
    return f"asset {name}"


_SKIPPERS = {FORCE_PLATE: _skip_force_plate, DEVICE: _skip_device, CAMERA: _skip_camera,
             ASSET: _skip_asset}


def encode_model_defs(defs: ModelDefs, version: Version) -> bytes:
    """Rigid bodies, skeletons and marker sets, in the order Motive 2.1 sends them."""
    w = Writer()
    w.i32(len(defs.marker_sets) + len(defs.rigid_bodies) + len(defs.skeletons))
    for body in defs.rigid_bodies:
        size_at = _description_header(w, RIGID_BODY, version)
        _write_body_def(w, body, version)
        _close(w, size_at)
    for name, skel_id, bones in defs.skeletons:
        size_at = _description_header(w, SKELETON, version)
        w.cstring(name)
        w.i32(skel_id)
        w.i32(len(bones))
        for bone in bones:
            _write_body_def(w, bone, version)
        _close(w, size_at)
    for name, markers in defs.marker_sets:
        size_at = _description_header(w, MARKER_SET, version)
        w.cstring(name)
        w.i32(len(markers))
        for marker in markers:
            w.cstring(marker)
        _close(w, size_at)
    return w.bytes()


def _description_header(w: Writer, kind: int, version: Version) -> int | None:
    w.i32(kind)
    return w.reserve_i32() if has_section_sizes(version) else None


def _close(w: Writer, size_at: int | None) -> None:
    if size_at is not None:
        w.patch_size(size_at)


def _write_body_def(w: Writer, body: RigidBodyDef, version: Version) -> None:
    if version >= (2, 0):
        w.cstring(body.name)
    w.i32(body.id)
    w.i32(body.parent_id)
    w.vec3(body.offset)
    if version >= (3, 0):
        w.i32(len(body.markers))
        for offset, _, _ in body.markers:
            w.vec3(offset)
        for _, label, _ in body.markers:
            w.i32(label)
        if version >= (4, 0):
            for _, _, name in body.markers:
                w.cstring(name)
