"""The MAVLink sentinel: a child process that lands the vehicle the moment the agent dies
(docs/safety.md, "When the agent dies").

An autopilot flies a dead agent's last attitude target until its own offboard-loss timeout
(PX4 COM_OF_LOSS_T, ArduPilot GUID_TIMEOUT), then its failsafe: PX4 SIH killed at 0.46 m/s
went 0.70 m further toward the wall, tilted for the timeout, then braking in Land. The
sentinel holds a copy of the driver's link (the same socket: the vehicle hears the partner
it knows) and one end of a socket pair whose other end only the driver holds. When that
closes without a release while perchd flies the vehicle (the kernel closes it on SIGKILL,
the OOM killer, a crash), the sentinel commands the autopilot's LAND at once and repeats it
LAND_REPEATS times, LAND_REPEAT_S apart (a lost datagram would leave the vehicle flying).

Wire (SOCK_SEQPACKET, one byte per message), driver -> sentinel: b"F" perchd flies the
vehicle (its offboard mode was acknowledged); b"D" it does not any more (the driver has
commanded LAND itself); b"R" release: exit without acting.

Run as `python -m perchd.drivers.mavsentinel CTL_FD LINK_FD DEST SSYS SCOMP SYS COMP MAIN
SUB` by drivers/mavlink.py: DEST is HOST:PORT[,HOST:PORT...] for a UDP link, "-" for a
stream; SSYS, SCOMP the driver's own ids; SYS, COMP the vehicle's; MAIN, SUB the LAND mode
as DO_SET_MODE's param2 and param3.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import sys
import threading
import time
from typing import Any

from perchd.drivers import childproc

LAND_REPEATS = 10
LAND_REPEAT_S = 0.1
"""LAND goes out at once and then every LAND_REPEAT_S, LAND_REPEATS times in all (1 s)."""
CMD_DO_SET_MODE = 176
CUSTOM_MODE_ENABLED = 1  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED

log = logging.getLogger("perchd.drivers.mavsentinel")


def land_frame(source: tuple[int, int], target: tuple[int, int], main: int, sub: int
               ) -> bytes:
    """COMMAND_LONG DO_SET_MODE to the LAND mode from `source` (the driver's system and
    component), framed in the MAVLink version pymavlink speaks here (the driver's own)."""
    from pymavlink import mavutil
    mav = mavutil.mavlink.MAVLink(None, *source)
    msg = mav.command_long_encode(*target, CMD_DO_SET_MODE, 0, CUSTOM_MODE_ENABLED, main,
                                  sub, 0, 0, 0, 0)
    return msg.pack(mav)


def agent_died_flying(ctl: socket.socket) -> bool:
    """Wait for the driver: True when its end closed while it flew the vehicle, False on a
    release or when it closed with the vehicle not (or no longer) its to fly."""
    flying = False
    while True:
        try:
            msg = ctl.recv(16)
        except OSError:
            msg = b""
        if not msg:
            return flying
        if msg == b"R":
            return False
        if msg in (b"F", b"D"):
            flying = msg == b"F"


def send_land(link_fd: int, dest: str, frame: bytes) -> None:
    if dest == "-":
        os.write(link_fd, frame)
        return
    with socket.socket(fileno=os.dup(link_fd)) as sock:
        for addr in dest.split(","):
            host, _, port = addr.rpartition(":")
            sock.sendto(frame, (host, int(port)))


def main(argv: list[str]) -> int:
    # The agent's Ctrl-C, a service stop and systemd's watchdog signal reach the whole
    # group: the sentinel outlives them and acts only on its socket's closing.
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGABRT):
        signal.signal(sig, signal.SIG_IGN)
    ctl_fd, link_fd, dest = int(argv[0]), int(argv[1]), argv[2]
    source, target, mode = (tuple(map(int, argv[i:i + 2])) for i in (3, 5, 7))
    frame = land_frame(source, target, *mode)
    if not agent_died_flying(socket.socket(fileno=ctl_fd)):
        return 0
    sys.stderr.write("perchd mavsentinel: the agent died flying the vehicle: LAND\n")
    for i in range(LAND_REPEATS):
        try:
            send_land(link_fd, dest, frame)
        except OSError as err:  # the link itself is gone: nothing more to do
            sys.stderr.write(f"perchd mavsentinel: LAND not sent: {err}\n")
            return 1
        if i + 1 < LAND_REPEATS:
            time.sleep(LAND_REPEAT_S)
    return 0


def link_endpoint(conn: Any) -> tuple[int, str]:
    """(fd, DEST) of a pymavlink connection: its socket and, for UDP, the addresses it
    writes to (udpin: every partner heard, as pymavlink writes to; udpout: the one given).
    ValueError when a udpin link has heard no one yet."""
    port = conn.port
    if not (isinstance(port, socket.socket) and port.type == socket.SOCK_DGRAM):
        return port.fileno(), "-"
    if conn.udp_server:
        heard = getattr(conn, "clients", None) or {getattr(conn, "last_address", None)} - {None}
    else:
        heard = {conn.destination_addr}
    if not heard:
        raise ValueError("the UDP link has heard no vehicle address yet")
    return port.fileno(), ",".join(f"{host}:{p}" for host, p in sorted(heard))


class Sentinel:
    """The driver's side: starts the sentinel on the connection `conn` for the vehicle
    `target` (system, component) with its LAND `mode` (main, sub); flying(True/False)
    tells it whether perchd flies the vehicle; release() ends it without acting."""

    def __init__(self, conn: Any, target: tuple[int, int], mode: tuple[int, int]) -> None:
        link_fd, dest = link_endpoint(conn)
        self._sock, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        source = (conn.mav.srcSystem, conn.mav.srcComponent)
        argv = [str(theirs.fileno()), str(link_fd), dest,
                *map(str, (*source, *target, *mode))]
        try:
            self._proc = childproc.start("perchd.drivers.mavsentinel", argv,
                                         (theirs.fileno(), link_fd))
        finally:
            theirs.close()
        self._lock = threading.Lock()
        self._flying: bool | None = None

    def flying(self, on: bool) -> None:
        if on != self._flying:
            self._flying = on
            self._send(b"F" if on else b"D")

    def release(self) -> None:
        """Normal end: the sentinel exits without a word to the vehicle."""
        self._send(b"R")
        with self._lock:
            sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()
        childproc.reap_later(self._proc, 2.0, "mavsentinel-reap")

    def _send(self, msg: bytes) -> None:
        with self._lock:
            if self._sock is None:
                return
            try:
                self._sock.send(msg)
            except OSError as err:
                log.warning("the MAVLink sentinel is gone (%s): if the agent dies, only the "
                            "autopilot's own failsafe acts", err)
                self._sock.close()
                self._sock = None


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
