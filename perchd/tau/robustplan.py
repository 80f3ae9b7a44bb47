"""Robust IPTS plans as files: one k certified over a box of trigger states, its plan
flown from a nominal state, and the re-certification `perchd plan check` runs."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from perchd.core.errors import PlanError
from perchd.tau.certify import Box, Certificate
from perchd.tau.limits import Limits
from perchd.tau.plan import Plan, given, make_plan
from perchd.tau.profiles import Coefficients
from perchd.tau.robust import RobustLimits, RobustResult, retarget_k

METHOD = (
    "certify_box: monotone t_s in k0, mean-value enclosures on adaptive k0 x t cells "
    "(perchd/tau/certify.py)"
)


def _inward(box: Box, digits: int = 4) -> Box:
    """The box with edges rounded inward (a sub-box of a certified box is certified)."""
    f: int = 10**digits

    def up(e: float) -> float:
        return math.ceil(round(e * f, 6)) / f

    def down(e: float) -> float:
        return math.floor(round(e * f, 6)) / f

    return Box((up(box.x0[0]), down(box.x0[1])), (up(box.v0[0]), down(box.v0[1])))


def robust_plan(
    k: Coefficients,
    box: Box,
    lim: RobustLimits,
    x0: float,
    v0: float,
    extra: dict[str, Any] | None = None,
) -> Plan:
    """The Plan (perchd.tau.make_plan) of k flown from (x0, v0), carrying its certified box."""
    plan = make_plan(
        "ipts",
        x0,
        v0,
        lim.tau_s,
        Limits(lim.v_contact, lim.v_max, lim.a_max),
        k=retarget_k(k, box, x0, v0),
        robust=(box.x0, box.v0),
    )
    return replace(plan, extra=extra) if extra else plan


def certified_plan(
    result: RobustResult, lim: RobustLimits, nominal: tuple[float, float] | None = None
) -> Plan:
    """The plan file's Plan for a robust result, flown from `nominal` (default: box centre),
    its box rounded inward to 0.1 mm, re-certified, and the certificate in plan.extra."""
    box = _inward(result.box)
    cert = lim.certify(result.k, box)
    if not cert.certified:
        raise PlanError(f"rounded box lost its certificate: {cert.reason}")
    x0, v0 = nominal or (round(sum(box.x0) / 2, 4), round(sum(box.v0) / 2, 4))
    record = {
        "method": METHOD,
        "area": box.area,
        "v_peak": cert.bounds["v_peak"],
        "a_peak": cert.bounds["a_peak"],
        "v_contact": [float(v) for v in cert.bounds["v_contact"]],
        "duration": [float(d) for d in cert.duration],
    }
    return robust_plan(result.k, box, lim, x0, v0, {"certificate": record})


def check_plan(plan: Plan) -> Certificate:
    """Re-certify a robust Plan over its whole box (`perchd plan check` calls this).
    Returns the Certificate; PlanError names the broken limit and the state, or the field."""
    lim = plan.limits
    if plan.strategy != "ipts" or plan.tau_s is None:
        raise PlanError(f"robust: only two-stage ipts plans can be robust, got {plan.strategy}")
    if lim.v_max is None or lim.a_max is None:
        raise PlanError("robust: limits.v_max and limits.a_max are needed to certify a box")
    (x_lo, x_hi), (v_lo, v_hi) = given(plan.robust, "robust")
    box = Box((x_lo, x_hi), (v_lo, v_hi))
    if not box.x0[0] < box.x0[1] < 0 < box.v0[0] < box.v0[1]:
        raise PlanError(f"robust: box must have x0 lo < hi < 0 < v0 lo < hi, got {plan.robust}")
    k = given(plan.k, "stage1.k")
    if not math.isclose(k[0], plan.v0 / plan.x0, rel_tol=1e-9):
        raise PlanError(f"stage1.k[0] = {k[0]:g} is not v0/x0 = {plan.v0 / plan.x0:g}")
    lo, hi = lim.v_contact
    cert = RobustLimits(plan.tau_s, (lo, hi), lim.v_max, lim.a_max).certify(k[1:], box)
    if not cert.certified:
        raise PlanError(
            f"robust box x0 {box.x0[0]:g}..{box.x0[1]:g} m, v0 {box.v0[0]:g}..{box.v0[1]:g} "
            f"m/s {cert.reason}"
        )
    return cert
