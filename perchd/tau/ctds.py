"""CTDS planner: constant tau-dot to zero-speed contact (paper section 2.1)."""

from __future__ import annotations

import math

from perchd.core.errors import PlanError
from perchd.tau.limits import Limits
from perchd.tau.plan import Plan, check_trigger, make_plan
from perchd.tau.verify import check_limits


def plan_ctds(x0: float, v0: float, c: float, limits: Limits | None = None) -> Plan:
    """Constant tau-dot c in (0, 0.5]: contact in finite time at zero speed (section 2.1)."""
    check_trigger(x0, v0)
    if not math.isfinite(c) or c <= 0:
        raise PlanError(
            f"c = {c:g}: with c <= 0 the vehicle never arrives (X -> 0 only as t -> inf)"
        )
    if c > 0.5:
        raise PlanError(
            f"c = {c:g}: above 0.5 the acceleration is infinite at contact "
            f"(c must be in (0, 0.5]; at c = 1 speed stays v0, above 1 it diverges)"
        )
    plan = make_plan("ctds", x0, v0, None, limits or Limits((0.0, 0.0)), c=c)
    return check_limits(plan)
