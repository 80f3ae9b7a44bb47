"""Table 1 of the paper, with docs/errata.md §1, §2, §4, §5, §6 applied, re-derived independently."""

import math

import numpy as np
import pytest
from integrate import fly_tau, ipts_tau

from perchd.tau import plan_bound, plan_ctds, plan_ctdts, plan_ipts

X0, V0, TAU_S = -3.0, 1.5, -0.5


def test_ctds_with_c_half_perches_in_4_s_at_zero_speed():
    plan = plan_ctds(X0, V0, 0.5)
    assert plan.duration == pytest.approx(4.0, abs=1e-12)
    t, x, v, _ = fly_tau(lambda s: 0.5 * s + X0 / V0, X0, 3.999)
    assert x[-1] == pytest.approx(0.0, abs=1e-5) and v[-1] == pytest.approx(0.0, abs=3e-3)
    assert plan.x(t) == pytest.approx(x, abs=1e-7)


@pytest.mark.parametrize(
    "v_c, c, t_s, total", [(1.0, 0.7737, 1.9387, 2.4387), (0.94, 0.7479, 2.0057, 2.5057)]
)
def test_ctdts_matches_the_corrected_closed_form(v_c, c, t_s, total):
    plan = plan_ctdts(X0, V0, TAU_S, v_c, a_max=1.4)
    assert (plan.c, plan.t_switch, plan.duration) == pytest.approx((c, t_s, total), abs=1e-4)
    # Integrating tau = c t + tau0 must reach tau_s at the speed V_c.
    t, x, v, _ = fly_tau(lambda s: plan.c * s + X0 / V0, X0, plan.t_switch)
    assert x[-1] / v[-1] == pytest.approx(TAU_S, abs=1e-8)
    assert v[-1] == pytest.approx(v_c, abs=1e-8)
    assert -x[-1] / v_c == pytest.approx(plan.duration - plan.t_switch, abs=1e-8)


def test_ctdts_peak_deceleration_is_at_the_switch_for_c_above_half():
    plan = plan_ctdts(X0, V0, TAU_S, 1.0, a_max=1.4)
    t, _, _, a = fly_tau(lambda s: plan.c * s + X0 / V0, X0, plan.t_switch)
    assert int(np.argmax(np.abs(a))) == len(a) - 1
    eq10 = (1 - plan.c) * V0**2 / X0 * (1.0 / V0) ** ((1 - 2 * plan.c) / (1 - plan.c))
    assert plan.peaks.a == pytest.approx(abs(eq10), rel=1e-6)


def _verify_ipts(plan, v_max, a_max):
    t, x, v, a = fly_tau(ipts_tau(plan.k), X0, plan.t_switch, n=20001)
    assert x[-1] / v[-1] == pytest.approx(TAU_S, abs=1e-7)
    assert 0.7 - 1e-9 <= v[-1] <= 1.0 + 1e-9
    assert v.max() <= v_max * (1 + 1e-6)
    assert np.abs(a[1:-1]).max() <= a_max * (1 + 1e-4)  # finite differences
    assert np.all(x / v < 0)  # tau negative throughout
    return v[-1], np.abs(a[1:-1]).max()


def test_ipts_case1_order3_is_the_paper_optimum():
    plan = plan_ipts(X0, V0, TAU_S, (0.7, 1.0), 2.5, 1.4, order=3)
    assert plan.duration == pytest.approx(2.0148, abs=2e-4)
    assert plan.k[1:] == pytest.approx((-0.7166, -0.1907, 0.0067), abs=2e-4)
    v_c, a_peak = _verify_ipts(plan, 2.5, 1.4)
    assert v_c == pytest.approx(1.0, abs=1e-6) and a_peak == pytest.approx(1.4, abs=2e-3)


def test_ipts_case2_order3_beats_the_papers_local_minimum():
    plan = plan_ipts(X0, V0, TAU_S, (0.7, 1.0), 2.0, 1.0, order=3)
    assert plan.duration < 2.2628 - 0.03
    _verify_ipts(plan, 2.0, 1.0)


def test_the_papers_case2_coefficients_are_slower_than_ours():
    from perchd.tau import Limits, make_plan

    paper = make_plan(
        "ipts", X0, V0, TAU_S, Limits((0.7, 1.0), 2.0, 1.0), k=[-0.5, -0.5745, 0.295, -0.2563]
    )
    ours = plan_ipts(X0, V0, TAU_S, (0.7, 1.0), 2.0, 1.0, order=3)
    assert paper.duration == pytest.approx(2.2628, abs=2e-3)
    assert ours.duration < paper.duration


@pytest.mark.parametrize("v_max, a_max", [(2.5, 1.4), (2.0, 1.0)])
def test_the_ratio_to_the_bound_falls_with_the_order(v_max, a_max):
    ratios = [
        plan_ipts(X0, V0, TAU_S, (0.7, 1.0), v_max, a_max, order=n).duration for n in (2, 3, 4)
    ]
    bound = plan_bound(plan_ipts(X0, V0, TAU_S, (0.7, 1.0), v_max, a_max, order=3))
    assert ratios[0] >= ratios[1] >= ratios[2] > bound


def test_the_bound_is_bang_bang_by_hand():
    # Case 1: gap 2.5 m from 1.5 to 1.0 m/s at 1.4 m/s^2 peaks at sqrt(5.125) m/s.
    v_p = math.sqrt((2 * 1.4 * 2.5 + 1.5**2 + 1.0) / 2)
    expected = (2 * v_p - 1.5 - 1.0) / 1.4 + 0.5
    assert plan_bound(plan_ipts(X0, V0, TAU_S, (0.7, 1.0), 2.5, 1.4, 3)) == pytest.approx(expected)


def _order1_least_peak_acceleration(v_lo=0.7, v_hi=1.0):
    """Order 1 has one free coefficient, fixed by t_s: scan t_s, integrate each profile and
    keep the least peak |a| among those contacting within [V_l, V_u]."""
    best = math.inf
    for t_s in np.linspace(1.3, 1.9, 61):
        k = (V0 / X0, (1 / TAU_S - V0 / X0) / t_s)
        _, _, v, a = fly_tau(ipts_tau(k), X0, t_s, n=801)
        if v_lo <= v[-1] <= v_hi:
            best = min(best, np.abs(a[1:-1]).max())
    return best


@pytest.mark.parametrize("v_max, a_max", [(2.5, 1.4), (2.0, 1.0)])
def test_order1_is_refused_because_no_single_coefficient_meets_a_max(v_max, a_max):
    from perchd.core.errors import PlanError

    assert _order1_least_peak_acceleration() > a_max + 0.4  # about 1.87 m/s^2
    with pytest.raises(PlanError, match="order-1"):
        plan_ipts(X0, V0, TAU_S, (0.7, 1.0), v_max, a_max, order=1)
