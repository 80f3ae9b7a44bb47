"""OptiTrack's own Python NatNet client (NatNet SDK 4.1, on PyPI as `natnetsdk`) talks to the
emulator: server info, model definitions, frames and keep-alives, in unicast and multicast on
loopback.

In multicast its data socket binds the client address and the data port it is told (not the
one the server announces). On Linux a socket bound to an interface address receives no
multicast, so the client address is 0.0.0.0, and its group membership then goes to the
interface of the route to the group: not loopback here, so the test joins the group on
loopback itself, as a route for 239.0.0.0/8 via lo would. Its NatNet 4.0 reader expects the
4.1 precision timestamp; OptiTrack's C++ PacketClient and the 4.1 notes put that in 4.1+, as
the emulator does, so 4.0 is not tried with it here.

The client reads a frame with the NatNet version the server info told it, and as version 0.0
before that: a 4.1 frame read so has no rigid body. The emulator sends a unicast client its
server info before any frame; a multicast client hears the group from its start, so the test
joins the group on loopback only once the client has the version.
"""

from __future__ import annotations

import socket
import time

import pytest

from perchd.core.clock import MonotonicClock
from perchd.core.types import Pose
from perchd.mocap.natnet.uris import NatNetServer

natnetsdk = pytest.importorskip("natnetsdk.NatNetClient")


pytestmark = pytest.mark.solo  # real-time bounds: see tests/conftest.py


def stop(client) -> None:
    """Its receive threads block in recvfrom; wake them before its shutdown joins them."""
    client.stop_threads = True
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as waker:
        for sock in (client.data_socket, client.command_socket):
            waker.sendto(b"\0\0\0\0", ("127.0.0.1", sock.getsockname()[1]))
    client.shutdown()


@pytest.mark.parametrize("multicast", [False, True], ids=["unicast", "multicast"])
@pytest.mark.parametrize("version", [(3, 0), (4, 1)], ids=["3.0", "4.1"])
def test_optitracks_client_reads_the_emulator(version, multicast, capsys):
    clock = MonotonicClock()
    server = NatNetServer({"cf1": 1, "wand": 2}, version, rate_hz=100.0, multicast=multicast)
    # the pose first: no frame may come bodiless
    server.publish(Pose("cf1", 0, clock.now(), (0.5, 1.0, 1.5), (0.0, 0.0, 0.0, 1.0)))
    server.start()
    bodies, frames, printed = [], [], []
    client = natnetsdk.NatNetClient()
    client.set_client_address("0.0.0.0" if multicast else "127.0.0.1")
    client.set_server_address("127.0.0.1")
    client.set_use_multicast(multicast)
    client.command_port, client.data_port = server.command_port, server.data_port
    loopback_member = None
    client.set_print_level(10**9)  # quiet frames, but print the model definitions
    client.rigid_body_listener = lambda body_id, p, q: bodies.append((body_id, p, q))
    client.new_frame_listener = frames.append
    try:
        assert client.run()
        if multicast:
            _until(lambda: (client.get_major(), client.get_minor()) == version)
            loopback_member = joined_on_loopback(server.group)
        _until(lambda: len(frames) >= 5)
        client.send_request(
            client.command_socket,
            client.NAT_REQUEST_MODELDEF,
            "",
            ("127.0.0.1", server.command_port),
        )
        _until(lambda: printed.append(capsys.readouterr().out) or "cf1" in "".join(printed))
    finally:
        stop(client)
        server.close()
        if loopback_member is not None:
            loopback_member.close()
    assert client.connected() and client.get_application_name() == "Motive"
    assert client.get_nat_net_version_server()[:2] == list(version)
    assert bodies[-1] == (1, pytest.approx((0.5, 1.5, -1.0)), (0.0, 0.0, 0.0, 1.0))  # Y up
    numbers = [f["frame_number"] for f in frames]
    # Multicast on loopback may hand the client one datagram twice; frames never go back.
    heard = [n for i, n in enumerate(numbers) if i == 0 or n != numbers[i - 1]]
    counts = [f["rigid_body_count"] for f in frames]
    assert heard == sorted(set(numbers)) and set(counts) == {1}, counts  # every frame: cf1
    assert "wand" in "".join(printed)
    assert (server.keepalives > 0) is not multicast  # keep-alives are a unicast client's


def joined_on_loopback(group: str) -> socket.socket:
    """A socket holding `group` on loopback: Linux then hands the group's datagrams that
    arrive there to every socket bound to their port on 0.0.0.0 (IP_MULTICAST_ALL)."""
    member = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    member.setsockopt(
        socket.IPPROTO_IP,
        socket.IP_ADD_MEMBERSHIP,
        socket.inet_aton(group) + socket.inet_aton("127.0.0.1"),
    )
    return member


def _until(condition, timeout: float = 3.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)
