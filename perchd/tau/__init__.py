"""Tau planning: CTDS, CTDTS and IPTS plans, their bound, files and verification."""

from perchd.tau.bound import min_time_bound, plan_bound
from perchd.tau.ctds import plan_ctds
from perchd.tau.ctdts import plan_ctdts
from perchd.tau.ipts import plan_ipts
from perchd.tau.limits import Limits
from perchd.tau.plan import Peaks, Plan, make_plan
from perchd.tau.planfile import load_plan, plan_from_json, plan_to_json, save_plan
from perchd.tau.retarget import retarget
from perchd.tau.verify import check_limits, report, verify_plan, violations

__all__ = [
    "Limits",
    "Peaks",
    "Plan",
    "check_limits",
    "load_plan",
    "make_plan",
    "min_time_bound",
    "plan_bound",
    "plan_ctds",
    "plan_ctdts",
    "plan_from_json",
    "plan_ipts",
    "plan_to_json",
    "report",
    "retarget",
    "save_plan",
    "verify_plan",
    "violations",
]
