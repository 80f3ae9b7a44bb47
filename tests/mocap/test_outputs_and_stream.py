"""Pose outputs a simulator opens by URI, and the shared stream rules of every source."""

from __future__ import annotations

import logging
import math
import time

import pytest

from perchd.core.errors import UriError
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.mocap.base import open_source
from perchd.mocap.outputs import open_pose_output
from perchd.mocap.stream import Drop, PoseLimits, PoseStream, RateLimitedWarning

LEVEL = (0.0, 0.0, 0.0, 1.0)


@pytest.mark.parametrize(
    "text",
    [
        "natnet://127.0.0.1:0",
        "natnet://127.0.0.1:0?version=3.0&rate=200",
        "natnet://127.0.0.1:0?version=2.9&multicast=1",
        "natnet://127.0.0.1:0?multicast=1&up=z",
        "zmq://127.0.0.1:0",
    ],
)
def test_an_output_opened_by_uri_is_read_back_by_the_uri_it_names(text):
    runtime = Runtime.real()
    output = open_pose_output(text, ["cf1"], runtime.clock)
    source = open_source(output.uri("cf1"), runtime)
    source.start()
    try:
        pose = None
        for seq in range(1, 100):  # a ZMQ subscriber joins asynchronously
            output.publish(Pose("cf1", seq, runtime.clock.now(), (0.5, 1.5, 2.5), LEVEL))
            if (pose := source.wait(-1, 0.05)) is not None:
                break
    finally:
        source.close()
        output.close()
    assert pose is not None and pose.p == pytest.approx((0.5, 1.5, 2.5))


@pytest.mark.parametrize(
    "text, message",
    [
        ("udp://127.0.0.1:5", "natnet://HOST"),
        ("zmq://127.0.0.1", "zmq://HOST:PORT"),
        ("natnet://127.0.0.1:0?version=5.0", "outside the NatNet 2.0..4.1"),
        ("natnet://127.0.0.1:0?version=four", "not MAJOR.MINOR"),
        ("natnet://127.0.0.1:0?rate=0", "rate=0 Hz is outside"),
        ("natnet://127.0.0.1:0?speed=1", "unknown parameter 'speed'"),
        ("natnet://127.0.0.1:0?up=w", "up='w'"),
    ],
)
def test_bad_output_uris_get_one_clear_line(text, message):
    with pytest.raises(UriError, match=message):
        open_pose_output(text, ["cf1"], Runtime.real().clock)


def stream(**limits) -> PoseStream:
    return PoseStream(
        "cf1", PoseLimits(**limits), RateLimitedWarning(logging.getLogger("test.stream"), "test")
    )


def pose(seq, p=(0.0, 0.0, 1.0), q=LEVEL, valid=True, latency=0.0) -> Pose:
    return Pose("cf1", seq, 10.0, p, q, valid, latency)


def test_a_restarted_sender_is_followed_after_enough_backwards_poses():
    s = stream(resync_after=3)
    assert s.offer(pose(100))
    assert not s.offer(pose(1)) and not s.offer(pose(2))
    assert s.offer(pose(3))  # the third in a row: the sender restarted
    assert s.latest().seq == 3 and s.drops().out_of_order == 2


def test_a_quaternion_is_normalised_and_an_invalid_pose_is_kept_printable():
    s = stream()
    assert s.offer(pose(1, q=(0.0, 0.0, 0.0, 1.05)))
    assert s.latest().q == (0.0, 0.0, 0.0, 1.0)
    assert s.offer(pose(2, p=(math.nan, math.nan, math.nan), valid=False))
    assert s.latest().p == (0.0, 0.0, 0.0) and not s.latest().valid


@pytest.mark.parametrize(
    "bad, reason",
    [
        (pose(1, latency=0.6), Drop.STALE),
        (pose(1, latency=-0.1), Drop.STALE),
        (pose(1, p=(0.0, math.inf, 0.0)), Drop.BAD_VALUE),
        (pose(1, p=(2000.0, 0.0, 0.0)), Drop.BAD_VALUE),
        (pose(1, q=(0.0, 0.0, 0.0, 0.5)), Drop.BAD_VALUE),
    ],
)
def test_unbelievable_poses_are_dropped_with_their_reason(bad, reason):
    s = stream()
    assert not s.offer(bad)
    assert s.latest() is None and s.stats().dropped == 1
    assert getattr(s.drops(), reason.name.lower()) == 1


def test_wait_returns_a_newer_pose_or_none_after_the_timeout():
    s = stream()
    start = time.monotonic()
    assert s.wait(-1, 0.05) is None and time.monotonic() - start >= 0.05
    s.offer(pose(5))
    assert s.wait(4, 0.0).seq == 5 and s.wait(5, 0.01) is None
