"""IPTS planner properties over random feasible cases: loosening a limit never fails or slows
the plan; every plan survives an evaluation written here, independent of perchd.tau's own
verification; infeasibility comes with a certificate that checks out."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from perchd.tau import plan_ipts
from perchd.tau.ipts import MAX_ORDER, InfeasiblePlan

X0, V0, TAU_S, WINDOW = -3.0, 1.5, -0.5, (0.7, 1.0)
REL = 1e-6  # relative slack on a limit met with equality
SLOWER = 1e-6  # [s] a looser plan may be slower by no more than solver tolerance

SETTINGS = settings(
    max_examples=5,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow],
)


# -- an evaluation of the plan that shares nothing with perchd.tau's checks ------------------
def evaluate(plan, n: int = 20001):
    """(t, tau, X, V, A) over stage 1 from the plan's k alone: p = 1/tau is the polynomial,
    X = x0 exp(integral of p) by the trapezoid rule, V = X p, A = X (p' + p^2)."""
    k = np.asarray(plan.k, float)
    t = np.linspace(0.0, plan.t_switch, n)
    p = sum(ki * t**i for i, ki in enumerate(k))
    dp = sum(i * ki * t ** (i - 1) for i, ki in enumerate(k) if i)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(t))])
    x = plan.x0 * np.exp(integral)
    return t, 1.0 / p, x, x * p, x * (dp + p * p)


def assert_meets(plan, x0, v0, tau_s, window, v_max, a_max):
    t, tau, x, v, a = evaluate(plan)
    assert plan.k[0] == pytest.approx(v0 / x0, rel=1e-12)
    assert np.all(tau < 0)  # closing the whole way
    assert np.all(tau[:-1] < tau_s)  # no earlier switch
    assert tau[-1] == pytest.approx(tau_s, abs=1e-7)
    assert plan.duration == pytest.approx(plan.t_switch - tau_s, abs=1e-12)
    assert window[0] * (1 - REL) <= v[-1] <= window[1] * (1 + REL)
    assert v.max() <= v_max * (1 + REL) and np.abs(a).max() <= a_max * (1 + REL)
    # stage 2 at V(t_s) for |tau_s| seconds lands exactly on the surface
    assert x[-1] + v[-1] * -tau_s == pytest.approx(0.0, abs=1e-5)


# -- random feasible cases ------------------------------------------------------------------
states = st.tuples(
    st.floats(1.5, 4.0),
    st.floats(0.8, 2.2),
    st.floats(0.15, 0.45),
    st.floats(0.4, 1.1),
    st.floats(0.0, 0.4),
)
tight = st.tuples(st.floats(1.05, 1.6), st.floats(0.6, 3.0))  # v_max / v0, a_max
looser = st.tuples(
    st.floats(1.0, 20.0), st.floats(1.0, 20.0), st.floats(0.0, 0.2), st.floats(0.0, 0.2)
)


def case(state, lim):
    gap, v0, frac, lo, width = state
    x0 = -gap
    tau_s = x0 / v0 * frac
    return x0, v0, tau_s, (lo, lo + width), v0 * lim[0], lim[1]


def plan_or_none(x0, v0, tau_s, window, v_max, a_max, order=3):
    try:
        return plan_ipts(x0, v0, tau_s, window, v_max, a_max, order, probe_orders=False)
    except InfeasiblePlan:
        return None


@SETTINGS
@given(states, tight, looser)
def test_loosening_any_limit_never_fails_nor_slows_the_plan(state, lim, loose):
    x0, v0, tau_s, window, v_max, a_max = case(state, lim)
    base = plan_or_none(x0, v0, tau_s, window, v_max, a_max)
    assume(base is not None)
    fv, fa, wl, wh = loose
    wide = (max(window[0] - wl, 0.0), window[1] + wh)
    loosened = plan_ipts(x0, v0, tau_s, wide, v_max * fv, a_max * fa, 3, probe_orders=False)
    assert loosened.duration <= base.duration + SLOWER
    assert_meets(loosened, x0, v0, tau_s, wide, v_max * fv, a_max * fa)


@SETTINGS
@given(states, tight)
def test_every_plan_meets_its_limits_by_an_independent_evaluation(state, lim):
    x0, v0, tau_s, window, v_max, a_max = case(state, lim)
    plan = plan_or_none(x0, v0, tau_s, window, v_max, a_max)
    assume(plan is not None)
    assert_meets(plan, x0, v0, tau_s, window, v_max, a_max)


@SETTINGS
@given(states, st.tuples(st.floats(0.7, 1.3), st.floats(0.05, 1.0)))
def test_infeasibility_is_reported_only_with_a_certificate_that_holds(state, lim):
    x0, v0, tau_s, window, v_max, a_max = case(state, lim)
    try:
        plan_ipts(x0, v0, tau_s, window, v_max, a_max, 3, probe_orders=False)
    except InfeasiblePlan as err:
        check_certificate(err, x0, v0, tau_s, window, v_max, a_max)
    else:
        assume(False)


def check_certificate(err, x0, v0, tau_s, window, v_max, a_max, order=3):
    assert err.shortfalls, str(err)
    given_ = {"v_max": v_max, "a_max": a_max}
    for short in err.shortfalls:
        assert short.given == given_[short.limit] and short.needed > short.given
        assert f"{short.limit} = {short.given:g}" in str(err) and "short by" in str(err)
    if err.any_order:  # no trajectory at all: re-derive the bound that is broken
        (short,) = err.shortfalls
        if short.limit == "v_max":
            assert v_max < max(v0, window[0])
        else:
            v_c = np.linspace(*window, 2001)
            brake = (v0**2 - v_c**2) / (2 * (-x0 + tau_s * v_c))
            assert brake.min() > a_max
        return
    # order-specific: limits raised to what the closest plan needs do plan, and meet them
    raised = {s.limit: s.needed * (1 + 1e-6) for s in err.shortfalls}
    vm, am = raised.get("v_max", v_max), raised.get("a_max", a_max)
    plan = plan_ipts(x0, v0, tau_s, window, vm, am, order, probe_orders=False)
    assert_meets(plan, x0, v0, tau_s, window, vm, am)


# -- the cases reported against the planner -------------------------------------------------
@pytest.mark.parametrize("order", [3, 5])
def test_case1_with_loosened_limits_plans_no_slower_than_with_the_paper_limits(order):
    base = plan_ipts(X0, V0, TAU_S, WINDOW, 2.5, 1.4, order)
    last = base.duration
    for v_max, a_max in [(2.5, 3), (5, 3), (5, 5), (10, 10), (1000, 1000), (None, None)]:
        plan = plan_ipts(X0, V0, TAU_S, WINDOW, v_max, a_max, order)
        assert plan.duration <= last + SLOWER, (v_max, a_max)
        assert_meets(plan, X0, V0, TAU_S, WINDOW, v_max or 1e3, a_max or 1e3)
        last = plan.duration


def test_a_higher_order_is_suggested_only_once_it_plans():
    with pytest.raises(InfeasiblePlan) as info:
        plan_ipts(X0, V0, TAU_S, WINDOW, 1.6, 0.6, 3)
    err = info.value
    assert 3 < err.higher_order <= MAX_ORDER and f"--order {err.higher_order}" in str(err)
    plan = plan_ipts(X0, V0, TAU_S, WINDOW, 1.6, 0.6, err.higher_order)
    assert_meets(plan, X0, V0, TAU_S, WINDOW, 1.6, 0.6)
    check_certificate(err, X0, V0, TAU_S, WINDOW, 1.6, 0.6)


def test_at_the_highest_order_no_higher_order_is_suggested():
    # a_max just above what braking over the gap needs (0.25 m/s^2): no order meets it
    with pytest.raises(InfeasiblePlan) as info:
        plan_ipts(X0, V0, TAU_S, WINDOW, 2.5, 0.2505, MAX_ORDER)
    err = info.value
    assert err.higher_order is None and not err.any_order
    assert "--order" not in str(err) and "higher" not in str(err)
    check_certificate(err, X0, V0, TAU_S, WINDOW, 2.5, 0.2505, MAX_ORDER)


def test_a_limit_no_trajectory_meets_is_named_with_its_shortfall():
    with pytest.raises(InfeasiblePlan, match=r"a_max = 0.2 m/s\^2: short by 0.05") as info:
        plan_ipts(X0, V0, TAU_S, WINDOW, 2.5, 0.2, 3)
    assert info.value.any_order and "--order" not in str(info.value)
    with pytest.raises(InfeasiblePlan, match=r"v_max = 1.2 m/s: short by 0.3") as info:
        plan_ipts(X0, V0, TAU_S, WINDOW, 1.2, 1.4, 3)
    assert info.value.any_order
