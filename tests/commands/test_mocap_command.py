"""`perchd mocap URI [--count N] [--json]` against the emulator and a ZMQ publisher."""

from __future__ import annotations

import json
import threading

import pytest

from perchd.cli import main
from perchd.core.clock import MonotonicClock
from perchd.core.types import Pose
from perchd.mocap.natnet.uris import NatNetServer
from perchd.mocap.zmq import ZmqPosePublisher

LEVEL = (0.0, 0.0, 0.0, 1.0)


class Feeder:
    """Publishes a pose of cf1 every 5 ms on a thread, as a simulator would."""

    def __init__(self, publish) -> None:
        self._publish, self._stop = publish, threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> Feeder:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        clock, seq = MonotonicClock(), 0
        while not self._stop.wait(0.005):
            seq += 1
            self._publish(Pose("cf1", seq, clock.now() - 0.002, (0.25, -0.5, 1.0), LEVEL))


def test_json_lines_from_a_natnet_server(capsys):
    with NatNetServer({"cf1": 1}, (4, 1)) as server, Feeder(server.publish):
        assert main(["mocap", server.uri + "&body=cf1", "--count", "3", "--json"]) == 0
    out, err = capsys.readouterr()
    lines = [json.loads(line) for line in out.splitlines()]
    assert len(lines) == 3
    assert set(lines[0]) == {"body", "seq", "t", "p", "q", "valid", "latency"}
    assert all(p["body"] == "cf1" and p["p"] == pytest.approx([0.25, -0.5, 1.0]) for p in lines)
    assert [p["seq"] for p in lines] == sorted({p["seq"] for p in lines})
    assert all(0.002 <= p["latency"] < 0.4 for p in lines)
    assert "3 poses" in err


def test_readable_lines_from_a_zmq_publisher(capsys):
    publisher = ZmqPosePublisher()
    try:
        with Feeder(publisher.publish):
            assert main(["mocap", publisher.uri("cf1"), "--count", "2"]) == 0
    finally:
        publisher.close()
    out, _ = capsys.readouterr()
    lines = out.splitlines()
    assert len(lines) == 2
    assert lines[0].startswith("cf1 #") and "p=[+0.2500 -0.5000 +1.0000] m" in lines[0]
    assert "valid" in lines[0] and "latency" in lines[0]


def test_silence_ends_with_a_link_error_and_exit_1(capsys):
    publisher = ZmqPosePublisher()
    try:
        assert main(["mocap", publisher.uri("cf1"), "--timeout", "0.2"]) == 1
    finally:
        publisher.close()
    assert "no pose from zmq://" in capsys.readouterr().err


def test_a_bad_uri_is_one_line_and_exit_2(capsys):
    assert main(["mocap", "natnet://10.0.0.5?up=y"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "body=NAME" in err
