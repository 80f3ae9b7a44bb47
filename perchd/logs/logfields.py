"""What a flight log line may hold, checked as it is read: a log from another program, an
older schema, a hand edit or garbage is refused naming the line and field, so nothing that
reads a FlightLog (summary, plots, MCAP export) meets a value of the wrong kind."""

from __future__ import annotations

import dataclasses
import math
from typing import Any


class LogFormatError(ValueError):
    """A line of a flight log with a field of the wrong kind; str() names line and field."""


NUMBER, TEXT = "float", "str"
HEADER = {
    "plan": {"v_contact": NUMBER, "duration": NUMBER, "strategy": TEXT},
    "config": {"rate_hz": NUMBER, "sync": TEXT},
}
"""The header fields readers use; others are carried unchecked (shown, never computed on)."""
END = {"outcome": TEXT, "detail": TEXT, "summary": {"contact_speed": NUMBER, "perch_time": NUMBER}}


def is_number(value: Any) -> bool:
    """A finite JSON number a float holds (not a bool, not an integer beyond a float)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def _fits(value: Any, kind: str) -> bool:
    """`value` is of the kind a dataclass annotation names ("float | None", "dict[str, float]")."""
    base, _, rest = kind.partition(" |")
    if value is None:
        return rest.strip() == "None"
    if base == "float":
        return is_number(value)
    if base == "int":
        return isinstance(value, int) and not isinstance(value, bool) and abs(value) < 1 << 63
    if base == "str":
        return isinstance(value, str)
    if base == "dict[str, float]":  # an event's figures: flags and unknown (null) ones too
        return isinstance(value, dict) and all(
            v is None or isinstance(v, bool) or is_number(v) for v in value.values()
        )
    raise TypeError(f"no check for a field of kind {kind}")


def record(cls: type, obj: Any, where: str) -> dict[str, Any]:
    """`obj` as keyword arguments of dataclass `cls`, every field of its annotated kind;
    LogFormatError naming `where` and the field otherwise."""
    if not isinstance(obj, dict):
        raise LogFormatError(f"{where}: expected an object")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for name in obj.keys() - fields.keys():
        raise LogFormatError(f"{where}: unknown field {name!r}")
    for name, f in fields.items():
        if name not in obj:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise LogFormatError(f"{where}: field {name!r} missing")
        elif not _fits(obj[name], str(f.type)):
            raise LogFormatError(f"{where}: {name} = {obj[name]!r:.40} is not a {f.type}")
    return obj


def shaped(obj: Any, spec: dict[str, Any], where: str) -> dict[str, Any]:
    """`obj` if it is an object whose fields named in `spec` are absent, None or of their
    kind (a nested spec: an object checked alike); LogFormatError otherwise."""
    if not isinstance(obj, dict):
        raise LogFormatError(f"{where}: expected an object")
    for name, kind in spec.items():
        value = obj.get(name)
        if value is None:
            continue
        if isinstance(kind, dict):
            shaped(value, kind, f"{where}.{name}")
        elif not _fits(value, kind):
            raise LogFormatError(f"{where}.{name} = {value!r:.40} is not a {kind}")
    return obj
