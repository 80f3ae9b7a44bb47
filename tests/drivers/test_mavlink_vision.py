"""Mocap to the autopilot over real MAVLink (pymavlink at both ends, loopback UDP): each pose
goes out as VISION_POSITION_ESTIMATE in NED, stamped on perchd's clock, TIMESYNC answered on
the same clock, and the autopilot's external-navigation set-up is checked at connect."""

from __future__ import annotations

import logging
import math
import time

import pytest

pytest.importorskip("pymavlink")

from mavlink_double import ARDUPILOT, PX4, SAFE_PARAMS, VehicleDouble, connected

from perchd.core.errors import ConfigError
from perchd.core.types import Pose
from perchd.sim.plant import quaternion

MASS = 0.5


def pose(t, p, roll=0.0, pitch=0.0, yaw=0.0, seq=1, valid=True):
    return Pose("cf1", seq, t, p, quaternion(roll, pitch, yaw), valid)


@pytest.mark.parametrize("autopilot", [ARDUPILOT, PX4])
@pytest.mark.parametrize(
    "yaw0_deg, world, ned",
    [
        (0, (1.0, 2.0, 3.0), (1.0, -2.0, -3.0)),  # NWU: X north, Y west, Z up
        (90, (1.0, 2.0, 3.0), (2.0, 1.0, -3.0)),  # ENU: X east, Y north
        (60, (1.0, 0.0, 0.5), (0.5, math.sqrt(3) / 2, -0.5)),  # X at heading 60 deg
    ],
)
def test_each_pose_goes_to_the_autopilot_in_ned_at_its_measurement_time(
    autopilot, yaw0_deg, world, ned
):
    v = VehicleDouble(autopilot, mavlink2=True)
    try:
        drv = connected(v, f"&yaw0={yaw0_deg}")
        runtime_now = drv.clock.now()
        for k in range(5):
            drv.observe_pose(pose(runtime_now + 0.01 * k, world, 0.1, 0.2, 0.3, seq=k + 1))
        assert v.wait_for(lambda: len(v.visions) == 5)
        _, m = v.visions[-1]
        assert (m.x, m.y, m.z) == pytest.approx(ned, abs=1e-6)
        # FRD in NED: roll stays, pitch flips, yaw is measured clockwise from yaw0
        assert (m.roll, m.pitch) == pytest.approx((0.1, -0.2), abs=1e-6)
        assert math.remainder(m.yaw - (math.radians(yaw0_deg) - 0.3), math.tau) == pytest.approx(
            0.0, abs=1e-6
        )
        assert m.usec == round((runtime_now + 0.04) * 1e6)
        cov = list(m.covariance)
        assert cov[0] == cov[6] == cov[11] > 0 and cov[15] == cov[18] == cov[20] > 0
        assert sum(cov) == pytest.approx(cov[0] * 3 + cov[15] * 3)
        drv.close()
    finally:
        v.close()


def test_invalid_poses_and_vision_off_send_nothing():
    v = VehicleDouble(ARDUPILOT)
    try:
        drv = connected(v)
        drv.observe_pose(pose(drv.clock.now(), (0.0, 0.0, 1.0), valid=False))
        drv.close()
        off = connected(v, "&vision=0")
        off.observe_pose(pose(off.clock.now(), (0.0, 0.0, 1.0)))
        v.wait_for(lambda: False, timeout=0.2)
        assert v.visions == []
        off.close()
    finally:
        v.close()


def test_yaw0_auto_forwards_from_the_first_pose_at_the_measured_offset():
    v = VehicleDouble(PX4, yaw_deg=100.0)
    try:
        drv = connected(v, "&yaw0=auto")
        v.wait_for(lambda: drv.vehicle.yaw_ned is not None)
        drv.observe_pose(pose(drv.clock.now(), (1.0, 0.0, 0.0), yaw=math.radians(30)))
        assert v.wait_for(lambda: len(v.visions) == 1)
        m = v.visions[0][1]
        assert math.degrees(m.yaw) == pytest.approx(100.0, abs=1e-3)  # its own heading
        # world X is at heading 130 deg: a point 1 m along it
        assert (m.x, m.y) == pytest.approx(
            (math.cos(math.radians(130)), math.sin(math.radians(130))), abs=1e-6
        )
        drv.close()
    finally:
        v.close()


def test_px4s_timesync_requests_are_answered_on_the_clock_the_poses_are_stamped_with():
    v = VehicleDouble(PX4, timesync=True)
    try:
        drv = connected(v)
        assert v.wait_for(lambda: len(v.timesync_replies) >= 3)
        arrival, tc1, ts1 = v.timesync_replies[-1]
        assert ts1 > 0  # its own stamp, back
        assert abs(tc1 * 1e-9 - drv.clock.now()) < 0.5
        drv.close()
    finally:
        v.close()


def test_vision_0_skips_the_external_navigation_check():
    params = {**SAFE_PARAMS[PX4], "EKF2_EV_CTRL": 0.0, "EKF2_HGT_REF": 1.0}
    v = VehicleDouble(PX4, params=params)
    try:
        connected(v, "&vision=0").close()
        assert v.param_sets == []
    finally:
        v.close()


def test_configure_sets_px4s_external_vision_keeping_its_other_bits(caplog):
    params = {**SAFE_PARAMS[PX4], "EKF2_EV_CTRL": 4.0, "EKF2_HGT_REF": 1.0}
    v = VehicleDouble(PX4, params=params)
    try:
        with caplog.at_level(logging.WARNING, logger="perchd.drivers.mavlink"):
            connected(v, "&configure=1").close()
        assert dict(v.param_sets) == {"EKF2_EV_CTRL": 15.0, "EKF2_HGT_REF": 3.0}  # bytewise
        assert "set EKF2_EV_CTRL from 4 to 15" in caplog.text
    finally:
        v.close()


def test_configure_sets_ardupilots_angle_boost_off():
    v = VehicleDouble(ARDUPILOT, params={**SAFE_PARAMS[ARDUPILOT], "ATC_ANGLE_BOOST": 1.0})
    try:
        connected(v, "&configure=1").close()
        assert v.params["ATC_ANGLE_BOOST"] == 0.0
    finally:
        v.close()


def test_configure_sets_viso_type_and_asks_for_the_reboot_it_needs():
    v = VehicleDouble(ARDUPILOT, params={**SAFE_PARAMS[ARDUPILOT], "VISO_TYPE": 0.0})
    try:
        with pytest.raises(ConfigError, match=r"set VISO_TYPE.*only at boot: reboot"):
            connected(v, "&configure=1")
        assert v.params["VISO_TYPE"] == 1.0 and v.modes == []
    finally:
        v.close()


def test_forwarding_keeps_the_mocap_rate():
    """100 poses at 100 Hz arrive as 100 estimates, none merged or dropped."""
    v = VehicleDouble(ARDUPILOT)
    try:
        drv = connected(v)
        t0 = drv.clock.now()
        for k in range(100):
            drv.observe_pose(pose(t0 + 0.01 * k, (0.0, 0.0, 1.0), seq=k + 1))
            time.sleep(0.01)
        assert v.wait_for(lambda: len(v.visions) == 100)
        stamps = [m.usec for _, m in v.visions]
        assert stamps == sorted(stamps) and len(set(stamps)) == 100
        drv.close()
    finally:
        v.close()
