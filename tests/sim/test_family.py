"""The vehicle family: its draws stay in their ranges and repeat per seed, the lab's config
changes mass and thrust only, and the family's corners fly end to end into well-formed rows."""

from __future__ import annotations

import dataclasses
import math
import statistics

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from simflight import PLANS

from perchd.campaign.familyrun import PARAMETERS, FamilyRow, fly_member, parameters
from perchd.core.types import EndReason
from perchd.flight.config import FlightConfig, TriggerConfig, TriggerPolicy
from perchd.sim.family import FAMILY, LAB_THRUST_MIN_SHARE, FamilyVehicle, lab_config, sample
from perchd.tau import load_plan


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_every_draw_is_inside_its_range(seed):
    for member in sample(25, seed):
        for name, value in parameters(member).items():
            span = getattr(FAMILY, name)
            assert span.lo <= value <= span.hi, (name, value)
        assert member.plant.thrust_max_n == pytest.approx(
            member.thrust_to_weight * member.plant.mass_kg * member.plant.g
        )


def test_the_draws_span_their_ranges_and_the_mass_is_log_uniform():
    members = sample(2000, 3)
    for name in PARAMETERS:
        span = getattr(FAMILY, name)
        scale = math.log if span.log else float
        places = [
            (scale(parameters(m)[name]) - scale(span.lo)) / (scale(span.hi) - scale(span.lo))
            for m in members
        ]
        assert min(places) < 0.01 and max(places) > 0.99, name
    masses = [m.plant.mass_kg for m in members]
    geometric_middle = math.sqrt(FAMILY.mass_kg.lo * FAMILY.mass_kg.hi)  # 0.27 kg
    assert statistics.median(masses) == pytest.approx(geometric_middle, rel=0.15)


def test_a_seed_draws_the_same_members_whatever_the_sample_size():
    assert sample(6, 11) == sample(6, 11)
    assert sample(12, 11)[:6] == sample(6, 11)
    assert [m.index for m in sample(6, 11)] == list(range(6))
    assert sample(6, 12) != sample(6, 11)
    assert len({m.seed for m in sample(50, 11)}) == 50


def test_lab_config_sets_mass_and_thrust_and_keeps_everything_else():
    base = FlightConfig(rate_hz=250.0, trigger=TriggerConfig(policy=TriggerPolicy.REPLAN))
    member = sample(1, 5)[0]
    cfg = lab_config(member, base)
    for f in dataclasses.fields(FlightConfig):
        if f.name != "vehicle":
            assert getattr(cfg, f.name) == getattr(base, f.name), f.name
    v, full = cfg.vehicle, member.plant.thrust_max_n
    assert (v.mass_kg, v.thrust_max_n, v.hover_thrust_n) == (member.plant.mass_kg, full, None)
    assert v.thrust_min_n == pytest.approx(LAB_THRUST_MIN_SHARE * full)
    assert 0.05 < LAB_THRUST_MIN_SHARE < 0.2
    assert v.g == base.vehicle.g


def corner(
    member: FamilyVehicle, mass_kg: float, thrust_to_weight: float, **plant: float
) -> FamilyVehicle:
    """`member` with its mass, full thrust and any other plant field set."""
    p = dataclasses.replace(
        member.plant,
        mass_kg=mass_kg,
        thrust_max_n=thrust_to_weight * mass_kg * member.plant.g,
        **plant,
    )
    return dataclasses.replace(member, plant=p)


def corners() -> list[FamilyVehicle]:
    """Lightest and weakest, heaviest, slowest attitude, longest delay, slowest motors with
    most drag, slowest and latest mocap: one each, the rest drawn."""
    f, ms = FAMILY, sample(6, 2)
    slow_mocap = dataclasses.replace(
        ms[5],
        mocap=dataclasses.replace(
            ms[5].mocap,
            rate_hz=f.mocap_rate_hz.lo,
            latency_s=f.mocap_latency_s.hi,
            noise_m=f.mocap_noise_m.hi,
        ),
    )
    return [
        corner(ms[0], f.mass_kg.lo, f.thrust_to_weight.lo),
        corner(ms[1], f.mass_kg.hi, f.thrust_to_weight.hi),
        corner(ms[2], 0.3, 2.0, attitude_tau_s=f.attitude_tau_s.hi),
        corner(ms[3], 0.3, 2.0, latency_s=f.latency_s.hi),
        corner(
            ms[4],
            0.3,
            2.0,
            motor_tau_s=f.motor_tau_s.hi,
            drag_per_s=f.drag_per_s.hi,
            qdrag_per_m=f.qdrag_per_m.hi,
        ),
        slow_mocap,
    ]


@pytest.mark.slow
@pytest.mark.parametrize("member", corners(), ids=lambda m: f"corner{m.index}")
def test_a_corner_of_the_family_flies_into_a_well_formed_row(member, tmp_path):
    plan = load_plan(PLANS / "case1-ipts-n3.json")
    base = FlightConfig(trigger=TriggerConfig(policy=TriggerPolicy.REPLAN))
    row = fly_member(plan, member, base, tmp_path / "flight.jsonl")
    assert isinstance(row, FamilyRow)
    assert EndReason[row.outcome] in EndReason
    assert {k: getattr(row, k) for k in PARAMETERS} == parameters(member)
    assert (row.index, row.seed) == (member.index, member.seed)
    assert (row.v_lo, row.v_hi) == tuple(plan.limits.v_contact)
    assert row.plan_duration > 0.0 and row.detail
    touched = row.contact_speed is not None
    assert touched == (row.perch_time is not None) == (row.perch_error_pct is not None)
    assert not touched or row.outcome == "CONTACT"
    assert row.in_window == (touched and row.v_lo <= row.contact_speed <= row.v_hi)
    assert row.on_time == (touched and abs(row.perch_error_pct) <= 3.0)
    if touched:
        assert row.perch_error_pct == pytest.approx(
            100.0 * (row.perch_time - row.plan_duration) / row.plan_duration
        )
