"""The link to a MAVLink vehicle: our Connection around pymavlink's, the heartbeat, the one
wait for a message (wait_for) and the parameters read and written over it.

One thread receives (Connection.pump): each message goes to its owner's handler first and
then to whoever waits for one (wait_for), so a wait that returns finds the owner's state
already updated by the message that ended it.
"""

from __future__ import annotations

import math
import queue
import select
import socket
import threading
from collections import deque
from collections.abc import Callable, Collection, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from perchd.core.clock import Clock
from perchd.core.errors import LinkError

SOURCE = (255, 191)
"""Our system and component ids: an onboard computer."""
HEARTBEAT_S = 0.5
"""[s] our heartbeat period (MAVLink asks for at least 1 Hz)."""
WAIT_PERIOD_S = 0.005
"""[s] a wait runs its idle() at least this often."""
PARAM_ASK_S = 0.5
"""[s] PARAM_REQUEST_READ and PARAM_SET are sent again this often: one can be lost."""
DATAGRAM_MAX = 65535
MAV_PARAM_TYPE_INT32, MAV_PARAM_TYPE_REAL32 = 6, 9
CMD_ARM, CMD_DO_SET_MODE, CMD_SET_MESSAGE_INTERVAL = 400, 176, 511
CUSTOM_MODE_ENABLED = 1  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
ATTITUDE_ID, LOCAL_POSITION_NED_ID, ATTITUDE_TARGET_ID, EXTENDED_SYS_STATE_ID = 30, 32, 83, 245
MAV_RESULT_ACCEPTED, MAV_RESULT_IN_PROGRESS = 0, 5

Handler = Callable[[Any], None]


def _nothing() -> None:
    """An idle() with nothing to do."""


class Connection:
    """Ours around the pymavlink connection `conn`, which it owns and closes.

    Sends may come from several threads (one lock). pump() is the one receiver. A udpout:
    link given `on_refused` is read and written here, its socket connected to the vehicle:
    the kernel then turns the ICMP port-unreachable that answers a datagram to a closed port
    into ECONNREFUSED on the next call, so a vehicle that has gone away is known one
    datagram later instead of after the heartbeat timeout (pymavlink's mavudp swallows it,
    and an unconnected socket never sees it)."""

    def __init__(self, conn: Any, on_refused: Callable[[], None] | None = None) -> None:
        self.conn = conn
        self._on_refused = on_refused or _nothing
        self._sock = _connected(conn) if on_refused is not None else None
        self._parsed: deque[Any] = deque()
        self._send_lock = threading.Lock()
        self._listen_lock = threading.Lock()
        self._listeners: list[tuple[frozenset[str], queue.SimpleQueue]] = []

    @property
    def mav(self) -> Any:
        """pymavlink's encoder, to build messages for send() (its protocol follows the
        vehicle's: MAVLink 2 once it has heard a MAVLink 2 frame)."""
        return self.conn.mav

    @property
    def source(self) -> tuple[int, int]:
        """Our (system, component)."""
        return self.conn.mav.srcSystem, self.conn.mav.srcComponent

    def send(self, msg: Any) -> None:
        with self._send_lock:
            if self._sock is None:
                self.conn.mav.send(msg)
                return
            mav = self.conn.mav
            buf = msg.pack(mav)
            mav.seq = (mav.seq + 1) % 256  # as pymavlink's own send counts them
            self._write(buf)

    def heartbeat(self) -> None:
        """Ours: an onboard controller, no autopilot, active."""
        self.send(self.mav.heartbeat_encode(18, 8, 0, 0, 4))

    def command(self, target: tuple[int, int], command: int, *params: float) -> None:
        """COMMAND_LONG to `target` (system, component), unused params 0."""
        p = list(params) + [0.0] * (7 - len(params))
        self.send(self.mav.command_long_encode(*target, command, 0, *p))

    def set_mode(self, target: tuple[int, int], main: int, sub: int) -> None:
        """DO_SET_MODE to a custom mode given as DO_SET_MODE's (main, sub)."""
        self.command(target, CMD_DO_SET_MODE, CUSTOM_MODE_ENABLED, main, sub)

    def recv(self, timeout_s: float) -> Any | None:
        """The next message within timeout_s [s]; None for none (or unparseable bytes)."""
        msg = (
            self.conn.recv_match(blocking=True, timeout=timeout_s)
            if self._sock is None
            else self._recv_connected(timeout_s)
        )
        return None if msg is None or msg.get_type() == "BAD_DATA" else msg

    def pump(self, timeout_s: float, handle: Handler) -> None:
        """Receive one message (timeout_s [s] at most): handle(msg), then to the waits."""
        msg = self.recv(timeout_s)
        if msg is None:
            return
        handle(msg)
        with self._listen_lock:
            for types, heard in self._listeners:
                if msg.get_type() in types:
                    heard.put(msg)

    @contextmanager
    def listen(self, types: Collection[str]) -> Iterator[queue.SimpleQueue]:
        """The messages of `types` pump() hands on while inside, in order."""
        entry = (frozenset(types), queue.SimpleQueue())
        with self._listen_lock:
            self._listeners.append(entry)
        try:
            yield entry[1]
        finally:
            with self._listen_lock:
                self._listeners.remove(entry)

    def endpoint(self) -> tuple[int, str]:
        """(fd, DEST) for a process that is to send on this link (the sentinel): its socket
        and, for UDP, the addresses it writes to (udpin: every partner heard, as pymavlink
        writes to; udpout: the one given), "-" for a stream. ValueError when a udpin link
        has heard no one yet."""
        conn, port = self.conn, self.conn.port
        if not (isinstance(port, socket.socket) and port.type == socket.SOCK_DGRAM):
            return port.fileno(), "-"
        if conn.udp_server:
            heard = getattr(conn, "clients", None) or {getattr(conn, "last_address", None)} - {None}
        else:
            heard = {conn.destination_addr}
        if not heard:
            raise ValueError("the UDP link has heard no vehicle address yet")
        return port.fileno(), ",".join(f"{host}:{p}" for host, p in sorted(heard))

    def close(self) -> None:
        self.conn.close()

    def _recv_connected(self, timeout_s: float) -> Any | None:
        if not self._parsed and select.select([self._sock], [], [], timeout_s)[0]:
            data = self._read()
            if data and self.conn.first_byte:
                self.conn.auto_mavlink_version(data)
            if data:
                self._parsed.extend(self.conn.mav.parse_buffer(data) or [])
        return self._parsed.popleft() if self._parsed else None

    def _read(self) -> bytes:
        try:
            return self._sock.recv(DATAGRAM_MAX)
        except (BlockingIOError, InterruptedError):
            return b""
        except ConnectionRefusedError:
            self._on_refused()
            return b""

    def _write(self, buf: bytes) -> None:
        try:
            self._sock.send(buf)
        except ConnectionRefusedError:
            self._on_refused()
        except OSError:
            pass  # as pymavlink: a full buffer or a transient error drops one datagram


def _connected(conn: Any) -> socket.socket:
    """A udpout: link's socket, connected to the vehicle's address."""
    sock = conn.port
    sock.connect((socket.gethostbyname(conn.destination_addr[0]), conn.destination_addr[1]))
    return sock


def bind_source_port(conn: Any, port: int, uri: str) -> None:
    """Give a pymavlink udpout: link a fixed source port, so a vehicle that answers only the
    first port it heard from (PX4) still answers the next run."""
    sock = conn.port
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(("0.0.0.0", port))
    except OSError as err:
        conn.close()
        raise LinkError(f"{uri}: cannot bind source port {port}: {err.strerror or err}") from None


def open_connection(
    device: str, uri: str, sport: int | None = None, on_refused: Callable[[], None] = _nothing
) -> Connection:
    """Our connection to `device` as SOURCE; a udpout: link from source port `sport` (None:
    an ephemeral one) that reports a refusal through on_refused()."""
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(device, source_system=SOURCE[0], source_component=SOURCE[1])
    if sport is not None:
        bind_source_port(conn, sport, uri)
    return Connection(conn, on_refused if device.startswith("udpout:") else None)


def wait_for(
    conn: Connection,
    types: Collection[str],
    predicate: Callable[[Any], bool],
    timeout_s: float,
    clock: Clock,
    *,
    ask: Callable[[], None] | None = None,
    ask_every_s: float = math.inf,
    idle: Callable[[], None] = _nothing,
) -> Any | None:
    """The first message of `types` conn's receiver hands on from now with predicate(msg)
    true, or None once timeout_s [s] on `clock` have passed. ask() (the request the answer
    is awaited to) goes out once listening, so no answer slips past, and again every
    ask_every_s [s]; idle() runs at least every WAIT_PERIOD_S and may raise to end the wait.
    types=() awaits nothing: a pause for timeout_s that runs idle()."""
    with conn.listen(types) as heard:
        start = asked = clock.now()
        if ask is not None:
            ask()
        while (now := clock.now()) - start <= timeout_s:
            if ask is not None and now - asked >= ask_every_s:
                asked = now
                ask()
            idle()
            try:
                msg = heard.get(timeout=WAIT_PERIOD_S)
            except queue.Empty:
                continue
            if predicate(msg):
                return msg
    return None


@dataclass(frozen=True)
class Waiter:
    """The driver's waits on `link`: each wait_s [s] at most on `clock`, idle() run
    meanwhile, a LinkError naming what was awaited when it does not come."""

    link: Connection
    uri: str
    wait_s: float
    clock: Clock
    idle: Callable[[], None] = _nothing

    def until(
        self,
        types: Collection[str],
        done: Callable[[], bool],
        what: str,
        *,
        causes: str = "",
        ask: Callable[[], None] | None = None,
        ask_every_s: float = math.inf,
    ) -> None:
        """Until done() (the link owner's state), checked now and on each message of
        `types`; ask() as in wait_for."""
        if (
            not done()
            and wait_for(
                self.link,
                types,
                lambda _msg: done(),
                self.wait_s,
                self.clock,
                ask=ask,
                ask_every_s=ask_every_s,
                idle=self.idle,
            )
            is None
        ):
            hint = f": {causes}" if causes else ""
            raise LinkError(f"{self.uri}: waited {self.wait_s:g} s for {what} in vain{hint}")

    def pause(self, seconds: float) -> None:
        """`seconds` [s] of idle()."""
        wait_for(self.link, (), lambda _msg: False, seconds, self.clock, idle=self.idle)


class ParamIO:
    """One vehicle's parameters over the link: values (name -> value, filled by the
    receiver's on_value) read and written through `waiter`, to the vehicle `target`."""

    def __init__(self, waiter: Waiter, target: tuple[int, int]) -> None:
        self.waiter, self.target = waiter, target
        self.values: dict[str, float] = {}

    def on_value(self, name: str, value: float) -> None:
        self.values[name] = value

    def read(self, name: str) -> float:
        """Asked again every PARAM_ASK_S: a PARAM_REQUEST_READ can be lost."""
        link = self.waiter.link
        self.waiter.until(
            ("PARAM_VALUE",),
            lambda: name in self.values,
            f"parameter {name}",
            ask=lambda: link.send(
                link.mav.param_request_read_encode(*self.target, name.encode(), -1)
            ),
            ask_every_s=PARAM_ASK_S,
        )
        return self.values[name]

    def write(self, name: str, wire: float, kind: int) -> float:
        """PARAM_SET of `wire` as MAV_PARAM_TYPE `kind`, then the value read back."""
        link = self.waiter.link
        self.values.pop(name, None)
        link.send(link.mav.param_set_encode(*self.target, name.encode(), wire, kind))
        return self.read(name)
