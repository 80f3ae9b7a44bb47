"""One family member's first flight: a fresh simulated world of its plant and mocap, the lab's
config for it (perchd.sim.family.lab_config), no memory of earlier flights, and one row of
figures measured by the simulator's truth."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from perchd.core.errors import PerchdError
from perchd.core.types import EndReason
from perchd.flight.config import FlightConfig
from perchd.flight.run import FlightResult
from perchd.session import open_session
from perchd.sim.family import FamilyVehicle, lab_config
from perchd.sim.world import WorldParams
from perchd.tau.plan import Plan

PERCH_TOLERANCE_PCT = 3.0
"""[%] a perch time this close to the plan's duration is on time."""

UNSTABLE = frozenset(
    {
        EndReason.SPEED_LIMIT,
        EndReason.GEOFENCE,
        EndReason.TILT_LIMIT,
        EndReason.TAU_DIVERGENCE,
        EndReason.STALE_MOCAP,
        EndReason.LOST_LINK,
        EndReason.DEADLINE_OVERRUN,
        EndReason.TIMEOUT,
        EndReason.SOFTWARE_ERROR,
        EndReason.SIGNAL,
        EndReason.OPERATOR_ABORT,
    }
)
"""Endings that are the safety net catching a vehicle out of control, or aborts that on a
simulated link and mocap cannot be the vehicle's doing. The rest end safely: CONTACT,
PLAN_COMPLETE (no contact in time), TRIGGER_REFUSED and HOVER_UNLEARNED (refusals)."""


@dataclass(frozen=True)
class FamilyRow:
    """One flight. The member's parameters (units as in perchd.sim.family.Family), then:
    outcome (EndReason name) and detail; contact_speed [m/s] and perch_time [s, trigger to
    contact] by the simulator's truth, contact_speed_est [m/s] the agent's estimate (None
    without contact); plan_duration [s] and plan_v_contact [m/s] of the plan flown; v_lo,
    v_hi [m/s] its contact window; in_window; perch_error_pct [%] of plan_duration;
    on_time (within PERCH_TOLERANCE_PCT); unstable (outcome in UNSTABLE)."""

    index: int
    seed: int
    mass_kg: float
    thrust_to_weight: float
    attitude_tau_s: float
    latency_s: float
    motor_tau_s: float
    drag_per_s: float
    qdrag_per_m: float
    mocap_rate_hz: float
    mocap_latency_s: float
    mocap_noise_m: float
    draught_mps2: float
    draught_reach_m: float
    outcome: str
    detail: str
    contact_speed: float | None
    contact_speed_est: float | None
    perch_time: float | None
    plan_duration: float
    plan_v_contact: float
    v_lo: float
    v_hi: float
    in_window: bool
    perch_error_pct: float | None
    on_time: bool
    unstable: bool


PARAMETERS = tuple(f.name for f in dataclasses.fields(FamilyRow))[2:14]
"""The member's parameter columns of a FamilyRow."""


def parameters(member: FamilyVehicle) -> dict[str, float]:
    """The member's PARAMETERS by name."""
    p, m = member.plant, member.mocap
    return {
        "mass_kg": p.mass_kg,
        "thrust_to_weight": member.thrust_to_weight,
        "attitude_tau_s": p.attitude_tau_s,
        "latency_s": p.latency_s,
        "motor_tau_s": p.motor_tau_s,
        "drag_per_s": p.drag_per_s,
        "qdrag_per_m": p.qdrag_per_m,
        "mocap_rate_hz": m.rate_hz,
        "mocap_latency_s": m.latency_s,
        "mocap_noise_m": m.noise_m,
        "draught_mps2": p.draught_mps2,
        "draught_reach_m": member.draught_reach_m,
    }


def fly_member(
    plan: Plan, member: FamilyVehicle, base: FlightConfig, log_path: str | Path
) -> FamilyRow:
    """Fly `plan` once on `member` with lab_config(member, base); its row. A flight the
    software refuses or breaks off with an error is a SOFTWARE_ERROR row, not an exception:
    a family run reports every member."""
    cfg = lab_config(member, base)
    session = open_session(
        params=WorldParams(plant=member.plant, mocap=member.mocap, seed=member.seed),
        surface=cfg.surface,
    )
    try:
        res = session.fly(plan, log_path, cfg)
    except PerchdError as err:
        return _row(member, plan, None, f"{type(err).__name__}: {err}")
    return _row(member, plan, res, res.detail)


def _row(member: FamilyVehicle, plan: Plan, res: FlightResult | None, detail: str) -> FamilyRow:
    lo, hi = plan.limits.v_contact
    outcome = res.outcome if res else EndReason.SOFTWARE_ERROR
    hit = outcome is EndReason.CONTACT and res.true_contact_speed is not None
    speed = res.true_contact_speed if hit else None
    perch = res.true_perch_time if hit else None
    duration = res.plan_duration if res else float(plan.duration)
    err = None if perch is None else 100.0 * (perch - duration) / duration
    return FamilyRow(
        member.index,
        member.seed,
        **parameters(member),
        outcome=outcome.name,
        detail=detail,
        contact_speed=speed,
        contact_speed_est=res.contact_speed if hit else None,
        perch_time=perch,
        plan_duration=duration,
        plan_v_contact=res.v_contact_plan if res else float(plan.v_contact),
        v_lo=lo,
        v_hi=hi,
        in_window=hit and lo <= speed <= hi,
        on_time=err is not None and abs(err) <= PERCH_TOLERANCE_PCT,
        perch_error_pct=err,
        unstable=outcome in UNSTABLE,
    )
