"""One sender steers the simulated vehicle: a second zmq:// driver's setpoints and stops are
refused while the first is live, counted, and named in one line (sim/onesender.py)."""

from __future__ import annotations

import argparse
import math
import time

import pytest

from perchd.commands.sim import make_world
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Phase, Setpoint
from perchd.drivers.base import open_driver
from perchd.sim.onesender import SenderGate
from perchd.sim.receiver import Counts, SetpointInbox


def level(t: float) -> Setpoint:
    return Setpoint(t, 0.0, 0.0, 0.0, 0.3, 0, Phase.STAGE1)


def until(cond, send, timeout=5.0) -> None:
    """Keep sending until cond() holds (a PUB's first messages may precede its subscription)."""
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "the inbox never got there"
        send()
        time.sleep(0.01)


@pytest.fixture
def inbox():
    args = argparse.Namespace(
        latency=0.0,
        noise=0.0,
        start=None,
        surface=(0.0, 0.0, 0.0),
        normal=(1.0, 0.0, 0.0),
        body="cf1",
    )
    counts, lines = Counts(), []
    # live forever: which sender holds the vehicle must not depend on this machine's speed
    box = SetpointInbox(
        "zmq://127.0.0.1:0",
        make_world(args),
        "cf1",
        counts,
        log=lines.append,
        gate=SenderGate(live_s=math.inf),
    )
    yield box, counts, lines
    box.close()


def test_a_second_sender_is_refused_counted_and_named_until_the_first_stops(inbox):
    box, counts, lines = inbox
    first, second = (open_driver(box.uri, Runtime.real()) for _ in range(2))
    first.connect()
    second.connect()  # one process: the machine's lock is counted, as on two machines
    try:
        until(lambda: counts.setpoints > 0, lambda: first.send(level(1.0)))
        until(lambda: counts.foreign >= 3, lambda: second.send(level(1.0)))
        second.failsafe(EndReason.OPERATOR_ABORT)  # its stop must not stop the first's flight
        until(lambda: counts.foreign >= 4, lambda: None)
        assert counts.stops == 0 and box.gate.holder == first.sender
        assert lines == [
            (f"refusing sender {second.sender}: sender {first.sender} is steering the vehicle")
        ]
        first.failsafe(EndReason.CONTACT)
        until(lambda: counts.stops == 1, lambda: None)
        taken = counts.setpoints
        second.engage()
        until(lambda: counts.setpoints > taken, lambda: second.send(level(2.0)))
        assert box.gate.holder == second.sender
    finally:
        first.close()
        second.close()


def test_a_silent_holder_gives_way_and_its_own_stop_frees_the_vehicle():
    gate = SenderGate(live_s=1.0)
    assert gate.admit("a", 10.0) and not gate.admit("b", 10.5)
    assert not gate.stop("b", 10.9) and gate.holder == "a"
    assert gate.admit("b", 11.2)  # a silent for more than live_s: gone without a stop
    assert not gate.admit("a", 11.3)
    assert gate.stop("b", 11.4) and gate.holder is None and gate.admit("a", 11.5)
