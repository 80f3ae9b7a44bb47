"""The recorded NatNet packets in tests/fixtures/natnet, and a UDP player that serves them.

The player is Motive as recorded: it answers connect and model-definition requests with the
recorded replies and sends the recorded frames, byte for byte, over a real socket.
"""

from __future__ import annotations

import csv
import json
import select
import socket
import threading
from dataclasses import dataclass
from pathlib import Path

# a copy of tests/fixtures/natnet, kept in the repository so a clean clone tests alone
FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "natnet"
V3 = FIXTURES / "motive-2.1-natnet-3.0"
V2X = FIXTURES / "motive-1.x-natnet-2.x"
SESSION = FIXTURES / "motive-2.1-session"


def packet(path: Path) -> bytes:
    return path.read_bytes()


def payload(path: Path) -> bytes:
    return path.read_bytes()[4:]


@dataclass(frozen=True)
class Recorded:
    index: int
    message_id: int
    data: bytes


def session_packets() -> list[Recorded]:
    out = []
    for line in (SESSION / "index.jsonl").read_text().splitlines():
        row = json.loads(line)
        out.append(
            Recorded(row["i"], row["msg_id"], (SESSION / "packets" / row["file"]).read_bytes())
        )
    return out


def session_frames() -> list[Recorded]:
    return [p for p in session_packets() if p.message_id == 7]


def first_reply(message_id: int) -> bytes:
    return next(p.data for p in session_packets() if p.message_id == message_id)


def expected_rows() -> list[dict[str, str]]:
    with open(SESSION / "expected_rigid_bodies.csv", newline="") as f:
        return list(csv.DictReader(f))


class RecordedMotive:
    """Serves the session's server info and model definitions on a loopback command port
    (not echoes: the recorded ones answer another client's stamps), then, in unicast as
    Motive does, sends frames to the socket a client connected from."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.server_info = first_reply(1)
        self.model_defs = first_reply(5)
        self.client: tuple[str, int] | None = None
        self.connected = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            if not select.select([self.sock], [], [], 0.05)[0]:
                continue
            data, address = self.sock.recvfrom(70000)
            message_id = int.from_bytes(data[:2], "little")
            if message_id == 0:
                self.client = address
                self.sock.sendto(self.server_info, address)
                self.connected.set()
            elif message_id == 4:
                self.sock.sendto(self.model_defs, address)

    def send(self, datagram: bytes) -> None:
        assert self.client is not None, "no client connected"
        self.sock.sendto(datagram, self.client)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.sock.close()
