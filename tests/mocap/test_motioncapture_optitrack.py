"""libmotioncapture's own `optitrack` backend reads perchd's NatNet emulator over multicast on
loopback (NatNet 3.0 to 4.1), through the motioncapture:// source; and the source ends
cleanly whatever the server does: never answers, answers then vanishes, or sends a body that
comes and goes.

The library joins the group on interface_ip=127.0.0.1, so no route for the group is needed;
each server announces a data port free at start-up, so parallel runs do not share frames."""

from __future__ import annotations

import math
import socket
import time

import pytest

from perchd.core.clock import MonotonicClock
from perchd.core.errors import LinkError
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.core.uri import parse_uri
from perchd.mocap.motioncapture import open_motioncapture
from perchd.mocap.natnet.server import NatNetServer

pytest.importorskip("motioncapture")

RATE_HZ = 100.0
YAW_30 = (0.0, 0.0, math.sin(math.radians(15)), math.cos(math.radians(15)))  # world, Z up


pytestmark = pytest.mark.solo  # real-time bounds: see tests/conftest.py


def reader(command_port: int, **extra: str):
    query = "&".join(
        f"{k}={v}"
        for k, v in {
            "hostname": "127.0.0.1",
            "interface_ip": "127.0.0.1",
            "port_command": command_port,
            "body": "cf1",
            **extra,
        }.items()
    )
    return open_motioncapture(
        parse_uri(f"motioncapture://optitrack?{query}"), Runtime(MonotonicClock())
    )


def emulator(version=(4, 1)) -> NatNetServer:
    return NatNetServer({"cf1": 1, "wand": 2}, version, multicast=True, rate_hz=RATE_HZ).start()


def publish(server: NatNetServer, valid: bool = True) -> None:
    server.publish(Pose("cf1", 0, time.monotonic(), (0.5, -1.0, 1.5), YAW_30, valid))


def collect(src, seconds: float) -> list[Pose]:
    """The poses newer than the latest one, for `seconds`."""
    poses, end = [], time.monotonic() + seconds
    seq = src.latest().seq if src.latest() is not None else 0
    while time.monotonic() < end:
        pose = src.wait(seq, 0.1)
        if pose is not None:
            poses.append(pose)
            seq = pose.seq
    return poses


def closing_time(src) -> float:
    began = time.monotonic()
    src.close()
    return time.monotonic() - began


@pytest.mark.parametrize(
    "version", [(3, 0), (3, 1), (4, 0), (4, 1)], ids=["3.0", "3.1", "4.0", "4.1"]
)
def test_libmotioncaptures_optitrack_backend_reads_the_emulator(version):
    server = emulator(version)
    publish(server)
    src = reader(server.command_port)
    try:
        src.start()
        poses = collect(src, 1.0)
    finally:
        closing = closing_time(src)
        server.close()
    assert src.stats().dropped == 0  # the body was in every frame
    seqs = [p.seq for p in poses]  # wait() gives the newest: a late reader may skip, never repeat
    assert seqs == sorted(set(seqs))
    assert 0.5 * RATE_HZ <= len(poses) <= 1.5 * RATE_HZ  # the emulator's rate, loosely
    for pose in poses:
        assert pose.p == pytest.approx((0.5, -1.0, 1.5), abs=1e-6)  # Y up streamed, Z up read
        assert pose.q == pytest.approx(YAW_30, abs=1e-6)
    assert closing < 0.5


def test_a_body_that_comes_and_goes_is_dropped_while_gone():
    server = emulator()
    publish(server)
    src = reader(server.command_port)
    try:
        src.start()
        before = collect(src, 0.3)
        publish(server, valid=False)  # untracked: libmotioncapture leaves it out of the frame
        time.sleep(2.0 / RATE_HZ)  # the frames already on their way
        gone = collect(src, 0.3)
        publish(server)
        back = collect(src, 0.3)
    finally:
        closing = closing_time(src)
        server.close()
    assert before and back and not gone
    assert src.drops().no_body >= 0.2 * RATE_HZ
    assert closing < 0.5


def test_a_server_that_never_answers_fails_within_the_timeout():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:  # holds the port, mute
        silent.bind(("127.0.0.1", 0))
        src = reader(silent.getsockname()[1], timeout="0.5")
        began = time.monotonic()
        with pytest.raises(
            LinkError,
            match=r"^motioncapture optitrack 127\.0\.0\.1: no answer "
            r"within 0\.5 s",
        ):
            src.start()
        assert time.monotonic() - began < 1.0


def test_a_server_that_vanishes_leaves_a_source_that_still_closes_at_once():
    server = emulator()
    publish(server)
    src = reader(server.command_port)
    try:
        src.start()
        assert collect(src, 0.3)
        server.close()
        time.sleep(0.1)  # the worker is now blocked in the library's receive
        newest = src.latest().seq
        assert src.wait(newest, 0.3) is None
    finally:
        closing = closing_time(src)
    assert closing < 0.5
