"""The client end of a firmware's socket: where cflib's `udp://HOST:PORT` link connects.

cf2 answers whoever sent it the last datagram (src/hal/src/socketlink.c replies to the
source of its latest recvfrom), so exactly one process may talk to it: the physics. cflib's
packets come in here and the physics forwards them on its own firmware socket; the
firmware's packets for the client go back out from here, so cflib's connected socket sees
them come from the address it connected to.

cflib's udp:// driver probes a port with the lone byte 0xFF when it scans; it is answered
here (not forwarded). Any datagram makes its sender the client.
"""

from __future__ import annotations

import socket
from dataclasses import dataclass

from perchd.core.errors import LinkError, UriError
from perchd.core.netbind import check_bind
from perchd.core.uri import parse_uri
from perchd.core.uriparams import bool_param
from perchd.sim.firmware.cf2wire import MAX_DATAGRAM, PROBE

RCVBUF_BYTES = 1 << 21
"""cflib bursts (a TOC download is hundreds of packets) wait here, not in the firmware's
5-deep link queue, which drops when full."""


@dataclass
class RelayCounts:
    from_client: int = 0
    to_client: int = 0
    probes: int = 0
    oversize: int = 0  # datagrams longer than one CRTP packet, dropped


class ClientRelay:
    """A non-blocking UDP socket bound at `udp://HOST:PORT` (port 0: any free port)."""

    def __init__(self, text: str) -> None:
        uri = parse_uri(text)
        if uri.scheme != "udp" or not uri.host or uri.port is None or set(uri.query) - {"public"}:
            raise UriError(f"--link {text}: expected udp://HOST:PORT[?public=1]")
        check_bind(uri.host, bool_param(uri, "public"), f"--link {text}")
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
            self.sock.bind((uri.host, uri.port))
        except OSError as err:
            self.sock.close()
            raise LinkError(f"--link {text}: cannot bind: {err}") from None
        self.sock.setblocking(False)
        self.host, self.port = self.sock.getsockname()[:2]
        self.client: tuple[str, int] | None = None
        self.counts = RelayCounts()

    @property
    def uri(self) -> str:
        return f"udp://{self.host}:{self.port}"

    def poll(self, limit: int) -> list[bytes]:
        """Up to `limit` packets from the client, oldest first (the rest wait their turn)."""
        out: list[bytes] = []
        while len(out) < limit:
            try:
                data, addr = self.sock.recvfrom(256)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # e.g. ICMP port unreachable from a client that went away
                continue
            self.client = addr
            if data == PROBE:
                self.counts.probes += 1
                self._send(PROBE)
            elif 0 < len(data) <= MAX_DATAGRAM:
                self.counts.from_client += 1
                out.append(data)
            else:
                self.counts.oversize += 1
        return out

    def send(self, data: bytes) -> None:
        """A firmware packet for the client (dropped while none has spoken)."""
        if self.client is not None:
            self.counts.to_client += 1
            self._send(data)

    def _send(self, data: bytes) -> None:
        try:
            self.sock.sendto(data, self.client)  # type: ignore[arg-type]
        except OSError:
            pass  # a client that left: UDP has no one to tell

    def close(self) -> None:
        self.sock.close()
