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
from typing import Any

from perchd.core.errors import PerchdError
from perchd.core.safefile import OutputError, Stream, read_regular
from perchd.logs.logfields import END, HEADER, LogFormatError, record, shaped

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
    """Open with the header; `row`, `event` as the flight goes; `close(end)` once.

    The file is a safefile.Stream: created exclusively at `path` (or, replacing an existing
    log with `force`, beside it and renamed at close). A failure to open it or to write the
    header is an OutputError before anything flies; a write failing later (a full disk)
    never raises out of the flight loop: writing stops, `lost` says why, and the flight
    reads it (flight/run.py ends a flight whose record is lost)."""

    def __init__(
        self, path: str | os.PathLike, header: dict[str, Any], force: bool = False
    ) -> None:
        self.path = Path(path)
        self.rows = 0
        self.lost: str | None = None
        self._stream: Stream | None = Stream(self.path, "--log", force)
        self._write({"schema": SCHEMA, **jsonable(header)})
        if self.lost is not None:
            self._stream.abandon()
            raise OutputError(f"--log {self.lost}")

    @property
    def closed(self) -> bool:
        return self._stream is None

    def _write(self, obj: dict[str, Any]) -> None:
        if self._stream is None or self.lost is not None:
            return
        try:
            self._stream.file.write(json.dumps(obj, separators=(",", ":")).encode() + b"\n")
            self._stream.file.flush()
        except (OSError, ValueError) as err:
            why = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
            self.lost = f"{self.path}: cannot write ({why})"

    def row(self, row: LogRow) -> None:
        # LogRow is flat (numbers, strings, None): skip jsonable's recursion, once per tick.
        self._write({"row": {name: _finite(getattr(row, name)) for name in _ROW_FIELDS}})
        self.rows += 1

    def event(self, ev: LogEvent) -> None:
        self._write({"event": jsonable(ev)})

    def close(self, end: dict[str, Any] | None = None) -> None:
        """The end line written and the file put in place; a failure sets `lost`."""
        if self._stream is None:
            return
        if end is not None:
            self._write({"end": jsonable(end)})
        stream, self._stream = self._stream, None
        if self.lost is not None:
            stream.abandon()
            return
        try:
            stream.finish()
        except OSError as err:
            stream.abandon()
            self.lost = f"{self.path}: cannot write ({err.strerror or err})"


MAX_LOG_BYTES = 1 << 30
"""[bytes] largest flight log read (a minute at 500 Hz is ~15 MB)."""


def read_log(path: str | os.PathLike) -> FlightLog:
    """Parse a flight log; a torn last line (killed writer) is ignored. Anything else that
    is not a perchd flight log (another schema, garbage, a field of the wrong kind) is one
    PerchdError naming the file and line."""
    text = read_regular(path, "", PerchdError, MAX_LOG_BYTES)
    lines = text.splitlines()
    objs = []
    for i, line in enumerate(lines):
        try:
            objs.append(json.loads(line))
        except (ValueError, RecursionError):
            if i == len(lines) - 1 and i > 0:
                break  # torn by a crash mid-write
            raise PerchdError(f"{path}: line {i + 1} is not JSON") from None
    if not objs or not isinstance(objs[0], dict) or objs[0].get("schema") != SCHEMA:
        raise PerchdError(f"{path}: not a perchd flight log (schema {SCHEMA} expected)")
    try:
        return parse_lines(objs)
    except LogFormatError as err:
        raise PerchdError(f"{path}: {err}") from None


def parse_lines(objs: list[Any]) -> FlightLog:
    """The FlightLog of a log's parsed lines (the first its header); LogFormatError naming
    the first line that is not a row, an event or the end, or holds a field of the wrong kind."""
    header = shaped(objs[0], HEADER, "line 1 (header)")
    rows, events, end = [], [], None
    for i, obj in enumerate(objs[1:], 2):
        kind = next(iter(obj), None) if isinstance(obj, dict) and len(obj) == 1 else None
        if kind == "row":
            rows.append(LogRow(**record(LogRow, obj["row"], f"line {i} (row)")))
        elif kind == "event":
            events.append(LogEvent(**record(LogEvent, obj["event"], f"line {i} (event)")))
        elif kind == "end" and end is None:
            end = shaped(obj["end"], END, f"line {i} (end)")
        else:
            raise LogFormatError(f"line {i}: not a row, an event or the one end")
    return FlightLog(header, rows, events, end, end is not None)
