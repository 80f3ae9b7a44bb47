"""A plan checked before it flies: the verification `perchd plan check` runs (figures
re-derived, limits met, perchd.tau.verify) and its figures inside this vehicle's envelope
(the config's speed limit, tilt saturation and geofence). Every flight passes here: the
commands before any link opens, flight.run.fly again before it engages."""

from __future__ import annotations

import math

from perchd.core.errors import PlanError
from perchd.flight.config import FlightConfig
from perchd.tau.plan import Plan
from perchd.tau.verify import verify_plan


def envelope_faults(plan: Plan, cfg: FlightConfig) -> list[str]:
    """Each way the plan leaves the vehicle's limits, naming the field and by how much."""
    s, found = cfg.safety, []
    speed = max(plan.peaks.v, plan.v0, plan.limits.v_contact[1])
    if speed > s.speed_max_mps:
        found.append(
            f"plan speed {speed:.4g} m/s (peak, v0 or v_contact) exceeds [safety] "
            f"speed_max_mps = {s.speed_max_mps:g} m/s by {speed - s.speed_max_mps:.4g} m/s"
        )
    tilt = math.atan2(plan.peaks.a, cfg.vehicle.g)
    if tilt > cfg.tilt_limit_rad:
        found.append(
            f"plan peaks.a = {plan.peaks.a:.4g} m/s^2 needs {math.degrees(tilt):.1f} deg "
            f"of tilt, above tilt_limit_rad = {math.degrees(cfg.tilt_limit_rad):.1f} "
            f"deg by {math.degrees(tilt - cfg.tilt_limit_rad):.1f} deg"
        )
    if plan.x0 < s.x_min_m:
        found.append(
            f"plan x0 = {plan.x0:g} m is outside the geofence [safety] x_min_m = "
            f"{s.x_min_m:g} m by {s.x_min_m - plan.x0:.4g} m"
        )
    return found


def check_flight_plan(plan: Plan, cfg: FlightConfig) -> Plan:
    """The plan itself, or one PlanError (exit 2) naming its first fault."""
    verify_plan(plan)
    faults = envelope_faults(plan, cfg)
    if faults:
        raise PlanError(faults[0])
    return plan
