"""Verify a plan against its limits; the figures `perchd plan check` prints."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from perchd.core.errors import PlanError
from perchd.tau.bound import plan_bound
from perchd.tau.figures import disagreement, figures
from perchd.tau.plan import Plan, make_plan
from perchd.tau.robustplan import check_plan

TOL = 1e-6  # relative slack for a limit met with equality by an optimiser


def violations(plan: Plan) -> list[str]:
    """Each broken limit in words, naming the limit and by how much (empty: all met)."""
    found = []
    for name, peak, limit, unit in (
        ("a_max", plan.peaks.a, plan.limits.a_max, "m/s^2"),
        ("v_max", plan.peaks.v, plan.limits.v_max, "m/s"),
    ):
        if limit is not None and peak > limit * (1 + TOL):
            found.append(
                f"{plan.strategy}: peak {name[0]} = {peak:.4f} {unit} exceeds "
                f"{name} = {limit:g} {unit} by {peak - limit:.4f} {unit} "
                f"({100 * (peak / limit - 1):.1f} %)"
            )
    lo, hi = plan.limits.v_contact
    if not lo - TOL <= plan.v_contact <= hi + TOL:
        found.append(
            f"{plan.strategy}: contact speed {plan.v_contact:.4f} m/s is outside "
            f"v_contact [{lo:g}, {hi:g}] m/s"
        )
    return found + _robust_violations(plan)


def _robust_violations(plan: Plan) -> list[str]:
    if plan.robust is None:
        return []

    try:
        check_plan(plan)
    except PlanError as err:
        return [str(err)]
    return []


def verify_plan(plan: Plan) -> Plan:
    """The plan itself, or PlanError naming its first fault: a figure its parameters do not
    give (re-derived as the loader does), or a limit it breaks (what `perchd plan check`
    reports infeasible)."""
    derived = make_plan(
        plan.strategy,
        plan.x0,
        plan.v0,
        plan.tau_s,
        plan.limits,
        c=plan.c,
        k=plan.k,
        robust=plan.robust,
    )
    why = disagreement(figures(plan), derived)
    if why is not None:
        raise PlanError(why)
    return check_limits(plan)


def check_limits(plan: Plan) -> Plan:
    """The plan itself, or PlanError with its first broken limit."""
    broken = violations(plan)
    if broken:
        raise PlanError(broken[0])
    return plan


@dataclass(frozen=True)
class Report:
    """What `perchd plan check --json` prints (docs/contracts.md §2); times s, speeds m/s, m/s^2."""

    strategy: str
    order: int | None
    x0: float
    v0: float
    tau_s: float | None
    duration: float
    t_switch: float
    v_contact: float
    v_peak: float
    a_peak: float
    bound: float
    ratio: float
    feasible: bool
    violations: tuple[str, ...]
    robust: dict[str, list[float]] | None

    def to_json(self) -> dict[str, Any]:
        return asdict(self) | {"violations": list(self.violations)}


def report(plan: Plan) -> Report:
    bound = plan_bound(plan)
    broken = violations(plan)
    robust = (
        None if plan.robust is None else {"x0": list(plan.robust[0]), "v0": list(plan.robust[1])}
    )
    return Report(
        plan.strategy,
        plan.order,
        plan.x0,
        plan.v0,
        plan.tau_s,
        plan.duration,
        plan.t_switch,
        plan.v_contact,
        plan.peaks.v,
        plan.peaks.a,
        bound,
        plan.duration / bound,
        not broken,
        tuple(broken),
        robust,
    )
