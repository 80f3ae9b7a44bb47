"""CTDTS planner: constant tau-dot to V_c at tau_s, then constant speed (paper section 2.2,
docs/errata.md §1, §2, §4)."""

from __future__ import annotations

import math

from perchd.core.errors import PlanError
from perchd.tau.limits import Limits
from perchd.tau.plan import Plan, check_trigger, make_plan
from perchd.tau.verify import check_limits


def ctdts_c(x0: float, v0: float, tau_s: float, v_c: float) -> float:
    """Corrected eq. 7: c = log(tau_s/tau_0) / (log(V_c/Xdot_0) + log(tau_s/tau_0))."""
    tau0 = x0 / v0
    if not tau0 < tau_s < 0:
        raise PlanError(f"tau_s = {tau_s:g} s must lie in (tau_0, 0) = ({tau0:g}, 0)")
    if not 0 < v_c < v0:
        raise PlanError(
            f"v_contact = {v_c:g} m/s must lie in (0, v0) = (0, {v0:g}): CTDTS can only decelerate"
        )
    ratio = math.log(tau_s / tau0)
    return ratio / (math.log(v_c / v0) + ratio)


def plan_ctdts(
    x0: float,
    v0: float,
    tau_s: float,
    v_c: float,
    a_max: float | None,
    v_max: float | None = None,
    window: tuple[float, float] | None = None,
) -> Plan:
    """Two stages: constant tau-dot down to V_c at tau_s, then constant speed to contact.

    window [m/s]: the contact speeds the vehicle tolerates, recorded in the plan's limits so
    the flight can aim inside it (V_c on the window's edge leaves no room for tracking
    error); default (V_c, V_c). V_c must lie inside it."""
    check_trigger(x0, v0)
    c = ctdts_c(x0, v0, tau_s, v_c)
    window = (v_c, v_c) if window is None else (float(window[0]), float(window[1]))
    plan = make_plan("ctdts", x0, v0, tau_s, Limits(window, v_max, a_max), c=c)
    return check_limits(plan)
