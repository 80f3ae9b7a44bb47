"""The link under the MAVLink driver and the harnesses (drivers/mavlink/link.py): one wait for
a message, fed by the one receiving thread after its handler; a udpout: link that learns of a
vehicle gone from the kernel's refusal. Real pymavlink, real sockets on loopback."""

from __future__ import annotations

import socket
import threading
import time

import pytest

pytest.importorskip("pymavlink")

from pymavlink import mavutil

from perchd.core.clock import MonotonicClock
from perchd.drivers.mavlink.link import Connection, open_connection, wait_for

CLOCK = MonotonicClock()


class Autopilot:
    """A vehicle's socket on loopback: it says hello (a heartbeat) to `port`, and answers each
    PARAM_REQUEST_READ for a name in `params` with its PARAM_VALUE; requests counted."""

    def __init__(self, port: int, params: dict[str, float]) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.02)
        self.port, self.params, self.requests = port, params, 0
        self.mav = mavutil.mavlink.MAVLink(None, 1, 1)
        self._parser = mavutil.mavlink.MAVLink(None)
        self._stop = threading.Event()
        self._send(self.mav.heartbeat_encode(2, 3, 0, 0, 4))
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _send(self, msg) -> None:
        self.sock.sendto(msg.pack(self.mav), ("127.0.0.1", self.port))

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.sock.recv(512)
            except TimeoutError:
                continue
            for msg in self._parser.parse_buffer(data) or []:
                if msg.get_type() == "PARAM_REQUEST_READ":
                    self.requests += 1
                    name = msg.param_id
                    if name in self.params:
                        self._send(
                            self.mav.param_value_encode(
                                name.encode(), self.params[name], 9, len(self.params), 0
                            )
                        )

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.sock.close()


class Receiver:
    """The link's one receiving thread, its handler keeping every PARAM_VALUE."""

    def __init__(self, link: Connection) -> None:
        self.link, self.values = link, {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _handle(self, msg) -> None:
        if msg.get_type() == "PARAM_VALUE":
            self.values[msg.param_id] = msg.param_value

    def _run(self) -> None:
        while not self._stop.is_set():
            self.link.pump(0.02, self._handle)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


@pytest.fixture
def wired():
    """(our link, the receiving thread, the autopilot), the link having heard it."""
    link = Connection(mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255))
    receiver = Receiver(link)
    autopilot = Autopilot(link.conn.port.getsockname()[1], {"GUID_OPTIONS": 8.0})
    deadline = time.monotonic() + 2.0
    while not link.conn.clients and time.monotonic() < deadline:
        time.sleep(0.005)
    yield link, receiver, autopilot
    receiver.close()
    autopilot.close()
    link.close()


def request(link: Connection, name: str):
    return lambda: link.send(link.mav.param_request_read_encode(1, 1, name.encode(), -1))


def test_the_answer_asked_for_is_the_one_returned_its_handler_already_run(wired):
    link, receiver, autopilot = wired
    msg = wait_for(
        link,
        ("PARAM_VALUE",),
        lambda m: m.param_id == "GUID_OPTIONS",
        2.0,
        CLOCK,
        ask=request(link, "GUID_OPTIONS"),
    )
    assert msg is not None and msg.param_value == 8.0
    assert receiver.values["GUID_OPTIONS"] == 8.0  # the owner's state before the waiter's
    assert autopilot.requests == 1  # asked once, not again


def test_no_answer_is_none_after_the_timeout_asked_again_meanwhile(wired):
    link, _, autopilot = wired
    idles = []
    start = time.monotonic()
    msg = wait_for(
        link,
        ("PARAM_VALUE",),
        lambda m: True,
        0.35,
        CLOCK,
        ask=request(link, "NO_SUCH"),
        ask_every_s=0.1,
        idle=lambda: idles.append(1),
    )
    assert msg is None and 0.35 <= time.monotonic() - start < 1.0
    time.sleep(0.05)
    assert 3 <= autopilot.requests <= 5 and len(idles) >= 10


def test_an_idle_that_raises_ends_the_wait(wired):
    link = wired[0]

    def stop() -> None:
        raise RuntimeError("a failsafe meanwhile")

    with pytest.raises(RuntimeError, match="failsafe meanwhile"):
        wait_for(link, ("PARAM_VALUE",), lambda m: True, 2.0, CLOCK, idle=stop)


def test_a_udpout_link_learns_of_a_closed_port_from_the_refusal_and_patches_nothing():
    gone = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gone.bind(("127.0.0.1", 0))
    port = gone.getsockname()[1]
    gone.close()
    refused = threading.Event()
    link = open_connection(f"udpout:127.0.0.1:{port}", "mavlink:test", on_refused=refused.set)
    try:
        assert not {"recv", "write", "recv_msg"} & set(vars(link.conn))  # pymavlink's own
        deadline = time.monotonic() + 2.0
        while not refused.is_set() and time.monotonic() < deadline:
            link.heartbeat()
            link.pump(0.02, lambda msg: None)
        assert refused.is_set()
    finally:
        link.close()
