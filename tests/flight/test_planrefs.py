"""PlanSampler gives the same references as the Plan API, in float math, for every plan."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import refplans

from perchd.flight.planrefs import PlanSampler
from perchd.tau import load_plan

PLANS = sorted((Path(__file__).resolve().parents[2] / "plans").glob("*.json"))


@pytest.mark.parametrize("path", PLANS, ids=[p.stem for p in PLANS])
def test_it_matches_the_plan_api_over_the_whole_plan(path):
    plan = load_plan(path)
    sampler = PlanSampler(plan)
    two_stage = plan.tau_s is not None
    # the Plan API cannot evaluate a ctds plan's tau_ref (it has no stage 2): use stage 1
    stage1 = {
        "tau_ref": plan.stage1.tau,
        "x": plan.stage1.x,
        "v": plan.stage1.v,
        "a": plan.stage1.a,
    }
    end = plan.duration if two_stage else plan.t_switch * (1 - 1e-9)
    for s in np.linspace(0.0, end, 400):
        got = sampler.at(float(s))
        assert got.stage == plan.stage(s)
        for name in ("tau_ref", "x", "v", "a"):
            want = float((getattr(plan, name) if two_stage else stage1[name])(s))
            assert getattr(got, name) == pytest.approx(want, rel=1e-12, abs=1e-12), (name, s)


def test_a_plan_it_does_not_know_is_asked_through_its_own_methods():
    plan = refplans.ipts()  # the tests' closed-form reference, not a perchd.tau Plan
    got = PlanSampler(plan).at(0.5)
    assert got == (
        int(plan.stage(0.5)),
        float(plan.tau_ref(0.5)),
        float(plan.x(0.5)),
        float(plan.v(0.5)),
        float(plan.a(0.5)),
    )
