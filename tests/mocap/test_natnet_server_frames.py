"""What the NatNet emulator's frames carry from the first one on: every pose published before
start() is in every frame, the very first included; and a unicast client gets its server info
(the NatNet version to read frames with) before any frame."""

from __future__ import annotations

import random
import socket
import time

import pytest

from perchd.core.types import Pose
from perchd.mocap.natnet import protocol as proto
from perchd.mocap.natnet.frame import decode_frame
from perchd.mocap.natnet.uris import NatNetServer

BODIES = {"cf1": 1, "cf2": 2, "wand": 3}
LEVEL = (0.0, 0.0, 0.0, 1.0)


def published(server: NatNetServer, names: list[str]) -> set[int]:
    for i, name in enumerate(names):
        server.publish(Pose(name, 0, 1.0, (0.5 + i, 1.0, 1.5), LEVEL))
    return {BODIES[name] for name in names}


def listener(server: NatNetServer) -> socket.socket:
    """A socket on the server's data port holding its group on loopback."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(
        socket.IPPROTO_IP,
        socket.IP_ADD_MEMBERSHIP,
        socket.inet_aton(server.group) + socket.inet_aton("127.0.0.1"),
    )
    sock.bind(("0.0.0.0", server.data_port))
    sock.settimeout(2.0)
    return sock


def frame_of(datagram: bytes, version) -> tuple[int, set[int]]:
    message_id, payload = proto.unpack(datagram)
    assert message_id == proto.NAT_FRAMEOFDATA
    frame = decode_frame(payload, version)
    return frame.number, {body.id for body in frame.rigid_bodies}


@pytest.mark.parametrize("version", [(3, 0), (4, 1)], ids=["3.0", "4.1"])
def test_poses_published_before_start_are_in_the_very_first_frame_and_every_one_after(version):
    rng = random.Random(7)
    for _ in range(50):
        names = rng.sample(sorted(BODIES), rng.randint(1, len(BODIES)))
        server = NatNetServer(BODIES, version, multicast=True, rate_hz=500.0)
        sock = listener(server)
        try:
            ids = published(server, names)
            server.start()
            frames = [frame_of(sock.recv(proto.MAX_PACKET), version) for _ in range(3)]
        finally:
            server.close()
            sock.close()
        assert frames[0][0] == 1, frames  # the very first frame the server sent
        assert all(bodies == ids for _, bodies in frames), (names, frames)


@pytest.mark.parametrize("version", [(3, 0), (4, 1)], ids=["3.0", "4.1"])
def test_a_unicast_client_gets_its_server_info_before_any_frame(version, monkeypatch):
    # The server info takes longer to build than several frame periods, so a frame sent
    # to the client as soon as it is known would overtake it.
    encode = proto.encode_server_info

    def slow_encode(info):
        time.sleep(0.1)
        return encode(info)

    monkeypatch.setattr(proto, "encode_server_info", slow_encode)
    server = NatNetServer(BODIES, version, rate_hz=200.0)
    ids = published(server, ["cf1", "wand"])
    server.start()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.settimeout(2.0)
    try:
        client.sendto(proto.pack(proto.NAT_CONNECT), ("127.0.0.1", server.command_port))
        first = client.recv(proto.MAX_PACKET)
        later = [client.recv(proto.MAX_PACKET) for _ in range(3)]
    finally:
        server.close()
        client.close()
    message_id, payload = proto.unpack(first)
    assert message_id == proto.NAT_SERVERINFO, message_id
    assert proto.decode_server_info(payload).natnet_version[:2] == version
    assert all(bodies == ids for _, bodies in (frame_of(d, version) for d in later))
