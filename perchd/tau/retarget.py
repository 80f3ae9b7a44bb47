"""Fly a plan's strategy and limits from the trigger state actually measured."""

from __future__ import annotations

from typing import TYPE_CHECKING

from perchd.core.errors import PlanError
from perchd.tau.certify import Box
from perchd.tau.ctds import plan_ctds
from perchd.tau.ctdts import plan_ctdts
from perchd.tau.ipts import plan_ipts
from perchd.tau.plan import Plan, given, make_plan
from perchd.tau.robust import retarget_k

if TYPE_CHECKING:
    from perchd.tau.library import PlanLibrary


def retarget(plan: Plan, x0: float, v0: float, library: PlanLibrary | None = None) -> Plan:
    """The same strategy and limits from (x0 [m], v0 [m/s]).

    A robust IPTS plan keeps k_1..k_n and takes k_0 = v0/x0; its certificate covers the box,
    and a state outside it is refused. Other plans are replanned: CTDS keeps c, CTDTS keeps
    tau_s and V_c, IPTS is re-optimised at the same order. PlanError names what fails.
    With a plan library (same order and limits as a non-robust IPTS plan) the IPTS replan is
    one warm local solve from the library's grid (milliseconds); a state outside its grid is
    refused, not cold-solved, so the caller never blocks a tick on a global solve.
    """

    lim = plan.limits
    if plan.robust is not None:
        k = retarget_k(given(plan.k, "stage1.k")[1:], Box(*plan.robust), x0, v0)
        return make_plan("ipts", x0, v0, plan.tau_s, lim, k=k, robust=plan.robust)
    if library is not None:
        why = library.matches(plan)
        if why:
            raise PlanError(f"library cannot retarget this plan: {why}")
        return library.replan(x0, v0)
    if plan.strategy == "ctds":
        return plan_ctds(x0, v0, given(plan.c, "stage1.c"), lim)
    if plan.strategy == "ctdts":
        return plan_ctdts(
            x0, v0, given(plan.tau_s, "tau_s"), plan.v_contact, lim.a_max, lim.v_max, lim.v_contact
        )
    return plan_ipts(
        x0,
        v0,
        given(plan.tau_s, "tau_s"),
        lim.v_contact,
        lim.v_max,
        lim.a_max,
        given(plan.order, "stage1.k"),
    )
