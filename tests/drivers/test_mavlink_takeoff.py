"""Ground take-off and the set-up target over real MAVLink (pymavlink at both ends, loopback):
ArduCopter armed on the ground applies no thrust until its motors have spooled up, so the
driver's connect() returns only once it does; until the loop's first setpoint the vehicle
gets a target that neither drops it (in the air) nor lifts it (on the ground)."""

from __future__ import annotations

import time

import pytest

pytest.importorskip("pymavlink")

from mavlink_double import ARDUPILOT, PX4, SAFE_PARAMS, VehicleDouble, connected
from ticks import level

from perchd.core.errors import LinkError
from perchd.drivers.mavlink import SPOOL_FRACTION

MASS = 0.5
WEIGHT = MASS * 9.81
HOVER = SAFE_PARAMS[ARDUPILOT]["MOT_THST_HOVER"]


def test_a_ground_start_returns_only_once_the_motors_apply_thrust():
    """The loop's first setpoint must act at once: thrust it sends while ArduCopter still
    spools (0.8 s here) would be ignored and the take-off ramp would wind up meanwhile."""
    v = VehicleDouble(ARDUPILOT, spool_s=0.8)
    try:
        start = time.monotonic()
        drv = connected(v, "&arm=1")
        returned = time.monotonic()
        assert v.applied_thrust(returned) > 0.0
        armed_at = next(t for t, c, _ in v.commands if c == 400)
        assert returned - armed_at >= 0.8 and returned - start < 3.0
        spool = [t for t in v.targets if t.t > armed_at]
        assert spool and {round(t.thrust, 4) for t in spool} == {round(SPOOL_FRACTION * HOVER, 4)}
        assert SPOOL_FRACTION * HOVER < 0.5 * HOVER  # far below lift-off
        drv.send(level(WEIGHT))
        assert v.wait_for(lambda: v.applied_thrust(time.monotonic()) == pytest.approx(HOVER))
        drv.close()
    finally:
        v.close()


def test_motors_that_never_spool_up_fail_the_connect_by_name():
    v = VehicleDouble(ARDUPILOT, spool_s=60.0)
    try:
        with pytest.raises(LinkError, match="spool up"):
            connected(v, "&arm=1&wait=0.5")
    finally:
        v.close()


def test_an_airborne_or_unarmed_start_does_not_wait_for_a_spool_up():
    for kwargs, query in (({"airborne": True}, "&arm=1"), ({}, "")):
        v = VehicleDouble(ARDUPILOT, spool_s=60.0, **kwargs)
        try:
            start = time.monotonic()
            connected(v, query).close()
            assert time.monotonic() - start < 2.0
        finally:
            v.close()


@pytest.mark.parametrize("autopilot", [ARDUPILOT, PX4])
def test_late_mocap_after_an_airborne_take_over_repeats_hover_thrust_never_zero(autopilot):
    """The set-up target repeats until the loop's first setpoint (late mocap: 0.5 s here)."""
    v = VehicleDouble(autopilot, airborne=True, yaw_deg=70.0)
    hover = SAFE_PARAMS[autopilot]["MOT_THST_HOVER" if autopilot == ARDUPILOT else "MPC_THR_HOVER"]
    try:
        drv = connected(v)
        done = time.monotonic()
        v.wait_for(lambda: False, timeout=0.5)
        late = [t for t in v.targets if t.t >= done]
        assert len(late) >= 4  # the keep-alive streams it
        assert {round(t.thrust, 4) for t in late} == {hover}
        drv.close()
    finally:
        v.close()


def test_late_mocap_after_a_ground_arm_repeats_the_spool_thrust_and_lifts_nothing():
    v = VehicleDouble(ARDUPILOT, spool_s=0.3)
    try:
        drv = connected(v, "&arm=1")
        done = time.monotonic()
        v.wait_for(lambda: False, timeout=0.5)
        late = [t for t in v.targets if t.t >= done]
        assert len(late) >= 4
        assert max(t.thrust for t in late) == pytest.approx(SPOOL_FRACTION * HOVER)
        drv.close()
    finally:
        v.close()
