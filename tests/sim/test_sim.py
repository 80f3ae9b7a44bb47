"""The simulated world: a plant that hovers and flies as commanded, a surface that records
contact, and mocap at its rate, latency and noise; both sim:// plug-ins share it."""

from __future__ import annotations

import math
import statistics

import pytest

from perchd.core.clock import ManualClock
from perchd.core.errors import UriError
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Phase, Setpoint
from perchd.core.uri import parse_uri
from perchd.core.uriparams import split_sim
from perchd.drivers.base import open_driver
from perchd.mocap.base import open_source

G = 9.81


def world(uri="sim://"):
    rt = Runtime(ManualClock(0.0))
    driver_uri, mocap_uri = split_sim(parse_uri(uri))  # one world's keys, each its side's
    d, m = open_driver(driver_uri, rt), open_source(mocap_uri, rt)
    d.connect()
    m.start()
    return rt, d, m


def sp(t, pitch=0.0, thrust=0.030 * G):
    return Setpoint(t, 0.0, pitch, 0.0, thrust, 0, Phase.STAGE1)


def coast(uri: str, vx: float, ticks: int = 101):
    """The world of `uri`, its vehicle set moving at vx [m/s] along X, then held level at
    its weight for `ticks` 10 ms ticks."""
    rt, d, _ = world(uri)
    rt.sim.plant.v[0] = vx
    for k in range(ticks):
        rt.clock.sleep_until(k * 0.01)
        d.send(sp(k * 0.01))
    return rt


def test_driver_and_mocap_share_one_world_created_by_the_first_to_open():
    rt, d, m = world()
    assert d.world is rt.sim and m.world is rt.sim


def test_a_hovering_vehicle_given_its_weight_stays_put():
    p = coast("sim://", 0.0, ticks=200).sim.state().p
    assert p == pytest.approx((-4.5, 0.0, 1.0), abs=1e-6)


def test_a_pitched_vehicle_accelerates_as_the_attitude_and_motor_lags_allow():
    rt, d, m = world()
    pitch = math.radians(10.0)
    thrust = 0.030 * G / math.cos(pitch)
    for k in range(101):
        rt.clock.sleep_until(k * 0.01)
        d.send(sp(k * 0.01, pitch, thrust))
    v = rt.sim.state().v
    # G tan(10 deg) = 1.73 m/s^2 for 1 s, less what the 0.07 s attitude lag costs
    assert v[0] == pytest.approx(G * math.tan(pitch) * (1.0 - 0.07), rel=0.02)
    assert v[2] == pytest.approx(0.0, abs=0.02)


def test_quadratic_drag_brakes_by_qdrag_times_the_speed_squared():
    """Level at the weight, 2 m/s along X: v' = -q v^2, so v(t) = v0 / (1 + q v0 t)."""
    rt = coast("sim://?qdrag=0.5", 2.0)
    assert rt.sim.state().v[0] == pytest.approx(2.0 / (1.0 + 0.5 * 2.0 * 1.0), rel=0.01)


def test_a_draught_pushes_only_beyond_its_x():
    rt = coast("sim://?draught=-4.4,-0.5", 1.0)  # from x = -4.5: 0.1 m free, then braked
    # 0.1 s to reach x = -4.4, then 0.9 s braked: v = 1 - 0.5 x 0.9
    assert rt.sim.state().v[0] == pytest.approx(1.0 - 0.5 * 0.9, abs=0.01)


def test_command_latency_delays_the_setpoint():
    rt, d, _ = world("sim://?latency=0.02")
    d.send(sp(0.0, 0.2))
    rt.clock.sleep_until(0.019)
    assert rt.sim.applied() is None
    rt.clock.sleep_until(0.021)
    assert rt.sim.applied().pitch == 0.2


def test_mocap_poses_come_at_the_rate_with_the_latency_and_the_noise_configured():
    rt, _, m = world("sim://?mocap_rate=100&mocap_latency=0.01&noise=0.002&seed=3")
    seen = []
    for k in range(1, 1001):
        rt.clock.sleep_until(k * 0.001)
        p = m.latest()
        if p is not None and (not seen or p.seq != seen[-1].seq):
            seen.append(p)
            assert rt.clock.now() - p.t == pytest.approx(0.01, abs=1.1e-3)
    assert len(seen) == 100 and seen[1].t - seen[0].t == pytest.approx(0.01)
    assert statistics.pstdev([p.p[0] for p in seen]) == pytest.approx(0.002, rel=0.2)


def test_waiting_for_a_pose_moves_simulated_time_to_its_arrival():
    rt, _, m = world()
    pose = m.wait(-1, 1.0)
    assert pose.seq == 1 and rt.clock.now() == pytest.approx(0.004)
    assert m.wait(pose.seq, 0.001) is None


def test_reaching_the_surface_records_contact_time_and_speed_and_the_vehicle_stays_perched():
    rt = coast("sim://?start=-0.5,0,1", 1.0, ticks=100)
    c = rt.sim.contact
    assert c.t == pytest.approx(0.5, abs=1e-3) and c.speed == pytest.approx(1.0)
    assert rt.sim.state().p[0] == pytest.approx(0.0, abs=2e-3)


def test_the_failsafe_stops_the_motors_once_and_later_setpoints_are_ignored():
    rt, d, _ = world()
    d.failsafe(EndReason.GEOFENCE)
    d.failsafe(EndReason.GEOFENCE)
    d.send(sp(0.0, 0.3))
    assert rt.sim.failsafes == [EndReason.GEOFENCE]
    assert [s.thrust for s in rt.sim.sent] == [0.0]
    rt.clock.sleep_until(2.0)
    assert rt.sim.state().p[2] == 0.0  # fell to the floor


def test_a_bad_sim_option_is_one_clear_error():
    with pytest.raises(UriError, match="latency=5 s is outside"):
        open_driver("sim://?latency=5", Runtime(ManualClock()))
    with pytest.raises(UriError, match="start='1,2' must be X,Y,Z"):
        open_driver("sim://?start=1,2", Runtime(ManualClock()))
    with pytest.raises(UriError, match="draught='-1,inf' must be X,A"):
        open_driver("sim://?draught=-1,inf", Runtime(ManualClock()))
