"""Real packets recorded from Motive decode to the values their sources assert."""

from __future__ import annotations

import struct

import pytest
from natnet_recordings import (
    V2X,
    V3,
    RecordedMotive,
    expected_rows,
    packet,
    payload,
    session_frames,
)

from perchd.core.runtime import Runtime
from perchd.mocap.frames import UpAxis
from perchd.mocap.natnet import models as natdefs
from perchd.mocap.natnet import protocol as proto
from perchd.mocap.natnet.client import NatNetConfig, NatNetSource
from perchd.mocap.natnet.frame import decode_frame, encode_frame


def test_every_frame_of_the_recorded_session_decodes_to_the_expected_csv():
    frames = session_frames()
    rows = expected_rows()
    assert len(frames) == len(rows) == 518
    for recorded, row in zip(frames, rows):
        assert int(row["pcap_index"]) == recorded.index
        message_id, body = proto.unpack(recorded.data)
        frame = decode_frame(body, (3, 0))
        rb = frame.rigid_bodies[0]
        assert (message_id, frame.number, rb.id) == (7, int(row["frame_number"]), int(row["rb_id"]))
        assert frame.timing.timestamp == float(row["timestamp"])
        assert rb.p == tuple(float(row[k]) for k in ("x", "y", "z"))
        assert rb.q == tuple(float(row[k]) for k in ("qx", "qy", "qz", "qw"))
        assert rb.mean_error == float(row["mean_error"])
        assert rb.tracking_valid == (row["tracking_valid"] == "1")
        assert len(frame.labeled_markers) == int(row["n_labelled_markers"])


def test_the_reference_frame_carries_motives_stamps_and_latency():
    frame = decode_frame(payload(V3 / "mocapframe_packet_v3.bin"), (3, 0))
    t = frame.timing
    assert (t.camera_mid_exposure, t.data_received, t.transmit) == (
        1416497730518,
        1416497745808,
        1416497748722,
    )
    clock_hz = proto.decode_server_info(payload(V3 / "serverinfo_packet_v3.bin")).clock_hz
    assert clock_hz == 3312787
    assert (t.transmit - t.camera_mid_exposure) / clock_hz == pytest.approx(5.50e-3, abs=0.005e-3)
    assert (t.transmit - t.data_received) / clock_hz == pytest.approx(0.88e-3, abs=0.005e-3)


def test_an_occluded_frame_still_has_its_body_with_fewer_markers():
    full = decode_frame(payload(V3 / "mocapframe_packet_v3.bin"), (3, 0))
    occluded = decode_frame(payload(V3 / "mocapframe_packet_occluded_v3.bin"), (3, 0))
    assert len(occluded.rigid_bodies) == 1
    assert len(occluded.labeled_markers) < len(full.labeled_markers)


def test_a_natnet_2_10_frame_has_an_untracked_body_and_a_21_bone_skeleton():
    frame = decode_frame(payload(V3 / "mocapframe_packet_v2.bin"), (2, 10))
    rb = frame.rigid_bodies[0]
    assert frame.number == 109238 and rb.id == 1 and not rb.tracking_valid
    assert rb.p == pytest.approx((1.38, 1.21, 1.62), abs=0.01)
    assert [len(s.bones) for s in frame.skeletons] == [21]
    assert len(frame.labeled_markers) == 44


@pytest.mark.parametrize(
    "motive, version, timestamped",
    [("1.5.0", (2, 5), False), ("1.7.2", (2, 7), True), ("1.9.0", (2, 9), True)],
)
def test_natnet_2_5_to_2_9_frames_decode_with_the_version_their_server_announces(
    motive, version, timestamped
):
    info = proto.decode_server_info(payload(V2X / f"frame-motive-{motive}-000.bin"))
    assert info.version == version
    numbers = []
    for i in (1, 2):
        frame = decode_frame(payload(V2X / f"frame-motive-{motive}-00{i}.bin"), info.version)
        assert len(frame.rigid_bodies) == 1 and len(frame.labeled_markers) == 3
        assert len(frame.rigid_bodies[0].markers) == 3
        assert "all" in [name for name, _ in frame.marker_sets]
        assert (frame.timing.timestamp > 0) == timestamped
        numbers.append(frame.number)
    assert numbers[1] == numbers[0] + 1


def test_server_info_and_model_definitions_decode():
    info = proto.decode_server_info(payload(V3 / "serverinfo_packet_v3.bin"))
    assert (info.app_name, info.app_version[:2], info.version) == ("Motive", (2, 1), (3, 0))
    assert (info.data_port, info.multicast, info.multicast_group) == (1511, True, "239.255.42.99")
    defs = natdefs.decode_model_defs(payload(V3 / "modeldef_packet_v3.bin"), (3, 0))
    assert [(b.name, b.id, b.parent_id, len(b.markers)) for b in defs.rigid_bodies] == [
        ("RaceQuad", 2, -1, 5)
    ]
    assert [name for name, _ in defs.marker_sets] == ["RaceQuad", "all"]
    cameras = natdefs.decode_model_defs(payload(V3 / "modeldef_packet_v3_2.bin"), (3, 0))
    assert cameras.body_ids() == {"crossbow": 54}
    assert sum(o.startswith("camera") for o in cameras.others) == 4
    skeleton = natdefs.decode_model_defs(payload(V3 / "modeldef_packet_skeleton_v3.bin"), (3, 0))
    assert [(n, i) for n, i, _ in skeleton.skeletons] == [("Skeleton 002", 3)]
    v2 = natdefs.decode_model_defs(payload(V3 / "modeldef_packet_v2.bin"), (2, 10))
    assert v2.body_ids() == {"RigidBody 1": 1}
    assert [(n, i) for n, i, _ in v2.skeletons] == [("Karlie", 4)]


def test_the_encoder_reproduces_motives_bytes():
    for name, decode, encode in [
        ("mocapframe_packet_v3.bin", decode_frame, encode_frame),
        ("modeldef_packet_v3.bin", natdefs.decode_model_defs, natdefs.encode_model_defs),
    ]:
        body = payload(V3 / name)
        assert encode(decode(body, (3, 0)), (3, 0)) == body


def test_client_requests_match_what_natnetlib_sends():
    connect = packet(V3 / "connect_packet_v3.bin")
    assert proto.connect_request((3, 0, 0, 0)) == connect
    assert proto.pack(proto.NAT_REQUEST_MODELDEF) == packet(V3 / "requestmodeldef_packet_v3.bin")
    request, response = (
        packet(V3 / "echorequest_packet_v3.bin"),
        packet(V3 / "echoresponse_packet_v3.bin"),
    )
    stamp = struct.unpack_from("<Q", request, 4)[0]
    assert proto.echo_request(stamp) == request
    assert proto.decode_echo_response(response[4:])[0] == stamp


def test_the_client_replays_the_whole_session_from_recorded_motive_over_udp():
    motive = RecordedMotive()
    source = NatNetSource(
        NatNetConfig(
            "127.0.0.1",
            "RaceQuad",
            command_port=motive.port,
            transport="unicast",
            local="127.0.0.1",
            up=UpAxis.Z,
            connect_timeout_s=0.3,
        ),
        Runtime.real().clock,
    )
    try:
        source.start()
        assert source.version == (3, 0) and not source.multicast
        poses = []
        for recorded in session_frames():
            motive.send(recorded.data)
            poses.append(source.wait(poses[-1].seq if poses else -1, 2.0))
    finally:
        source.close()
        motive.close()
    rows = expected_rows()
    assert [p.seq for p in poses] == [int(r["frame_number"]) for r in rows]
    assert all(p.body == "RaceQuad" and p.valid for p in poses)
    assert [p.p for p in poses] == [tuple(float(r[k]) for k in "xyz") for r in rows]
    first = decode_frame(session_frames()[0].data[4:], (3, 0)).timing
    assert poses[0].latency == pytest.approx((first.transmit - first.camera_mid_exposure) / 3312787)
    assert source.stats().dropped == 0
