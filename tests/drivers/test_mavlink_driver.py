"""The MAVLink driver, through real pymavlink over loopback UDP, against a vehicle double."""

from __future__ import annotations

import math
import sys

import pytest

pytest.importorskip("pymavlink")

from mavlink_double import ARDUPILOT, PX4, VehicleDouble
from perchd.drivers.base import open_driver
from pymavlink import mavutil
from pymavlink.quaternion import Quaternion
from ticks import level, ticks_until_lost

from perchd.core.errors import ConfigError, LinkError, MissingExtraError, UriError
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Phase, Setpoint

MASS = 0.5
WEIGHT = MASS * 9.81


@pytest.fixture
def ardupilot():
    v = VehicleDouble(ARDUPILOT)
    yield v
    v.close()


@pytest.fixture
def px4():
    v = VehicleDouble(PX4)
    yield v
    v.close()


def connected(vehicle, query=""):
    drv = open_driver(f"{vehicle.uri}?mass={MASS}{query}", Runtime.real())
    drv.connect()
    return drv


def test_ardupilot_is_put_in_guided_nogps_and_left_disarmed_unless_asked(ardupilot):
    drv = connected(ardupilot)
    try:
        assert ardupilot.custom_mode == 20 and drv.health().ok
        assert not ardupilot.armed
        assert 400 not in [c for _, c, _ in ardupilot.commands]
    finally:
        drv.close()


def test_our_heartbeat_goes_out_at_2_hz(ardupilot):
    drv = connected(ardupilot)
    try:
        ardupilot.wait_for(lambda: False, timeout=1.3)
        beats = ardupilot.gcs_heartbeats
        gaps = [b - a for a, b in zip(beats, beats[1:])]
        assert len(beats) >= 3 and max(gaps) < 0.6
    finally:
        drv.close()


def test_arming_happens_on_request_and_a_refusal_is_named():
    v = VehicleDouble(ARDUPILOT)
    try:
        drv = connected(v, "&arm=1")
        assert v.armed
        drv.close()
    finally:
        v.close()
    stubborn = VehicleDouble(ARDUPILOT, refuse_arm=True)
    try:
        with pytest.raises(LinkError, match="refused to arm"):
            connected(stubborn, "&arm=1")
    finally:
        stubborn.close()


def test_ardupilot_without_thrust_as_thrust_is_refused_before_any_mode_change():
    v = VehicleDouble(ARDUPILOT, params={"GUID_OPTIONS": 4.0, "MOT_THST_HOVER": 0.35})
    try:
        with pytest.raises(ConfigError, match=r"GUID_OPTIONS=4 lacks bit 3.*GUID_OPTIONS=12"):
            connected(v)
        assert v.modes == []
    finally:
        v.close()


def test_px4_gets_offboard_only_after_a_second_of_streamed_setpoints(px4):
    drv = connected(px4)
    try:
        switch_t = next(t for t, c, p in px4.commands if c == 176 and int(p[1]) == 6)
        assert switch_t - px4.targets[0].t > 1.0
        assert px4.custom_mode == 6 << 16 and drv.health().ok
    finally:
        drv.close()


def test_the_attitude_is_a_unit_ned_quaternion_w_first(ardupilot):
    drv = connected(ardupilot)
    try:
        drv.send(Setpoint(0.0, 0.1, 0.2, 0.3, WEIGHT, 3, Phase.STAGE1))
        assert ardupilot.wait_for(lambda: ardupilot.targets[-1].thrust > 0)
        target = ardupilot.targets[-1]
        assert math.fsum(c * c for c in target.q) == pytest.approx(1.0, abs=1e-6)
        # FRD-in-NED: roll keeps its sign, pitch and yaw flip (Z-up -> Z-down)
        assert Quaternion(list(target.q)).euler == pytest.approx([0.1, -0.2, -0.3], abs=1e-6)
        assert target.type_mask == 0b111 and target.target == (1, 1)
    finally:
        drv.close()


def test_thrust_is_normalised_through_the_vehicles_hover_thrust(ardupilot):
    drv = connected(ardupilot)
    try:
        for newtons in (WEIGHT, 2 * WEIGHT, 10 * WEIGHT, 0.0):
            drv.send(level(newtons))
        assert ardupilot.wait_for(lambda: len(ardupilot.targets) >= 5)
        thrusts = [round(t.thrust, 4) for t in ardupilot.targets[-4:]]
        assert thrusts == [0.35, 0.70, 1.0, 0.0]  # MOT_THST_HOVER read from the vehicle
    finally:
        drv.close()


def test_a_hover_thrust_in_the_uri_overrides_the_vehicles(px4):
    drv = connected(px4, "&hover=0.25")
    try:
        drv.send(level(WEIGHT))
        assert px4.wait_for(lambda: round(px4.targets[-1].thrust, 4) == 0.25)
    finally:
        drv.close()


def test_failsafe_hands_ardupilot_to_land_and_stops_streaming(ardupilot):
    drv = connected(ardupilot)
    drv.send(level(WEIGHT))
    drv.failsafe(EndReason.TAU_DIVERGENCE)
    assert ardupilot.wait_for(lambda: ardupilot.custom_mode == 9)
    count = len(ardupilot.targets)
    drv.send(level(WEIGHT))
    ardupilot.wait_for(lambda: False, timeout=0.3)
    assert len(ardupilot.targets) == count
    drv.close()


def lands(vehicle) -> int:
    return sum(1 for _, c, p in vehicle.commands if (c, p[1]) == (176, 9))


def test_land_is_repeated_until_the_vehicles_heartbeat_shows_it_taken(ardupilot):
    drv = connected(ardupilot)
    try:
        drv.send(level(WEIGHT))
        ardupilot.mute()  # it obeys but cannot say so: LAND must go out again
        drv.failsafe(EndReason.LOST_LINK)
        ardupilot.wait_for(lambda: False, timeout=0.9)
        assert lands(ardupilot) >= 2 + 2  # the failsafe's two, then one per LAND_RETRY_S
        ardupilot.unmute()  # the next LAND's heartbeat shows custom mode 9
        assert ardupilot.wait_for(lambda: drv._mode == 9)
        taken = lands(ardupilot)
        ardupilot.wait_for(lambda: False, timeout=0.6)
        assert lands(ardupilot) == taken  # and then no more
    finally:
        drv.close()


def test_closing_the_driver_ends_the_land_repeats(ardupilot):
    drv = connected(ardupilot)
    ardupilot.mute()
    drv.failsafe(EndReason.LOST_LINK)
    drv.close()
    ardupilot.wait_for(lambda: False, timeout=0.6)  # open, it would have sent 2 more
    assert lands(ardupilot) == 2


def test_closing_a_flying_px4_lands_it(px4):
    with open_driver(f"{px4.uri}?mass={MASS}", Runtime.real()) as drv:
        drv.send(level(WEIGHT))
    assert px4.wait_for(lambda: px4.custom_mode == (4 << 16) | (6 << 24))


def test_a_pilot_taking_the_vehicle_back_makes_the_link_unhealthy(ardupilot):
    drv = connected(ardupilot)
    try:
        ardupilot.switch_mode_by_pilot(5)  # LOITER
        assert ardupilot.wait_for(lambda: not drv.health().ok)
        assert "left the offboard mode" in drv.health().detail
    finally:
        drv.close()


def test_no_vehicle_fails_the_connect_by_name():
    drv = open_driver("mavlink:udpout:127.0.0.1:9?mass=1&wait=0.3", Runtime.real())
    with pytest.raises(LinkError, match="0.3 s for a heartbeat from the vehicle"):
        drv.connect()


@pytest.mark.parametrize("uri, message", [
    ("mavlink:udpout:127.0.0.1:14550?mass=90", "mass=90 kg is outside"),
    ("mavlink:nonsense", "expected mavlink:udpout"),
])
def test_bad_uris_are_refused_by_name(uri, message):
    with pytest.raises(UriError, match=message):
        open_driver(uri, Runtime.real())


@pytest.mark.parametrize("uri, port", [("mavlink:tcp:host:xx?mass=1", "'xx'"),
                                       ("mavlink:udpout:127.0.0.1?mass=1", "''"),
                                       ("mavlink:udpin:0.0.0.0:70000?mass=1", "'70000'")])
def test_a_network_device_without_a_port_is_refused_before_pymavlink_sees_it(uri, port):
    with pytest.raises(UriError, match=f"needs HOST:PORT with a port 1..65535, got {port}"):
        open_driver(uri, Runtime.real())


def test_a_hung_autopilot_is_lost_within_3_ticks_and_sent_to_land(ardupilot):
    drv = connected(ardupilot, "&timeout=0.06")
    try:
        lost_after = ticks_until_lost(drv, 25.0, level(WEIGHT), ardupilot.mute)
        assert lost_after is not None and lost_after <= 3
        assert "no message from the vehicle" in drv.health().detail
        assert ardupilot.wait_for(lambda: ardupilot.custom_mode == 9)  # it still listens
    finally:
        drv.close()


def test_a_dead_autopilot_is_lost_within_3_ticks_and_the_land_command_still_goes_out(ardupilot):
    drv = connected(ardupilot)  # default 1.5 s timeout: the kernel's refusal tells first
    witness = None
    try:
        lost_after = ticks_until_lost(drv, 100.0, level(WEIGHT), ardupilot.die)
        assert lost_after is not None and lost_after <= 3
        assert "gone away" in drv.health().detail
        witness = mavutil.mavlink_connection(f"udpin:127.0.0.1:{ardupilot.port}")
        drv.failsafe(EndReason.LOST_LINK)
        land = witness.recv_match(type="COMMAND_LONG", blocking=True, timeout=2.0)
        assert (land.command, land.param2) == (176, 9)
        assert drv.failsafe_reasons[0] is EndReason.LOST_LINK
    finally:
        drv.close()
        if witness is not None:
            witness.close()


def test_without_pymavlink_the_factory_names_the_extra_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "pymavlink", None)  # as if not installed
    with pytest.raises(MissingExtraError, match=r"pip install 'perchd\[mavlink\]'"):
        open_driver("mavlink:udpout:127.0.0.1:14550?mass=1", Runtime.real())
