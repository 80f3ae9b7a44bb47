"""NatNet 4.1 (no public capture exists): packets built here from the protocol description,
and round trips through the emulator over real sockets."""

from __future__ import annotations

import struct

import pytest

from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.core.uri import parse_uri
from perchd.mocap.natnet import protocol as proto
from perchd.mocap.natnet.frame import (
    AnalogDevice,
    Asset,
    Frame,
    LabeledMarker,
    RigidBodySample,
    Skeleton,
    Timing,
    decode_frame,
    encode_frame,
)
from perchd.mocap.natnet.uris import NatNetServer, open_natnet
from perchd.mocap.natnet.wire import MalformedPacket


def section(count: int, body: bytes) -> bytes:
    """4.1: each frame section is its count, then its size in bytes, then its items."""
    return struct.pack("<ii", count, len(body)) + body


def body_41(body_id, p, q, error, valid) -> bytes:
    return struct.pack("<i3f4ffh", body_id, *p, *q, error, 1 if valid else 0)


def hand_built_41_frame() -> bytes:
    markers = section(1, b"cf1\0" + struct.pack("<i3f", 1, 0.1, 0.2, 0.3))
    others = section(1, struct.pack("<3f", 9.0, 8.0, 7.0))
    bodies = section(
        2,
        body_41(1, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0), 0.0005, True)
        + body_41(7, (4.0, 5.0, 6.0), (0.5, 0.5, 0.5, 0.5), 0.001, False),
    )
    skeletons = section(1, struct.pack("<ii", 3, 1) + body_41(30, (0, 1, 0), (0, 0, 0, 1), 0, True))
    asset_marker = struct.pack("<i3ffhf", 65537, 1.0, 1.0, 1.0, 0.014, 4, 0.0002)
    assets = section(
        1,
        struct.pack("<ii", 5, 1)
        + body_41(50, (2, 2, 2), (0, 0, 0, 1), 0.0, True)
        + struct.pack("<i", 1)
        + asset_marker,
    )
    labelled = section(2, struct.pack("<i3ffhf", 65537, 0.1, 0.2, 0.3, 0.014, 0, 0.0001) * 2)
    plates = section(1, struct.pack("<iii3f", 1, 1, 3, 0.5, 0.6, 0.7))
    devices = section(0, b"")
    suffix = struct.pack("<IIdQQQIIhi", 0x01020304, 0, 12.5, 1000, 1200, 1300, 1700000000, 42, 2, 0)
    return (
        struct.pack("<i", 777)
        + markers
        + others
        + bodies
        + skeletons
        + assets
        + labelled
        + plates
        + devices
        + suffix
    )


def test_a_41_frame_built_from_the_protocol_description_decodes():
    frame = decode_frame(hand_built_41_frame(), (4, 1))
    assert frame.number == 777
    assert [(b.id, b.p, b.tracking_valid) for b in frame.rigid_bodies] == [
        (1, (1.0, 2.0, 3.0), True),
        (7, (4.0, 5.0, 6.0), False),
    ]
    assert frame.marker_sets[0][0] == "cf1" and frame.other_markers == ((9.0, 8.0, 7.0),)
    assert frame.skeletons[0].id == 3 and frame.skeletons[0].bones[0].id == 30
    assert frame.assets[0].id == 5 and frame.assets[0].bodies[0].id == 50
    assert frame.assets[0].markers[0].params == 4
    assert len(frame.labeled_markers) == 2
    assert frame.force_plates[0].channels == ((0.5, pytest.approx(0.6), pytest.approx(0.7)),)
    t = frame.timing
    assert (t.timestamp, t.camera_mid_exposure, t.data_received, t.transmit) == (
        12.5,
        1000,
        1200,
        1300,
    )
    assert (t.precision_s, t.precision_frac, frame.params) == (1700000000, 42, 2)


def test_the_emulators_41_encoding_is_the_hand_built_one():
    frame = decode_frame(hand_built_41_frame(), (4, 1))
    assert encode_frame(frame, (4, 1)) == hand_built_41_frame()


@pytest.mark.parametrize("cut", [5, 40, 100])
def test_a_41_section_whose_byte_count_lies_is_malformed(cut):
    data = bytearray(hand_built_41_frame())
    rigid_size_at = data.index(struct.pack("<i", 2) + struct.pack("<i", 2 * 38)) + 4
    struct.pack_into("<i", data, rigid_size_at, 2 * 38 - cut)
    with pytest.raises(MalformedPacket):
        decode_frame(bytes(data), (4, 1))


def rich_frame() -> Frame:
    body = RigidBodySample(1, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0), 0.25, True)
    marker = LabeledMarker(65537, (0.5, 0.25, 0.125), 0.015625, 4, 0.5)
    return Frame(
        9,
        (body, RigidBodySample(2, (0.5, 0.5, 0.5), (0.5, 0.5, 0.5, 0.5), 0.0, False)),
        Timing(3.5, 100, 150, 200, None, 7, 1, 1234, 5678),
        marker_sets=(("cf1", ((0.5, 0.5, 0.5),)), ("all", ())),
        other_markers=((1.0, 1.0, 1.0),),
        skeletons=(Skeleton(4, (body,)),),
        assets=(Asset(6, (body,), (marker,)),),
        labeled_markers=(marker, marker),
        force_plates=(AnalogDevice(1, ((1.0, 2.0), (3.0,))),),
        devices=(AnalogDevice(2, ((4.0,),)),),
        params=1,
    )


def test_every_section_survives_an_emulator_round_trip_over_udp():
    frame = rich_frame()
    with NatNetServer({"cf1": 1}, (4, 1)) as server:
        source = open_natnet(parse_uri(server.uri + "&body=cf1&up=z"), Runtime.real())
        received = []
        source.handle_datagram = lambda datagram, arrival: received.append(datagram)
        source.start()
        try:
            server.send_raw(proto.pack(proto.NAT_FRAMEOFDATA, encode_frame(frame, (4, 1))))
            _wait_for(lambda: received)
        finally:
            source.close()
    message_id, body = proto.unpack(received[0])
    assert message_id == proto.NAT_FRAMEOFDATA and decode_frame(body, (4, 1)) == frame


def test_a_41_client_gets_poses_and_model_definitions_from_the_emulator():
    runtime = Runtime.real()
    with NatNetServer({"cf1": 1, "wand": 2}, (4, 1)) as server:
        source = open_natnet(parse_uri(server.uri + "&body=wand"), runtime)
        source.start()
        try:
            assert source.info.version == (4, 1) and source.models.body_ids() == {
                "cf1": 1,
                "wand": 2,
            }
            server.publish(
                Pose("wand", 0, runtime.clock.now(), (0.1, 0.2, 0.3), (0.0, 0.0, 0.0, 1.0))
            )
            pose = source.wait(-1, 2.0)
        finally:
            source.close()
    assert pose.body == "wand" and pose.p == pytest.approx((0.1, 0.2, 0.3))


def _wait_for(condition, timeout: float = 2.0) -> None:
    import time

    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.005)
