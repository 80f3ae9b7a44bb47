"""A live view of a flight over the Foxglove WebSocket protocol (`perchd fly --foxglove`).

The channels, schemas and messages are the MCAP export's (perchd.logs.mcapexport,
docs/contracts.md §5): /perchd/estimate, reference, setpoint, loop, phase, events and flight.
They are read back from the flight log as the writer flushes it, by a process of its own
(ViewProcess, at a lower CPU priority), so the control loop does no more than it does
without a view: it writes its log, and the view follows the file. In the flying process a
thread would share its interpreter lock, and its wake-ups wait for it (measured:
benchmarks/README.md). A client that subscribes late sees the flight from then on; the
/perchd/flight message is sent when the first row is written (header, `complete` false) and
again when the end is (with `end`, `complete` true), both stamped, as in MCAP, with the first
row's time.

The server is the foxglove-sdk package (import `foxglove`, extra `foxglove`).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from perchd.core.errors import LinkError, PerchdError, UriError
from perchd.core.extras import require
from perchd.core.netbind import port_error
from perchd.core.realtime import leave_realtime
from perchd.logs.flightlog import SCHEMA, LogEvent, LogRow
from perchd.logs.mcapexport import (
    Message,
    event_message,
    flight_message,
    payload_bytes,
    row_messages,
    schemas,
)

DEFAULT_HOST = "127.0.0.1"
POLL_S = 0.02
"""[s] how often the view looks for new lines: 2 ticks at 100 Hz, a live plot's refresh."""
CLOSE_GRACE_S = 0.2
"""[s] after the last message, before the server stops: its send queues drain to clients."""


@dataclass(frozen=True)
class Address:
    """Where the view listens: host and TCP port (0: any free one)."""

    host: str
    port: int


def parse_address(text: str) -> Address:
    """`[HOST:]PORT` (host default 127.0.0.1); UriError naming --foxglove."""
    host, _, port = text.rpartition(":")
    host = host.strip("[]") or DEFAULT_HOST
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UriError(f"--foxglove {text}: expected [HOST:]PORT, PORT 0..65535 (0: any free one)")
    return Address(host, int(port))


class LogFollower:
    """The complete lines a flight log gains, parsed, as its writer flushes them. A file
    already at `path` when following starts (an old log about to be overwritten with
    --force) is skipped until it changes."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._stale = _identity(self.path)
        self._f: Any = None
        self._buf = ""

    def poll(self) -> list[dict[str, Any]]:
        if self._f is None and not self._open():
            return []
        self._buf += self._f.read()
        *lines, self._buf = self._buf.split("\n")
        return [json.loads(line) for line in lines if line]

    def _open(self) -> bool:
        ident = _identity(self.path)
        if ident is None or ident == self._stale:
            return False
        try:
            self._f = open(self.path, encoding="utf-8")
        except FileNotFoundError:
            return False
        return True

    def close(self) -> None:
        if self._f is not None:
            self._f.close()


def _identity(path: Path) -> tuple[int, int, int] | None:
    try:
        st = path.stat()
    except FileNotFoundError:
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


class Channels:
    """The export's channels on one foxglove server; publish() sends a Message."""

    def __init__(self, foxglove: Any, context: Any) -> None:
        self._by_topic = {
            topic: foxglove.Channel(
                topic,
                message_encoding="json",
                context=context,
                schema=foxglove.Schema(
                    name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode()
                ),
            )
            for topic, schema in schemas().items()
        }

    def publish(self, m: Message) -> None:
        self._by_topic[m.topic].log(payload_bytes(m.payload), log_time=m.log_time)

    def close(self) -> None:
        for channel in self._by_topic.values():
            channel.close()


class Replay:
    """Log lines (header, rows, events, end) turned into the export's messages, in order."""

    def __init__(self) -> None:
        self.ended = False  # the log's end line has been turned into messages
        self.header: dict[str, Any] | None = None
        self.phase: str | None = None
        self.t0: float | None = None  # [s] the first row's: /perchd/flight's time, as in MCAP

    def messages(self, obj: dict[str, Any]) -> list[Message]:
        if obj.get("schema") == SCHEMA:
            self.header = obj
            return []
        if "row" in obj:
            return self._row(LogRow(**obj["row"]))
        if "event" in obj:
            return [event_message(LogEvent(**obj["event"]))]
        if "end" in obj:
            self.ended = True
            if self.header is not None and self.t0 is not None:
                return [flight_message(self.header, obj["end"], self.t0)]
        return []

    def _row(self, row: LogRow) -> list[Message]:
        out = []
        if self.t0 is None and self.header is not None:
            self.t0 = row.t
            out.append(flight_message(self.header, None, row.t))
        out += row_messages(row, self.phase)
        self.phase = row.phase
        return out


class LiveView:
    """A foxglove WebSocket server publishing one flight log as it is written."""

    def __init__(self, address: Address) -> None:
        foxglove = require("foxglove", "foxglove")
        self.context = foxglove.Context()
        try:
            self.server = foxglove.start_server(
                name="perchd", host=address.host, port=address.port, context=self.context
            )
        except (RuntimeError, OSError) as err:
            raise port_error(f"--foxglove {address.host}:{address.port}", err) from None
        self.url = f"ws://{address.host}:{self.server.port}"
        self.channels = Channels(foxglove, self.context)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def follow(self, log: str | os.PathLike) -> None:
        """Publish `log` from now on, in a thread of its own, until close()."""
        follower = LogFollower(log)
        self._thread = threading.Thread(
            target=self._run, args=(follower,), name="perchd-foxglove", daemon=True
        )
        self._thread.start()

    def _run(self, follower: LogFollower) -> None:
        replay = Replay()
        try:
            while not replay.ended:
                stopping = self._stop.is_set()  # read before the last poll: nothing is lost
                for obj in follower.poll():
                    for m in replay.messages(obj):
                        self.channels.publish(m)
                if stopping:
                    return
                self._stop.wait(POLL_S)
        finally:
            follower.close()

    def stop(self) -> None:
        """Stop following once what the log holds now is published."""
        self._stop.set()

    def wait(self) -> None:
        """Until the log has ended (or close() was asked for) and all of it is published."""
        if self._thread is not None:
            self._thread.join()

    def close(self) -> None:
        """Publish what the log still holds, then stop serving."""
        self.stop()
        if self._thread is not None:
            self._thread.join()
            time.sleep(CLOSE_GRACE_S)
        self.channels.close()
        self.server.stop()


VIEW_NICE = 10
"""The view process's niceness: the flying process comes first when the CPUs are busy."""
VIEW_STOP_S = 5.0
"""[s] longest wait for the view process to publish the rest of the log and stop."""


class ViewProcess:
    """A LiveView in a child process (`python -m perchd.logs.foxglove HOST PORT LOG`): bound,
    or its one-line refusal raised here, before the flight starts. Closing its stdin, or this
    process dying, tells it to publish what the log still holds and stop."""

    def __init__(self, address: Address, log: str | os.PathLike) -> None:
        require("foxglove", "foxglove")  # here: the missing extra is one line, at once
        self.proc = subprocess.Popen(
            [sys.executable, "-m", __name__, address.host, str(address.port), str(log)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        line = self.proc.stdout.readline()
        said = (
            json.loads(line)
            if line.startswith("{")
            else {
                "error": f"the view process ended at start (exit {self.proc.wait()})",
                "exit_code": 1,
            }
        )
        if "error" in said:
            self.proc.wait()
            raise (UriError if said["exit_code"] == 2 else LinkError)(said["error"])
        self.url = said["url"]

    def close(self) -> None:
        self.proc.stdin.close()
        try:
            self.proc.wait(VIEW_STOP_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def main(argv: list[str]) -> int:
    """The view process: serve, say where (one JSON line on stdout), follow LOG to its end
    or until stdin closes. Ctrl-C reaches the whole process group: the flight's own end
    stops this process, not the signal."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    leave_realtime()
    os.nice(VIEW_NICE)
    host, port, log = argv
    try:
        view = LiveView(Address(host, int(port)))
    except PerchdError as err:
        print(json.dumps({"error": str(err), "exit_code": err.exit_code}), flush=True)
        return err.exit_code
    print(json.dumps({"url": view.url}), flush=True)
    view.follow(log)
    threading.Thread(target=_stop_at_eof, args=(view,), daemon=True).start()
    view.wait()
    view.close()
    return 0


def _stop_at_eof(view: LiveView) -> None:
    sys.stdin.read()  # returns when the flying process closes the pipe, or dies
    view.stop()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
