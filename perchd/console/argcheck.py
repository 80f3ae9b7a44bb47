"""Argument helpers shared by the commands: negative numbers as option values, and finite,
bounded numeric flags refused as one line naming the flag, the value and what is allowed
(docs/contracts.md §6)."""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Iterable

from perchd.core.errors import ConfigError, PerchdError

NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.IGNORECASE)
"""What argparse should take as a (negative) value, not an option: -3, -.5, -1e-3, -inf."""


def numbers_as_values(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Let `--x0 -1e-3` parse: argparse's own pattern misses exponents (-1e-3 looked like a flag).
    None of perchd's flags looks like a number, so nothing is shadowed."""
    parser._negative_number_matcher = NUMBER  # the hook argparse consults for this
    return parser


def within(
    flag: str,
    values: float | Iterable[float] | None,
    lo: float,
    hi: float,
    unit: str,
    error: type[PerchdError] = ConfigError,
) -> None:
    """`error` unless every value is finite and in [lo, hi]; None (an unset flag) passes."""
    if values is None:
        return
    for v in (values,) if isinstance(values, (int, float)) else values:
        if not (math.isfinite(v) and lo <= v <= hi):
            raise error(f"{flag} {v:g}: must be a finite number in {lo:g}..{hi:g} {unit}".rstrip())
