"""A stand-in Crazyflie on the far end of cflib's `udp://` link, for tests.

cflib's UdpDriver sends one CRTP packet per datagram (byte 0 the header, the rest the
payload) from a connected socket, and queues whatever comes back. What the responder must
answer, and what it records:
- link echo (port 15, channel 0, header 0xFC): answered with the same bytes, as the
  firmware's link service does. This is the driver's connect handshake and its proof of
  life on a link without radio acks.
- commander RPYT (port 3, channel 0, header 0x3C, payload `<fffH>`: roll deg, pitch deg as
  on the wire (cflib negates it), yaw rate deg/s clockwise-positive as on the wire (the
  firmware negates it), thrust 0..65535): recorded, not answered.
- generic commander stop (port 7, channel 0, header 0x7C, payload `<B>` = 0): recorded.
- localization ext-pose (port 6, channel 1, header 0x6D, `<Bfffffff>` type 8): recorded.
Nothing else is needed: the driver never downloads TOCs.

mute() keeps recording but stops answering (a hung vehicle); die() closes the socket
(the kernel then refuses datagrams, which cflib reports as a link error).
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from dataclasses import dataclass

from ticks import wait_for

ECHO, RPYT, STOP, EXTPOSE = 0xFC, 0x3C, 0x7C, 0x6D


@dataclass(frozen=True)
class Rpyt:
    """One commander packet as the firmware would decode it."""

    t: float  # [s] time.monotonic() at arrival
    roll_deg: float
    wire_pitch_deg: float  # firmware (legacy) convention: positive nose-up
    yawrate_dps: float  # as on the wire: positive clockwise (the firmware negates it)
    thrust: int


@dataclass(frozen=True)
class Datagram:
    t: float
    header: int
    payload: bytes


class CrtpResponder:
    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.uri = f"udp://127.0.0.1:{self.port}"
        self.received: list[Datagram] = []
        self._lock = threading.Lock()
        self._answering = True
        self._alive = True
        self._thread = threading.Thread(target=self._serve, name="crtp-responder", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while self._alive:
            try:
                data, addr = self.sock.recvfrom(64)
            except TimeoutError:
                continue
            except OSError:
                return
            if not data:
                continue
            with self._lock:
                self.received.append(Datagram(time.monotonic(), data[0], data[1:]))
            if data[0] == ECHO and self._answering:
                try:
                    self.sock.sendto(data, addr)
                except OSError:
                    return  # closed under us (a test killing the link)

    # -- what the vehicle saw ----------------------------------------------------------
    def of(self, header: int) -> list[Datagram]:
        with self._lock:
            return [d for d in self.received if d.header == header]

    def setpoints(self) -> list[Rpyt]:
        return [Rpyt(d.t, *struct.unpack("<fffH", d.payload)) for d in self.of(RPYT)]

    def stops(self) -> list[Datagram]:
        return [d for d in self.of(STOP) if d.payload[:1] == b"\x00"]

    def extposes(self) -> list[tuple[float, ...]]:
        return [struct.unpack("<Bfffffff", d.payload)[1:] for d in self.of(EXTPOSE)]

    wait_for = staticmethod(wait_for)

    # -- failures ----------------------------------------------------------------------
    def mute(self) -> None:
        self._answering = False

    def die(self) -> None:
        self._alive = False
        self.sock.close()
        self._thread.join(timeout=1.0)

    def close(self) -> None:
        if self._alive:
            self.die()
