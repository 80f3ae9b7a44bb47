"""Hypothesis strategies shared by the fuzz tests: JSON values, byte-level mutations of real
inputs, and structural mutations of a JSON document (replace, delete or add one field)."""

from __future__ import annotations

import copy
import re
from typing import Any

from hypothesis import strategies as st

NASTY_NUMBERS = [
    0,
    -0.0,
    1e-300,
    -1e-300,
    1e300,
    -1e300,
    2**63,
    -(2**63),
    10**40,
    float("nan"),
    float("inf"),
    float("-inf"),
]

json_scalars = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.sampled_from(NASTY_NUMBERS)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=12)
)
json_values = st.recursive(
    json_scalars,
    lambda inner: (
        st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner, max_size=5)
    ),
    max_leaves=16,
)


@st.composite
def mutated_bytes(draw, seeds: list[bytes]) -> bytes:
    """A real input with 1..6 flips, cuts, inserts or splices of extreme 4-byte words."""
    data = bytearray(draw(st.sampled_from(seeds)))
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(["flip", "cut", "insert", "splice"]))
        at = draw(st.integers(0, max(0, len(data) - 1)))
        if kind == "flip" and data:
            data[at] ^= draw(st.integers(1, 255))
        elif kind == "cut":
            del data[at : at + draw(st.integers(1, 64))]
        elif kind == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=16))
        else:
            data[at : at + 4] = draw(
                st.sampled_from([b"\xff\xff\xff\x7f", b"\0\0\0\x80", b"\0\0\0\0"])
            )
    return bytes(data)


def _paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key/index path in a JSON document, containers included."""
    out = [prefix] if prefix else []
    items = (
        doc.items() if isinstance(doc, dict) else enumerate(doc) if isinstance(doc, list) else ()
    )
    for key, value in items:
        out += _paths(value, (*prefix, key))
    return out


@st.composite
def mutated_document(draw, doc: dict) -> Any:
    """`doc` with 1..3 of: a field replaced by any JSON value, a field deleted, a key added,
    or a number scaled; sometimes the whole document replaced."""
    if draw(st.integers(0, 19)) == 0:
        return draw(json_values)
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(doc)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        key = path[-1]
        kind = draw(st.sampled_from(["replace", "delete", "add", "scale"]))
        if kind == "replace":
            parent[key] = draw(json_values)
        elif kind == "delete":
            del parent[key]
        elif kind == "add" and isinstance(parent, dict):
            parent[draw(st.text(max_size=8))] = draw(json_values)
        elif (
            kind == "scale"
            and isinstance(parent[key], (int, float))
            and not isinstance(parent[key], bool)
        ):
            parent[key] = parent[key] * draw(st.sampled_from([-1, 0, 0.5, 1 + 1e-9, 2, 1e6, 1e-6]))
    return doc


NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
NASTY_TOKENS = [
    b"1e999",
    b"-1e999",
    b"NaN",
    b"Infinity",
    b"nan",
    b"inf",
    b"9" * 400,
    b"-" + b"9" * 400,
    b"9" * 5000,
    b"true",
    b"false",
    b"null",
    b'"1"',
    b"1e-400",
    b"-0",
    b"[]",
    b"{}",
    b"0x10",
    b"0x" + b"f" * 4000,
    b"1_000",
]


@st.composite
def spliced_numbers(draw, seeds: list[bytes]) -> bytes:
    """A real input with 1..3 of its numbers replaced by an extreme or ill-typed token
    (1e999, 400 and 5000 digits, NaN, booleans, strings, containers)."""
    data = draw(st.sampled_from(seeds))
    spans = [m.span() for m in NUMBER.finditer(data)]
    for _ in range(draw(st.integers(1, 3))):
        if not spans:
            break
        start, end = draw(st.sampled_from(spans))
        token = draw(st.sampled_from(NASTY_TOKENS))
        data = data[:start] + token + data[end:]
        spans = [m.span() for m in NUMBER.finditer(data)]
    return data
