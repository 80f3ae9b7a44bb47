"""A flight log (docs/contracts.md §5) as an MCAP file that Foxglove and PlotJuggler open as is.

One channel per stream, JSON messages, a JSON Schema per channel (undefined values stay
`null`, which the schemas allow). Log and publish times are the flight's clock, `t` of each
row or event in ns. The header carries no time of its own, so the one /perchd/flight message
(header, end, complete) is logged at the first row's `t`.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from perchd.core.errors import PerchdError
from perchd.core.extras import require
from perchd.core.safefile import write_atomic
from perchd.logs.flightlog import FlightLog, LogEvent, LogRow, jsonable

PREFIX = "/perchd"


@dataclass(frozen=True)
class RowStream:
    """A channel carrying some of each row's fields."""

    topic: str
    fields: tuple[str, ...]


ROW_STREAMS = (
    RowStream(f"{PREFIX}/estimate", ("t", "x", "xdot", "tau", "y", "z", "age", "pose_seq")),
    RowStream(f"{PREFIX}/reference", ("tau_ref", "x_plan", "v_plan", "a_plan")),
    RowStream(f"{PREFIX}/setpoint", ("roll", "pitch", "yaw", "thrust", "ux", "uy", "uz", "e")),
    RowStream(f"{PREFIX}/loop", ("k", "jitter_s", "compute_s", "end")),
)
PHASE = f"{PREFIX}/phase"
EVENTS = f"{PREFIX}/events"
FLIGHT = f"{PREFIX}/flight"
TOPICS = tuple(s.topic for s in ROW_STREAMS) + (PHASE, EVENTS, FLIGHT)

_NUMBER_OR_NULL = {"type": ["number", "null"]}
# LogRow's annotations are strings (postponed evaluation): their JSON Schema types.
_ROW_TYPES = {
    "float": {"type": "number"},
    "float | None": _NUMBER_OR_NULL,
    "int": {"type": "integer"},
    "str": {"type": "string"},
    "str | None": {"type": ["string", "null"]},
}
_ROW_FIELD_TYPES = {f.name: _ROW_TYPES[str(f.type)] for f in dataclasses.fields(LogRow)}


def _schema(title: str, props: dict[str, Any]) -> dict[str, Any]:
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "type": "object",
        "properties": props,
        "required": list(props),
    }


def schemas() -> dict[str, dict[str, Any]]:
    """The JSON Schema of every topic."""
    out = {
        s.topic: _schema(
            f"perchd{s.topic.removeprefix(PREFIX).replace('/', '.')}",
            {name: _ROW_FIELD_TYPES[name] for name in s.fields},
        )
        for s in ROW_STREAMS
    }
    out[PHASE] = _schema(
        "perchd.phase", {"phase": {"type": "string"}, "previous": {"type": ["string", "null"]}}
    )
    out[EVENTS] = _schema(
        "perchd.event",
        {
            "t": {"type": "number"},
            "kind": {"type": "string"},
            "detail": {"type": "string"},
            "values": {"type": "object", "additionalProperties": _NUMBER_OR_NULL},
        },
    )
    out[FLIGHT] = _schema(
        "perchd.flight",
        {
            "header": {"type": "object"},
            "end": {"type": ["object", "null"]},
            "complete": {"type": "boolean"},
        },
    )
    return out


def ns(t: float) -> int:
    """Clock time [s] as an MCAP log time [ns]; MCAP times are unsigned."""
    if t < 0:
        raise PerchdError(f"time {t} s is negative; MCAP log times are unsigned")
    return round(t * 1e9)


@dataclass(frozen=True)
class Message:
    topic: str
    log_time: int
    payload: dict[str, Any]


def messages(log: FlightLog) -> list[Message]:
    """Every message of the export, sorted by log time (stable: rows before events at a tie)."""
    return sorted([*_flight(log), *_rows(log), *_events(log)], key=lambda m: m.log_time)


def _flight(log: FlightLog) -> Iterator[Message]:
    start = log.rows[0].t if log.rows else (log.events[0].t if log.events else 0.0)
    yield flight_message(log.header, log.end, start)


def _rows(log: FlightLog) -> Iterator[Message]:
    previous: str | None = None
    for row in log.rows:
        yield from row_messages(row, previous)
        previous = row.phase


def _events(log: FlightLog) -> Iterator[Message]:
    for ev in log.events:
        yield event_message(ev)


def flight_message(header: dict[str, Any], end: dict[str, Any] | None, t: float) -> Message:
    """The /perchd/flight message at `t` [s]: `complete` once the log has its end."""
    return Message(FLIGHT, ns(t), {"header": header, "end": end, "complete": end is not None})


def row_messages(row: LogRow, previous: str | None) -> list[Message]:
    """A row's message on every row channel, and on /perchd/phase when its phase differs
    from `previous` (the phase of the row before; None for the first)."""
    t = ns(row.t)
    out = [
        Message(s.topic, t, {name: getattr(row, name) for name in s.fields}) for s in ROW_STREAMS
    ]
    if row.phase != previous:  # phase changes only
        out.append(Message(PHASE, t, {"phase": row.phase, "previous": previous}))
    return out


def event_message(ev: LogEvent) -> Message:
    return Message(
        EVENTS, ns(ev.t), {"t": ev.t, "kind": ev.kind, "detail": ev.detail, "values": ev.values}
    )


def payload_bytes(payload: dict[str, Any]) -> bytes:
    """A message's JSON; jsonable: a non-finite float (read from a hand-edited log) is null,
    never a bare NaN."""
    return json.dumps(jsonable(payload), separators=(",", ":"), allow_nan=False).encode()


def write_mcap(log: FlightLog, out: IO[bytes]) -> int:
    """Write `log` as MCAP to the binary stream `out`; the number of messages written.
    MissingExtraError (exit 2) without the `mcap` extra."""
    mcap_writer = require("mcap.writer", "mcap")
    w = mcap_writer.Writer(out)
    w.start(profile="", library="perchd")
    channels = {}
    for topic, schema in schemas().items():
        sid = w.register_schema(
            name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode()
        )
        channels[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
    seq = dict.fromkeys(channels, 0)
    msgs = messages(log)
    for m in msgs:
        w.add_message(
            channel_id=channels[m.topic],
            log_time=m.log_time,
            publish_time=m.log_time,
            sequence=seq[m.topic],
            data=payload_bytes(m.payload),
        )
        seq[m.topic] += 1
    w.add_metadata(
        "perchd.flightlog",
        {
            "schema": str(log.header.get("schema", "")),
            "outcome": str((log.end or {}).get("outcome", "")),
            "complete": str(log.complete).lower(),
        },
    )
    w.finish()
    return len(msgs)


def export_mcap(log: FlightLog, out: Path, force: bool, flag: str = "--mcap") -> None:
    """`log` as MCAP at `out` (checked by check_output), by the one rule for written files
    (core/safefile.py:write_atomic): a failed export leaves `out` as it was."""
    write_atomic(out, lambda f: write_mcap(log, f), flag, force)
