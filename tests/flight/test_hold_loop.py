"""Stage 2's speed loop (flight/references.py `hold_loop`, docs/controller.md "Stage 2"):
its gain, integral and margin follow from the vehicle's lag and the wall's push alone."""

from __future__ import annotations

import dataclasses

import pytest
from caseplans import case1
from hypothesis import given, settings
from hypothesis import strategies as st
from simflight import Sim

from perchd.core.types import EndReason
from perchd.flight.config import FlightConfig, TauGains
from perchd.flight.references import (
    HOLD_RATE,
    KI_SHARE,
    MARGIN_MAX_MPS,
    hold_loop,
    hold_speed,
)
from perchd.logs.flightlog import read_log

PLAN = case1("ipts")


def test_the_readme_plan_on_a_fast_vehicle_holds_its_droop_inside_the_window():
    """Re-derived by hand: lag 0.071 s allows 1/0.071 = 14.1 /s, above kp_fast (10.56 m/s^2
    at V_c 1 m/s: 10.56 /s), so kp = kp_fast; a 0.3 m/s^2 push droops 0.3 / 10.56 = 0.0284
    m/s; V_hold = 1.0 - 0.0284."""
    loop = hold_loop(PLAN, TauGains(), 0.071)
    assert loop.kp_mps2 == pytest.approx(10.559375)
    assert loop.margin_mps == pytest.approx(0.3 / 10.559375, rel=1e-9)
    assert loop.v_hold_mps == pytest.approx(1.0 - 0.3 / 10.559375, abs=1e-9)
    assert loop.ki_mps3 == pytest.approx(0.25 * 10.559375**2, rel=1e-9)


def test_a_slow_vehicle_gets_a_slow_loop_and_the_largest_margin():
    """ArduCopter's lag, 0.34 s: kp = 1.0 / 0.34 = 2.94 m/s^2; its droop, 0.102 m/s, is
    held to MARGIN_MAX_MPS; the integral stays the configured one (2.2 < 6.0 m/s^3)."""
    loop = hold_loop(PLAN, TauGains(), 0.34)
    assert loop.kp_mps2 == pytest.approx(1.0 / 0.34, rel=1e-9)
    assert loop.margin_mps == MARGIN_MAX_MPS
    assert loop.v_hold_mps == pytest.approx(1.0 - MARGIN_MAX_MPS)
    assert loop.ki_mps3 == TauGains().ki


def test_a_vehicle_of_unknown_lag_gets_the_cautious_loop():
    """No lag identified (a refused fit, identification off): kp_slow, the configured
    integral and the largest margin, whatever the configured lead would allow."""
    loop = hold_loop(PLAN, TauGains(), None)
    assert (loop.kp_mps2, loop.ki_mps3) == (TauGains().kp_slow, TauGains().ki)
    assert loop.margin_mps == MARGIN_MAX_MPS
    assert loop.v_hold_mps == pytest.approx(1.0 - MARGIN_MAX_MPS)
    calm = dataclasses.replace(TauGains(), wall_push_mps2=0.0)
    assert hold_loop(PLAN, calm, None).v_hold_mps == pytest.approx(float(PLAN.v_contact))


def test_no_push_holds_the_plans_contact_speed():
    gains = dataclasses.replace(TauGains(), wall_push_mps2=0.0)
    assert hold_loop(PLAN, gains, 0.1).v_hold_mps == pytest.approx(float(PLAN.v_contact))


@settings(max_examples=300, deadline=None)
@given(
    lag=st.floats(0.0, 1.0),
    push=st.floats(0.0, 5.0),
    kp_fast=st.floats(0.1, 200.0),
    ki=st.floats(0.0, 100.0),
)
def test_the_loop_is_never_faster_than_the_vehicle_and_its_margin_is_its_droop(
    lag, push, kp_fast, ki
):
    gains = dataclasses.replace(TauGains(), kp_fast=kp_fast, ki=ki, wall_push_mps2=push)
    loop = hold_loop(PLAN, gains, lag)
    v_c = float(PLAN.v_contact)
    lo, hi = PLAN.limits.v_contact
    assert 0.0 < loop.kp_mps2 <= kp_fast
    if lag > 0.0:
        assert loop.kp_mps2 * lag <= HOLD_RATE * v_c * (1 + 1e-12)
    assert loop.ki_mps3 >= ki
    assert loop.ki_mps3 >= KI_SHARE * loop.kp_mps2**2 / v_c * (1 - 1e-12)
    droop = push * v_c / loop.kp_mps2
    assert loop.margin_mps == pytest.approx(min(droop, MARGIN_MAX_MPS))
    assert loop.v_hold_mps == hold_speed(PLAN, loop.margin_mps)
    assert lo <= loop.v_hold_mps <= min(hi, v_c)
    slower = hold_loop(PLAN, gains, lag + 0.05)
    assert slower.v_hold_mps <= loop.v_hold_mps  # a slower vehicle never holds faster


def test_the_flight_holds_the_loop_its_lag_gives_and_says_so(tmp_path):
    log = tmp_path / "f.jsonl"
    res = Sim("sim://?noise=0.001&seed=0").fly(PLAN, log, FlightConfig())
    assert res.outcome is EndReason.CONTACT
    events = read_log(log).events
    said = next(e for e in events if e.kind == "hold-loop")
    lag = next(e for e in events if e.kind == "lag-identified").values["lag_s"]
    expected = hold_loop(PLAN, TauGains(), lag)
    assert said.values["v_hold_mps"] == pytest.approx(expected.v_hold_mps, abs=1e-9)
    assert said.values["kp_mps2"] == pytest.approx(expected.kp_mps2, abs=1e-9)
    assert res.v_hold_mps == pytest.approx(expected.v_hold_mps, abs=1e-9)
    assert f"holds {expected.v_hold_mps:.3f} m/s" in said.detail
