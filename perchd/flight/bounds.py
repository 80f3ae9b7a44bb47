"""Every setting's unit and range, declared beside its field, and the one walk that checks them.

A numeric field of a config dataclass is declared `name: float = setting(default, "m/s",
0.0, 10.0)`: the range is inclusive, and its sign is the setting's (lo >= 0: never
negative). check_bounds walks a config's numeric leaves (floats, ints, optional ones when
set, each number of a tuple) and raises ConfigError on the first outside its range, naming
the key as the TOML file spells it ("[tau_gains] kp_fast"), the value and the range.
Booleans, enums and strings have no range: their type is the check (service/config.py).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import types
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from perchd.core.errors import ConfigError

TOP = "flight"
"""The TOML table of the top dataclass's own fields (service/config.py's [flight])."""


@dataclass(frozen=True)
class Bound:
    """unit: the setting's unit ("" for a ratio or a count); lo, hi: its inclusive range."""

    unit: str
    lo: float
    hi: float

    def span(self) -> str:
        """'0..200 m/s^2', with degrees beside radians."""
        text = f"{self.lo:g}..{self.hi:g}{_unit(self.unit)}"
        if self.unit == "rad":
            text += f" ({math.degrees(self.lo):g}..{math.degrees(self.hi):g} deg)"
        return text

    def fault(self, key: str, value: float) -> str | None:
        """The one line refusing value, or None when it is inside."""
        shown = f"{key} = {value:g}{_unit(self.unit) if math.isfinite(value) else ''}"
        if self.unit == "rad" and math.isfinite(value):
            shown += f" ({math.degrees(value):g} deg)"
        if not math.isfinite(value):
            return f"{shown}: not a finite number (range {self.span()})"
        if not self.lo <= value <= self.hi:
            return f"{shown}: outside its range {self.span()}"
        return None


REQUIRED: Any = dataclasses.MISSING
"""setting()'s default for a field its dataclass's callers always give."""


def setting(default: Any, unit: str, lo: float, hi: float) -> Any:
    """A dataclass field with its Bound (module docstring)."""
    return dataclasses.field(default=default, metadata={"bound": Bound(unit, lo, hi)})


@dataclass(frozen=True)
class Leaf:
    """One setting: path the attribute names from the top config, bound (None: no range
    declared), tp its type hint."""

    path: tuple[str, ...]
    bound: Bound | None
    tp: Any

    @property
    def key(self) -> str:
        """As the TOML file spells it: '[tau_gains] kp_fast', '[flight] rate_hz'."""
        return f"[{'.'.join(self.path[:-1]) or TOP}] {self.path[-1]}"

    @property
    def numeric(self) -> bool:
        """A number or numbers: it must declare a range."""
        tp = _unwrapped(self.tp)
        if typing.get_origin(tp) is tuple:
            return all(a in (int, float) for a in typing.get_args(tp))
        return tp in (int, float)

    def value(self, cfg: Any) -> Any:
        return functools.reduce(getattr, self.path, cfg)


@functools.cache  # the classes never change; every FlightConfig is checked
def leaves(cls: type, path: tuple[str, ...] = ()) -> tuple[Leaf, ...]:
    """Every non-dataclass field under cls, depth first, in declaration order."""
    hints = typing.get_type_hints(cls)
    out: list[Leaf] = []
    for f in dataclasses.fields(cls):
        tp: Any = hints[f.name]
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            out.extend(leaves(tp, (*path, f.name)))
        else:
            out.append(Leaf((*path, f.name), f.metadata.get("bound"), tp))
    return tuple(out)


def faults(cfg: Any) -> Iterator[str]:
    """One line per number of cfg outside its declared range."""
    cls: Any = type(cfg)
    for leaf in leaves(cls):
        value = leaf.value(cfg)
        if leaf.bound is None or value is None:
            continue
        numbers = value if isinstance(value, tuple) else (value,)
        for i, x in enumerate(numbers):
            key = leaf.key + (f"[{i}]" if isinstance(value, tuple) else "")
            fault = leaf.bound.fault(key, x)
            if fault is not None:
                yield fault


def check_bounds(cfg: Any) -> None:
    """ConfigError naming the first setting of cfg outside its range."""
    for fault in faults(cfg):
        raise ConfigError(fault)


def table(cls: type) -> list[str]:
    """The settings as Markdown table rows: key, unit, range, default (docs/contracts.md)."""
    rows = ["| key | unit | range | default |", "| --- | --- | --- | --- |"]
    defaults = cls()
    for leaf in leaves(cls):
        b = leaf.bound
        span = f"{b.lo:g}..{b.hi:g}" if b else _choices(leaf.tp)
        rows.append(
            f"| `{leaf.key}` | {b.unit if b else ''} | {span} | {_default(leaf.value(defaults))} |"
        )
    return rows


def _choices(tp: Any) -> str:
    tp = _unwrapped(tp)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return " / ".join(f"`{m.value}`" for m in tp)
    return {bool: "true / false", str: "a path"}.get(tp, str(tp))


def _default(value: Any) -> str:
    if value is None:
        return "unset"
    if isinstance(value, tuple):
        return "[" + ", ".join(f"{x:g}" for x in value) + "]"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.6g}"
    return f"`{value.value}`" if hasattr(value, "value") else str(value)


def _unwrapped(tp: Any) -> Any:
    """X of X | None."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        return inner[0] if len(inner) == 1 else tp
    return tp


def _unit(unit: str) -> str:
    return f" {unit}" if unit else ""
