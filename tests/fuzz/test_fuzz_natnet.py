"""NatNet gaps left by tests/mocap/test_natnet_property.py (which fuzzes frames through the
client's receive path): the start-up replies (server info, model definitions) a client decodes
before its receive loop, model definitions arriving mid-stream, and the server emulator's
command port fed garbage over a real UDP socket."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from mutate import mutated_bytes

from perchd.core.clock import ManualClock
from perchd.mocap.natnet import models as natdefs
from perchd.mocap.natnet import protocol as proto
from perchd.mocap.natnet.client import NatNetConfig, NatNetSource
from perchd.mocap.natnet.server import NatNetServer
from perchd.mocap.natnet.wire import MalformedPacket

V3 = Path(__file__).resolve().parents[1] / "fixtures" / "natnet" / "motive-2.1-natnet-3.0"
MODELDEFS = [
    (V3 / f).read_bytes()
    for f in (
        "modeldef_packet_v3.bin",
        "modeldef_packet_v3_2.bin",
        "modeldef_packet_skeleton_v3.bin",
        "modeldef_packet_v2.bin",
    )
]
SERVERINFO = [
    (V3 / f).read_bytes() for f in ("serverinfo_packet_v3.bin", "serverinfo_packet_v2.bin")
]
VERSIONS = [(2, 5), (2, 9), (2, 10), (3, 0), (3, 1), (4, 0), (4, 1)]
FAST = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])


def verdict(decode, payload):
    """'ok' or 'malformed'; any exception but MalformedPacket fails the test."""
    try:
        decode(payload)
    except MalformedPacket:
        return "malformed"
    return "ok"


@FAST
@given(st.one_of(mutated_bytes(SERVERINFO), st.binary(max_size=300)))
def test_a_mutated_server_info_decodes_or_is_malformed(packet):
    event(verdict(proto.decode_server_info, packet[4:]))


@FAST
@given(st.sampled_from(VERSIONS), st.one_of(mutated_bytes(MODELDEFS), st.binary(max_size=300)))
def test_mutated_model_definitions_decode_or_are_malformed(version, packet):
    event(verdict(lambda p: natdefs.decode_model_defs(p, version), packet[4:]))


@FAST
@given(st.lists(mutated_bytes(MODELDEFS), min_size=1, max_size=4))
def test_model_definitions_mid_stream_never_raise_and_are_counted(packets):
    source = NatNetSource(NatNetConfig("127.0.0.1", "RaceQuad"), ManualClock(10.0))
    source.info = type("Info", (), {"version": (3, 0)})()
    for packet in packets:
        source.handle_datagram(packet, 10.0)
    stats = source.stats()
    assert stats.received == len(packets) and stats.poses == 0


@pytest.fixture(scope="module")
def server():
    s = NatNetServer(["cf1"], (4, 1)).start()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.settimeout(2.0)
    yield s, client
    client.close()
    s.close()


requests = st.one_of(
    st.binary(max_size=80),
    st.tuples(
        st.sampled_from(sorted(proto.KNOWN_IDS)), st.binary(max_size=40), st.integers(0, 0xFFFF)
    ).map(lambda t: t[0].to_bytes(2, "little") + t[2].to_bytes(2, "little") + t[1]),
    st.text(max_size=30).map(lambda s: proto.string_request(s)),
)


@settings(
    deadline=None,
    max_examples=60,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(st.lists(requests, min_size=1, max_size=5))
def test_the_server_emulator_answers_a_connect_after_any_garbage(server, garbage):
    s, client = server
    for datagram in garbage:
        client.sendto(datagram, ("127.0.0.1", s.command_port))
    client.sendto(proto.connect_request(), ("127.0.0.1", s.command_port))
    infos = 1 + sum(map(asks_server_info, garbage))
    while infos:  # every reply arrives, in order; a dead command thread times this out
        message_id, payload = proto.unpack(client.recv(proto.MAX_PACKET + 1), strict=False)
        if message_id == proto.NAT_SERVERINFO:
            assert proto.decode_server_info(payload).version == (4, 1)
            infos -= 1


def asks_server_info(datagram: bytes) -> bool:
    try:
        return proto.unpack(datagram, strict=False)[0] in (proto.NAT_CONNECT, proto.NAT_DISCOVERY)
    except MalformedPacket:
        return False
