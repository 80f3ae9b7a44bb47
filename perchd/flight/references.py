"""What the flight aims at, tick by tick: the approach's speed reference to the plan's trigger
state, and the stages' references from the plan flown, by time and by place, with the lead,
lag and scale corrections (docs/errata.md §9, §10). No control and no identification of its
own: the vehicle's response (flight/response.py) is read, never fitted, here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from perchd.core.types import State
from perchd.flight.config import FlightConfig, TauGains
from perchd.flight.planrefs import PlanPoint, PlanSampler
from perchd.flight.response import VehicleResponse
from perchd.flight.trigger import TriggerDesk
from perchd.tau.plan import Plan


@dataclass(frozen=True, slots=True)
class Refs:
    """Plan references at a tick: tau_ref [s], x/v/a [m, m/s, m/s^2]; None outside stages."""

    tau_ref: float | None = None
    x: float | None = None
    v: float | None = None
    a: float | None = None


NO_REFS = Refs()


HOLD_RATE = 1.0
"""[1/lag] stage 2's speed loop is at most this fast against the vehicle's lag: e = 1 -
Xdot/V_hold makes kp a speed gain of kp / V_hold [1/s], and a loop faster than once per lag
brakes on what the vehicle will already do a lag later (ArduCopter's 0.34 s lag met 4.4 /s
from the switch and touched at 0.80-0.83 m/s)."""
KI_SHARE = 0.25
"""Stage 2's integral gain in speed units, at least KI_SHARE x its speed gain squared: the
loop s^2 + k s + ki on a vehicle that integrates its acceleration is critically damped at
ki = k^2 / 4, so a push is worked off within a few loop times instead of leaving the
proportional droop until the wall."""
MARGIN_MAX_MPS = 0.05
"""[m/s] the most stage 2's margin takes: a vehicle of lag over 0.17 s (its droop under 0.3
m/s^2 over 0.05 m/s) would be asked for more, but it arrives at the switch still braking and
touches under V_hold by more than that (the family's attitude time constant:
docs/controller.md), and each 0.01 m/s costs 0.27 % of perch time on the README's plan."""


@dataclass(frozen=True, slots=True)
class HoldLoop:
    """Stage 2's speed loop: it holds v_hold_mps [m/s] with gains kp_mps2 [m/s^2] and
    ki_mps3 [m/s^3] on e = 1 - Xdot/V_hold, margin_mps [m/s] inside the window's top."""

    v_hold_mps: float
    kp_mps2: float
    ki_mps3: float
    margin_mps: float


def hold_speed(plan: Plan, margin_mps: float) -> float:
    """[m/s] the plan's V_c moved at least margin_mps [m/s] inside its contact window (its
    middle when the window is narrower than twice the margin)."""
    v = float(plan.v_contact)
    lo, hi = plan.limits.v_contact
    if hi - lo <= 2.0 * margin_mps:
        return 0.5 * (lo + hi)
    return min(max(v, lo + margin_mps), hi - margin_mps)


def hold_loop(plan: Plan, gains: TauGains, lag_s: float | None) -> HoldLoop:
    """Stage 2's loop for a vehicle of lag lag_s [s]: as fast as HOLD_RATE lets it, up to
    kp_fast; the integral at least KI_SHARE of critical damping; and V_hold moved inside
    the window by the loop's droop under the wall's push, wall_push V_c / kp [m/s], at most
    MARGIN_MAX_MPS (docs/controller.md, "Stage 2"). lag_s None (no lag identified): the
    loop a vehicle of unknown lag is given, kp_slow with the configured integral and the
    largest margin, wall_push permitting."""
    if lag_s is None:
        margin = MARGIN_MAX_MPS if gains.wall_push_mps2 > 0.0 else 0.0
        return HoldLoop(hold_speed(plan, margin), gains.kp_slow, gains.ki, margin)
    v_c = max(float(plan.v_contact), 1e-3)
    kp = gains.kp_fast if lag_s <= 0.0 else min(gains.kp_fast, HOLD_RATE * v_c / lag_s)
    ki = max(gains.ki, KI_SHARE * kp * kp / v_c)
    margin = min(gains.wall_push_mps2 * v_c / kp, MARGIN_MAX_MPS) if kp > 0.0 else MARGIN_MAX_MPS
    return HoldLoop(hold_speed(plan, margin), kp, ki, margin)


class References:
    """The plan flown and what the references need of the flight: t0 [s] the plan's t = 0
    on the clock (None before the trigger), t_stage2 [s] the stage-2 switch (None before),
    hold: stage 2's loop, fixed at the switch (None before), a_app [m/s^2] the approach's
    acceleration to the trigger state. desk: the trigger's (a
    replan awaited holds the approach's speed); response: the vehicle's, as fitted so far."""

    def __init__(
        self, plan: Plan, cfg: FlightConfig, desk: TriggerDesk, response: VehicleResponse
    ) -> None:
        self.plan = plan
        self.cfg = cfg
        self.desk = desk
        self.response = response
        self.t0: float | None = None
        self.t_stage2: float | None = None
        self.hold: HoldLoop | None = None
        self.a_app = 0.0
        self._sampler = PlanSampler(plan)
        self._memo: tuple[Any, Refs] = (None, NO_REFS)  # (tick key, its Refs)

    def start(self, plan: Plan, t0: float) -> None:
        """Fly `plan` from t0 [s] on the clock."""
        self.plan, self.t0 = plan, t0
        if plan is not self._sampler.plan:
            self._sampler = PlanSampler(plan)

    def fix_hold(self) -> HoldLoop:
        """Stage 2's loop from here on (`hold`): the one the lag identified gives."""
        self.hold = self._loop_for_lag()
        return self.hold

    def _loop_for_lag(self) -> HoldLoop:
        """hold_loop for the lag identified so far (None to it when none was)."""
        known = self.response.model is not None
        return hold_loop(self.plan, self.cfg.tau_gains, self.response.ff.lead_s if known else None)

    @property
    def v_hold(self) -> float:
        """[m/s] the stage-2 speed held: the fixed loop's, before the switch the one the lag
        identified so far gives."""
        return (self.hold or self._loop_for_lag()).v_hold_mps

    @property
    def tau_s(self) -> float | None:
        tau_s: float | None = getattr(self.plan, "tau_s", None)  # a test's plan may lack one
        return tau_s

    # --- the approach -----------------------------------------------------------------------
    def v_ref(self, x: float) -> float:
        """[m/s] the approach's speed reference at X = x: the profile to (x0, v0), or, while a
        replan is awaited past x0, the speed measured at the trigger (held constant)."""
        if self.desk.wait is not None:
            return self.desk.wait.v
        v0 = self.plan.v0
        return math.sqrt(max(0.0, v0 * v0 - 2.0 * self.a_app * (self.plan.x0 - x)))

    def approach(self, x: float, lead_s: float) -> tuple[float, float]:
        """(v_ref [m/s] at X = x [m], the feed-forward [m/s^2] for where the vehicle will be
        lead_s [s] later). Past x0 the references are the plan's own: the vehicle answers
        a lag late, so the approach's last commands already fly the start of the plan
        (docs/errata.md §10)."""
        ff, wait = self.response.ff, self.desk.wait
        if wait is not None:
            return wait.v, ff.accel(0.0, wait.v)
        x0 = self.plan.x0
        v_ref = self._plan_at(x).v if x >= x0 else self.v_ref(x)
        ahead = x + v_ref * max(lead_s, 0.0)
        if ahead < x0:
            return v_ref, ff.accel(self.a_app, v_ref)
        p = self._plan_at(ahead)
        return v_ref, ff.accel(p.a if p.stage == 1 else 0.0, p.v)

    # --- the plan by time and by place ------------------------------------------------------
    def now(self, t: float) -> PlanPoint:
        """The plan's point at tick time t [s] (its time held within 0..duration)."""
        return self._sampler.at(self._plan_s(t))

    def _plan_s(self, t: float) -> float:
        """[s] the plan's time at tick time t [s], held within 0..duration."""
        return min(max(t - self._trigger_t(), 0.0), self.plan.duration)

    def _trigger_t(self) -> float:
        """[s] the plan's t = 0 on the clock."""
        if self.t0 is None:
            raise RuntimeError("the plan's references are asked before the trigger")
        return self.t0

    def _plan_at(self, x: float) -> PlanPoint:
        """The plan's point where its X is x [m] (>= x0)."""
        return self._sampler.at(self._plan_time(x, (x - self.plan.x0) / self.plan.v0))

    def _plan_time(self, x: float, guess_s: float) -> float:
        """[s] the plan's time where its X is x [m] (>= x0), by Newton's method from
        guess_s [s] (X is monotone in the plan's time)."""
        plan, at, s = self.plan, self._sampler.at, guess_s
        for _ in range(3):
            s = min(max(s, 0.0), plan.duration)
            p = at(s)
            s -= (p.x - x) / max(p.v, 1e-3)
        return min(max(s, 0.0), plan.duration)

    def _plan_ahead(self, s: float, lead_s: float) -> tuple[PlanPoint, float]:
        """The plan's point at its time s [s], and the feed-forward [m/s^2] for its point
        lead_s [s] later (its acceleration there while in stage 1, the drag at its speed)."""
        here = self._sampler.at(s)
        ahead = self._sampler.at(min(s + lead_s, self.plan.duration)) if lead_s else here
        return here, self.response.ff.accel(ahead.a if ahead.stage == 1 else 0.0, ahead.v)

    # --- the stages -------------------------------------------------------------------------
    def for_tick(self, t: float, x: float | None) -> Refs:
        """The references at tick time t for the vehicle at X = x; computed once per tick
        (the tau watch and the controller both ask), again only if the stage or the plan
        changed in between."""
        key = (t, self.t_stage2, self.t0, x)
        if self._memo[0] != key:
            self._memo = (key, self.at(t, x, self.response.ff.lead_s))
        return self._memo[1]

    def at(self, t: float, x: float | None, lead_s: float) -> Refs:
        """The references at time t [s] for the vehicle at X = x [m], with the feed-forward
        taken lead_s [s] ahead."""
        ff = self.response.ff
        here, a = self._plan_ahead(self._plan_s(t), lead_s)
        if self.t_stage2 is None or x is None:
            return Refs(here.tau_ref, here.x, here.v, a)
        # Stage 2 holds V_hold: tau_ref = X / V_hold makes e = 1 - Xdot/V_hold (docs/errata.md §9).
        return Refs(min(x, 0.0) / self.v_hold, here.x, here.v, ff.accel(0.0, self.v_hold))

    def scale_corrected(self, t: float, st: State, aim: Refs) -> float:
        """Stage 1's tau reference for the vehicle at st: the clock's, scale-corrected
        (_scale_corrected), the correction faded out from three lags before the plan's
        switch to two (a catch-up that late would reach the switch as speed)."""
        lag, left = self.response.ff.lead_s, self.plan.t_switch - (t - self._trigger_t())
        weight = min(max((left - 2.0 * lag) / lag, 0.0), 1.0) if lag > 0.0 else 1.0
        return self._scale_corrected(st, aim, weight)

    def _scale_corrected(self, seen: State, aim: Refs, weight: float) -> float:
        """The tau reference corrected for the scale error c = X / X_plan: tau = X/Xdot is
        blind to it (c times the plan's X and Xdot keep the plan's tau), yet it reaches the
        stage-2 switch as c times the plan's speed there. Aiming at tau_ref c^-gamma brings
        c back to 1 with time constant |tau| / gamma, never faster than twice the lag;
        gamma is scaled by weight (stage 1's end fades it out: a catch-up that late would
        reach the switch as speed; TauGains.scale_gain, docs/errata.md §10)."""
        assert aim.tau_ref is not None  # the stages' references are all set
        gamma, lag = self.cfg.tau_gains.scale_gain, self.response.ff.lead_s
        if gamma <= 0.0 or lag <= 0.0 or aim.x is None or aim.x >= 0.0 or seen.x >= 0.0:
            return aim.tau_ref
        gamma = weight * min(gamma, -aim.tau_ref / (2.0 * lag))
        c = min(max(seen.x / aim.x, 0.5), 2.0)
        scale: float = c**-gamma  # float ** float is typed Any
        return aim.tau_ref * scale
