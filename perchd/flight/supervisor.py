"""Flight phases and every end rule: one `tick` per control period, no I/O of its own.

Phases: TAKEOFF (only when the flight starts below the take-off height) -> HOLD at the start
point, at least hold_s and until the hover thrust has been learned (flight/hover.py;
HOVER_UNLEARNED after hover.timeout_s) -> APPROACH (accelerate along X so that the plan's trigger state (x0, v0) is reached at
x0) -> trigger -> STAGE1 (tau_ref indexed by time since the trigger) -> STAGE2 when the
*measured* tau reaches tau_s (docs/errata.md §9; tau_ref = tau_s + time since that switch) ->
CONTACT (the post-contact action for post_contact_s) -> DONE.

End rules, checked in this order on every tick: operator abort, signal, stale mocap, lost
link, geofence, tilt, speed limit, tau divergence, deadline overrun streak, timeout, contact,
plan complete. The trigger itself may end the flight (TRIGGER_REFUSED): what it flies or
refuses is flight/trigger.py's decision; what the flight knows of the vehicle's response
and feeds forward is flight/response.py's.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from dataclasses import dataclass
from typing import Any

from perchd.core.envelope import MARGIN_M
from perchd.core.types import EndReason, LinkHealth, Phase, Setpoint, State
from perchd.flight.config import FlightConfig, PostContact
from perchd.flight.control import AxisController, Controller, FeedForward
from perchd.flight.frame import PerchFrame
from perchd.flight.hover import HoverLearner
from perchd.flight.planner_worker import Planner
from perchd.flight.planrefs import PlanPoint, PlanSampler
from perchd.flight.response import VehicleResponse, feed_forward
from perchd.flight.takeoff import TakeoffProfile
from perchd.flight.trigger import TriggerDesk
from perchd.logs.flightlog import LogEvent
from perchd.tau.plan import Plan

FROZEN_MAX_S = 0.3
"""[s] once the approach has begun, poses with a bit-identical position for longer than this
are a stuck tracker re-sending its last position with fresh stamps, not a vehicle (noise
alone moves a real measurement; a commanded vehicle moves a noiseless simulated one within
its command latency and attitude response, well under this)."""
_MOVING = (Phase.APPROACH, Phase.STAGE1, Phase.STAGE2)
_OBSERVED = (Phase.HOLD, Phase.APPROACH, Phase.STAGE1, Phase.STAGE2)
"""The phases whose ticks the lag identification records (flight/lagid.py)."""


class FlightAbort:
    """The external abort hook: any thread (a signal handler, the control socket) calls
    request(); the supervisor ends the flight on its next tick with that reason."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._reason: EndReason | None = None

    def request(self, reason: EndReason = EndReason.OPERATOR_ABORT) -> None:
        with self._lock:
            if self._reason is None:
                self._reason = reason

    @property
    def reason(self) -> EndReason | None:
        with self._lock:
            return self._reason


@dataclass(frozen=True, slots=True)
class Refs:
    """Plan references at a tick: tau_ref [s], x/v/a [m, m/s, m/s^2]; None outside stages."""

    tau_ref: float | None = None
    x: float | None = None
    v: float | None = None
    a: float | None = None


NO_REFS = Refs()
NO_U = (0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class TickReport:
    """What one tick decided: the setpoint to send (None: send nothing), the end reason once
    the flight has ended, whether the loop should stop, and the figures for the log."""

    phase: Phase
    setpoint: Setpoint | None
    end: EndReason | None
    finished: bool
    refs: Refs
    u: tuple[float, float, float]
    e: float | None


@dataclass(frozen=True, slots=True)
class Trigger:
    """t [s] on the clock when X crossed the flown plan's x0 (the plan's t = 0; at most a tick
    before the triggering tick); x [m], v [m/s] measured at the triggering tick;
    plan_x0/plan_v0 [m, m/s] of the plan finally flown; action: how the plan was chosen."""

    t: float
    x: float
    v: float
    plan_x0: float
    plan_v0: float
    action: str


@dataclass(frozen=True, slots=True)
class ContactEstimate:
    """t [s] estimated time at X = 0; speed [m/s] estimated Xdot then."""

    t: float
    speed: float


@dataclass(frozen=True, slots=True)
class Conditions:
    """What the supervisor checks besides the state, sampled once per tick.

    health: the driver's link.  overrun_streak: deadlines missed in a row by the loop.
    abort: an external request (operator, signal), None when there is none.
    mocap_period_s: [s] the measured pose period, None until known.
    arrival_age_s: [s] since the newest pose used arrived, None before the first.
    """

    health: LinkHealth
    overrun_streak: int = 0
    abort: EndReason | None = None
    mocap_period_s: float | None = None
    arrival_age_s: float | None = None


class Supervisor:
    """planner: where the trigger's ROBUST and REPLAN get their plans (TriggerDesk); None:
    solved in the tick. The caller owns it (starts and closes it)."""

    def __init__(
        self, plan: Plan, cfg: FlightConfig, frame: PerchFrame, planner: Planner | None = None
    ) -> None:
        self.plan = plan
        self.cfg = cfg
        self.frame = frame
        self.ctl = Controller(cfg, frame)
        self.phase = Phase.IDLE
        self.end: EndReason | None = None
        self.end_detail = ""
        self.events: list[LogEvent] = []
        self.trigger: Trigger | None = None
        self.contact: ContactEstimate | None = None
        self.t_start: float | None = None
        self.t_stage2: float | None = None
        self._t_prev: float | None = None
        self._t_phase = 0.0
        self._t_end: float | None = None
        self._t_bad_tau: float | None = None
        self._hold: tuple[float, float, float] | None = None
        self._hold_x: AxisController | None = None  # the X position loop of the hold
        self._t_moving = 0.0  # [s] when the approach began moving the vehicle
        self._z_ref = 0.0
        self._takeoff: TakeoffProfile | None = None  # the TAKEOFF phase's height reference
        self._a_app = 0.0
        self._x: float | None = None  # [m] measured X of the tick in hand
        self._sampler = PlanSampler(plan)
        self._refs_memo: tuple[Any, Refs] = (None, NO_REFS)  # (tick key, its Refs)
        self.desk = TriggerDesk(plan, cfg, planner, self.events)
        self.hover = HoverLearner(cfg.hover, cfg.vehicle.hover_guess_n, cfg.vehicle.g)
        self.hover_learned_n: float | None = None  # [N] once the hold's estimate settled
        self._hover_waiting = False
        self._v_int = 0.0  # [m/s] integral of the approach's speed error
        self.response = VehicleResponse(cfg.tau_gains, cfg.lag_id, self.events)
        self._t_refit = -math.inf  # [s] the approach's last refit

    # --- helpers ----------------------------------------------------------------------------
    def _enter(self, phase: Phase, t: float, detail: str = "", **values: float) -> None:
        self.phase, self._t_phase = phase, t
        self.events.append(LogEvent(t, phase.value, detail, values))

    def _finish(self, reason: EndReason, t: float, detail: str = "") -> None:
        if self.end is None:
            self.end, self.end_detail, self._t_end = reason, detail, t
            self.events.append(
                LogEvent(t, "end", f"{reason.value}{': ' if detail else ''}{detail}")
            )

    # --- the tick ---------------------------------------------------------------------------
    def tick(self, t: float, state: State | None, cond: Conditions) -> TickReport:
        """One control tick at `t` [s]: check every end rule, then fly the phase."""
        dt = 0.0 if self._t_prev is None else t - self._t_prev
        self._t_prev = t
        if self.t_start is None:
            self.t_start = t
        self._x = None if state is None else state.x
        if self.end is None:
            reason, detail = self._check(t, state, cond)
            if reason is not None:
                self._finish(reason, t, detail)
        if self.end is not None:
            return self._ended(t, state)
        if state is None:  # waiting for the first pose (bounded by the stale-mocap rule)
            return TickReport(self.phase, None, None, False, NO_REFS, NO_U, None)
        return self._fly(t, dt, state)

    def _check(
        self, t: float, state: State | None, cond: Conditions
    ) -> tuple[EndReason | None, str]:
        s, health, arrival_age = self.cfg.safety, cond.health, cond.arrival_age_s
        if cond.abort is not None:
            return cond.abort, ""
        limit = s.stale_timeout_s or s.stale_periods * (cond.mocap_period_s or 0.01)
        if state is None:
            if t - self.t_start > max(limit, 0.5):
                return EndReason.STALE_MOCAP, f"no pose in {t - self.t_start:.3f} s"
        elif arrival_age is not None and arrival_age > limit:
            return EndReason.STALE_MOCAP, f"newest pose arrived {arrival_age * 1000:.0f} ms ago"
        elif self.phase in _MOVING and min(state.frozen_s, t - self._t_moving) > FROZEN_MAX_S:
            return EndReason.STALE_MOCAP, (
                f"mocap frozen: the same position for {state.frozen_s * 1000:.0f} ms while flying"
            )
        if not health.ok:
            return EndReason.LOST_LINK, health.detail
        if health.rtt_s is not None and health.rtt_s > s.link_rtt_max_s:
            return EndReason.LOST_LINK, (
                f"link too slow: round trip {health.rtt_s * 1000:.0f} ms"
                f" > {s.link_rtt_max_s * 1000:.0f} ms"
            )
        if state is not None:
            why = self._limits(state)
            if why is not None:
                return why
            why = self._tau_watch(t, state)
            if why is not None:
                return why
        if cond.overrun_streak >= s.overrun_streak:
            return EndReason.DEADLINE_OVERRUN, f"{cond.overrun_streak} deadlines missed in a row"
        if t - self.t_start > s.timeout_s:
            return EndReason.TIMEOUT, (
                f"flying {t - self.t_start:.3f} s, longer than "
                f"[safety] timeout_s = {s.timeout_s:g} s"
            )
        if state is not None and self._contact(t, state):
            return EndReason.CONTACT, f"at {self.contact.speed:.3f} m/s"
        since = None if self.trigger is None else t - self.trigger.t
        if since is not None and since > self.plan.duration + s.plan_grace_s:
            return EndReason.PLAN_COMPLETE, f"{since:.2f} s after the trigger, X = {state.x:.3f} m"
        return None, ""

    def _limits(self, st: State):
        s = self.cfg.safety
        airborne = self.phase not in (Phase.IDLE, Phase.TAKEOFF)
        height = self.frame.point[2] + self.frame.rotate_out((st.x, st.y, st.z))[2]
        if not s.x_min_m <= st.x <= s.x_max_m:
            return EndReason.GEOFENCE, f"X = {st.x:.3f} m outside {s.x_min_m:g}..{s.x_max_m:g} m"
        if self._hold is not None:
            dy, dz = st.y - self._hold[1], st.z - self._z_ref
            if airborne and max(abs(dy), abs(dz)) > s.lateral_max_m:
                return EndReason.GEOFENCE, (
                    f"{math.hypot(dy, dz):.2f} m off the approach line "
                    f"(limit {s.lateral_max_m:g} m)"
                )
        if airborne and height < s.floor_m:
            return (
                EndReason.GEOFENCE,
                f"height {height:.3f} m below the floor limit {s.floor_m:g} m",
            )
        if height > s.ceiling_m:
            return EndReason.GEOFENCE, f"height {height:.3f} m above the ceiling {s.ceiling_m:g} m"
        if st.tilt > s.tilt_max_rad:
            return EndReason.TILT_LIMIT, (
                f"tilt {math.degrees(st.tilt):.1f} deg > {math.degrees(s.tilt_max_rad):.1f} deg"
            )
        speed = math.sqrt(st.xdot**2 + st.ydot**2 + st.zdot**2)
        if speed > s.speed_max_mps:
            return EndReason.SPEED_LIMIT, f"{speed:.2f} m/s > {s.speed_max_mps:g} m/s"
        return None

    def _tau_watch(self, t: float, st: State):
        if self.phase not in (Phase.STAGE1, Phase.STAGE2):
            return None
        s = self.cfg.safety
        ref = self._refs(t).tau_ref
        bad = st.tau is None or abs(st.tau - ref) > max(s.tau_error_max, s.tau_error_rel * abs(ref))
        if not bad:
            self._t_bad_tau = None
            return None
        self._t_bad_tau = self._t_bad_tau if self._t_bad_tau is not None else t
        if t - self._t_bad_tau >= s.tau_error_s:
            got = "undefined" if st.tau is None else f"{st.tau:.3f} s"
            return EndReason.TAU_DIVERGENCE, f"tau {got} vs tau_ref {ref:.3f} s"
        return None

    def _contact(self, t: float, st: State) -> bool:
        if self.phase not in (Phase.APPROACH, Phase.STAGE1, Phase.STAGE2):
            return False
        reach = max(st.xdot, 0.0) / self.cfg.rate_hz + self.cfg.safety.contact_margin_m
        if st.x + reach < 0.0:
            return False
        lead = -st.x / st.xdot if st.xdot > 0 and st.x < 0 else 0.0
        self.contact = ContactEstimate(t + lead, st.xdot)
        self._enter(Phase.CONTACT, t, "contact", speed=st.xdot, x=st.x)
        return True

    # --- ends -------------------------------------------------------------------------------
    def _ended(self, t: float, state: State | None) -> TickReport:
        seq = state.pose_seq if state else -1
        if self.end is not EndReason.CONTACT:
            if self.phase is not Phase.ABORT:
                self._enter(Phase.ABORT, t, self.end.value)
            return TickReport(Phase.ABORT, None, self.end, True, NO_REFS, NO_U, None)
        done = t - self._t_end >= self.cfg.post_contact_s
        yaw = self.frame.yaw_facing
        if self.cfg.post_contact is PostContact.IDLE:
            thrust = self.cfg.idle_thrust_n
            thrust = self.cfg.vehicle.thrust_min_n if thrust is None else thrust
            sp = Setpoint(t, 0.0, 0.0, yaw, thrust, seq, Phase.CONTACT)
        else:
            sp = Setpoint(t, 0.0, 0.0, yaw, 0.0, seq, Phase.CONTACT)
        if done and self.phase is not Phase.DONE:
            self._enter(Phase.DONE, t, self.cfg.post_contact.value)
        return TickReport(self.phase, sp, self.end, done, NO_REFS, NO_U, None)

    # --- flying -----------------------------------------------------------------------------
    def _fly(self, t: float, dt: float, st: State) -> TickReport:
        if self.phase is Phase.IDLE:
            self._start(t, st)
        if self.phase is Phase.TAKEOFF and self._takeoff.done and st.z >= self._z_ref - 0.05:
            self._enter(Phase.HOLD, t)
        self._learn_hover(t, dt, st)
        if (
            self.phase is Phase.HOLD
            and t - self._t_phase >= self.cfg.approach.hold_s
            and self._hover_ready(t, st)
            and self.desk.ready(t)
        ):
            self._begin_approach(t, st)
        if self.end is not None:
            return self._ended(t, st)
        if self.phase is Phase.APPROACH:
            self._approach_plans(t, dt, st)
            if self.end is not None:
                return self._ended(t, st)
        else:
            self.desk.note_late(t)
        if self.phase is Phase.STAGE1:
            self._switch(t, st)
        refs, ux, e, vz_ref = NO_REFS, 0.0, None, 0.0
        if self.phase in (Phase.STAGE1, Phase.STAGE2):
            refs = self._refs(t)
            g = self.cfg.tau_gains
            if (
                self.phase is Phase.STAGE2
                and not g.stage2_hold_speed
                and refs.tau_ref > -g.terminal_s
            ):
                ux = 0.0  # terminal: constant speed (see TauGains.terminal_s)
            else:
                hold = self.phase is Phase.STAGE2 and g.stage2_hold_speed
                seen, aim = self._lag_view(t, st, refs)
                tau_aim = aim.tau_ref
                if self.phase is Phase.STAGE1:
                    tau_aim, aim = self._stage1_aim(t, seen, aim)
                ux = self.ctl.tau.step(
                    seen, tau_aim, aim.a, dt, self.ctl.saturated, schedule=not hold
                )
            e = self.ctl.tau.last_error
        elif self.phase is Phase.APPROACH:
            ux = self._approach_accel(t, st, dt)
        else:
            ux = self._hold_x.step(self._hold[0], st.x, st.xdot, dt, self.ctl.saturated)
        z_ref, az_ref = self._z_ref, 0.0
        if self.phase is Phase.TAKEOFF:
            ref = self._takeoff.step(dt, st.z)
            z_ref, vz_ref, az_ref = ref.z, ref.vz, ref.az
        uy, uz = self.ctl.lateral(st, self._hold[1], z_ref, dt, vz_ref)
        if self.phase is Phase.TAKEOFF and not self._takeoff.lifted:
            self.ctl.z.pid.integral = 0.0  # the ground carries the deficit: nothing to learn
        u = (ux, uy, uz + az_ref)
        sp = self.ctl.setpoint(u, t, st.pose_seq, self.phase)
        self._observe_response(t, st)
        return TickReport(self.phase, sp, None, False, refs, u, e)

    def _switch(self, t: float, st: State) -> None:
        """Stage 2 from the tick tau reaches tau_s (docs/errata.md §9): the measured tau, or
        with TauGains.switch_predicted and a lag identified beyond ff_lead_s, the tau the
        tau PID acts on, predicted over that excess: the switch is decided on the state
        the controller flies, not a horizon after it has passed stage 1's end."""
        if self._tau_s is None:
            return
        tau, horizon = st.tau, 0.0
        if self.cfg.tau_gains.switch_predicted:
            x, v, horizon = self.response.predicted(t, st.x, st.xdot)
            if horizon > 0.0:
                tau = x / v if v > self.cfg.estimator.min_speed_mps else None
        if tau is None or tau < self._tau_s:
            return
        self.t_stage2 = t
        self._enter(
            Phase.STAGE2,
            t,
            "predicted tau reached tau_s" if horizon > 0.0 else "measured tau reached tau_s",
            tau=tau,
            horizon_s=horizon,
            since_trigger=t - self.trigger.t,
        )
        self._refit_stage2(t)

    @property
    def v_hold(self) -> float:
        """[m/s] the stage-2 speed held: V_c, kept v_contact_margin_mps inside the window."""
        v, m = float(self.plan.v_contact), self.cfg.tau_gains.v_contact_margin_mps
        lo, hi = self.plan.limits.v_contact
        return min(max(v, lo + m), hi - m) if hi - lo > 2 * m else v

    @property
    def _tau_s(self) -> float | None:
        return getattr(self.plan, "tau_s", None)

    def _start(self, t: float, st: State) -> None:
        self._hold = (st.x, st.y, st.z)
        self._hold_x = AxisController(self.cfg.lateral.z)
        start_world = self.frame.rotate_out((st.x, st.y, st.z))
        height = self.frame.point[2] + start_world[2]
        s = self.cfg.safety
        top = s.ceiling_m - MARGIN_M  # every height reference stays below (core/envelope.py)
        if height > top:
            self._finish(
                EndReason.GEOFENCE,
                t,
                (
                    f"start height {height:.3f} m is above safety.ceiling_m = {s.ceiling_m:g} m "
                    f"less the {MARGIN_M:g} m margin by {height - top:.3f} m: the hold would "
                    f"fly there"
                ),
            )
        target = min(max(self.cfg.approach.takeoff_height_m, s.floor_m + MARGIN_M), top)
        climb = target - height
        self._z_ref = st.z + climb if climb > 0.1 else st.z
        if climb > 0.1:  # perchd/flight/takeoff.py: held until off the ground, never ahead
            self._takeoff = TakeoffProfile(st.z, self._z_ref, self.cfg.approach.takeoff_speed_mps)
        self._enter(Phase.TAKEOFF if climb > 0.1 else Phase.HOLD, t, "", x=st.x, y=st.y, z=st.z)

    def _begin_approach(self, t: float, st: State) -> None:
        gap = self.plan.x0 - st.x
        need = self.plan.v0**2 / (2.0 * gap) if gap > 0 else math.inf
        if need > self.cfg.approach.accel_max_mps2:
            self._finish(
                EndReason.TRIGGER_REFUSED,
                t,
                f"reaching v0 = {self.plan.v0:g} m/s by x0 = {self.plan.x0:g} m from "
                f"X = {st.x:.2f} m needs {need:.2f} m/s^2 > approach limit "
                f"{self.cfg.approach.accel_max_mps2:g} m/s^2",
            )
            return
        self._a_app, self._t_moving, self._v_int = need, t, 0.0
        self._enter(Phase.APPROACH, t, "", accel=need)

    def _approach_accel(self, t: float, st: State, dt: float) -> float:
        """Feed-forward (with the drag identified so far) + PI on the speed reference; the
        integral takes up what the feed-forward misses (ApproachConfig.ki_v), frozen while
        the mapping saturates."""
        a = self.cfg.approach
        x, v, horizon = self.response.predicted(t, st.x, st.xdot)
        v_ref, a_ff = self._approach_ref(x, self.response.ff.lead_s - horizon)
        err = v_ref - v
        if not self.ctl.saturated and a.ki_v > 0.0:
            bound = a.i_limit_mps2 / a.ki_v
            self._v_int = min(max(self._v_int + err * dt, -bound), bound)
        return a_ff + a.kv * err + a.ki_v * self._v_int

    def _approach_ref(self, x: float, lead_s: float) -> tuple[float, float]:
        """(v_ref [m/s] at X = x [m], the feed-forward [m/s^2] for where the vehicle will be
        lead_s [s] later). Past x0 the references are the plan's own: the vehicle answers
        a lag late, so the approach's last commands already fly the start of the plan
        (ApproachConfig.lead_into_plan, docs/errata.md §10)."""
        ff, wait = self.response.ff, self.desk.wait
        if wait is not None:
            return wait.v, ff.accel(0.0, wait.v)
        leads, x0 = self.cfg.approach.lead_into_plan, self.plan.x0
        v_ref = self._plan_at(x).v if leads and x >= x0 else self._v_ref(x)
        ahead = x + v_ref * max(lead_s, 0.0)
        if not leads or ahead < x0:
            return v_ref, ff.accel(self._a_app, v_ref)
        p = self._plan_at(ahead)
        return v_ref, ff.accel(p.a if p.stage == 1 else 0.0, p.v)

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

    def _v_ref(self, x: float) -> float:
        """[m/s] the approach's speed reference at X = x: the profile to (x0, v0), or, while a
        replan is awaited past x0, the speed measured at the trigger (held constant)."""
        if self.desk.wait is not None:
            return self.desk.wait.v
        v0 = self.plan.v0
        return math.sqrt(max(0.0, v0 * v0 - 2.0 * self._a_app * (self.plan.x0 - x)))

    # --- the hover thrust (flight/hover.py) -------------------------------------------------
    def _learn_hover(self, t: float, dt: float, st: State) -> None:
        """Fold this tick into the hover estimate while taking off (once clear of the floor,
        which would carry part of the weight) and holding, until it has settled."""
        if not self.cfg.hover.learn or self.hover_learned_n is not None:
            return
        if self.phase not in (Phase.TAKEOFF, Phase.HOLD) or self.ctl.last_thrust_z is None:
            return
        if self.phase is Phase.TAKEOFF and st.z < self._hold[2] + 0.1:
            return
        self.hover.update(t, self.ctl.last_thrust_z, st.zddot, dt)
        self.ctl.hover_n = self.hover.estimate_n
        # The estimate does the z integral's job here; both at once would wind the integral
        # up against a deficit the estimate then removes, and the height would overshoot.
        self.ctl.z.pid.integral = 0.0

    def _hover_ready(self, t: float, st: State) -> bool:
        """True once the hover thrust is known; says in the log what the hold waits for, and
        ends the flight HOVER_UNLEARNED after hover.timeout_s in HOLD."""
        h, v = self.cfg.hover, self.cfg.vehicle
        if not h.learn or self.hover_learned_n is not None:
            return True
        status = self.hover.status(t, st.z - self._z_ref, st.zdot)
        ratio = status.estimate_n / (v.mass_kg * v.g)
        if self.hover.settled(status):
            return self._hover_settled(t, status.estimate_n, ratio)
        if not self._hover_waiting:
            self._hover_waiting = True
            self.events.append(
                LogEvent(
                    t,
                    "hover-wait",
                    "waiting for the hover thrust to settle before the approach",
                    {"estimate_n": status.estimate_n, "spread": status.spread},
                )
            )
        if t - self._t_phase > h.timeout_s:
            self._finish(
                EndReason.HOVER_UNLEARNED,
                t,
                (
                    f"hover thrust unsettled after {t - self._t_phase:.1f} s in hold: estimate "
                    f"{status.estimate_n:.4f} N ({ratio:.3f} x the weight of "
                    f"{v.mass_kg:g} kg), spread {status.spread:.1%} over "
                    f"{status.steady_s:.2f} s steady (need {h.rel_tol:.1%} over {h.settle_s:g} s)"
                ),
            )
        return False

    def _hover_settled(self, t: float, hover_n: float, ratio: float) -> bool:
        h, v = self.cfg.hover, self.cfg.vehicle
        if not h.ratio_min <= ratio <= h.ratio_max:
            self._finish(
                EndReason.HOVER_UNLEARNED,
                t,
                (
                    f"learned hover thrust {hover_n:.4f} N is {ratio:.3f} x the weight of "
                    f"vehicle.mass_kg = {v.mass_kg:g} kg, outside {h.ratio_min:g}..{h.ratio_max:g}:"
                    f" check the mass and the driver's thrust calibration"
                ),
            )
            return False
        self.hover_learned_n = self.ctl.hover_n = hover_n
        self.events.append(
            LogEvent(
                t,
                "hover-learned",
                f"{hover_n:.4f} N",
                {
                    "hover_n": hover_n,
                    "ratio": ratio,
                    "guess_n": self.hover.guess_n,
                    "since_hold_s": t - self._t_phase,
                },
            )
        )
        return True

    # --- the trigger (flight/trigger.py) ---------------------------------------------------
    def _approach_plans(self, t: float, dt: float, st: State) -> None:
        """Per approach tick: what the trigger desk decided, flown or refused."""
        d = self.desk.approach_tick(t, dt, st, self._v_ref(st.x))
        if d is None:
            return
        if d.plan is None:
            self._finish(EndReason.TRIGGER_REFUSED, t, d.action)
        else:
            self._start_plan(t, d.t_meas, d.x, d.v, d.plan, d.action)

    def _start_plan(
        self, t: float, t_meas: float, x: float, v: float, plan: Plan, action: str
    ) -> None:
        """Fly `plan` from tick t; the trigger state (x [m], v [m/s]) was measured at t_meas.
        The plan's clock starts when X crossed its x0, at most a tick before t_meas."""
        late = (x - plan.x0) / v if v > 0 else 0.0
        t0 = t_meas - min(max(late, 0.0), 1.0 / self.cfg.rate_hz)
        self.plan = plan
        if plan is not self._sampler.plan:
            self._sampler = PlanSampler(plan)
        self.trigger = Trigger(t0, x, v, plan.x0, plan.v0, action)
        # What the approach's integral took up, a push the feed-forward misses, does not end
        # at x0: stage 1's integral starts with it (docs/errata.md §10).
        self.ctl.tau.reset(self.cfg.approach.ki_v * self._v_int)
        self._enter(Phase.STAGE1, t, action, x=x, v=v, plan_x0=plan.x0, plan_v0=plan.v0)

    def _refs(self, t: float) -> Refs:
        """The references at tick time t; computed once per tick (the tau watch and the
        controller both ask), again only if the stage or the plan changed in between."""
        key = (t, self.t_stage2, self.trigger, self._x)
        if self._refs_memo[0] != key:
            self._refs_memo = (key, self._compute_refs(t))
        return self._refs_memo[1]

    def _compute_refs(self, t: float) -> Refs:
        if self.response.identified is None and self.cfg.tau_gains.identify:
            self._identify(t)
        return self._refs_at(t, self._x, self.response.ff.lead_s)

    def _identify(self, t: float) -> None:
        """The trigger's fit (VehicleResponse.identify). The integral handed over at the
        trigger may hold what that fit now feeds forward: it gives that back, as at every
        refit."""
        before = self.response.ff
        self.response.identify(t)
        p = self._sampler.at(min(max(t - self.trigger.t, 0.0), self.plan.duration))
        a = p.a if p.stage == 1 else 0.0
        self.ctl.tau.give_back(self.response.ff.step_from(before, a, p.v))

    def _refs_at(self, t: float, x: float | None, lead_s: float) -> Refs:
        """The references at time t [s] for the vehicle at X = x [m], with the feed-forward
        taken lead_s [s] ahead."""
        plan, ff = self.plan, self.response.ff
        s = min(max(t - self.trigger.t, 0.0), plan.duration)
        here, a = self._plan_ahead(s, lead_s)
        if self.t_stage2 is None:
            tau_ref = here.tau_ref
        elif self.cfg.tau_gains.stage2_hold_speed and x is not None:
            tau_ref = min(x, 0.0) / self.v_hold
            a = ff.accel(0.0, self.v_hold)
        else:
            tau_ref = self._tau_s + (t - self.t_stage2)
            a = ff.accel(0.0, float(plan.v_contact))
        return Refs(tau_ref, here.x, here.v, a)

    def _lag_view(self, t: float, st: State, refs: Refs) -> tuple[State, Refs]:
        """The state and references the tau controller acts on: predicted over the lag
        beyond what the gains were made for (VehicleResponse.predicted, docs/errata.md
        §10)."""
        x, v, horizon = self.response.predicted(t, st.x, st.xdot)
        if horizon == 0.0:
            return st, refs
        # Predicted at or past the surface: tau = X/Xdot from just before it, so that the
        # stage-2 error stays 1 - Xdot/V_c instead of tau's sign flipping.
        x = min(x, -1e-3)
        tau = x / v if v > self.cfg.estimator.min_speed_mps else None
        seen = dataclasses.replace(st, x=x, xdot=v, tau=tau)
        return seen, self._refs_at(t + horizon, x, self.response.ff.lead_s - horizon)

    def _plan_ahead(self, s: float, lead_s: float) -> tuple[PlanPoint, float]:
        """The plan's point at its time s [s], and the feed-forward [m/s^2] for its point
        lead_s [s] later (its acceleration there while in stage 1, the drag at its speed)."""
        here = self._sampler.at(s)
        ahead = self._sampler.at(min(s + lead_s, self.plan.duration)) if lead_s else here
        return here, self.response.ff.accel(ahead.a if ahead.stage == 1 else 0.0, ahead.v)

    def _stage1_aim(self, t: float, seen: State, aim: Refs) -> tuple[float, Refs]:
        """Stage 1's tau reference and feed-forward for the state seen. Early, the clock's,
        scale-corrected; from three lags before the plan's switch to two, handed over to
        the plan's point where the vehicle is (TauGains.end_by_position): a vehicle still
        behind the plan in X then reaches the switch point nearer the plan's speed, and
        the braking ends where the plan's does, not when (docs/errata.md §10)."""
        lag = self.response.ff.lead_s
        left = self.plan.t_switch - (t - self.trigger.t)
        end = 1.0 - min(max((left - 2.0 * lag) / lag, 0.0), 1.0) if lag > 0.0 else 0.0
        tau_ref = self._scale_corrected(seen, aim, 1.0 - end)
        if end == 0.0 or not self.cfg.tau_gains.end_by_position or seen.x >= 0.0:
            return tau_ref, aim
        horizon = self.response.horizon_s
        s = self._plan_time(seen.x, t + horizon - self.trigger.t)
        here, a = self._plan_ahead(s, lag - horizon)
        return (
            (1.0 - end) * tau_ref + end * here.tau_ref,
            dataclasses.replace(aim, a=(1.0 - end) * aim.a + end * a),
        )

    def _scale_corrected(self, seen: State, aim: Refs, weight: float) -> float:
        """The tau reference corrected for the scale error c = X / X_plan: tau = X/Xdot is
        blind to it (c times the plan's X and Xdot keep the plan's tau), yet it reaches the
        stage-2 switch as c times the plan's speed there. Aiming at tau_ref c^-gamma brings
        c back to 1 with time constant |tau| / gamma, never faster than twice the lag;
        gamma is scaled by weight (stage 1's end fades it out: a catch-up that late would
        reach the switch as speed; TauGains.scale_gain, docs/errata.md §10)."""
        gamma, lag = self.cfg.tau_gains.scale_gain, self.response.ff.lead_s
        if gamma <= 0.0 or lag <= 0.0 or aim.x is None or aim.x >= 0.0 or seen.x >= 0.0:
            return aim.tau_ref
        gamma = weight * min(gamma, -aim.tau_ref / (2.0 * lag))
        c = min(max(seen.x / aim.x, 0.5), 2.0)
        return aim.tau_ref * c**-gamma

    def _observe_response(self, t: float, st: State) -> None:
        """Record the ticks for the lag identification (the stages' commands feed its
        prediction), and refit every LagIdGains.refit_s of the approach so the approach's
        own feed-forward meets the drag."""
        if not self.cfg.tau_gains.identify or self.phase not in _OBSERVED:
            return
        self.response.record(t, self.ctl.last_ux_sent, st.x, st.xdot)
        self.response.record_lean(t, self.ctl.last_lean_sent, t - st.age, st.lean_x)
        if self.phase is not Phase.APPROACH or t - self._t_refit < self.cfg.lag_id.refit_s:
            return
        self._t_refit = t
        model = self.response.refit()
        if model is not None:
            self._hand_over_integral(st, feed_forward(model))
            self.response.adopt(model)

    def _hand_over_integral(self, st: State, ff: FeedForward) -> None:
        """What a new feed-forward adds (the drag), the approach's integral, which was
        taking it up, gives back: the command does not step and nothing counts twice."""
        a = self.cfg.approach
        if a.ki_v <= 0.0:
            return
        v_ref = self._v_ref(st.x)
        step = ff.step_from(self.response.ff, self._a_app, v_ref)
        bound = a.i_limit_mps2 / a.ki_v
        self._v_int = min(max(self._v_int - step / a.ki_v, -bound), bound)

    def _refit_stage2(self, t: float) -> None:
        """Stage 2 flies the drag refitted from stage 1 (VehicleResponse.refit_stage2); what
        that adds, the tau PID's integral gives back as far as it holds it."""
        self.ctl.tau.give_back(self.response.refit_stage2(t, self.trigger.t, self.v_hold))
