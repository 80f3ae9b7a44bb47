"""matplotlib's refusals (a format it lacks, a write error) as one line naming the flag."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from perchd.core.safefile import OutputError


def draw(plotter: Callable[[Any, Path], None], data: Any, out: Path, flag: str) -> None:
    """plotter(data, out), its OSError or ValueError as one OutputError."""
    try:
        plotter(data, out)
    except (OSError, ValueError) as err:
        raise OutputError(f"{flag} {out}: cannot draw ({err})") from None
