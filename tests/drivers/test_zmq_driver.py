"""The ZMQ setpoint driver, over real pyzmq sockets on loopback."""

from __future__ import annotations

import json
import os

import pytest
from ticks import level, ticks_until_lost
from zmq_subscriber import SetpointSubscriber

from perchd.core.errors import LinkError, UriError
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Phase, Setpoint
from perchd.drivers.base import open_driver
from perchd.drivers.zmq import BadSetpoint, parse_setpoint_message, setpoint_message


@pytest.fixture
def sub():
    s = SetpointSubscriber()
    yield s
    s.close()


def test_setpoints_follow_contract_3_with_the_pose_they_came_from(sub):
    with open_driver(sub.uri + "?vehicle=cf7", Runtime.real()) as drv:
        drv.send(Setpoint(12.35, 0.1, -0.2, 0.3, 0.27, 17, Phase.STAGE1))
        drv.send(Setpoint(12.36, 0.0, 0.0, 0.0, 0.26, 18, Phase.STAGE2))
        assert sub.wait_for(lambda: len(sub.of("setpoint")) == 2)
    first, second = sub.of("setpoint")
    assert first == {
        "vehicle": "cf7",
        "seq": 0,
        "t": 12.35,
        "pose_seq": 17,
        "roll": 0.1,
        "pitch": -0.2,
        "yaw": 0.3,
        "thrust": 0.27,
        "phase": "stage1",
        "sender": drv.sender,
    }
    assert (second["seq"], second["pose_seq"], second["phase"]) == (1, 18, "stage2")
    assert drv.sender.startswith(f"{os.getpid()}-") and second["sender"] == drv.sender
    assert sub.wait_for(lambda: sub.of("stop")) and sub.of("stop")[-1]["sender"] == drv.sender


def test_failsafe_publishes_stop_with_the_named_reason_once_and_silences_setpoints(sub):
    drv = open_driver(sub.uri, Runtime.real())
    drv.connect()
    drv.failsafe(EndReason.GEOFENCE)
    drv.send(level(0.3))
    drv.close()
    assert sub.wait_for(lambda: sub.of("stop"))
    assert sub.of("stop")[0]["reason"] == "geofence violated"
    assert sub.of("stop")[0]["code"] == "GEOFENCE" and len(sub.of("stop")) == 1
    assert sub.of("setpoint") == []


def test_closing_without_a_failsafe_still_says_stop(sub):
    with open_driver(sub.uri, Runtime.real()) as drv:
        drv.send(level(0.3))
    assert sub.wait_for(lambda: sub.of("stop"))
    assert sub.of("stop")[0]["code"] == "CLOSED"


def test_nobody_listening_fails_the_connect():
    drv = open_driver("zmq://127.0.0.1:9?wait=0.2", Runtime.real())
    with pytest.raises(LinkError, match="no subscriber to 'setpoint' within 0.2 s"):
        drv.connect()


def test_a_uri_without_a_port_is_refused():
    with pytest.raises(UriError, match="needs host and port"):
        open_driver("zmq://localhost", Runtime.real())


def test_a_subscriber_that_dies_mid_flight_is_lost_within_3_ticks(sub):
    drv = open_driver(sub.uri, Runtime.real())
    drv.connect()
    try:
        lost_after = ticks_until_lost(drv, 100.0, level(0.3), sub.die)
        assert lost_after is not None and lost_after <= 3
        assert drv.failsafe_reasons == [EndReason.LOST_LINK]
        assert "no subscriber" in drv.health().detail
    finally:
        drv.close()


def test_the_receiving_end_reads_back_exactly_what_the_driver_sent():
    sp = Setpoint(3.5, 0.1, -0.2, 0.3, 0.27, 17, Phase.STAGE2)
    body = json.dumps(setpoint_message("cf1", 9, sp)).encode()
    assert parse_setpoint_message(body) == ("cf1", 9, sp)


@pytest.mark.parametrize(
    "body, field",
    [
        (b"{", "not JSON"),
        (b"[1]", "not a JSON object"),
        (
            b'{"t": 0, "roll": "x", "pitch": 0, "yaw": 0, "thrust": 0}',
            "'roll' must be a finite number",
        ),
        (b'{"t": 0, "roll": 0, "pitch": 0, "yaw": 0, "thrust": NaN}', "'thrust' must be a finite"),
        (b'{"t": 0, "roll": 0, "pitch": 0, "yaw": 0, "thrust": 0, "phase": "up"}', "'phase'"),
    ],
)
def test_a_malformed_setpoint_is_refused_naming_the_field(body, field):
    with pytest.raises(BadSetpoint, match=field):
        parse_setpoint_message(body)


def test_a_flight_after_a_failsafe_on_the_same_link_streams_again(sub):
    """perchd serve keeps its links across flights: the next flight's engage lifts the
    last flight's stop, and nothing streams between the failsafe and that engage."""
    with open_driver(sub.uri, Runtime.real()) as drv:
        drv.failsafe(EndReason.GEOFENCE)
        drv.send(level(0.3))  # the ended flight's late tick: silenced
        drv.engage()
        drv.send(level(0.25))
        assert sub.wait_for(lambda: sub.of("setpoint"))
    assert [s["thrust"] for s in sub.of("setpoint")] == [0.25]
