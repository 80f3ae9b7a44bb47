"""The box certifier proves what a brute-force check confirms, and names what it refutes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from robust_brute import fly, worst_over_box

from perchd.tau.certify import Box, certify_box, first_switch, scale_functions

LIMITS = dict(v_contact=(0.7, 1.0), v_max=2.5, a_max=1.4, tau_s=-0.5)
K3 = (-0.3111, -0.3082, 0.02853)  # an order-3 k found by perchd's search
BOX3 = Box((-3.65, -2.94), (0.67, 2.49))  # and a box it holds over
TABLE2 = {  # the paper's Table 2 as printed: k_1..k_n, Z_0 (= x0) range, V_0 range
    3: ((-0.60, -0.057, 0.054), (-3.88, -3.73), (1.89, 1.99)),
    4: ((-0.60, 0.15, -0.31, 0.14), (-2.92, -2.0), (1.0, 1.65)),
    5: ((-0.57, 0.13, -0.57, 0.53, -0.14), (-3.43, -2.0), (1.4, 2.15)),
}


def certify(k, box, **over):
    return certify_box(k, box, **{**LIMITS, **over})


def test_structure_the_trajectory_scales_with_x0_at_fixed_tau0():
    tau0 = -2.0
    a, b = fly(K3, -3.0, 1.5, -0.5), fly(K3, -2.0, 1.0, -0.5)
    assert a.t_s == pytest.approx(b.t_s, abs=1e-6)
    assert a.v_peak / 3.0 == pytest.approx(b.v_peak / 2.0, rel=1e-6)
    assert a.v_contact / 3.0 == pytest.approx(b.v_contact / 2.0, rel=1e-6)
    assert first_switch(np.array(K3), 1 / tau0, -0.5)[0] == pytest.approx(a.t_s, abs=1e-6)


def test_a_box_the_brute_force_confirms_is_certified_with_bounds_that_cover_it():
    cert = certify(K3, BOX3)
    assert cert.certified, cert.reason
    brute = worst_over_box(K3, BOX3.x0, BOX3.v0, -0.5, n=7)
    assert brute["reaches"]
    assert brute["v_peak"] <= cert.bounds["v_peak"] <= 2.5
    assert brute["a_peak"] <= cert.bounds["a_peak"] + 1e-4 and cert.bounds["a_peak"] <= 1.4
    lo, hi = cert.bounds["v_contact"]
    assert 0.7 <= lo <= brute["vc_lo"] and brute["vc_hi"] <= hi <= 1.0


def test_the_worst_case_duration_is_that_of_the_largest_tau0_magnitude():
    cert = certify(K3, BOX3)
    slowest = fly(K3, BOX3.x0[0], BOX3.v0[0], -0.5)  # x0 most negative, slowest
    fastest = fly(K3, BOX3.x0[1], BOX3.v0[1], -0.5)
    assert cert.duration[1] == pytest.approx(slowest.t_s + 0.5, abs=1e-5)
    assert cert.duration[0] == pytest.approx(fastest.t_s + 0.5, abs=1e-5)


@pytest.mark.parametrize(
    "box, limit",
    [
        (Box((-3.80, -2.94), (0.67, 2.49)), "v_contact_high"),
        (Box((-3.65, -2.50), (0.67, 2.49)), "v_contact_low"),
    ],
)
def test_a_box_with_a_violating_state_is_refused_naming_limit_and_state(box, limit):
    cert = certify(K3, box)
    assert not cert.certified and cert.violation is not None
    v = cert.violation
    assert v.limit == limit
    assert box.x0[0] <= v.x0 <= box.x0[1] and box.v0[0] <= v.v0 <= box.v0[1]
    f = fly(K3, v.x0, v.v0, -0.5)
    assert f.v_contact == pytest.approx(v.value, rel=1e-5)
    assert (f.v_contact > 1.0) if limit == "v_contact_high" else (f.v_contact < 0.7)
    assert f"x0={v.x0:.4f}" in cert.reason


@pytest.mark.parametrize("limit, over", [("a_max", {"a_max": 1.3}), ("v_max", {"v_max": 2.3})])
def test_peak_limits_are_refused_at_a_state_that_breaks_them(limit, over):
    cert = certify(K3, BOX3, **over)
    assert cert.violation is not None and cert.violation.limit == limit
    v = cert.violation
    f = fly(K3, v.x0, v.v0, -0.5)
    peak = f.a_peak if limit == "a_max" else f.v_peak
    assert peak > over[limit]


def test_an_a_max_just_under_the_boxs_true_peak_is_refused_at_a_state_that_breaks_it():
    brute_peak = worst_over_box(K3, BOX3.x0, BOX3.v0, -0.5, n=7)["a_peak"]
    a_max = brute_peak - 2e-3
    cert = certify(K3, BOX3, a_max=a_max)
    assert not cert.certified and cert.violation.limit == "a_max"
    assert fly(K3, cert.violation.x0, cert.violation.v0, -0.5).a_peak > a_max


@pytest.mark.parametrize("order", [3, 4])
def test_paper_table2_low_orders_never_reach_tau_s_anywhere_in_their_box(order):
    k, x0r, v0r = TABLE2[order]
    cert = certify(k, Box(x0r, v0r))
    assert not cert.certified and cert.violation.limit == "tau_s"
    for x0 in np.linspace(*x0r, 4):  # docs/errata.md §7: nowhere in the printed ranges
        for v0 in np.linspace(*v0r, 4):
            assert not fly(k, x0, v0, -0.5).reaches


def test_paper_table2_fifth_order_misses_the_contact_speed_at_a_corner():
    k, x0r, v0r = TABLE2[5]
    cert = certify(k, Box(x0r, v0r))
    v = cert.violation
    assert not cert.certified and v.limit == "v_contact_low"
    assert fly(k, v.x0, v.v0, -0.5).v_contact < 0.7


def test_scale_functions_match_the_integrated_flight():
    k0, t = 1.5 / -3.0, np.linspace(0, 1.2, 5)
    p, f1, f2 = scale_functions(np.array(K3), k0, t)
    f = fly(K3, -3.0, 1.5, -0.5)
    assert 3.0 * f1.max() <= f.v_peak + 1e-9
    assert p[0] == k0 and 3.0 * f1[0] == pytest.approx(1.5)


def test_a_trigger_already_past_tau_s_is_refused():
    cert = certify(K3, Box((-1.0, -0.4), (1.0, 1.2)))
    assert cert.violation.limit == "tau_s" and "tau0" in cert.reason


@settings(max_examples=12, deadline=None)
@given(scale=st.floats(0.3, 1.3), dk=st.floats(-0.01, 0.01))
def test_whatever_it_certifies_the_brute_force_confirms(scale, dk):
    k = (K3[0] + dk, K3[1], K3[2])
    box = BOX3.scaled(scale)
    cert = certify(k, box)
    rng = np.random.default_rng(0)
    states = [(rng.uniform(*box.x0), rng.uniform(*box.v0)) for _ in range(6)]
    states += [(box.x0[0], box.v0[0]), (box.x0[1], box.v0[1])]
    if cert.certified:
        for x0, v0 in states:
            f = fly(k, x0, v0, -0.5)
            assert f.reaches and f.v_peak <= 2.5 + 1e-9 and f.a_peak <= 1.4 + 1e-3
            assert 0.7 - 1e-9 <= f.v_contact <= 1.0 + 1e-9
    elif cert.violation is not None:
        v = cert.violation
        f = fly(k, v.x0, v.v0, -0.5)
        broken = {
            "v_contact_low": f.v_contact < 0.7,
            "v_contact_high": f.v_contact > 1.0,
            "v_max": f.v_peak > 2.5,
            "a_max": f.a_peak > 1.4 - 1e-4,
            "tau_s": not f.reaches,
            "tau": not f.reaches,
        }[v.limit]
        assert broken, cert.reason
