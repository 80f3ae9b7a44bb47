"""Robust search, retargeting, the `plan robust` command and the robust plans in plans/."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from robust_brute import fly, worst_over_box

from perchd.cli import main as perchd
from perchd.core.errors import PlanError
from perchd.tau import Limits, robust
from perchd.tau.certify import Box
from perchd.tau.planfile import load_plan, plan_from_json
from perchd.tau.robust import (
    RobustLimits,
    contact_ratio,
    fastest_k,
    retarget_k,
    shrink_until_certified,
)
from perchd.tau.robustplan import check_plan

LIM = RobustLimits(-0.5, (0.7, 1.0), 2.5, 1.4)
PLANS = sorted((Path(__file__).parents[2] / "plans").glob("robust-*.json"))
K3 = (-0.3111, -0.3082, 0.02853)
ARGS = [
    "plan",
    "robust",
    "--tau-s",
    "-0.5",
    "--v-contact",
    "0.7",
    "1.0",
    "--v-max",
    "2.5",
    "--a-max",
    "1.4",
]


@pytest.fixture(scope="module")
def contracts_box():
    """The docs/contracts.md §2 example box, solved once for the module."""
    return fastest_k(3, Box((-3.9, -3.7), (1.8, 2.0)), LIM, maxiter=10)


def test_a_given_box_gets_a_k_the_brute_force_confirms(contracts_box):
    r = contracts_box
    assert r.certificate.certified
    w = worst_over_box(r.k, r.box.x0, r.box.v0, -0.5, n=5)
    assert w["reaches"] and w["v_peak"] <= 2.5 and w["a_peak"] <= 1.4 + 1e-4
    assert 0.7 <= w["vc_lo"] and w["vc_hi"] <= 1.0


def test_its_worst_duration_is_the_slowest_corner_and_beats_the_paper_table2_k(contracts_box):
    r = contracts_box
    slow = fly(r.k, -3.9, 1.8, -0.5)
    assert r.certificate.duration[1] == pytest.approx(slow.t_s + 0.5, abs=1e-5)
    assert r.certificate.duration[1] < 2.5


@pytest.mark.parametrize(
    "order, box", [(4, Box((-2.92, -2.0), (1.0, 1.65))), (5, Box((-3.43, -2.0), (1.4, 2.15)))]
)
def test_paper_table2_boxes_4_and_5_cannot_be_held_by_any_k(order, box):
    ratio, k0 = contact_ratio(box)
    assert ratio > 1.0 / 0.7
    lo, hi = box.segment(k0)  # two states on one ray: contact speeds scale with |x0|
    assert hi / lo == pytest.approx(ratio)
    with pytest.raises(PlanError, match="no k of any order"):
        fastest_k(order, box, LIM, maxiter=1)


def test_shrinking_finds_the_certified_sub_box_about_a_state():
    grown = Box((-3.8, -2.94), (0.67, 2.49))
    r = shrink_until_certified(K3, grown, LIM, about=(-3.0, 1.5))
    assert r.certificate.certified and r.box.contains(-3.0, 1.5)
    assert (
        r.box.area < grown.area and not LIM.certify(K3, r.box.scaled(1.02, (-3.0, 1.5))).certified
    )


def test_retarget_keeps_k1_to_kn_and_takes_k0_from_the_measured_state():
    box = Box((-3.65, -2.94), (0.67, 2.49))
    k = retarget_k(K3, box, -3.2, 1.6)
    assert k[0] == -0.5 and tuple(k[1:]) == K3
    with pytest.raises(PlanError, match=r"x0 = -3.700 m.*outside the robust box"):
        retarget_k(K3, box, -3.7, 1.6)
    with pytest.raises(PlanError, match="v0 = 2.600"):
        retarget_k(K3, box, -3.2, 2.6)


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--x0", "-3.9", "-3.7", "--v0", "1.8"], "--x0 and --v0 go together"),
        (["--x0", "-3.7", "-3.9", "--v0", "1.8", "2.0"], "--x0 LO must be below HI"),
        (["--x0", "3", "--v0", "1.5"], "--x0 must be < 0"),
        (["--x0", "-3", "--v0", "1", "2", "3"], "--v0 takes LO HI"),
        (["--x0", "-3.43", "-2", "--v0", "1.4", "2.15", "--order", "5"], "no k of any order"),
        (["--order", "9"], "--order must be 1..7"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(extra, words, tmp_path, capsys):
    assert perchd(ARGS + extra + ["--out", str(tmp_path / "P.json")]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1 and not (tmp_path / "P.json").exists()


def test_plan_robust_writes_a_plan_file_plan_check_recertifies(tmp_path, capsys):
    out = tmp_path / "P.json"
    argv = ARGS + [
        "--x0",
        "-3.9",
        "-3.7",
        "--v0",
        "1.8",
        "2.0",
        "--maxiter",
        "8",
        "--out",
        str(out),
        "--json",
    ]
    assert perchd(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    plan = load_plan(out)
    assert plan.robust == ((-3.9, -3.7), (1.8, 2.0))
    assert summary["robust"] == {"x0": [-3.9, -3.7], "v0": [1.8, 2.0]}
    assert plan.k[0] == pytest.approx(1.9 / -3.8)
    assert check_plan(plan).certified
    f = fly(plan.k[1:], plan.x0, plan.v0, -0.5)
    assert plan.duration == pytest.approx(f.t_s + 0.5, abs=1e-5)
    assert plan.v_contact == pytest.approx(f.v_contact, rel=1e-5)
    assert perchd(["plan", "check", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["feasible"] is True


def test_a_given_box_takes_the_start_plans_k_as_its_seed(tmp_path, capsys, monkeypatch):
    """--start with a box (LO HI): the start plan's k, padded to --order, seeds the search."""
    seeds = []
    real = robust.differential_evolution

    def spy(*args, **kwargs):
        seeds.append(kwargs.get("x0"))
        return real(*args, **kwargs)

    monkeypatch.setattr(robust, "differential_evolution", spy)
    start = Path(__file__).parents[2] / "plans" / "robust-n3-contracts-example.json"
    box = ["--x0", "-3.9", "-3.7", "--v0", "1.8", "2.0", "--maxiter", "1"]
    out = tmp_path / "P.json"
    argv = ARGS + box + ["--order", "4", "--start", str(start), "--out", str(out)]
    assert perchd(argv) == 0
    assert seeds and seeds[0] is not None
    assert tuple(seeds[0]) == pytest.approx((*load_plan(start).k[1:], 0.0))
    assert check_plan(load_plan(out)).certified
    capsys.readouterr()
    argv = ARGS + box + ["--order", "2", "--start", str(start), "--out", str(out), "--force"]
    assert perchd(argv) == 2
    err = capsys.readouterr().err
    assert "order-3 plan cannot seed --order 2" in err and err.count("\n") == 1


def test_plan_check_refuses_a_plan_whose_box_was_grown_naming_limit_and_state(tmp_path, capsys):
    rec = json.loads(PLANS[0].read_text())
    rec["robust"]["x0"][0] -= 0.4
    with pytest.raises(PlanError, match=r"not certified: .* at x0=-\d"):
        check_plan(plan_from_json(rec))
    bad = tmp_path / "grown.json"
    bad.write_text(json.dumps(rec))
    assert perchd(["plan", "check", str(bad)]) != 0
    captured = capsys.readouterr()
    assert "not certified: contact speed above V_u" in captured.out + captured.err


def test_a_robust_plan_whose_k0_is_not_its_v0_over_x0_is_refused():
    plan = load_plan(PLANS[0])
    k = (plan.k[0] * 1.1, *plan.k[1:])
    with pytest.raises(PlanError, match="stage1.k"):
        check_plan(dataclasses.replace(plan, k=k))


@pytest.mark.parametrize("path", PLANS, ids=[p.name for p in PLANS])
def test_every_robust_plan_in_plans_loads_is_certified_and_flies_inside_its_limits(path):
    plan = load_plan(path)  # re-derives every stored figure
    cert = check_plan(plan)
    assert cert.certified
    assert plan.extra["certificate"]["area"] == pytest.approx(Box(*plan.robust).area)
    nominal = fly(plan.k[1:], plan.x0, plan.v0, -0.5)
    assert plan.duration == pytest.approx(nominal.t_s + 0.5, abs=1e-5)
    assert plan.peaks.a == pytest.approx(nominal.a_peak, rel=1e-3)
    rng = np.random.default_rng(1)
    (xl, xh), (vl, vh) = plan.robust
    for x0, v0 in [(xl, vl), (xh, vh), (xl, vh), (xh, vl)] + [
        (rng.uniform(xl, xh), rng.uniform(vl, vh)) for _ in range(3)
    ]:
        f = fly(plan.k[1:], x0, v0, -0.5)
        assert f.reaches and f.v_peak <= 2.5 and f.a_peak <= 1.4 + 1e-4
        assert 0.7 <= f.v_contact <= 1.0


def test_a_tighter_a_max_on_a_loaded_plan_is_refused_naming_a_max():
    plan = load_plan(PLANS[0])
    with pytest.raises(PlanError, match="a_max"):
        check_plan(dataclasses.replace(plan, limits=Limits((0.7, 1.0), 2.5, 1.2)))


def test_perchd_retarget_of_a_robust_plan_keeps_k_and_refuses_outside_the_box():
    from perchd.tau.retarget import retarget

    plan = load_plan(PLANS[0])
    (xl, xh), (vl, vh) = plan.robust
    x0, v0 = (xl + xh) / 2 + 0.01, (vl + vh) / 2 - 0.02
    new = retarget(plan, x0, v0)
    assert new.k[1:] == plan.k[1:] and new.k[0] == pytest.approx(v0 / x0)
    assert new.robust == plan.robust and new.duration == pytest.approx(
        fly(new.k[1:], x0, v0, -0.5).t_s + 0.5, abs=1e-5
    )
    with pytest.raises(PlanError, match="outside the robust box"):
        retarget(plan, xl - 0.01, v0)


def test_the_box_search_seeded_with_a_certified_box_returns_a_certified_larger_one():
    from perchd.tau.robust import RobustResult, largest_box

    seed_box = Box((-3.65, -2.94), (0.67, 2.49))
    r = largest_box(
        3,
        LIM,
        maxiter=1,
        popsize=3,
        polish_evals=150,
        start=RobustResult(K3, seed_box, LIM.certify(K3, seed_box)),
    )
    assert r.certificate.certified and r.box.area >= seed_box.area
    w = worst_over_box(r.k, r.box.x0, r.box.v0, -0.5, n=4)
    assert w["reaches"] and w["v_peak"] <= 2.5 and w["a_peak"] <= 1.4 + 1e-4
    assert 0.7 <= w["vc_lo"] and w["vc_hi"] <= 1.0


def test_a_start_whose_k_lies_outside_the_search_bounds_still_seeds_it():
    """A start k beyond the bounds (a polish may carry it there) seeds the search clipped
    into them, and still competes as it is: no error, never a smaller box than the start's."""
    from perchd.tau.robust import RobustResult, largest_box

    seed_box = Box((-3.65, -2.94), (0.67, 2.49))
    k_bound = 0.5 * max(abs(k) for k in K3[1:])
    r = largest_box(
        3,
        LIM,
        maxiter=1,
        popsize=3,
        k_bound=k_bound,
        polish_evals=50,
        start=RobustResult(K3, seed_box, LIM.certify(K3, seed_box)),
    )
    assert r.certificate.certified and r.box.area >= seed_box.area
