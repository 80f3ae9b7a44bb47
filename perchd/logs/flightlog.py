"""Flight log (docs/contracts.md §5): JSON lines, written and flushed as the flight goes.

Line 1 is the header (schema, plan, config, links); then one `row` object per control tick
(time, phase, measured X/Xdot/tau, tau_ref, planned X/V/A, Y/Z, the setpoint, the loop's
timing and the end reason on the last row), `event` objects between them (trigger, stage
switch, contact) and a final `end` object with the outcome. Every line is flushed to the OS
when written, so a killed process loses nothing already written (at most the tick in hand).
The reader tolerates a torn last line and a missing end (a crashed flight).
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from perchd.core.errors import PerchdError

SCHEMA = "perchd.flightlog/1"


@dataclass(frozen=True, slots=True)
class LogRow:
    """One control tick. t [s] clock time; k tick index; phase name; x [m], xdot [m/s],
    tau [s] (None: undefined), tau_ref [s] (None outside stages 1-2); x_plan [m], v_plan [m/s],
    a_plan [m/s^2] (None outside stages); y, z [m] perching frame; roll, pitch, yaw [rad],
    thrust [N] sent; ux, uy, uz [m/s^2] commanded perching-frame acceleration; e tau error;
    age [s] mocap staleness; pose_seq; jitter_s, compute_s [s] of the previous tick;
    end: the EndReason name on the flight's last row, else None."""

    t: float
    k: int
    phase: str
    x: float | None
    xdot: float | None
    tau: float | None
    tau_ref: float | None
    x_plan: float | None
    v_plan: float | None
    a_plan: float | None
    y: float | None
    z: float | None
    roll: float
    pitch: float
    yaw: float
    thrust: float
    ux: float
    uy: float
    uz: float
    e: float | None
    age: float | None
    pose_seq: int
    jitter_s: float
    compute_s: float
    end: str | None = None


@dataclass(frozen=True, slots=True)
class LogEvent:
    """t [s]; kind (trigger, stage2, contact, ...); detail: a sentence; values: figures."""

    t: float
    kind: str
    detail: str
    values: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class FlightLog:
    """What read_log returns; `end` is None and `complete` False for a flight cut short."""

    header: dict[str, Any]
    rows: list[LogRow]
    events: list[LogEvent]
    end: dict[str, Any] | None
    complete: bool


def jsonable(obj: Any) -> Any:
    """Dataclasses, enums, tuples and non-finite floats as plain JSON values."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


_ROW_FIELDS = tuple(f.name for f in dataclasses.fields(LogRow))


def _finite(value: Any) -> Any:
    """A LogRow value as JSON: non-finite floats become None, as jsonable makes them."""
    return None if isinstance(value, float) and not math.isfinite(value) else value


class FlightLogWriter:
    """Open with the header; `row`, `event` as the flight goes; `close(end)` once."""

    def __init__(self, path: str | os.PathLike, header: dict[str, Any]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f: IO[str] | None = open(self.path, "w", encoding="utf-8")
        self.rows = 0
        self._write({"schema": SCHEMA, **jsonable(header)})

    @property
    def closed(self) -> bool:
        return self._f is None

    def _write(self, obj: dict[str, Any]) -> None:
        if self._f is None:
            return
        self._f.write(json.dumps(obj, separators=(",", ":")) + "\n")
        self._f.flush()

    def row(self, row: LogRow) -> None:
        # LogRow is flat (numbers, strings, None): skip jsonable's recursion, once per tick.
        self._write({"row": {name: _finite(getattr(row, name)) for name in _ROW_FIELDS}})
        self.rows += 1

    def event(self, ev: LogEvent) -> None:
        self._write({"event": jsonable(ev)})

    def close(self, end: dict[str, Any] | None = None) -> None:
        if self._f is None:
            return
        if end is not None:
            self._write({"end": jsonable(end)})
        f, self._f = self._f, None
        f.close()


def read_log(path: str | os.PathLike) -> FlightLog:
    """Parse a flight log; a torn last line (killed writer) is ignored."""

    lines = Path(path).read_text(encoding="utf-8").splitlines()
    objs = []
    for i, line in enumerate(lines):
        try:
            objs.append(json.loads(line))
        except ValueError:
            if i == len(lines) - 1:
                break  # torn by a crash mid-write
            raise PerchdError(f"{path}: line {i + 1} is not JSON") from None
    if not objs or objs[0].get("schema") != SCHEMA:
        raise PerchdError(f"{path}: not a perchd flight log (schema {SCHEMA} expected)")
    header = objs[0]
    rows = [LogRow(**o["row"]) for o in objs[1:] if "row" in o]
    events = [LogEvent(**o["event"]) for o in objs[1:] if "event" in o]
    end = next((o["end"] for o in objs[1:] if "end" in o), None)
    return FlightLog(header, rows, events, end, end is not None)
