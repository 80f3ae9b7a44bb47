"""The ZMQ pose source and publisher (docs/contracts.md §3) over real pyzmq sockets on loopback."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from perchd.core.clock import ManualClock
from perchd.core.errors import UriError
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.mocap.base import open_source
from perchd.mocap.zmq import (
    ZmqPosePublisher,
    ZmqPoseSource,
    parse_pose_message,
    pose_message,
)

LEVEL = (0.0, 0.0, 0.0, 1.0)


@pytest.fixture
def link():
    """A publisher and a started source following cf1, subscribed before anything is sent."""
    runtime = Runtime.real()
    publisher = ZmqPosePublisher("tcp://127.0.0.1:0")
    source = open_source(publisher.uri("cf1"), runtime)
    source.start()
    assert publisher.wait_for_subscriber(2.0)
    yield publisher, source, runtime
    source.close()
    publisher.close()


def test_poses_arrive_as_sent_with_their_latency(link):
    publisher, source, runtime = link
    sent = Pose(
        "cf1", 17, runtime.clock.now() - 0.010, (1.0, -2.0, 0.5), (0.0, 0.0, 0.6, 0.8), False
    )
    publisher.publish(sent)
    got = source.wait(-1, 2.0)
    assert (got.body, got.seq, got.p, got.q, got.valid) == ("cf1", 17, sent.p, sent.q, False)
    assert 0.010 <= got.latency < 0.25 and got.t == pytest.approx(sent.t, abs=1e-9)


def test_the_message_is_the_contract_json():
    pose = Pose("cf1", 17, 12.345, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0), True, 0.004)
    assert json.loads(pose_message(pose)) == {
        "body": "cf1",
        "seq": 17,
        "t": 12.345,
        "p": [1.0, 2.0, 3.0],
        "q": [0.0, 0.0, 0.0, 1.0],
        "valid": True,
    }
    assert parse_pose_message(pose_message(pose)) == ("cf1", 17, 12.345, pose.p, pose.q, True)


def test_bad_messages_are_counted_and_dropped_while_good_ones_flow(link):
    publisher, source, runtime = link
    now = runtime.clock.now()

    def good(seq, p=(1.0, 2.0, 3.0), **changes) -> bytes:
        fields = {"body": "cf1", "seq": seq, "t": now, "p": list(p), "q": [0, 0, 0, 1]}
        return json.dumps({**fields, **changes}).encode()

    bad = {
        "garbage": [
            [b"pose", b"{not json"],
            [b"pose", b"[1, 2]"],
            [b"pose", good(5)[:-1]],
            [b"pose", good(5, q=[0, 0, 1])],
            [
                b"pose",
                json.dumps(
                    {"body": "cf1", "seq": "5", "t": now, "p": [0, 0, 0], "q": [0, 0, 0, 1]}
                ).encode(),
            ],
            [b"pose", good(5, valid="yes")],
            [b"pose", good(5), b"extra"],
        ],
        "oversized": [[b"pose", b" " * (70 * 1024)]],
        "bad_value": [
            [b"pose", good(6, (math.nan, 0, 0))],
            [b"pose", good(7, (1e7, 0, 0))],
            [b"pose", good(8, q=[0, 0, 0, 3])],
        ],
        "stale": [
            [
                b"pose",
                json.dumps(
                    {"body": "cf1", "seq": 9, "t": now - 5.0, "p": [0, 0, 0], "q": [0, 0, 0, 1]}
                ).encode(),
            ]
        ],
        "wrong_body": [[b"pose", good(10).replace(b'"cf1"', b'"cf2"')]],
        "out_of_order": [[b"pose", good(3)]],
    }
    publisher.send_raw([b"pose", good(4)])
    assert source.wait(-1, 2.0).seq == 4
    for messages in bad.values():
        for frames in messages:
            publisher.send_raw(frames)
    publisher.send_raw([b"pose", good(11, (9.0, 9.0, 9.0))])
    pose = source.wait(4, 2.0)
    assert pose.seq == 11 and pose.p == (9.0, 9.0, 9.0)
    drops = source.drops()
    assert {k: getattr(drops, k) for k in bad} == {k: len(v) for k, v in bad.items()}
    assert source.stats().poses == 2


def test_a_remote_clock_sender_is_ordered_by_seq_but_not_aged(link):
    publisher, _, runtime = link
    source = open_source(publisher.uri("cf1") + "&clock=remote", runtime)
    source.start()
    try:
        for attempt in range(50):  # the second subscriber joins asynchronously
            publisher.publish(Pose("cf1", attempt, -1.0e6, (0.0, 0.0, 1.0), LEVEL))
            if (pose := source.wait(-1, 0.05)) is not None:
                break
    finally:
        source.close()
    assert pose.latency == 0.0 and pose.t == pytest.approx(runtime.clock.now(), abs=1.0)


def test_a_simulated_clock_gives_exact_latency():
    clock = ManualClock(3.0)
    publisher = ZmqPosePublisher()
    source = open_source(publisher.uri("cf1"), Runtime(clock))
    source.start()
    try:
        assert publisher.wait_for_subscriber(2.0)
        publisher.publish(Pose("cf1", 1, 3.0 - 0.02, (0.0, 0.0, 1.0), LEVEL))
        pose = source.wait(-1, 2.0)
    finally:
        source.close()
        publisher.close()
    assert pose.latency == pytest.approx(0.02) and pose.t == pytest.approx(2.98)


@pytest.mark.parametrize(
    "uri, message",
    [
        ("zmq://127.0.0.1:5555", "body=NAME is required"),
        ("zmq://127.0.0.1?body=cf1", "needs host and port"),
        ("zmq://127.0.0.1:5555?body=cf1&clock=gps", "clock='gps'"),
        ("zmq://127.0.0.1:5555?body=cf1&bind=maybe", "bind='maybe'"),
        ("zmq://127.0.0.1:5555?body=cf1&max_age=-1", "max_age=-1 s is outside"),
        ("zmq://127.0.0.1:5555?body=cf1&boddy=x", "unknown parameter 'boddy'"),
    ],
)
def test_bad_zmq_uris_get_one_clear_line(uri, message):
    with pytest.raises(UriError, match=message):
        open_source(uri, Runtime.real())


def test_a_source_can_bind_and_the_publisher_connect():
    runtime = Runtime.real()
    source = open_source("zmq://127.0.0.1:0?body=cf1&bind=1", runtime)  # an ephemeral port
    source.start()
    assert not source.endpoint.endswith(":0")
    publisher = ZmqPosePublisher(source.endpoint, bind=False)
    try:
        assert publisher.wait_for_subscriber(2.0)
        publisher.publish(Pose("cf1", 1, runtime.clock.now(), (0.0, 0.0, 1.0), LEVEL))
        assert source.wait(-1, 2.0).p == (0.0, 0.0, 1.0)
    finally:
        publisher.close()
        source.close()


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner, max_size=4)
    ),
    max_leaves=12,
)
fields = st.fixed_dictionaries(
    {},
    optional={
        "body": st.sampled_from(["cf1", "cf2", 3]),
        "seq": json_values | st.integers(),
        "t": json_values,
        "p": json_values | st.lists(st.floats(), min_size=3, max_size=3),
        "q": json_values | st.lists(st.floats(), min_size=4, max_size=4),
        "valid": json_values,
    },
)


@settings(max_examples=150, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.lists(st.binary(max_size=64), max_size=3),
            fields.map(lambda f: [b"pose", json.dumps(f).encode()]),
        ),
        min_size=1,
        max_size=6,
    )
)
def test_arbitrary_messages_never_raise_and_are_counted(messages):
    source = ZmqPoseSource("tcp://127.0.0.1:1", "cf1", ManualClock(5.0))
    for frames in messages:
        source.handle_message(frames, 5.0)
    stats = source.stats()
    assert stats.received == len(messages) and stats.poses + stats.dropped == stats.received
    latest = source.latest()
    assert latest is None or all(math.isfinite(v) for v in (*latest.p, *latest.q))
