"""The service's idle feed (perchd/service/idle_feed.py): between flights each new pose of a
real ZMQ pose source reaches the driver once; paused, none does until it is resumed. The
driver here only records what it is handed (the feed's one call into it)."""

from __future__ import annotations

import threading
import time

from still_poses import StillPoses

from perchd.core.runtime import Runtime
from perchd.mocap.base import open_source
from perchd.service.idle_feed import WAIT_S, IdleFeed

RATE_HZ = 100.0


class Recorder:
    def __init__(self, fail_first: int = 0) -> None:
        self.seqs: list[int] = []
        self.threads: set[str] = set()
        self.fail_first = fail_first

    def observe_pose(self, pose) -> None:
        if self.fail_first > 0:
            self.fail_first -= 1
            raise OSError("send buffer full")
        self.seqs.append(pose.seq)
        self.threads.add(threading.current_thread().name)


def fed_during(rec: Recorder, seconds: float) -> list[int]:
    before = len(rec.seqs)
    time.sleep(seconds)
    return rec.seqs[before:]


def test_poses_reach_the_driver_once_each_while_resumed_and_none_while_paused():
    poses = StillPoses(rate_hz=RATE_HZ)
    source = open_source(poses.uri, Runtime.real())
    source.start()
    rec = Recorder()
    feed = IdleFeed(source, rec)
    try:
        assert fed_during(rec, 0.3) == []  # it starts paused
        feed.resume()
        fed = fed_during(rec, 1.0)
        assert len(fed) >= 0.6 * RATE_HZ  # a shared machine: most, not all
        assert fed == sorted(set(fed))  # each once, in order
        feed.pause()
        paused_at = len(rec.seqs)
        time.sleep(0.3)
        assert len(rec.seqs) == paused_at  # pause() returned: nothing more is handed over
        feed.resume()
        assert len(fed_during(rec, 0.5)) >= 0.3 * RATE_HZ
        assert rec.seqs == sorted(set(rec.seqs))
        assert rec.threads == {"perchd-idle-feed"}
    finally:
        feed.close()
        source.close()
        poses.close()
    closed_at = len(rec.seqs)
    time.sleep(0.2)
    assert len(rec.seqs) == closed_at


def test_a_pose_the_driver_refuses_is_said_once_and_the_next_ones_still_go(caplog):
    poses = StillPoses(rate_hz=RATE_HZ)
    source = open_source(poses.uri, Runtime.real())
    source.start()
    rec = Recorder(fail_first=5)
    feed = IdleFeed(source, rec)
    try:
        feed.resume()
        deadline = time.monotonic() + 2.0
        while len(rec.seqs) < 20 and time.monotonic() < deadline:
            time.sleep(WAIT_S)
        assert len(rec.seqs) >= 20
        lines = [r.getMessage() for r in caplog.records if "did not reach" in r.getMessage()]
        said = "between flights, a pose did not reach the driver: OSError: send buffer full"
        assert lines == [said]
        feed.pause()
        assert feed.fed == len(rec.seqs) and feed.alive
    finally:
        feed.close()
        source.close()
        poses.close()


def test_a_sender_that_restarts_its_numbering_is_followed_at_once():
    """Motive or a bridge restarted: its poses come numbered from 1 again. The feed goes
    on with them instead of waiting for the numbers to pass the old ones."""
    poses = StillPoses(rate_hz=RATE_HZ)
    poses.sent = 100_000  # a sender long running
    source = open_source(poses.uri, Runtime.real())
    source.start()
    rec = Recorder()
    feed = IdleFeed(source, rec)
    try:
        feed.resume()
        assert min(fed_during(rec, 0.5)) > 100_000
        poses.sent = 0  # restarted: it numbers from 1 again
        time.sleep(0.6)  # the source follows a lower numbering after some poses
        after = fed_during(rec, 0.5)
        assert len(after) >= 0.3 * RATE_HZ
        assert max(after) < 200  # the new numbering's, handed over
    finally:
        feed.close()
        source.close()
        poses.close()
