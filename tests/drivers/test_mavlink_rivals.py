"""The MAVLink driver refuses a vehicle another GCS or companion is steering, naming it, before
it sends anything that steers (drivers/mavlink/rivals.py): a rival on the link sending
SET_ATTITUDE_TARGET, or a vehicle armed in its offboard mode already. pymavlink on loopback."""

from __future__ import annotations

import threading

import pytest
from mavlink_double import connected
from pymavlink import mavutil
from udp_relay import UdpRelay

from perchd.core.runtime import Runtime
from perchd.drivers.base import open_driver
from perchd.drivers.targetlock import TargetBusy

GUIDED_NOGPS = 20


class RivalGcs:
    """A companion (system 7, component 191) whose heartbeats and attitude targets at 20 Hz
    reach the driver through `relay`, as a router forwards another controller's traffic."""

    def __init__(self, relay: UdpRelay) -> None:
        self.mav = mavutil.mavlink.MAVLink(None, srcSystem=7, srcComponent=191)
        self.relay, self.done = relay, threading.Event()
        self.thread = threading.Thread(target=self._stream, daemon=True)
        self.thread.start()

    def _stream(self) -> None:
        while not self.done.wait(0.05):
            for msg in (
                self.mav.heartbeat_encode(18, 8, 0, 0, 4),  # ONBOARD_CONTROLLER
                self.mav.set_attitude_target_encode(0, 1, 1, 0b111, [1, 0, 0, 0], 0, 0, 0, 0.5),
            ):
                self.relay.inject(msg.pack(self.mav))

    def close(self) -> None:
        self.done.set()
        self.thread.join()


def test_a_companion_streaming_attitude_targets_is_named_and_nothing_is_flown(ardupilot):
    vehicle = ardupilot
    relay = UdpRelay(vehicle.port)
    uri = f"mavlink:udpout:127.0.0.1:{relay.port}?mass=0.5"
    rival = RivalGcs(relay)
    try:
        with pytest.raises(TargetBusy) as err:
            open_driver(uri, Runtime.real()).connect()
        rival.close()
        drv = open_driver(uri, Runtime.real())
        drv.connect()  # the rival gone: the vehicle is taken
        drv.close()
    finally:
        rival.close()
        relay.close()
    assert str(err.value) == (
        f"{uri}: another companion (system 7, component 191) is steering "
        "the vehicle (SET_ATTITUDE_TARGET); stop it first"
    )
    assert vehicle.targets == [] and vehicle.modes == []


def test_a_vehicle_armed_in_its_offboard_mode_already_is_refused(ardupilot):
    vehicle = ardupilot
    vehicle.armed, vehicle.custom_mode = True, GUIDED_NOGPS
    with pytest.raises(
        TargetBusy,
        match="armed in its offboard mode already .custom mode 20.: "
        "another GCS or companion flies it",
    ):
        connected(vehicle, engage=False)
    assert vehicle.targets == []
