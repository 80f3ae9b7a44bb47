"""Acceptance: the paper's case-1 plans flown closed loop in simulation end in contact at
the planned speed and time, nominal and with 20 ms latency + 1 mm noise."""

from __future__ import annotations

import pytest
from simflight import NOISY, PLANS, Sim, case1

from perchd.core.types import EndReason
from perchd.flight.config import FlightConfig, LoopSync, TauGains
from perchd.logs.flightlog import read_log

LINKS = {"nominal": "sim://", "latency+noise": NOISY, "latency+noise seed 1": NOISY + "&seed=1"}


@pytest.fixture(
    scope="module",
    params=[(s, link) for s in ("ctdts", "ipts") for link in LINKS],
    ids=lambda p: f"{p[0]}-{p[1]}",
)
def flown(request, tmp_path_factory):
    strategy, link = request.param
    plan = case1(strategy)
    result = Sim(LINKS[link]).fly(plan, tmp_path_factory.mktemp("perch") / "f.jsonl")
    return plan, result


def test_the_perch_ends_in_contact_inside_the_speed_window(flown):
    plan, res = flown
    lo, hi = plan.limits.v_contact
    assert res.outcome is EndReason.CONTACT
    assert lo <= res.true_contact_speed <= hi
    assert res.true_contact_speed == pytest.approx(res.v_hold_mps, abs=0.05)


def test_the_perch_takes_the_planned_time_within_5_percent(flown):
    plan, res = flown
    assert res.true_perch_time == pytest.approx(plan.duration, rel=0.05)


def test_the_agent_estimates_its_own_contact_as_the_simulator_measured_it(flown):
    _, res = flown
    assert res.contact_speed == pytest.approx(res.true_contact_speed, abs=0.05)
    assert res.perch_time == pytest.approx(res.true_perch_time, abs=0.02)


def test_the_flight_triggered_at_the_plans_state_and_sent_no_failsafe(flown):
    plan, res = flown
    assert res.trigger.x == pytest.approx(plan.x0, abs=0.05)
    assert res.trigger.v == pytest.approx(plan.v0, abs=0.1)
    assert not res.failsafe_sent


def test_the_log_has_one_row_per_tick_and_ends_in_contact(flown):
    _, res = flown
    log = read_log(res.log)
    assert log.complete and log.end["outcome"] == "CONTACT"
    assert len(log.rows) == res.loop.ticks
    assert [r.k for r in log.rows] == list(range(len(log.rows)))
    assert log.rows[-1].end == "CONTACT"
    phases = [r.phase for r in log.rows]
    for a, b in [
        ("hold", "approach"),
        ("approach", "stage1"),
        ("stage1", "stage2"),
        ("stage2", "contact"),
    ]:
        assert phases.index(a) < phases.index(b)


@pytest.mark.parametrize("strategy", ["ctdts", "ipts"])
def test_without_feedforward_the_tau_pid_alone_still_perches_inside_the_window(strategy, tmp_path):
    plan = case1(strategy)
    cfg = FlightConfig(tau_gains=TauGains(feedforward=False))
    res = Sim().fly(plan, tmp_path / "f.jsonl", cfg)
    lo, hi = plan.limits.v_contact
    assert res.outcome is EndReason.CONTACT
    assert lo - 0.05 <= res.true_contact_speed <= hi + 0.05
    assert res.true_perch_time == pytest.approx(plan.duration, rel=0.10)


def test_stage_two_starts_when_the_measured_tau_reaches_tau_s(flown):
    plan, res = flown
    log = read_log(res.log)
    switch = next(e for e in log.events if e.kind == "stage2")
    assert switch.values["tau"] >= plan.tau_s
    before = [r for r in log.rows if r.phase == "stage1"][-1]
    assert before.tau < plan.tau_s


@pytest.mark.parametrize("action,thrust", [("cut", 0.0), ("idle", 0.08)])
def test_after_contact_the_motors_are_cut_or_idled_as_configured(action, thrust, tmp_path):
    from perchd.core.types import Phase
    from perchd.flight.config import PostContact
    from perchd.flight.supervisor import POST_CONTACT_S

    sim = Sim()
    cfg = FlightConfig(post_contact=PostContact(action), sync=LoopSync.FIXED)  # counts ticks
    res = sim.fly(case1("ctdts"), tmp_path / "f.jsonl", cfg)
    after = [sp for sp in sim.world.sent if sp.phase is Phase.CONTACT]
    assert res.outcome is EndReason.CONTACT and not res.failsafe_sent
    assert len(after) == pytest.approx(POST_CONTACT_S * cfg.rate_hz, abs=1)
    assert {sp.thrust for sp in after} == {thrust}
    assert read_log(res.log).rows[-1].phase == "done"


@pytest.mark.parametrize("rate_hz", [50.0, 500.0])
def test_the_loop_perches_as_well_at_50_and_500_hz(rate_hz, tmp_path):
    plan = case1("ipts")
    res = Sim(NOISY).fly(
        plan, tmp_path / "f.jsonl", FlightConfig(rate_hz=rate_hz, sync=LoopSync.FIXED)
    )
    assert res.outcome is EndReason.CONTACT
    assert res.true_contact_speed == pytest.approx(res.v_hold_mps, abs=0.05)
    assert res.loop.ticks == pytest.approx(rate_hz * read_log(res.log).rows[-1].t, rel=0.01)


def _retarget_or_skip():
    import perchd.tau as tau

    if not hasattr(tau, "retarget"):
        pytest.skip("perchd.tau has no retarget yet")
    return tau.retarget


@pytest.mark.parametrize("strategy", ["ctdts", "ipts"])
def test_the_replan_policy_flies_a_plan_made_for_the_measured_trigger_state(strategy, tmp_path):
    _retarget_or_skip()
    from perchd.flight.config import TriggerConfig, TriggerPolicy

    plan = case1(strategy)
    cfg = FlightConfig(trigger=TriggerConfig(TriggerPolicy.REPLAN))
    res = Sim(NOISY).fly(plan, tmp_path / "f.jsonl", cfg)
    assert res.outcome is EndReason.CONTACT
    assert (res.trigger.plan_x0, res.trigger.plan_v0) == (res.trigger.x, res.trigger.v)
    assert res.trigger.action.startswith("replan")
    assert res.true_perch_time == pytest.approx(res.plan_duration, rel=0.05)
    assert res.true_contact_speed == pytest.approx(res.v_hold_mps, abs=0.05)


def test_a_vehicle_on_the_ground_takes_off_holds_and_then_perches(tmp_path):
    sim = Sim("sim://?start=-4.5,0,0")
    res = sim.fly(case1("ipts"), tmp_path / "f.jsonl")
    kinds = [e.kind for e in read_log(res.log).events if not e.kind.startswith("hover-")]
    assert kinds[:3] == ["takeoff", "hold", "approach"]
    assert res.outcome is EndReason.CONTACT
    assert sim.world.contact.p[2] == pytest.approx(1.0, abs=0.1)  # at take-off height


def test_the_robust_policy_flies_a_certified_plan_from_the_measured_state(tmp_path):
    _retarget_or_skip()
    from perchd.flight.config import TriggerConfig, TriggerPolicy
    from perchd.tau import load_plan

    path = PLANS / "robust-n3-around-case1.json"
    if not path.exists():
        pytest.skip(f"{path.name} is not in this checkout")
    plan = load_plan(path)
    cfg = FlightConfig(trigger=TriggerConfig(TriggerPolicy.ROBUST))
    res = Sim(NOISY).fly(plan, tmp_path / "f.jsonl", cfg)
    lo, hi = plan.limits.v_contact
    assert res.outcome is EndReason.CONTACT
    assert res.trigger.action.startswith("robust")
    assert lo <= res.true_contact_speed <= hi
    assert res.true_perch_time == pytest.approx(res.plan_duration, rel=0.05)
