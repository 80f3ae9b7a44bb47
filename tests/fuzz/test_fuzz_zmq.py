"""ZMQ pose and setpoint messages (docs/contracts.md §3) under fuzzing. tests/mocap already feeds the
pose source arbitrary frames; here real messages are mutated field by field and byte by byte:
a message is either taken as sent (quaternion normalised) or counted and dropped, and the simulator's setpoint
inbox keeps obeying good setpoints over a real socket whatever arrives before them."""

from __future__ import annotations

import argparse
import json
import math
import time

import pytest
import zmq
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st
from mutate import json_values, mutated_bytes, mutated_document

from perchd.commands.sim import Counts, SetpointInbox, make_world
from perchd.core.clock import ManualClock
from perchd.core.types import Phase, Pose, Setpoint
from perchd.drivers.zmq import BadSetpoint, parse_setpoint_message, sender_of, setpoint_message
from perchd.mocap.zmq import ZmqPoseSource, pose_message
from perchd.sim.onesender import SenderGate

POSE = Pose("cf1", 17, 4.9, (-3.0, 0.1, 1.0), (0.0, 0.0, 0.0, 1.0), True, 0.0)
POSE_DOC = json.loads(pose_message(POSE))
SETPOINT = Setpoint(12.35, 0.01, -0.2, 0.0, 0.31, 17, Phase.STAGE1)
SP_DOC = setpoint_message("cf1", 9, SETPOINT)
FAST = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])


@FAST
@example(
    [
        b'{"body": "cf1", "seq": 17, "t": 4.9, "p": [-3.0, 0.1, 1.0], "q": [0.0, 0.0, 0.0, 1.000000001]}',
        b'{"body": "cf1", "seq": 18, "t": 4.9, "p": [NaN, 0.1, 1.0], "q": [0.0, 0.0, 0.0, 1.0], "valid": false}',
    ]
)
@given(
    st.lists(
        st.one_of(
            mutated_document(POSE_DOC).map(lambda d: json.dumps(d).encode()),
            mutated_bytes([json.dumps(POSE_DOC).encode()]),
        ),
        min_size=1,
        max_size=6,
    )
)
def test_a_mutated_pose_is_taken_as_sent_or_counted_and_dropped(bodies):
    source = ZmqPoseSource("tcp://127.0.0.1:1", "cf1", ManualClock(5.0))
    for body in bodies:
        before = source.stats().poses
        source.handle_message([b"pose", body], 5.0)
        if source.stats().poses > before:
            sent, got = json.loads(body), source.latest()
            assert (got.seq, got.t, got.valid) == (sent["seq"], sent["t"], sent.get("valid", True))
            assert all(math.isfinite(v) for v in (*got.p, *got.q, got.t))
            if got.valid:  # as sent, the quaternion normalised
                norm = math.sqrt(sum(v * v for v in sent["q"]))
                assert got.p == tuple(sent["p"]) and got.q == pytest.approx(
                    [v / norm for v in sent["q"]]
                )
            else:  # as sent, or a placeholder when what was sent is not finite
                assert (got.p, got.q) in (
                    (tuple(sent["p"]), tuple(sent["q"])),
                    ((0.0,) * 3, (0.0, 0.0, 0.0, 1.0)),
                )
            event("taken")
        else:
            event("dropped")
    stats = source.stats()
    assert stats.received == len(bodies) and stats.poses + stats.dropped == stats.received


@FAST
@given(
    st.one_of(
        mutated_document(SP_DOC).map(lambda d: json.dumps(d).encode()),
        mutated_bytes([json.dumps(SP_DOC).encode()]),
        json_values.map(lambda v: json.dumps(v).encode()),
        st.binary(max_size=200),
    )
)
def test_a_mutated_setpoint_parses_to_finite_values_or_is_one_bad_setpoint(body):
    try:
        vehicle, seq, sp = parse_setpoint_message(body)
    except BadSetpoint as err:
        assert str(err).startswith("setpoint")
        event("refused")
        return
    assert isinstance(vehicle, str) and isinstance(seq, int) and isinstance(sp.phase, Phase)
    assert all(math.isfinite(v) for v in (sp.t, sp.roll, sp.pitch, sp.yaw, sp.thrust))
    assert parse_setpoint_message(json.dumps(setpoint_message(vehicle, seq, sp)).encode())[2] == sp
    event("parsed")


@pytest.fixture(scope="module")
def inbox():
    args = argparse.Namespace(
        latency=0.0,
        noise=0.0,
        start=None,
        surface=(0.0, 0.0, 0.0),
        normal=(1.0, 0.0, 0.0),
        body="cf1",
    )
    counts = Counts()
    # the unnamed sender holds the vehicle throughout: a fuzzed sender id is refused
    box = SetpointInbox(
        "zmq://127.0.0.1:0", make_world(args), "cf1", counts, gate=SenderGate(live_s=math.inf)
    )
    pub = zmq.Context.instance().socket(zmq.PUB)
    pub.setsockopt(zmq.LINGER, 0)
    pub.connect("tcp://" + box.uri.split("//")[1].split("?")[0])
    good = [b"setpoint", json.dumps(SP_DOC).encode()]
    deadline = time.monotonic() + 5
    while counts.setpoints == 0:  # until the subscription has reached the publisher
        assert time.monotonic() < deadline
        pub.send_multipart(good)
        time.sleep(0.02)
    yield pub, counts, good
    pub.close(0)
    box.close()


frames = st.one_of(
    st.lists(st.binary(max_size=40), min_size=1, max_size=4).map(
        lambda f: [b"setpoint", *f[1:]] if len(f) > 2 else f
    ),
    mutated_document(SP_DOC).map(lambda d: [b"setpoint", json.dumps(d).encode()]),
    st.just([b"setpoint", b"[" * 100_000]),
    st.just([b"setpoint"]),
    st.just([b"setpoint", b"{}", b"{}"]),
)


@settings(
    deadline=None,
    max_examples=40,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(st.lists(frames, min_size=1, max_size=5))
def test_the_sim_inbox_obeys_the_next_good_setpoint_whatever_came_before(inbox, batch):
    pub, counts, good = inbox
    before = counts.setpoints
    for message in batch:
        pub.send_multipart(message)
    pub.send_multipart(good)
    want = before + 1 + sum(map(obeyed, batch))
    deadline = time.monotonic() + 3
    while counts.setpoints < want:
        assert time.monotonic() < deadline, "the inbox stopped taking setpoints"
        time.sleep(0.002)
    assert counts.setpoints == want


def obeyed(message: list[bytes]) -> bool:
    """Whether the inbox should take this message as a setpoint for cf1."""
    if len(message) != 2 or message[0] != b"setpoint":
        return False
    try:
        return parse_setpoint_message(message[1])[0] in ("", "cf1") and sender_of(message[1]) == ""
    except BadSetpoint:
        return False
