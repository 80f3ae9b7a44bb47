"""The NatNet client against the emulator over loopback: unicast and multicast, every
version, latency, keep-alive, and bad packets counted and dropped while good ones flow."""

from __future__ import annotations

import logging
import math
import struct
import time
from dataclasses import replace

import pytest

from perchd.core.clock import ManualClock
from perchd.core.errors import LinkError, UriError
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.core.uri import parse_uri
from perchd.mocap.natnet import protocol as proto
from perchd.mocap.natnet.frame import Frame, RigidBodySample, Timing, encode_frame
from perchd.mocap.natnet.uris import (
    NatNetServer,
    NatNetSource,
    config_from_uri,
    open_natnet,
)

LEVEL = (0.0, 0.0, 0.0, 1.0)
YAW_90 = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))  # world frame, about Z


def serve(version=(4, 1), multicast=False, clock=None, **kw) -> NatNetServer:
    return NatNetServer(
        {"cf1": 1, "wand": 2}, version, multicast=multicast, clock=clock, **kw
    ).start()


def connect(server: NatNetServer, runtime: Runtime, extra: str = ""):
    source = open_natnet(parse_uri(server.uri + "&body=cf1&timeout=1" + extra), runtime)
    source.start()
    return source


def collect(server, source, poses_in, timeout=2.0):
    out = []
    for pose in poses_in:
        server.publish(pose)
        out.append(source.wait(out[-1].seq if out else -1, timeout))
    return out


@pytest.mark.parametrize("multicast", [False, True], ids=["unicast", "multicast"])
@pytest.mark.parametrize(
    "version", [(2, 9), (3, 0), (4, 0), (4, 1)], ids=lambda v: f"{v[0]}.{v[1]}"
)
def test_world_poses_go_through_motive_y_up_and_come_back(version, multicast):
    runtime = Runtime.real()
    server = serve(version, multicast)
    source = connect(server, runtime)
    try:
        assert source.version == version and source.multicast == multicast
        sent = [
            Pose("cf1", 0, runtime.clock.now(), (0.5 + i, -1.25, 2.0), YAW_90) for i in range(3)
        ]
        got = collect(server, source, sent)
    finally:
        source.close()
        server.close()
    assert [p.p for p in got] == [pytest.approx(s.p) for s in sent]
    assert all(p.q == pytest.approx(YAW_90) and p.valid and p.body == "cf1" for p in got)
    assert [p.seq for p in got] == sorted({p.seq for p in got})
    assert source.stats().dropped == 0


def test_latency_is_exposure_to_arrival_on_a_shared_simulated_clock():
    clock = ManualClock(50.0)
    server = serve((3, 0), clock=clock)
    source = connect(server, Runtime(clock))
    try:
        assert source.clock_sync.synced
        pose = collect(server, source, [Pose("cf1", 0, 50.0 - 0.004, (1.0, 0.0, 0.0), LEVEL)])[0]
    finally:
        source.close()
        server.close()
    assert pose.latency == pytest.approx(0.004, abs=1e-6)
    assert pose.t == pytest.approx(50.0 - 0.004, abs=1e-6)


def test_latency_on_the_real_clock_adds_the_transit_to_the_servers_delay():
    runtime = Runtime.real()
    server = serve((4, 1))
    source = connect(server, runtime)
    try:
        pose = collect(
            server, source, [Pose("cf1", 0, runtime.clock.now() - 0.004, (1.0, 0.0, 0.0), LEVEL)]
        )[0]
    finally:
        source.close()
        server.close()
    assert 0.004 <= pose.latency < 0.25  # transit on a busy machine stays far below this
    assert source.clock_sync.round_trip_s < 0.25


def test_a_unicast_client_keeps_its_place_with_keepalives():
    server = serve((4, 1))
    config = replace(config_from_uri(parse_uri(server.uri + "&body=cf1")), keepalive_s=0.02)
    source = NatNetSource(config, Runtime.real().clock)
    source.start()
    try:
        deadline = time.monotonic() + 3.0
        while server.keepalives < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert server.keepalives >= 3 and len(server.clients) == 1
    finally:
        source.close()
        server.close()


def test_a_body_can_be_named_by_its_id_and_then_carries_its_name():
    runtime = Runtime.real()
    server = serve((3, 0))
    source = open_natnet(parse_uri(server.uri + "&body=2"), runtime)
    source.start()
    try:
        pose = collect(
            server, source, [Pose("wand", 0, runtime.clock.now(), (0.0, 1.0, 2.0), LEVEL)]
        )[0]
    finally:
        source.close()
        server.close()
    assert pose.body == "wand" and pose.p == pytest.approx((0.0, 1.0, 2.0))


def test_an_unknown_body_is_refused_naming_the_servers_bodies():
    server = serve((3, 0))
    try:
        with pytest.raises(UriError, match=r"'cf9'.*cf1 \(1\), wand \(2\)"):
            open_natnet(parse_uri(server.uri + "&body=cf9"), Runtime.real()).start()
    finally:
        server.close()


def test_no_server_is_a_link_error_within_the_timeout():
    start = time.monotonic()
    with pytest.raises(LinkError, match="no NatNet server answered at 127.0.0.1:9 within 0.2 s"):
        open_natnet(
            parse_uri("natnet://127.0.0.1:9?body=cf1&local=127.0.0.1&timeout=0.2"), Runtime.real()
        ).start()
    assert time.monotonic() - start < 1.0


@pytest.mark.parametrize(
    "query, message",
    [
        ("", "body=NAME"),
        ("body=cf1&up=x", "up='x'"),
        ("body=cf1&transport=tcp", "transport='tcp'"),
        ("body=cf1&multicast=10.0.0.1", "not a multicast address"),
        ("body=cf1&local=nowhere", "local='nowhere'"),
        ("body=cf1&data_port=70000", "data_port=70000 is outside"),
        ("body=cf1&data_port=1511.5", "not a whole port"),
        ("body=cf1&timeout=abc", "timeout='abc' is not a number"),
        ("body=cf1&bodyy=cf1", "unknown parameter 'bodyy'"),
    ],
)
def test_bad_natnet_uris_get_one_clear_line(query, message):
    with pytest.raises(UriError, match=message):
        config_from_uri(parse_uri(f"natnet://10.0.0.5?{query}"))


def test_a_multicast_group_in_the_uri_selects_multicast():
    config = config_from_uri(parse_uri("natnet://10.0.0.5:1510?body=cf1&multicast=239.255.42.99"))
    assert (config.transport, config.multicast_group, config.command_port) == (
        "multicast",
        "239.255.42.99",
        1510,
    )


def frame_of(server: NatNetServer, number: int, p=(1.0, 2.0, 3.0), body_id: int = 1) -> bytes:
    """A frame measured and sent now, on the server's clock."""
    now = server.ticks(time.monotonic())
    sample = RigidBodySample(body_id, p, LEVEL, 0.0, True)
    frame = Frame(number, (sample,), Timing(1.0, now, now, now))
    return proto.pack(proto.NAT_FRAMEOFDATA, encode_frame(frame, (4, 1)))


@pytest.mark.parametrize("multicast", [False, True], ids=["unicast", "multicast"])
def test_bad_packets_are_counted_and_dropped_while_good_ones_flow(multicast, caplog):
    server = serve((4, 1), multicast)
    source = connect(server, Runtime.real(), "&up=z")
    good = frame_of(server, 100)
    bad = {
        "garbage": [b"\xff" * 3, b"hello world, not natnet", proto.pack(77, b"??")],
        "truncated": [good[:-9], good[:40]],
        "oversized": [good + b"\0\0\0\0"],
        "out_of_order": [frame_of(server, 99)],
        "bad_value": [
            frame_of(server, 101, (math.nan, 0.0, 0.0)),
            frame_of(server, 102, (1e9, 0.0, 0.0)),
        ],
        "no_body": [frame_of(server, 103, body_id=5)],
    }
    try:
        with caplog.at_level(logging.WARNING, logger="perchd.mocap.natnet"):
            server.send_raw(good)
            assert source.wait(-1, 2.0).seq == 100
            for datagrams in bad.values():
                for datagram in datagrams:
                    server.send_raw(datagram)
            server.send_raw(frame_of(server, 104, (4.0, 5.0, 6.0)))
            pose = source.wait(100, 2.0)
        drops = source.drops()
    finally:
        source.close()
        server.close()
    assert pose.seq == 104 and pose.p == (4.0, 5.0, 6.0)
    assert {k: getattr(drops, k) for k in bad} == {k: len(v) for k, v in bad.items()}
    assert source.stats().poses == 2
    warnings = [r for r in caplog.records if "dropped a packet" in r.getMessage()]
    assert len(warnings) == 1  # rate-limited: one line for the burst


def test_the_emulator_streams_at_its_rate_with_the_newest_pose():
    runtime = Runtime.real()
    server = serve((4, 1), rate_hz=200.0)
    source = connect(server, runtime)
    try:
        server.publish(Pose("cf1", 0, runtime.clock.now(), (1.0, 1.0, 1.0), LEVEL))
        first = source.wait(-1, 2.0)
        time.sleep(0.2)
        later = source.latest()
    finally:
        source.close()
        server.close()
    assert later.seq - first.seq >= 5 and later.p == first.p
    assert later.latency > first.latency  # the same measurement, older on each frame


def test_the_emulator_answers_motives_string_requests():
    server = serve((4, 1), rate_hz=120.0)
    import socket

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(1.0)
    try:
        replies = {}
        for command in ("FrameRate", "UnitsToMillimeters", "Bitstream", "CurrentMode", "Nonsense"):
            sock.sendto(proto.string_request(command), ("127.0.0.1", server.command_port))
            replies[command] = proto.unpack(sock.recv(70000))
    finally:
        sock.close()
        server.close()
    assert struct.unpack("<f", replies["FrameRate"][1]) == (120.0,)
    assert struct.unpack("<f", replies["UnitsToMillimeters"][1]) == (1000.0,)
    assert replies["Bitstream"][1] == b"Bitstream,4.1\0"
    assert replies["CurrentMode"] == (proto.NAT_RESPONSE, b"\0\0\0\0")
    assert replies["Nonsense"][0] == proto.NAT_UNRECOGNIZED_REQUEST


def test_the_client_follows_its_body_when_motive_redefines_the_models():
    runtime = Runtime.real()
    server = serve((4, 1))
    source = connect(server, runtime)
    try:
        first = collect(
            server, source, [Pose("cf1", 0, runtime.clock.now(), (1.0, 0.0, 0.0), LEVEL)]
        )[0]
        server.redefine({"wand": 1, "cf1": 7})
        deadline, pose = time.monotonic() + 3.0, None
        while pose is None and time.monotonic() < deadline:
            server.publish(Pose("cf1", 0, runtime.clock.now(), (2.0, 0.0, 0.0), LEVEL))
            pose = source.wait(first.seq, 0.05)
    finally:
        source.close()
        server.close()
    assert pose is not None and pose.p == pytest.approx((2.0, 0.0, 0.0))
    assert source.models.body_ids() == {"wand": 1, "cf1": 7}
    assert source.stats().dropped == source.drops().no_body  # frames held while ids moved


def test_a_server_answering_garbage_is_a_link_error_not_a_traceback():
    import socket
    import threading

    fake = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    fake.bind(("127.0.0.1", 0))

    def answer():
        _, address = fake.recvfrom(2048)
        fake.sendto(proto.pack(proto.NAT_SERVERINFO, b"Motive\0"), address)  # cut short

    thread = threading.Thread(target=answer)
    thread.start()
    try:
        with pytest.raises(LinkError, match="natnet 127.0.0.1: .*bytes"):
            open_natnet(
                parse_uri(
                    f"natnet://127.0.0.1:{fake.getsockname()[1]}?body=cf1&local=127.0.0.1&timeout=1"
                ),
                Runtime.real(),
            ).start()
    finally:
        thread.join()
        fake.close()
