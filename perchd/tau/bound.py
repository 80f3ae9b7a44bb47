"""Minimum-time lower bound for any plan under the same limits (docs/errata.md, the lower bound).

Stage 1 flown bang-bang over the gap it must close, |x0| - V_c |tau_s|: accelerate at a_max,
cruise at v_max if reached, decelerate at a_max to V_c; the best V_c in [V_l, V_u]; plus
|tau_s| for stage 2. No plan meeting the same limits can be faster.
"""

from __future__ import annotations

import math

import numpy as np

from perchd.tau.plan import Plan


def stage1_min_time(gap: float, v0: float, v_c: float, a_max: float, v_max: float) -> float:
    """[s] shortest time over `gap` [m] from v0 to v_c with |a| <= a_max, v <= v_max; inf if
    the gap is too short to brake to v_c."""
    brake = (v0 * v0 - v_c * v_c) / (2 * a_max)
    if gap < brake - 1e-12:
        return math.inf
    v_peak = math.sqrt((2 * a_max * gap + v0 * v0 + v_c * v_c) / 2)
    if v_peak <= v_max:
        return (2 * v_peak - v0 - v_c) / a_max
    ramps = (2 * v_max - v0 - v_c) / a_max
    ramp_gap = (2 * v_max**2 - v0 * v0 - v_c * v_c) / (2 * a_max)
    return ramps + (gap - ramp_gap) / v_max


def min_time_bound(
    x0: float,
    v0: float,
    tau_s: float | None,
    v_contact: tuple[float, float],
    a_max: float,
    v_max: float | None,
) -> tuple[float, float]:
    """(bound [s], its best V_c [m/s]) over V_c in v_contact, by a dense scan then refinement."""
    v_max = math.inf if v_max is None else v_max
    hold = 0.0 if tau_s is None else -tau_s

    def total(v_c: float) -> float:
        return stage1_min_time(-x0 - v_c * hold, v0, v_c, a_max, v_max) + hold

    lo, hi = v_contact
    grid = np.linspace(lo, hi, 201) if hi > lo else np.array([lo])
    times = np.array([total(v) for v in grid])
    i = int(np.argmin(times))
    fine = np.linspace(grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)], 201)
    best = min(fine, key=total)
    return float(total(best)), float(best)


def plan_bound(plan: Plan) -> float:
    """The bound for a plan's own trigger state and limits (its peak |a| if a_max is unset)."""
    lim = plan.limits
    a_max = lim.a_max if lim.a_max is not None else plan.peaks.a
    v_contact = lim.v_contact if plan.strategy != "ctds" else (0.0, 0.0)
    return min_time_bound(plan.x0, plan.v0, plan.tau_s, v_contact, a_max, lim.v_max)[0]
