"""perchd.campaign.flights: what a campaign flies, how each flight goes, and the table it makes."""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import numpy as np
import pytest
from simflight import Sim  # the closed-loop tests' own simulated flight

from perchd.campaign.batches import units
from perchd.campaign.flights import (
    COLUMNS,
    FlightSpec,
    Spread,
    campaign_config,
    default_policy,
    default_ranges,
    fly_one,
    grid_specs,
    random_specs,
    run_campaign,
    start_for,
    summarize,
    write_table,
)
from perchd.core.errors import ConfigError
from perchd.flight.config import FlightConfig, SurfaceConfig, TriggerPolicy
from perchd.logs.flightlog import read_log
from perchd.tau import load_plan, retarget

PLANS = Path(__file__).parents[2] / "plans"
ROBUST = load_plan(PLANS / "robust-n3-largest.json")
CFG = campaign_config(FlightConfig(), TriggerPolicy.ROBUST)


def spec(x0: float, v0: float, gust_s: float = 0.0, dv=(0.0, 0.0, 0.0), seed: int = 3):
    return FlightSpec(0, x0, v0, gust_s, dv, seed)


def test_a_robust_plan_is_flown_inside_its_box_by_default_and_others_are_replanned():
    (xl, xh), (vl, vh) = ROBUST.robust
    (x, v) = default_ranges(ROBUST)
    assert x + v == pytest.approx((xl + 0.04, xh - 0.04, vl + 0.04, vh - 0.04))
    assert default_policy(ROBUST) is TriggerPolicy.ROBUST
    plain = load_plan(PLANS / "case1-ipts-n3.json")
    (x, v) = default_ranges(plain)
    assert x + v == pytest.approx((-3.3, -2.7, 1.35, 1.65))
    assert default_policy(plain) is TriggerPolicy.REPLAN


def test_a_grid_spans_the_ranges_corners_included():
    specs = grid_specs(Spread((-3.4, -2.8), (1.0, 2.0)), 3, 2, 2.0)
    assert [s.x0 for s in specs] == pytest.approx([-3.4, -3.4, -3.1, -3.1, -2.8, -2.8])
    assert [s.v0 for s in specs] == pytest.approx([1.0, 2.0, 1.0, 2.0, 1.0, 2.0])
    assert [s.index for s in specs] == list(range(6))
    assert grid_specs(Spread((-3.4, -2.8), (1.0, 2.0)), 1, 1, 2.0)[0].x0 == pytest.approx(-3.1)


def test_random_trigger_states_stay_in_their_ranges_and_a_seed_repeats_them():
    spread = Spread((-3.4, -2.8), (1.0, 2.0), gust_mps=0.3, seed=5)
    specs = random_specs(spread, 200, 2.0)
    xs, vs = np.array([s.x0 for s in specs]), np.array([s.v0 for s in specs])
    assert xs.min() >= -3.4 and xs.max() <= -2.8 and vs.min() >= 1.0 and vs.max() <= 2.0
    assert xs.max() - xs.min() > 0.5 and vs.max() - vs.min() > 0.9  # spread, not clumped
    gusts = np.array([s.gust_dv for s in specs])
    assert np.abs(gusts).max() <= 0.3 and np.abs(gusts).max() > 0.25
    assert all(0.2 <= s.gust_s <= 1.2 for s in specs)  # 10..60 % of the 2 s plan
    assert random_specs(spread, 200, 2.0) == specs
    assert random_specs(dataclasses.replace(spread, seed=6), 200, 2.0) != specs
    assert len({s.seed for s in specs}) == 200  # each flight its own mocap noise


def test_without_gusts_no_flight_is_kicked():
    assert all(
        s.gust_dv == (0.0, 0.0, 0.0) and s.gust_s == 0.0
        for s in random_specs(Spread((-3.4, -2.8), (1.0, 2.0)), 20, 2.0)
    )


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"x0": (-2.8, -3.4)}, "--x0 -2.8 -3.4: LO must not exceed HI (by 0.6)"),
        ({"x0": (-1.0, 0.5)}, "a trigger gap must be < 0 m"),
        ({"v0": (0.0, 1.0)}, "a closing speed must be > 0 m/s"),
        ({"gust_mps": 2.5}, "--gust 2.5 m/s is outside 0..2 m/s"),
        ({"seed": -1}, "--seed -1: must be >= 0"),
    ],
)
def test_a_bad_spread_is_one_error_naming_the_option(kwargs, words):
    base = {"x0": (-3.4, -2.8), "v0": (1.0, 2.0)}
    with pytest.raises(
        ConfigError, match=words.replace(".", r"\.").replace("(", r"\(").replace(")", r"\)")
    ):
        Spread(**{**base, **kwargs})


def test_a_campaign_needs_at_least_one_flight():
    spread = Spread((-3.4, -2.8), (1.0, 2.0))
    with pytest.raises(ConfigError, match="--flights 0"):
        random_specs(spread, 0, 2.0)
    with pytest.raises(ConfigError, match="--grid 0 3"):
        grid_specs(spread, 0, 3, 2.0)


def test_the_start_leaves_the_approach_within_its_acceleration_limit():
    cfg = FlightConfig()
    for x0, v0 in [(-3.0, 1.5), (-3.4, 2.45), (-2.7, 0.7)]:
        x, y, z = start_for(x0, v0, cfg)
        need = v0**2 / (2 * (x0 - x))
        assert need <= 0.75 * cfg.approach.accel_max_mps2 + 1e-9 and (y, z) == (0.0, 1.0)
    wall = dataclasses.replace(cfg, surface=SurfaceConfig((2.0, 1.0, 0.5), (0.0, 1.0, 0.0)))
    x, y, z = start_for(-3.0, 1.5, wall)
    assert (x, z) == pytest.approx((2.0, 1.5)) and y < 1.0 - 3.0


def test_a_flight_is_the_same_flight_the_closed_loop_tests_fly(tmp_path):
    """Re-derived through tests/closedloop/simflight.py: same plan, start and noise seed."""
    spread = Spread((-3.2, -3.0), (1.4, 1.6), latency_s=0.02, noise_m=0.001)
    row = fly_one(ROBUST, CFG, spread, spec(-3.1, 1.5), tmp_path / "a.jsonl")
    x, y, z = start_for(-3.1, 1.5, CFG)
    ref = Sim(f"sim://?start={x},{y},{z}&latency=0.02&noise=0.001&seed=3").fly(
        retarget(ROBUST, -3.1, 1.5), tmp_path / "b.jsonl", CFG
    )
    assert row.outcome == ref.outcome.name == "CONTACT"
    assert row.contact_speed == ref.true_contact_speed
    assert row.perch_time == ref.true_perch_time
    assert row.plan_duration == ref.plan_duration
    assert (row.trigger_x, row.trigger_v) == (ref.trigger.x, ref.trigger.v)
    assert "robust: retargeted" in row.action


def test_a_row_holds_the_figures_that_follow_from_each_other(tmp_path):
    row = fly_one(
        ROBUST, CFG, Spread((-3.2, -3.0), (1.4, 1.6)), spec(-3.1, 1.5), tmp_path / "f.jsonl"
    )
    assert row.perch_error_s == pytest.approx(row.perch_time - row.plan_duration)
    assert (row.v_lo, row.v_hi) == (0.7, 1.0) and row.in_window
    assert abs(row.trigger_x + 3.1) < 0.03 and abs(row.trigger_v - 1.5) < 0.03
    assert abs(row.contact_speed - row.contact_speed_est) < 0.02
    log = read_log(tmp_path / "f.jsonl")
    assert log.complete and log.end["outcome"] == "CONTACT"
    assert log.header["campaign_flight"]["x0"] == -3.1


def test_an_aim_outside_the_robust_box_is_refused(tmp_path):
    (xl, _), (vl, _) = ROBUST.robust
    row = fly_one(
        ROBUST, CFG, Spread((-4.0, -3.0), (1.4, 1.6)), spec(xl - 0.2, 1.5), tmp_path / "f.jsonl"
    )
    assert row.outcome == "TRIGGER_REFUSED" and "outside the robust box" in row.detail
    assert row.contact_speed is None and row.perch_error_s is None and not row.in_window


def test_a_gust_kicks_the_vehicle_at_its_moment_and_not_before(tmp_path):
    spread = Spread((-3.2, -3.0), (1.4, 1.6), gust_mps=0.5)
    calm = fly_one(ROBUST, CFG, spread, spec(-3.1, 1.5), tmp_path / "calm.jsonl")
    gust = fly_one(
        ROBUST, CFG, spread, spec(-3.1, 1.5, 0.8, (0.5, 0.0, 0.0)), tmp_path / "gust.jsonl"
    )
    assert calm.outcome == gust.outcome == "CONTACT"
    a, b = read_log(tmp_path / "calm.jsonl"), read_log(tmp_path / "gust.jsonl")
    t_trig = next(e.t for e in b.events if e.kind == "stage1")
    before = [(r.xdot, s.xdot) for r, s in zip(a.rows, b.rows) if r.t < t_trig + 0.79]
    after = [
        s.xdot - r.xdot for r, s in zip(a.rows, b.rows) if t_trig + 0.85 <= r.t <= t_trig + 0.9
    ]
    assert all(x == y for x, y in before)  # the same flight up to the gust
    assert min(after) > 0.3  # then 0.5 m/s faster, the controller braking
    assert gust.gust_dvx == 0.5 and gust.gust_s == 0.8


def test_worker_processes_fly_the_same_table(tmp_path):
    spread = Spread((-3.2, -2.9), (1.2, 1.8), noise_m=0.001, gust_mps=0.2, seed=2)
    specs = grid_specs(spread, 2, 2, ROBUST.duration)
    one = run_campaign(ROBUST, CFG, spread, specs, jobs=1)
    seen = []
    two = run_campaign(ROBUST, CFG, spread, specs, jobs=2, log_dir=tmp_path, on_row=seen.append)
    assert one == two and [r.index for r in two] == [0, 1, 2, 3]
    assert sorted(r.index for r in seen) == [0, 1, 2, 3]
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"flight-000{i}.jsonl" for i in range(4)]


def test_the_table_and_the_summary_agree_with_the_rows(tmp_path):
    spread = Spread((-3.3, -2.9), (0.8, 2.4), seed=4)
    (xl, _), _ = ROBUST.robust
    specs = grid_specs(spread, 2, 2, ROBUST.duration) + [
        FlightSpec(4, xl - 0.2, 1.5, 0.0, (0.0, 0.0, 0.0), 9)
    ]  # refused: outside the box
    rows = run_campaign(ROBUST, CFG, spread, specs)
    write_table(rows, tmp_path / "t.csv")
    with open(tmp_path / "t.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert tuple(table[0]) == COLUMNS and len(table) == 5
    outcomes = [t["outcome"] for t in table]
    speeds = sorted(float(t["contact_speed"]) for t in table if t["contact_speed"])
    errors = sorted(float(t["perch_error_s"]) for t in table if t["perch_error_s"])
    s = summarize(rows)
    assert s.flights == 5 and s.outcomes == {"CONTACT": 4, "TRIGGER_REFUSED": 1}
    assert outcomes.count("CONTACT") == 4 and table[4]["contact_speed"] == ""
    assert s.in_window == sum(t["in_window"] == "True" for t in table) == 4
    assert (s.contact_speed.min, s.contact_speed.max) == pytest.approx(
        (speeds[0], speeds[-1]), abs=1e-6
    )
    assert s.contact_speed.median == pytest.approx((speeds[1] + speeds[2]) / 2, abs=1e-6)
    assert s.perch_error_s.median == pytest.approx((errors[1] + errors[2]) / 2, abs=1e-6)
    dv = sorted(
        float(t["contact_speed"]) - float(t["plan_v_contact"]) for t in table if t["contact_speed"]
    )
    assert (s.speed_error_mps.min, s.speed_error_mps.max) == pytest.approx(
        (dv[0], dv[-1]), abs=1e-6
    )
    pct = sorted(
        100 * float(t["perch_error_s"]) / float(t["plan_duration"])
        for t in table
        if t["perch_error_s"]
    )
    assert s.perch_error_pct.max == pytest.approx(pct[-1], abs=1e-4)


def test_units_ramp_up_and_down_so_rows_come_at_once_and_the_workers_end_together():
    flights = list(range(100))  # units slice whatever they are given, in order
    cut = units(flights, 2, 25)
    assert [f for unit in cut for f in unit] == flights
    sizes = [len(unit) for unit in cut]
    assert sizes[:8] == [1, 1, 2, 2, 4, 4, 8, 8] and max(sizes) == 13  # 100 / (4 x 2)
    assert sizes[-4:] == [1, 1, 1, 1]  # none longer than what is left / (2 workers)
