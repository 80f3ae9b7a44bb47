"""NatNet model definitions (message 5): what Motive defines, decoded and encoded.

Each description is a type (0 marker set, 1 rigid body, 2 skeleton, 3 force plate, 4 device,
5 camera, 6 asset), from NatNet 4.1 followed by its size in bytes. perchd needs the rigid
bodies (name -> id); the others are walked over so the list can be read to its end.
"""

from __future__ import annotations

from dataclasses import dataclass

from perchd.mocap.natnet.wire import (
    MalformedPacket,
    Reader,
    Version,
    Writer,
    has_section_sizes,
)


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


_SKIPPERS = {
    FORCE_PLATE: _skip_force_plate,
    DEVICE: _skip_device,
    CAMERA: _skip_camera,
    ASSET: _skip_asset,
}


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
