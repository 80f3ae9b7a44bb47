"""Tau PID (eqs. 17, 20), Y/Z PID (eq. 18) and the eq. 19 mapping with eqs. 25-26."""

from __future__ import annotations

import math

import pytest

from perchd.core.types import State
from perchd.flight.config import UNIT_ACCEL, FlightConfig, TauGains, from_paper_units
from perchd.flight.control import Pid, TauController, map_attitude, tau_error
from perchd.flight.frame import body_z

M, G = 0.030, 9.81
TILT = math.radians(25.0)


def att(a, yaw=0.0, tmin=0.0, tmax=1.0):
    return map_attitude(a, yaw, M, G, TILT, tmin, tmax)


def state(tau):
    x = -1.0
    return State(0.0, x, x / tau if tau else 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, tau, 0.0, 0.0, 0.0, 1)


def test_paper_gains_convert_through_the_hover_thrust_of_errata_8():
    assert UNIT_ACCEL == pytest.approx(9.81 / 36000)
    assert from_paper_units(36000.0) == pytest.approx(9.81)  # hover units lift 1 g
    assert FlightConfig().lateral.y.kp == pytest.approx(14500 * 9.81 / 36000)


def test_the_tau_error_is_negative_when_too_fast_and_one_when_stopped():
    assert tau_error(-1.0, -0.5) == pytest.approx(-1.0)  # contact sooner than planned
    assert tau_error(-0.5, -1.0) == pytest.approx(0.5)
    assert tau_error(-0.5, None) == 1.0


def test_gain_scheduling_brakes_harder_than_it_speeds_up():
    g = TauGains(ki=0.0, kd=0.0, feedforward=False)
    fast, slow = TauController(g), TauController(g)
    u_fast = fast.step(state(-0.8), tau_ref=-1.0, a_plan=0.0, dt=0.01)  # e = -0.25
    u_slow = slow.step(state(-1.25), tau_ref=-1.0, a_plan=0.0, dt=0.01)  # e = +0.2
    assert u_fast == pytest.approx(g.kp_fast * -0.25)
    assert u_slow == pytest.approx(g.kp_slow * 0.2)
    assert g.kp_fast / g.kp_slow == pytest.approx(2.5)


def test_the_plans_acceleration_is_fed_forward_only_when_switched_on():
    on = TauController(TauGains(feedforward=True))
    off = TauController(TauGains(feedforward=False))
    st = state(-1.0)
    assert on.step(st, -1.0, -1.4, 0.01) == pytest.approx(-1.4)
    assert off.step(st, -1.0, -1.4, 0.01) == pytest.approx(0.0)


def test_the_integral_is_clamped_and_frozen_while_saturated():
    pid = Pid(ki=2.0, kd=0.0, i_limit=0.5, d_filter_s=0.0)
    for _ in range(1000):
        out = pid.step(0.0, 1.0, 0.01)
    assert out == pytest.approx(0.5)
    pid.reset()
    for _ in range(100):
        pid.step(0.0, 1.0, 0.01, freeze=True)
    assert pid.integral == 0.0


def test_hover_maps_to_level_attitude_and_weight():
    a = att((0.0, 0.0, 0.0))
    assert (a.roll, a.pitch) == (0.0, 0.0)
    assert a.thrust == pytest.approx(M * G) and not a.saturated


@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.0])
def test_the_mapped_attitude_and_thrust_produce_the_commanded_acceleration(yaw):
    cmd = (0.8, -0.5, 0.3)
    a = att(cmd, yaw)
    bz = body_z(a.roll, a.pitch, a.yaw)
    got = tuple(a.thrust / M * bz[i] - (G if i == 2 else 0.0) for i in range(3))
    assert got == pytest.approx(cmd, abs=1e-9)
    assert a.yaw == yaw


def test_tilt_saturates_at_25_degrees_and_thrust_at_the_vehicle_limits():
    a = att((20.0, 0.0, 0.0))
    assert a.pitch == pytest.approx(TILT) and a.saturated
    assert att((0.0, 0.0, 50.0), tmax=0.5).thrust == 0.5
    assert att((0.0, 0.0, -9.0), tmin=0.08).thrust == 0.08


def test_positive_pitch_accelerates_along_plus_x_and_positive_roll_along_minus_y():
    assert att((1.0, 0.0, 0.0)).pitch > 0.0
    assert att((0.0, 1.0, 0.0)).roll < 0.0


@pytest.mark.parametrize(
    "held, step, left",
    [(0.3, 0.2, 0.1), (0.3, 0.5, 0.0), (0.3, -0.2, 0.3), (-0.3, -0.2, -0.1), (-0.3, 0.2, -0.3)],
)
def test_a_growing_feed_forward_takes_back_only_what_the_integral_holds(held, step, left):
    """[m/s^2] the integral's contribution before (held) and after a feed-forward step."""
    ctl = TauController(TauGains())
    ctl.pid.integral = held / TauGains().ki
    ctl.give_back(step)
    assert TauGains().ki * ctl.pid.integral == pytest.approx(left, abs=1e-12)


@pytest.mark.parametrize("held, starts", [(0.3, 0.3), (-0.4, -0.4), (2.5, 1.0), (-3.0, -1.0)])
def test_a_reset_starts_the_integral_supplying_what_it_is_handed(held, starts):
    """[m/s^2] handed over (the approach's integral at the trigger), within i_limit (1)."""
    ctl = TauController(TauGains())
    ctl.pid.integral, ctl.pid._prev = 5.0, 0.2
    ctl.reset(held)
    assert TauGains().ki * ctl.pid.integral == pytest.approx(starts, abs=1e-12)
    assert ctl.pid._prev is None


@pytest.mark.parametrize("tau", [-0.4, -0.6])
@pytest.mark.parametrize("kp_hold", [0.5, 2.0, 100.0])
def test_a_speed_references_gain_is_the_one_given_both_ways(tau, kp_hold):
    """Stage 2 (kp_hold given): no schedule, kp_hold on either side of the reference;
    without it, eq. 20's schedule."""
    g = TauGains(ki=0.0, kd=0.0, feedforward=False)
    held, sched = TauController(g), TauController(g)
    e = tau_error(-0.5, tau)
    assert held.step(state(tau), -0.5, 0.0, 0.01, kp_hold=kp_hold) == pytest.approx(kp_hold * e)
    kp = g.kp_fast if e < 0.0 else g.kp_slow
    assert sched.step(state(tau), -0.5, 0.0, 0.01) == pytest.approx(kp * e)


@pytest.mark.parametrize("ki", [0.5, 6.0, 40.0])
def test_a_retuned_integral_supplies_what_it_supplied(ki):
    """Stage 2's integral gain (references.hold_loop) replaces the approach's without a
    step in the command; the next error then integrates at the new gain."""
    ctl = TauController(TauGains(kd=0.0, feedforward=False))
    ctl.reset(0.4)
    ctl.retune(ki)
    assert ctl.pid.ki * ctl.pid.integral == pytest.approx(0.4, abs=1e-12)
    before = ctl.pid.ki * ctl.pid.integral
    ctl.step(state(-0.5), -0.5, 0.0, 0.01, kp_hold=1.0)
    assert ctl.pid.ki * ctl.pid.integral - before == pytest.approx(0.0, abs=1e-12)
    ctl.step(state(-0.4), -0.5, 0.0, 0.01, kp_hold=1.0)
    assert ctl.pid.ki * ctl.pid.integral - before == pytest.approx(
        ki * tau_error(-0.5, -0.4) * 0.01, rel=1e-9
    )
