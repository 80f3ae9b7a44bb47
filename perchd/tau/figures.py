"""A plan's stored figures against those its parameters give: the one comparison the file
loader and the pre-flight verification share."""

from __future__ import annotations

import math

from perchd.tau.plan import Plan

REL_TOL = 1e-6  # stored figures are written at full precision; this absorbs re-derivation round-off


def figures(plan: Plan) -> dict[str, float]:
    """The derived figures a plan file stores, by their field names."""
    return {
        "t_switch": plan.t_switch,
        "duration": plan.duration,
        "v_contact": plan.v_contact,
        "peaks.v": plan.peaks.v,
        "peaks.a": plan.peaks.a,
    }


def disagreement(stored: dict[str, float], derived: Plan) -> str | None:
    """The first stored figure its parameters do not give, in words (None: all agree)."""
    for name, value in figures(derived).items():
        if not math.isclose(stored[name], value, rel_tol=REL_TOL, abs_tol=1e-9):
            return (
                f"{name}: file says {stored[name]:.6g} but its parameters give "
                f"{value:.6g} (tampered or stale plan)"
            )
    return None
