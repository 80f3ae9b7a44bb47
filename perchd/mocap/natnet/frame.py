"""NatNet frame of data (message 7): decode and encode, NatNet 2.0 to 4.1.

Layout per version, as OptiTrack's PacketClient reads it (positions in Motive's frame, metres):
frame number; marker sets; legacy "other" markers; rigid bodies; skeletons (2.1+); assets
(4.1+); labelled markers (2.3+); force plates (2.9+); devices (2.11+); suffix: a legacy
"latency" float (< 3.0), timecode, timestamp (none before 2.6, float in 2.6, double from
2.7), camera mid-exposure / data-received / transmit ticks (3.0+), precision timestamp
(4.1+), params (2.6+), and a zero end-of-data tag. From 4.1 each section header carries its
size in bytes, which the decoder checks section by section.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from perchd.core.types import Quat, Vec3
from perchd.mocap.natnet.wire import (
    MalformedPacket,
    Reader,
    Version,
    Writer,
    at_least,
    has_section_sizes,
)


@dataclass(frozen=True, slots=True)
class RigidBodySample:
    """One rigid body in one frame, in Motive's streaming frame.

    p: [m]; q: (x, y, z, w); mean_error: [m] mean marker residual (2.0+);
    tracking_valid: Motive tracked it this frame (2.6+; assumed True before);
    markers: (position [m], id, size [m]) per marker, sent only before NatNet 3.0.
    """

    id: int
    p: Vec3
    q: Quat
    mean_error: float = 0.0
    tracking_valid: bool = True
    markers: tuple[tuple[Vec3, int, float], ...] = ()


@dataclass(frozen=True, slots=True)
class LabeledMarker:
    """id: model id << 16 | marker id; p [m]; size [m]; params: occluded/solved bits;
    residual [m] (3.0+)."""

    id: int
    p: Vec3
    size: float
    params: int = 0
    residual: float = 0.0


@dataclass(frozen=True, slots=True)
class Skeleton:
    id: int
    bones: tuple[RigidBodySample, ...]


@dataclass(frozen=True, slots=True)
class Asset:
    """A trained markerset (4.1+): rigid bodies (always with error and params) and markers."""

    id: int
    bodies: tuple[RigidBodySample, ...]
    markers: tuple[LabeledMarker, ...]


@dataclass(frozen=True, slots=True)
class AnalogDevice:
    """Force plate or other device: per channel, the samples of this mocap frame."""

    id: int
    channels: tuple[tuple[float, ...], ...]


@dataclass(frozen=True, slots=True)
class Timing:
    """Frame timing. timestamp: [s] since Motive started (absent before 2.6: 0.0).
    camera_mid_exposure, data_received, transmit: server high-resolution clock ticks (3.0+),
    None before. legacy_latency: the 'latency' float of NatNet < 3.0 (None after); Motive 1.x
    fills it with the frame timestamp, so perchd never reads it as a latency.
    precision_s, precision_frac: PTP-style timestamp (4.1+), 0 when the server has none."""

    timestamp: float = 0.0
    camera_mid_exposure: int | None = None
    data_received: int | None = None
    transmit: int | None = None
    legacy_latency: float | None = None
    timecode: int = 0
    timecode_sub: int = 0
    precision_s: int = 0
    precision_frac: int = 0


@dataclass(frozen=True, slots=True)
class Frame:
    """A whole frame of data. params bit 0: recording; bit 1: tracked models changed."""

    number: int
    rigid_bodies: tuple[RigidBodySample, ...] = ()
    timing: Timing = field(default_factory=Timing)
    marker_sets: tuple[tuple[str, tuple[Vec3, ...]], ...] = ()
    other_markers: tuple[Vec3, ...] = ()
    skeletons: tuple[Skeleton, ...] = ()
    assets: tuple[Asset, ...] = ()
    labeled_markers: tuple[LabeledMarker, ...] = ()
    force_plates: tuple[AnalogDevice, ...] = ()
    devices: tuple[AnalogDevice, ...] = ()
    params: int = 0


# ---------------------------------------------------------------- decoding


def decode_frame(payload: bytes, version: Version) -> Frame:
    """Decode a frame payload (after the 4-byte header); MalformedPacket if it does not fit."""
    r = Reader(payload)
    number = r.i32()
    marker_sets = _section(r, version, "marker set", _read_marker_set)
    other = _section(r, version, "other marker", Reader.vec3)
    bodies = _section(r, version, "rigid body", lambda rr: _read_body(rr, version))
    skeletons = assets = labeled = plates = devices = ()
    if at_least(version, 2, 1):
        skeletons = _section(r, version, "skeleton", lambda rr: _read_skeleton(rr, version))
    if has_section_sizes(version):
        assets = _section(r, version, "asset", _read_asset)
    if at_least(version, 2, 3):
        labeled = _section(r, version, "labelled marker", lambda rr: _read_marker(rr, version))
    if at_least(version, 2, 9):
        plates = _section(r, version, "force plate", _read_device)
    if at_least(version, 2, 11):
        devices = _section(r, version, "device", _read_device)
    timing, params = _read_suffix(r, version)
    if r.remaining():
        raise MalformedPacket(f"{r.remaining()} bytes left after the end-of-data tag")
    return Frame(
        number,
        bodies,
        timing,
        marker_sets,
        other,
        skeletons,
        assets,
        labeled,
        plates,
        devices,
        params,
    )


def _section(r: Reader, version: Version, what: str, read_item) -> tuple:
    n = r.count(what)
    if not has_section_sizes(version):
        return tuple(read_item(r) for _ in range(n))
    size = r.i32()
    if size < 0 or size > r.remaining():
        raise MalformedPacket(f"{what} section says {size} bytes, {r.remaining()} left")
    inner = Reader(r.buf, r.pos, r.pos + size)
    items = tuple(read_item(inner) for _ in range(n))
    if inner.remaining():
        raise MalformedPacket(f"{what} section has {inner.remaining()} unread bytes")
    r.pos = inner.end
    return items


def _read_marker_set(r: Reader) -> tuple[str, tuple[Vec3, ...]]:
    name = r.cstring()
    return name, tuple(r.vec3() for _ in range(r.count("marker")))


_BODY = struct.Struct("<i3f4f")  # id, position, quaternion
_BODY_TAIL = struct.Struct("<fh")  # mean error, params (2.6+)
_MARKERS = {
    (3, 0): struct.Struct("<i3ffhf"),
    (2, 6): struct.Struct("<i3ffh"),
    (0, 0): struct.Struct("<i3ff"),
}  # id, position, size[, params[, residual]]


def _read_body(r: Reader, version: Version) -> RigidBodySample:
    if version >= (3, 0):  # the common case in one unpack
        i, x, y, z, qx, qy, qz, qw = r.record(_BODY)
        error, params = r.record(_BODY_TAIL)
        return RigidBodySample(i, (x, y, z), (qx, qy, qz, qw), error, bool(params & 0x01))
    body_id, p, q = r.i32(), r.vec3(), r.quat()
    markers: tuple = ()
    if version < (3, 0):
        n = r.count("rigid body marker")
        points = [r.vec3() for _ in range(n)]
        ids = [r.i32() for _ in range(n)] if at_least(version, 2, 0) else [0] * n
        sizes = [r.f32() for _ in range(n)] if at_least(version, 2, 0) else [0.0] * n
        markers = tuple(zip(points, ids, sizes))
    error = r.f32() if at_least(version, 2, 0) else 0.0
    valid = bool(r.i16() & 0x01) if at_least(version, 2, 6) else True
    return RigidBodySample(body_id, p, q, error, valid, markers)


def _read_skeleton(r: Reader, version: Version) -> Skeleton:
    skel_id = r.i32()
    return Skeleton(skel_id, tuple(_read_body(r, version) for _ in range(r.count("bone"))))


def _read_asset(r: Reader) -> Asset:
    asset_id = r.i32()
    bodies = tuple(_read_body(r, (3, 0)) for _ in range(r.count("asset body")))  # same layout
    markers = tuple(_read_marker(r, (4, 1)) for _ in range(r.count("asset marker")))
    return Asset(asset_id, bodies, markers)


def _read_marker(r: Reader, version: Version) -> LabeledMarker:
    layout = _MARKERS[(3, 0) if version >= (3, 0) else (2, 6) if version >= (2, 6) else (0, 0)]
    marker_id, x, y, z, size, *rest = r.record(layout)
    return LabeledMarker(marker_id, (x, y, z), size, *rest)


def _read_device(r: Reader) -> AnalogDevice:
    dev_id = r.i32()
    channels = []
    for _ in range(r.count("channel")):
        channels.append(tuple(r.f32() for _ in range(r.count("sample"))))
    return AnalogDevice(dev_id, tuple(channels))


def _read_timestamp(r: Reader, version: Version) -> float:
    if at_least(version, 2, 7):
        return r.f64()
    return r.f32() if at_least(version, 2, 6) else 0.0


def _read_suffix(r: Reader, version: Version) -> tuple[Timing, int]:
    legacy_latency = r.f32() if version < (3, 0) else None
    timecode, timecode_sub = r.u32(), r.u32()
    timestamp = _read_timestamp(r, version)
    exposure = received = transmit = None
    if at_least(version, 3, 0):
        exposure, received, transmit = r.u64(), r.u64(), r.u64()
    precision = (r.u32(), r.u32()) if has_section_sizes(version) else (0, 0)
    params = r.i16() if at_least(version, 2, 6) else 0
    if r.i32() != 0:
        raise MalformedPacket("end-of-data tag is not zero")
    return Timing(
        timestamp, exposure, received, transmit, legacy_latency, timecode, timecode_sub, *precision
    ), params


# ---------------------------------------------------------------- encoding


def encode_frame(frame: Frame, version: Version) -> bytes:
    """The payload of a frame of data as a server of `version` sends it."""
    w = Writer()
    w.i32(frame.number)
    _write_section(w, version, frame.marker_sets, _write_marker_set)
    _write_section(w, version, frame.other_markers, Writer.vec3)
    _write_section(w, version, frame.rigid_bodies, lambda ww, b: _write_body(ww, b, version))
    if at_least(version, 2, 1):
        _write_section(w, version, frame.skeletons, lambda ww, s: _write_skeleton(ww, s, version))
    if has_section_sizes(version):
        _write_section(w, version, frame.assets, _write_asset)
    if at_least(version, 2, 3):
        _write_section(
            w, version, frame.labeled_markers, lambda ww, m: _write_marker(ww, m, version)
        )
    if at_least(version, 2, 9):
        _write_section(w, version, frame.force_plates, _write_device)
    if at_least(version, 2, 11):
        _write_section(w, version, frame.devices, _write_device)
    _write_suffix(w, frame, version)
    return w.bytes()


def _write_section(w: Writer, version: Version, items, write_item) -> None:
    w.i32(len(items))
    size_at = w.reserve_i32() if has_section_sizes(version) else None
    for item in items:
        write_item(w, item)
    if size_at is not None:
        w.patch_size(size_at)


def _write_marker_set(w: Writer, item: tuple[str, tuple[Vec3, ...]]) -> None:
    name, points = item
    w.cstring(name)
    w.i32(len(points))
    for point in points:
        w.vec3(point)


def _write_body(w: Writer, body: RigidBodySample, version: Version) -> None:
    w.i32(body.id)
    w.vec3(body.p)
    w.quat(body.q)
    if version < (3, 0):
        w.i32(len(body.markers))
        for point, _, _ in body.markers:
            w.vec3(point)
        if at_least(version, 2, 0):
            for _, marker_id, _ in body.markers:
                w.i32(marker_id)
            for _, _, size in body.markers:
                w.f32(size)
    if at_least(version, 2, 0):
        w.f32(body.mean_error)
    if at_least(version, 2, 6):
        w.i16(1 if body.tracking_valid else 0)


def _write_skeleton(w: Writer, skeleton: Skeleton, version: Version) -> None:
    w.i32(skeleton.id)
    w.i32(len(skeleton.bones))
    for bone in skeleton.bones:
        _write_body(w, bone, version)


def _write_asset(w: Writer, asset: Asset) -> None:
    w.i32(asset.id)
    w.i32(len(asset.bodies))
    for body in asset.bodies:
        _write_body(w, body, (3, 0))  # id, pose, error, params: the 3.0 body layout
    w.i32(len(asset.markers))
    for marker in asset.markers:
        _write_marker(w, marker, (4, 1))


def _write_marker(w: Writer, marker: LabeledMarker, version: Version) -> None:
    w.i32(marker.id)
    w.vec3(marker.p)
    w.f32(marker.size)
    if at_least(version, 2, 6):
        w.i16(marker.params)
    if at_least(version, 3, 0):
        w.f32(marker.residual)


def _write_device(w: Writer, device: AnalogDevice) -> None:
    w.i32(device.id)
    w.i32(len(device.channels))
    for samples in device.channels:
        w.i32(len(samples))
        for value in samples:
            w.f32(value)


def _write_suffix(w: Writer, frame: Frame, version: Version) -> None:
    t = frame.timing
    if version < (3, 0):
        w.f32(t.legacy_latency if t.legacy_latency is not None else t.timestamp)
    w.u32(t.timecode)
    w.u32(t.timecode_sub)
    if at_least(version, 2, 7):
        w.f64(t.timestamp)
    elif at_least(version, 2, 6):
        w.f32(t.timestamp)
    if at_least(version, 3, 0):
        for ticks in (t.camera_mid_exposure, t.data_received, t.transmit):
            w.u64(ticks or 0)
    if has_section_sizes(version):
        w.u32(t.precision_s)
        w.u32(t.precision_frac)
    if at_least(version, 2, 6):
        w.i16(frame.params)
    w.i32(0)
