"""The MAVLink driver, through real pymavlink over loopback UDP, against a vehicle double."""

from __future__ import annotations

import math
import socket
import time

import pytest

pytest.importorskip("pymavlink")

from mavlink_double import ARDUPILOT, PX4, VehicleDouble, connected
from pymavlink import mavutil
from pymavlink.quaternion import Quaternion
from ticks import level, ticks_until_lost

from perchd.core.errors import LinkError
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Phase, Pose, Setpoint
from perchd.drivers.base import open_driver

MASS = 0.5
WEIGHT = MASS * 9.81


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
            connected(stubborn, "&arm=1&wait=1")  # asked again within the wait (vision on)
    finally:
        stubborn.close()


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


def test_a_pilot_taking_the_vehicle_back_makes_the_link_unhealthy(ardupilot):
    drv = connected(ardupilot)
    try:
        ardupilot.switch_mode_by_pilot(5)  # LOITER
        assert ardupilot.wait_for(lambda: not drv.health().ok)
        assert "left the offboard mode" in drv.health().detail
    finally:
        drv.close()


def test_no_vehicle_fails_the_connect_by_name_and_names_the_likely_causes():
    drv = open_driver("mavlink:udpout:127.0.0.1:9?mass=1&wait=0.3", Runtime.real())
    with pytest.raises(LinkError, match="0.3 s for a heartbeat from the vehicle") as err:
        drv.connect()
    assert "mavlink:udpin:127.0.0.1:14540" in str(err.value)  # the PX4 form
    assert "?sport=" in str(err.value) and "ArduPilot" in str(err.value)


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


# -- PX4: airborne take-over, level at the heading, udpout to PX4, failsafe parameters --


def heading_of(q) -> float:
    """[deg] NED yaw of a (w, x, y, z) target."""
    return math.degrees(Quaternion(list(q)).euler[2])


def test_px4_in_the_air_is_taken_over_at_hover_thrust_and_its_heading_on_the_ack():
    """No zero-thrust gap, no swing to north, no wait for the next 1 Hz heartbeat."""
    v = VehicleDouble(PX4, airborne=True, yaw_deg=120.0, prompt=False, heartbeat_s=3.0)
    try:
        drv = connected(v)
        returned = time.monotonic()
        switch_t = next(t for t, c, p in v.commands if c == 176 and int(p[1]) == 6)
        assert returned - switch_t < 0.3  # the ACK, not a heartbeat up to 3 s later
        assert drv.health().ok  # the heartbeat still showing HOLD predates the switch
        before = [t for t in v.targets if t.t <= switch_t]
        assert len(before) >= 10 and switch_t - before[0].t > 1.0
        assert {round(t.thrust, 4) for t in before} == {0.42}  # MPC_THR_HOVER, never 0
        for t in before:
            roll, pitch, _ = Quaternion(list(t.q)).euler
            assert (roll, pitch) == pytest.approx((0.0, 0.0), abs=1e-6)
            assert heading_of(t.q) == pytest.approx(120.0, abs=1e-3)
        drv.close()
    finally:
        v.close()


def test_on_the_ground_the_prestream_has_no_thrust_but_the_current_heading():
    v = VehicleDouble(PX4, yaw_deg=-45.0)
    try:
        drv = connected(v)
        assert {t.thrust for t in v.targets} == {0.0}
        assert heading_of(v.targets[-1].q) == pytest.approx(-45.0, abs=1e-3)
        drv.close()
    finally:
        v.close()


def test_the_keepalive_levels_at_the_last_commanded_heading_not_north(px4):
    drv = connected(px4)
    try:
        drv.send(Setpoint(0.0, 0.2, 0.1, -0.5, WEIGHT, 3, Phase.STAGE1))  # world yaw -0.5 rad
        px4.wait_for(lambda: False, timeout=0.3)  # silent loop: the keep-alive repeats
        last = px4.targets[-1]
        roll, pitch, yaw = Quaternion(list(last.q)).euler
        assert (roll, pitch) == pytest.approx((0.0, 0.0), abs=1e-6)
        assert yaw == pytest.approx(0.5, abs=1e-6)  # NED heading of world yaw -0.5
        assert last.thrust == pytest.approx(0.42, abs=1e-4)
    finally:
        drv.close()


def test_yaw0_turns_an_enu_world_onto_a_north_referenced_autopilot(px4):
    drv = connected(px4, "&yaw0=90")
    try:
        drv.send(Setpoint(0.0, 0.0, 0.0, math.pi / 2, WEIGHT, 3, Phase.STAGE1))  # world +Y
        assert px4.wait_for(lambda: px4.targets[-1].thrust > 0.4)
        assert heading_of(px4.targets[-1].q) == pytest.approx(0.0, abs=1e-3)  # north
    finally:
        drv.close()


def test_yaw0_auto_takes_the_offset_from_the_first_pose_and_the_vehicles_heading():
    v = VehicleDouble(PX4, yaw_deg=97.0)  # a compass 7 deg off an ENU world's north
    drv = connected(v, "&yaw0=auto")
    try:
        facing = math.radians(0.0)  # the mocap says it faces world +Y (ENU north)
        q = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))
        drv.observe_pose(Pose("b", 1, 0.0, (0.0, 0.0, 1.0), q))
        drv.send(Setpoint(0.0, 0.0, 0.0, math.pi / 2 + facing, WEIGHT, 1, Phase.HOLD))
        assert v.wait_for(lambda: v.targets[-1].thrust > 0.4)
        assert heading_of(v.targets[-1].q) == pytest.approx(97.0, abs=1e-3)  # no turn
        drv.send(Setpoint(0.0, 0.0, 0.0, math.pi / 2 - math.radians(10), WEIGHT, 2, Phase.HOLD))
        assert v.wait_for(lambda: abs(heading_of(v.targets[-1].q) - 107.0) < 1e-3)  # 10 deg right
        v.yaw = math.radians(99.0)  # the compass drifts 2 deg; the mocap sees no turn
        v.wait_for(lambda: False, timeout=0.1)
        drv.observe_pose(Pose("b", 2, 1.0, (0.0, 0.0, 1.0), q))  # 1 s on: the lag has caught up
        drv.send(Setpoint(0.0, 0.0, 0.0, math.pi / 2, WEIGHT, 3, Phase.HOLD))
        assert v.wait_for(lambda: abs(heading_of(v.targets[-1].q) - 99.0) < 1e-3)
    finally:
        drv.close()
        v.close()


def test_a_refused_mode_switch_is_named_at_once():
    v = VehicleDouble(ARDUPILOT)
    obey = v._command
    v._command = lambda command, p, now: 2 if command == 176 else obey(command, p, now)  # DENIED
    try:
        start = time.monotonic()
        with pytest.raises(LinkError, match=r"refused custom mode 20 \(MAV_RESULT 2\)"):
            connected(v)
        assert time.monotonic() - start < 2.0
    finally:
        v.close()


def test_udpout_to_a_px4_that_locks_onto_its_first_partner_needs_a_fixed_source_port():
    v = VehicleDouble(PX4, lock_partner=True)
    try:
        port = free_udp_port()
        for _ in range(2):  # two runs of perchd against one PX4 boot
            drv = connected(v, f"&sport={port}")
            drv.close()
        with pytest.raises(LinkError, match="udpin:127.0.0.1:14540"):
            connected(v, "&wait=0.5")  # an ephemeral port: PX4 would not answer it
    finally:
        v.close()


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
