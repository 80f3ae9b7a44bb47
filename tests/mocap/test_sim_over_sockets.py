"""Acceptance: a simulated perch whose mocap goes over real sockets, simulator -> NatNet
emulator -> NatNet client and simulator -> ZMQ publisher -> ZMQ source, ends as the same
flight with the in-process source does."""

from __future__ import annotations

from pathlib import Path

import pytest
from caseplans import case1_ipts

import perchd.flight.run as flight
from perchd.core.clock import ManualClock
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason
from perchd.drivers.base import open_driver
from perchd.mocap.base import open_source
from perchd.mocap.outputs import open_pose_output
from perchd.mocap.relay import RelayedSource


def perch(tmp_path: Path, output: str | None):
    runtime = Runtime(ManualClock(0.0))
    driver = open_driver("sim://", runtime)
    driver.connect()
    source = open_source("sim://", runtime)
    if output is not None:
        source = RelayedSource(source, open_pose_output(output, ["cf1"], runtime.clock), runtime)
    source.start()
    try:
        result = flight.fly(
            case1_ipts(),
            driver,
            source,
            runtime.clock,
            tmp_path / "flight.jsonl",
            world=runtime.sim,
        )
    finally:
        source.close()
        driver.close()
    return result, source.stats()


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    return perch(tmp_path_factory.mktemp("in_process"), None)[0]


@pytest.mark.parametrize(
    "output",
    ["natnet://127.0.0.1:0", "natnet://127.0.0.1:0?version=3.0&multicast=1", "zmq://127.0.0.1:0"],
    ids=["natnet-4.1-unicast", "natnet-3.0-multicast", "zmq"],
)
def test_a_perch_over_sockets_ends_as_the_in_process_one(output, in_process, tmp_path):
    result, stats = perch(tmp_path, output)
    assert in_process.outcome is EndReason.CONTACT
    assert result.outcome is in_process.outcome
    assert result.contact_speed == pytest.approx(in_process.contact_speed, abs=1e-3)
    assert result.perch_time == pytest.approx(in_process.perch_time, abs=0.011)  # a tick
    assert result.true_contact_speed == pytest.approx(in_process.true_contact_speed, abs=1e-3)
    assert stats.dropped == 0 and stats.poses > 300


def test_natnet_2_without_latency_stamps_still_perches(tmp_path):
    """NatNet 2.x frames carry no camera stamps, so the arrival stands in for the exposure:
    the perch still ends in contact, on a slightly different path."""
    result, stats = perch(tmp_path, "natnet://127.0.0.1:0?version=2.9")
    assert result.outcome is EndReason.CONTACT and stats.dropped == 0
