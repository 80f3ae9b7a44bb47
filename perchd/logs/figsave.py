"""A matplotlib figure saved by the one rule for written files (core/safefile.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from perchd.core.safefile import write_atomic


def save_figure(fig: Any, path: str | Path, dpi: int, flag: str, force: bool) -> Path:
    """`fig` drawn into a temporary file beside `path` and renamed onto it (an existing
    `path` only with `force`); the format is the suffix's (matplotlib's ValueError if it
    lacks it)."""
    out = Path(path)
    fmt = out.suffix[1:].lower() or "png"
    write_atomic(out, lambda f: fig.savefig(f, format=fmt, dpi=dpi), flag, force)
    return out
