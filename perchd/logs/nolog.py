"""The flight record when none is kept: a campaign's flights unless --logs asks for them.

A flight log costs a JSON line per tick, a sixth of a simulated flight's CPU; the campaign's
table row holds what a study of many flights reads."""

from __future__ import annotations

from typing import Any


class NoLog:
    """FlightLogWriter's interface (row, event, close, rows, lost), writing nothing."""

    rows = 0
    lost: str | None = None
    path = None

    def row(self, _row: Any) -> None:
        pass

    def event(self, _ev: Any) -> None:
        pass

    def close(self, _end: dict[str, Any] | None = None) -> None:
        pass
