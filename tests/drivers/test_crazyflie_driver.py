"""The Crazyflie driver, through real cflib over its udp:// link, against a CRTP responder."""

from __future__ import annotations

import math
import socket
import sys
import time

import pytest
from crtp_responder import STOP, CrtpResponder
from ticks import level, ticks_until_lost

from perchd.core.errors import LinkError, MissingExtraError, UriError
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Phase, Pose, Setpoint
from perchd.drivers import crazyflie
from perchd.drivers.base import open_driver
from perchd.drivers.crazyflie import PING_S
from perchd.drivers.thrust import CrazyflieThrust

pytest.importorskip("cflib")

HOVER_N = 0.030 * 9.81  # the default thrust model's vehicle


@pytest.fixture
def responder():
    r = CrtpResponder()
    yield r
    r.close()


@pytest.fixture
def cf(responder):
    driver = open_driver(responder.uri, Runtime.real())
    driver.connect()
    yield driver
    driver.close()


def foerster_motor_newtons(u: float) -> float:
    """Per-motor static thrust of a CF2.0 (Foerster 2015), written out again for the test."""
    return 2.130295e-11 * u**2 + 1.032633e-6 * u + 5.484560e-4


def test_connecting_sends_the_zero_thrust_setpoint_that_unlocks_the_motors(responder, cf):
    assert responder.wait_for(lambda: responder.setpoints())
    first = responder.setpoints()[0]
    assert (first.roll_deg, first.wire_pitch_deg, first.yawrate_dps, first.thrust) == (0, 0, 0, 0)
    assert cf.health().ok


def test_angles_go_out_in_degrees_with_cflibs_pitch_sign(responder, cf):
    cf.send(Setpoint(0.0, 0.1, 0.2, 0.0, HOVER_N, 7, Phase.STAGE1))
    assert responder.wait_for(lambda: any(s.thrust for s in responder.setpoints()))
    sent = next(s for s in responder.setpoints() if s.thrust)
    assert sent.roll_deg == pytest.approx(5.729578, abs=1e-4)
    # perchd's +0.2 rad is nose-down (accelerates along +X); the firmware's legacy pitch
    # is positive nose-up, so the wire carries -11.46 degrees.
    assert sent.wire_pitch_deg == pytest.approx(-11.459156, abs=1e-4)


def test_hover_thrust_is_36000_units_and_twice_the_weight_follows_the_motor_curve(responder, cf):
    cf.send(level(HOVER_N))
    cf.send(level(2 * HOVER_N))
    assert responder.wait_for(lambda: len({s.thrust for s in responder.setpoints()}) >= 3)
    thrusts = [s.thrust for s in responder.setpoints() if s.thrust]
    assert thrusts[0] == 36000
    # re-derive 2x weight by bisection on the identified curve: f(u) = 2 f(36000)
    lo, hi = 36000.0, 65535.0
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (
            (mid, hi)
            if foerster_motor_newtons(mid) < 2 * foerster_motor_newtons(36000)
            else (lo, mid)
        )
    assert thrusts[1] == pytest.approx(lo, abs=1)
    assert 50000 < thrusts[1] < 60000  # below the firmware's 60000 clamp


def test_the_thrust_model_clamps_and_round_trips():
    model = CrazyflieThrust()
    assert model.units(0.0) == 0 and model.units(-1.0) == 0 and model.units(math.nan) == 0
    assert model.units(10.0) == 60000  # the firmware's RPYT clamp (crtp_commander_rpyt.c)
    # the controller's thrust_max_n on the SITL vehicle's calibration: 63599 before the clamp
    assert CrazyflieThrust(hover_units=38800, mass_kg=0.0282).units(0.58) == 60000
    assert model.newtons(model.units(0.2)) == pytest.approx(0.2, abs=2e-5)
    light = CrazyflieThrust(hover_units=34000, mass_kg=0.027)
    assert light.units(0.027 * 9.81) == 34000


def test_setpoints_stream_at_the_loop_rate(responder, cf):
    start = time.monotonic()
    for k in range(30):  # 100 Hz for 0.3 s
        time.sleep(max(0.0, start + k * 0.01 - time.monotonic()))
        cf.send(Setpoint(k * 0.01, 0.01 * (k + 1), 0.0, 0.0, HOVER_N, k, Phase.STAGE1))
    time.sleep(0.05)
    rolls = [round(s.roll_deg, 3) for s in responder.setpoints()]
    expected = [round(math.degrees(0.01 * (k + 1)), 3) for k in range(30)]
    assert [r for r in rolls if r in expected] == expected  # every tick, in order


def test_a_silent_loop_never_leaves_the_firmware_500ms_without_a_levelled_setpoint(responder, cf):
    cf.send(Setpoint(0.0, 0.2, 0.2, 0.0, HOVER_N, 1, Phase.STAGE1))
    time.sleep(1.2)
    tail = [s for s in responder.setpoints() if s.thrust]
    gaps = [b.t - a.t for a, b in zip(tail, tail[1:])]
    assert len(tail) >= 8 and max(gaps) < 0.2
    # levelled at the thrust's vertical part, not the tilted thrust (which would climb)
    hold = cf.model.units(HOVER_N * math.cos(0.2) * math.cos(0.2))
    assert all((s.roll_deg, s.wire_pitch_deg, s.thrust) == (0, 0, hold) for s in tail[1:])


def test_yaw_becomes_a_rate_once_the_measured_yaw_is_known(responder, cf):
    cf.send(Setpoint(0.0, 0.0, 0.0, 0.1, HOVER_N, 1, Phase.STAGE1))
    half = math.sin(0.05)  # measured yaw 0.1 rad about +Z
    cf.observe_pose(Pose("cf1", 1, 0.0, (0, 0, 0), (0, 0, half, math.cos(0.05))))
    cf.send(Setpoint(0.0, 0.0, 0.0, 0.3, HOVER_N, 2, Phase.STAGE1))
    cf.send(Setpoint(0.0, 0.0, 0.0, -0.1, HOVER_N, 3, Phase.STAGE1))
    assert responder.wait_for(lambda: len([s for s in responder.setpoints() if s.thrust]) >= 3)
    rates = [s.yawrate_dps for s in responder.setpoints() if s.thrust][:3]
    assert rates[0] == 0.0  # no measured yaw yet: hold heading
    # the firmware negates the RPYT yaw rate (crtp_commander_rpyt.c: attitudeRate.yaw =
    # -yaw), so the wire carries it clockwise-positive: a counter-clockwise correction
    # (setpoint 0.3 rad, measured 0.1 rad) goes out negative
    assert rates[1] == pytest.approx(-2.0 * math.degrees(0.2), abs=1e-3)
    assert rates[2] == pytest.approx(2.0 * math.degrees(0.2), abs=1e-3)  # clockwise


def test_observed_poses_reach_the_estimator_as_extpose_when_asked():
    r = CrtpResponder()
    try:
        with open_driver(r.uri + "?extpose=1", Runtime.real()) as cf:
            cf.observe_pose(Pose("cf1", 1, 0.0, (1.0, -2.0, 0.5), (0.0, 0.0, 0.0, 1.0)))
            assert r.wait_for(lambda: r.extposes())
        assert r.extposes()[0] == pytest.approx((1.0, -2.0, 0.5, 0.0, 0.0, 0.0, 1.0))
    finally:
        r.close()


def test_failsafe_sends_the_stop_setpoint_and_nothing_after_it(responder, cf):
    cf.send(level(HOVER_N))
    cf.failsafe(EndReason.TILT_LIMIT)
    cf.failsafe(EndReason.TILT_LIMIT)  # idempotent
    cf.send(level(HOVER_N))  # dropped: nothing re-arms thrust after a failsafe
    time.sleep(0.3)
    stops = responder.stops()
    assert len(stops) >= 4  # each failsafe sends the stop twice, then the repeats
    assert all(s.t < stops[0].t for s in responder.setpoints())


def test_the_stop_is_repeated_at_the_ping_rate_until_close(responder, cf):
    """A stop sent into a dead link is lost: the driver keeps sending it, so a link that
    comes back delivers it (tests/faults: the relay's outage)."""
    cf.failsafe(EndReason.LOST_LINK)
    time.sleep(0.5)
    first = len(responder.stops())
    gaps = [b.t - a.t for a, b in zip(responder.stops()[2:], responder.stops()[3:])]
    assert first >= 2 + 0.5 / PING_S * 0.5  # at least half the ping rate on a shared CPU
    assert max(gaps) < 5 * PING_S
    cf.close()
    time.sleep(0.1)
    closed = len(responder.stops())
    time.sleep(0.2)
    assert len(responder.stops()) == closed  # close() ends the repeats


def test_the_stop_repeats_end_after_their_window(responder, monkeypatch):
    monkeypatch.setattr(crazyflie, "FAILSAFE_REPEAT_S", 0.2)
    with open_driver(responder.uri, Runtime.real()) as cf:
        cf.failsafe(EndReason.LOST_LINK)
        time.sleep(0.35)
        ended = len(responder.stops())
        time.sleep(0.2)
        assert len(responder.stops()) == ended
        assert 2 + 0.2 / PING_S * 0.5 <= ended <= 2 + 0.2 / PING_S + 1


def test_closing_a_flying_driver_stops_the_motors(responder):
    with open_driver(responder.uri, Runtime.real()) as cf:
        cf.send(level(HOVER_N))
    assert responder.wait_for(lambda: responder.stops())
    assert cf.health().ok is False


def test_a_vehicle_that_never_answers_fails_the_connect_with_a_named_cause(responder):
    responder.mute()
    driver = open_driver(responder.uri + "?wait=0.3", Runtime.real())
    with pytest.raises(LinkError, match="connection failed: no answer to a link echo within 0.3 s"):
        driver.connect()


@pytest.mark.parametrize(
    "query, field",
    [
        ("?mass=1", "mass=1 kg is outside"),
        ("?hover=70000", "hover=70000 units"),
        ("?timeout=x", "timeout='x' is not a number"),
    ],
)
def test_bad_options_are_refused_by_name(query, field):
    with pytest.raises(UriError, match=field):
        open_driver("udp://127.0.0.1:19850" + query, Runtime.real())


@pytest.mark.parametrize(
    "uri",
    ["radio://0/80/2M/ZZZ", "radio://0/200/2M", "radio://0/80/3M", "radio://x/80/2M", "radio://0"],
)
def test_a_radio_uri_typo_is_refused_before_connecting(uri):
    with pytest.raises(UriError, match=r"expected radio://DONGLE/CHANNEL/RATE\[/ADDRESS\]"):
        open_driver(uri, Runtime.real())


def test_well_formed_radio_uris_open_without_a_dongle_until_connect():
    for uri in ("radio://0/80/2M/E7E7E7E7E7", "radio://*/80/250K", "radio://1/0/1M"):
        assert open_driver(uri, Runtime.real()).uri == uri


def test_a_vehicle_that_dies_mid_flight_is_lost_within_3_ticks_and_gets_a_stop(responder):
    cf = open_driver(responder.uri, Runtime.real())
    cf.connect()
    witness = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def die_and_leave_a_witness():
        responder.die()  # the kernel refuses the next datagram: cflib's link error

    try:
        lost_after = ticks_until_lost(cf, 100.0, level(HOVER_N), die_and_leave_a_witness)
        assert lost_after is not None and lost_after <= 3
        assert "connection lost" in cf.health().detail
        witness.bind(("127.0.0.1", responder.port))  # where the vehicle was
        witness.settimeout(1.0)
        cf.failsafe(EndReason.LOST_LINK)  # the attempt reaches the vehicle's address
        heard = [witness.recv(64) for _ in range(40)]  # link pings go there too
        assert bytes([STOP, 0]) in heard
        assert cf.failsafe_reasons[0] is EndReason.LOST_LINK
    finally:
        witness.close()
        cf.close()


def test_a_vehicle_that_hangs_mid_flight_is_lost_within_3_ticks(responder):
    cf = open_driver(responder.uri + "?timeout=0.06", Runtime.real())
    cf.connect()
    try:
        lost_after = ticks_until_lost(cf, 25.0, level(HOVER_N), responder.mute)
        assert lost_after is not None and lost_after <= 3
        assert "silent for" in cf.health().detail
        assert responder.wait_for(lambda: responder.stops())  # the failsafe went out
    finally:
        cf.close()


def test_without_cflib_the_factory_names_the_extra_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "cflib", None)  # as if not installed
    with pytest.raises(MissingExtraError, match=r"pip install 'perchd\[crazyflie\]'"):
        open_driver("radio://0/80/2M/E7E7E7E7E7", Runtime.real())
