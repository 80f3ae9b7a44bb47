"""Simulated campaign: one robust plan, trigger states drawn across its box, flown closed loop
through the supervisor's 'robust' trigger policy (retarget at the measured state)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from simflight import Sim  # the closed-loop tests' simulated flight

from perchd.campaign.flights import Spread, default_ranges, random_specs, run_campaign
from perchd.core.types import EndReason
from perchd.flight.config import FlightConfig, TriggerConfig, TriggerPolicy
from perchd.tau import load_plan, retarget

PLANS = Path(__file__).parents[2] / "plans"
START = "sim://?start=-7.8,0,1"  # far enough back to reach v0 = 2.5 m/s by |x0| = 3.5 m
ROBUST = FlightConfig(trigger=TriggerConfig(policy=TriggerPolicy.ROBUST))


def robust_plan(name: str, x0: float, v0: float):
    """The plan file retargeted to (x0, v0): the approach aims there, and at trigger the
    supervisor retargets again to the state it measures (same k_1..k_n, same box)."""
    return retarget(load_plan(PLANS / name), x0, v0)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["robust-n3-largest.json", "robust-n5-largest.json"])
def test_a_hundred_flights_across_the_box_all_perch_inside_the_speed_window(name):
    plan = load_plan(PLANS / name)
    # aims 4 cm, 4 cm/s inside the box: the vehicle triggers within ~2 cm, 1 cm/s of its aim
    spread = Spread(*default_ranges(plan), seed=7)
    rows = run_campaign(plan, ROBUST, spread, random_specs(spread, 100, plan.duration))
    for r in rows:
        assert r.outcome == "CONTACT", (r.x0_aim, r.v0_aim, r.detail)
        assert "retargeted" in r.action
    speeds = [r.contact_speed for r in rows]
    assert 0.7 <= min(speeds) and max(speeds) <= 1.0, (min(speeds), max(speeds))


def test_a_trigger_outside_the_box_is_refused_before_stage_one(tmp_path):
    plan = robust_plan("robust-n3-largest.json", -3.0, 1.5)
    (xl, xh), (vl, vh) = plan.robust
    plan = dataclasses.replace(plan, robust=((xl, xh), (vl, 1.4)))  # 1.5 m/s is now outside
    res = Sim(START).fly(plan, tmp_path / "f.jsonl", ROBUST)
    assert res.outcome is EndReason.TRIGGER_REFUSED
    assert "outside the plan's robust box" in res.detail
