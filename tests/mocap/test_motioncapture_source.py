"""The motioncapture:// source driven by libmotioncapture's own mock backend: frames with the
body, without it and with it again; the worker process end to end; the URI's one-line errors.

In-process, the mock's real `rigidBodies` are turned into the worker's lines (mcworker's
frame_line) and handed to a source that was not started; end to end, the worker process runs
the library itself."""

from __future__ import annotations

import time

import pytest

from perchd.core.clock import MonotonicClock
from perchd.core.errors import LinkError, UriError
from perchd.core.runtime import Runtime
from perchd.core.uri import parse_uri
from perchd.mocap.mcworker import frame_line
from perchd.mocap.motioncapture import open_motioncapture

motioncapture = pytest.importorskip("motioncapture")

CF1 = "cf1(1,2,3,1,0,0,0)"  # name(x,y,z,qw,qx,qy,qz), the mock's notation
WAND = "wand(0,0,1,1,0,0,0)"


def source(query: str):
    return open_motioncapture(parse_uri(f"motioncapture://mock?{query}"), Runtime(MonotonicClock()))


def mock_frames(rigid_bodies: str, seqs: range) -> list[str]:
    mc = motioncapture.connect("mock", {"rigid_bodies": rigid_bodies, "frequency": "1000"})
    lines = []
    for seq in seqs:
        mc.waitForNextFrame()
        lines.append(frame_line(mc.rigidBodies, "cf1", seq, time.monotonic()))
    return lines


def test_a_body_that_appears_vanishes_and_comes_back():
    src = source("body=cf1")
    frames = (
        mock_frames(f"{CF1};{WAND}", range(1, 4))
        + mock_frames(WAND, range(4, 7))
        + mock_frames(CF1, range(7, 10))
    )
    seen = []
    for line in frames:
        src.handle_line(line, time.monotonic())
        seen.append(src.latest().seq if src.latest() else None)
    assert seen == [1, 2, 3, 3, 3, 3, 7, 8, 9]
    assert (src.stats().received, src.stats().poses, src.stats().dropped) == (9, 6, 3)
    assert src.drops().no_body == 3
    pose = src.latest()
    assert pose.p == (1.0, 2.0, 3.0) and pose.q == (0.0, 0.0, 0.0, 1.0) and pose.valid


def test_up_y_turns_the_servers_axes_into_perchds():
    src = source("body=cf1&up=y")
    src.handle_line(mock_frames(CF1, range(1, 2))[0], time.monotonic())
    assert src.latest().p == (1.0, -3.0, 2.0)


def test_a_pose_that_waited_longer_than_max_age_is_stale():
    src = source("body=cf1&max_age=0.05")
    mc = motioncapture.connect("mock", {"rigid_bodies": CF1})
    src.handle_line(frame_line(mc.rigidBodies, "cf1", 1, time.monotonic() - 0.2), 0.0)
    assert src.latest() is None and src.drops().stale == 1


def test_garbage_from_the_worker_is_counted_not_raised():
    src = source("body=cf1")
    for line in ("not json\n", "[1, 2]\n", '{"seq": 1, "t": 0, "p": [1], "q": [0]}\n'):
        src.handle_line(line, 0.0)
    assert src.latest() is None and src.drops().garbage == 3


def test_the_worker_process_streams_the_mock_and_closes_at_once():
    src = source(f"body=cf1&rigid_bodies={CF1};{WAND}&frequency=100")
    src.start()
    try:
        first = src.wait(0, 2.0)
        time.sleep(0.5)
        last = src.latest()
    finally:
        began = time.monotonic()
        src.close()
        closing = time.monotonic() - began
    assert first is not None and first.p == (1.0, 2.0, 3.0)
    assert 25 <= last.seq - first.seq <= 60  # ~50 frames at the mock's 100 Hz, loosely
    assert src.stats().dropped == 0 and 0.0 <= last.latency < 0.25  # as tests/mocap's others
    assert closing < 0.5


def test_a_body_the_system_does_not_have_is_dropped_every_frame():
    src = source(f"body=cf1&rigid_bodies={WAND}&frequency=200")
    src.start()
    try:
        time.sleep(0.3)
    finally:
        src.close()
    assert src.latest() is None and src.stats().dropped == src.stats().received > 10


def test_the_librarys_connect_error_is_one_line():
    with pytest.raises(LinkError, match=r"^motioncapture optitrack not-an-ip: Invalid argument$"):
        open_motioncapture(
            parse_uri("motioncapture://optitrack?hostname=not-an-ip&body=cf1"),
            Runtime(MonotonicClock()),
        ).start()


@pytest.mark.parametrize(
    "uri, message",
    [
        ("motioncapture://nokov?body=cf1", r"has no backend 'nokov'; it has: mock, optitrack"),
        ("motioncapture://mock?body=cf1&hostnme=x", "unknown parameter 'hostnme'"),
        ("motioncapture://optitrack?body=cf1&port_command=1510a", "not a whole number"),
        ("motioncapture://mock?rigid_bodies=x", "body=NAME"),
        ("motioncapture://mock?body=cf1&up=x", "up='x' must be y"),
        ("motioncapture://mock?body=cf1&timeout=0", "timeout=0 s is outside"),
    ],
)
def test_bad_uris_are_one_line(uri, message):
    with pytest.raises(UriError, match=message):
        open_motioncapture(parse_uri(uri), Runtime(MonotonicClock()))
