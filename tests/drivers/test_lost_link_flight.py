"""A link that dies mid-flight ends the flight as LOST_LINK within 3 ticks, with a failsafe.

The real flight loop (perchd.flight.run.fly, 100 Hz, real time) flies each real driver against
its test peer (CRTP responder, MAVLink double, ZMQ subscriber). The peer's decoded commands
drive a simulated world, whose mocap the agent reads, so the flight is physically coherent
until the peer dies half a second in.
"""

from __future__ import annotations

import threading

import pytest
from caseplans import case1_ipts
from rigs import CrazyflieRig, MavlinkRig, ZmqRig, bridge, kill_after

import perchd.flight.run as flight
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason
from perchd.drivers.base import open_driver
from perchd.logs.flightlog import read_log
from perchd.mocap.base import open_source


@pytest.mark.parametrize(
    "rig_cls", [CrazyflieRig, MavlinkRig, ZmqRig], ids=["crazyflie-udp", "mavlink", "zmq"]
)
def test_a_link_that_dies_mid_flight_ends_it_as_lost_link_within_3_ticks(rig_cls, tmp_path):
    rig = rig_cls()
    runtime = Runtime.real()
    source = open_source("sim://", runtime)  # the world, on the real clock
    world = runtime.sim
    driver = open_driver(rig.uri, runtime)
    stop, killed = threading.Event(), []
    helpers = [
        threading.Thread(target=bridge, args=(rig, world, stop), daemon=True),
        threading.Thread(target=kill_after, args=(rig, world, 50, killed), daemon=True),
    ]
    try:
        driver.connect()
        source.start()
        for h in helpers:
            h.start()
        result = flight.fly(
            case1_ipts(), driver, source, runtime.clock, tmp_path / "f.jsonl", world=world
        )
    finally:
        stop.set()
        source.close()
        driver.close()
        rig.close()
    assert result.outcome is EndReason.LOST_LINK
    assert result.failsafe_sent and driver.failsafe_reasons[0] is EndReason.LOST_LINK
    rows = read_log(result.log).rows
    after_kill = [r for r in rows if r.t >= killed[0]]
    assert 1 <= len(after_kill) <= 3 and after_kill[-1].end == "LOST_LINK"
