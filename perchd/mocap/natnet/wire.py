"""Bounded little-endian reading and writing for NatNet packets.

Every read checks the bounds first, so a short or lying packet raises `Truncated` (a
`MalformedPacket`) instead of reading past its end: the client counts and drops it.
"""

from __future__ import annotations

import struct

Version = tuple[int, int]
"""NatNet bitstream version (major, minor)."""

_I16 = struct.Struct("<h")
_U16 = struct.Struct("<H")
_I32 = struct.Struct("<i")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_F32 = struct.Struct("<f")
_F64 = struct.Struct("<d")
_VEC3 = struct.Struct("<3f")
_QUAT = struct.Struct("<4f")

MAX_COUNT = 100_000  # no NatNet list is longer; a bigger count is a corrupt packet
MAX_NAME = 256  # NatNet MAX_NAMELENGTH


class MalformedPacket(ValueError):
    """A packet that does not follow the NatNet layout for its version."""


class Truncated(MalformedPacket):
    """A packet shorter than its own contents say."""


class Reader:
    """Cursor over one payload; `end` bounds it (a 4.1 section or the whole payload)."""

    __slots__ = ("buf", "pos", "end")

    def __init__(self, buf: bytes, pos: int = 0, end: int | None = None) -> None:
        self.buf = buf
        self.pos = pos
        self.end = len(buf) if end is None else end

    def remaining(self) -> int:
        return self.end - self.pos

    def _take(self, n: int) -> int:
        at = self.pos
        if n < 0 or at + n > self.end:
            raise Truncated(f"needs {n} bytes at offset {at}, only {self.end - at} left")
        self.pos = at + n
        return at

    def skip(self, n: int) -> None:
        self._take(n)

    def i16(self) -> int:
        return _I16.unpack_from(self.buf, self._take(2))[0]

    def u16(self) -> int:
        return _U16.unpack_from(self.buf, self._take(2))[0]

    def i32(self) -> int:
        return _I32.unpack_from(self.buf, self._take(4))[0]

    def u32(self) -> int:
        return _U32.unpack_from(self.buf, self._take(4))[0]

    def u64(self) -> int:
        return _U64.unpack_from(self.buf, self._take(8))[0]

    def f32(self) -> float:
        return _F32.unpack_from(self.buf, self._take(4))[0]

    def f64(self) -> float:
        return _F64.unpack_from(self.buf, self._take(8))[0]

    def vec3(self) -> tuple[float, float, float]:
        return _VEC3.unpack_from(self.buf, self._take(12))

    def quat(self) -> tuple[float, float, float, float]:
        return _QUAT.unpack_from(self.buf, self._take(16))

    def record(self, layout: struct.Struct) -> tuple:
        """Several fields at once (the hot path: one bounds check, one unpack)."""
        return layout.unpack_from(self.buf, self._take(layout.size))

    def count(self, what: str) -> int:
        n = self.i32()
        if not 0 <= n <= MAX_COUNT:
            raise MalformedPacket(f"{what} count {n} outside 0..{MAX_COUNT}")
        return n

    def cstring(self) -> str:
        """A NUL-terminated name of at most MAX_NAME bytes."""
        stop = self.buf.find(b"\0", self.pos, min(self.end, self.pos + MAX_NAME))
        if stop < 0:
            raise Truncated(f"unterminated name at offset {self.pos}")
        text = bytes(self.buf[self.pos : stop]).decode("utf-8", "replace")
        self.pos = stop + 1
        return text

    def fixed_string(self, size: int) -> str:
        at = self._take(size)
        return bytes(self.buf[at : at + size]).split(b"\0", 1)[0].decode("utf-8", "replace")


class Writer:
    """Appends little-endian fields; `section()` back-fills a 4.1 byte count."""

    __slots__ = ("out",)

    def __init__(self) -> None:
        self.out = bytearray()

    def i16(self, v: int) -> None:
        self.out += _I16.pack(v)

    def u16(self, v: int) -> None:
        self.out += _U16.pack(v)

    def i32(self, v: int) -> None:
        self.out += _I32.pack(v)

    def u32(self, v: int) -> None:
        self.out += _U32.pack(v)

    def u64(self, v: int) -> None:
        self.out += _U64.pack(v)

    def f32(self, v: float) -> None:
        self.out += _F32.pack(v)

    def f64(self, v: float) -> None:
        self.out += _F64.pack(v)

    def vec3(self, v: tuple[float, float, float]) -> None:
        self.out += _VEC3.pack(*v)

    def quat(self, v: tuple[float, float, float, float]) -> None:
        self.out += _QUAT.pack(*v)

    def cstring(self, text: str) -> None:
        self.out += text.encode("utf-8")[: MAX_NAME - 1] + b"\0"

    def fixed_string(self, text: str, size: int) -> None:
        raw = text.encode("utf-8")[: size - 1]
        self.out += raw + bytes(size - len(raw))

    def reserve_i32(self) -> int:
        """Write a placeholder int and return where it is, to be patched later."""
        at = len(self.out)
        self.i32(0)
        return at

    def patch_size(self, at: int) -> None:
        """Store the number of bytes written since the placeholder at `at`."""
        _I32.pack_into(self.out, at, len(self.out) - at - 4)

    def bytes(self) -> bytes:
        return bytes(self.out)


def at_least(version: Version, major: int, minor: int) -> bool:
    return version >= (major, minor)


def has_section_sizes(version: Version) -> bool:
    """NatNet 4.1 put a byte count after each frame section's (and each model's) header."""
    return version >= (4, 1)
