"""Opt-in (PERCHD_CF2): the Crazyflie firmware in the loop, flown through perchd's
Crazyflie driver over cflib's udp:// link. Every field of the RPYT packet is checked
against what the firmware made the physics do: sign and size of roll, pitch, yaw rate and
thrust (docs/firmware.md)."""

from __future__ import annotations

import math

import pytest
from cf2rig import CALIBRATION, MASS, Pilot, cf2_vehicle, needs_cf2, rpy

from perchd.core.runtime import Runtime

pytestmark = [pytest.mark.firmware, needs_cf2]
pytest.importorskip("cflib")

DEG = math.pi / 180.0


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    from perchd.drivers.base import open_driver

    with cf2_vehicle(tmp_path_factory.mktemp("cf2")) as v:
        with open_driver(v.relay.uri + CALIBRATION, Runtime.real()) as cf:
            pilot = Pilot(v, cf)
            pilot.fly(2.5)  # take off to 0.5 m
            yield v, pilot


def test_it_arms_takes_off_and_hovers_at_the_models_hover_pwm(rig):
    v, pilot = rig
    pwm, heights = [], []
    pilot.fly(1.5, every=lambda tr: (heights.append(tr.p[2]), pwm.append(sum(v._pwm) / 4)))
    assert all(abs(z - 0.5) < 0.05 for z in heights), (min(heights), max(heights))
    assert abs(sum(pwm) / len(pwm) - v.params.model.hover_pwm) < 800
    assert v.summary()["imu"]["rate_hz"] > 900  # real time on 2 shared cores
    print(
        f"\nhover: z {min(heights):.3f}..{max(heights):.3f} m, mean PWM "
        f"{sum(pwm) / len(pwm):.0f} (model {v.params.model.hover_pwm:.0f}), IMU "
        f"{v.summary()['imu']['rate_hz']:.1f} Hz"
    )


@pytest.mark.parametrize("sign", [1, -1], ids=["right", "left"])
def test_roll_is_right_handed_about_x_and_reaches_the_commanded_angle(rig, sign):
    v, pilot = rig
    pilot.hover()
    vy0 = v.truth().v[1]
    pilot.fly(0.6, roll=sign * 10 * DEG)
    roll = rpy(v)[0]
    dvy = v.truth().v[1] - vy0
    pilot.hover()
    print(f"\nroll {sign * 10:+d} deg: flown {math.degrees(roll):+.1f} deg, dvy {dvy:+.2f} m/s")
    assert roll == pytest.approx(sign * 10 * DEG, abs=2 * DEG)
    assert -sign * dvy > 0.3  # a right roll (positive) moves right: -y


@pytest.mark.parametrize("sign", [1, -1], ids=["nose-down", "nose-up"])
def test_pitch_is_right_handed_about_y_nose_down_positive_and_reaches_the_angle(rig, sign):
    v, pilot = rig
    pilot.hover()
    vx0 = v.truth().v[0]
    pilot.fly(0.6, pitch=sign * 10 * DEG)
    pitch = rpy(v)[1]
    dvx = v.truth().v[0] - vx0
    pilot.hover()
    print(f"\npitch {sign * 10:+d} deg: flown {math.degrees(pitch):+.1f} deg, dvx {dvx:+.2f} m/s")
    assert pitch == pytest.approx(sign * 10 * DEG, abs=2 * DEG)
    assert sign * dvx > 0.3  # nose down accelerates forward: +x


@pytest.mark.parametrize("target", [0.5, -0.5], ids=["ccw", "cw"])
def test_yaw_turns_to_the_setpoint_and_holds_it(rig, target):
    v, pilot = rig
    pilot.hover(1.0)
    yaws = []
    pilot.fly(2.5, yaw=target, every=lambda tr: yaws.append(rpy(v)[2]))
    pilot.fly(2.0, yaw=0.0)
    final = yaws[-1]
    print(
        f"\nyaw to {target:+.2f} rad: final {final:+.3f} rad, range "
        f"{min(yaws):+.3f}..{max(yaws):+.3f} rad"
    )
    assert final == pytest.approx(target, abs=0.1)
    assert max(abs(y) for y in yaws) < abs(target) + 0.2  # no run-away


@pytest.mark.parametrize("factor", [1.25, 0.8])
def test_thrust_in_newtons_gives_the_acceleration_it_should(rig, factor):
    v, pilot = rig
    pilot.hover(1.0)
    t0, vz0 = v.truth().t, v.truth().v[2]
    pilot.fly(0.3, thrust=factor * MASS * 9.81)
    tr = v.truth()
    az = (tr.v[2] - vz0) / (tr.t - t0)
    pilot.hover(2.0)
    expected = (factor - 1.0) * 9.81
    print(f"\nthrust x{factor}: vertical acceleration {az:+.2f} m/s^2 (expected {expected:+.2f})")
    # the motors' lag (12.5/25 ms) and the firmware's one-step delay take ~10 % of 0.3 s
    assert az == pytest.approx(expected, rel=0.35)
