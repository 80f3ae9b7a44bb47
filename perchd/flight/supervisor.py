"""The flight's phases: one `tick` per control period, no I/O of its own.

Phases: TAKEOFF (only when the flight starts below the take-off height) -> HOLD at the start
point, at least hold_s and until the hover thrust has been learned (flight/hover.py; after
hover.timeout_s a vehicle holding its height flies its estimate) -> APPROACH (accelerate
along X so that the plan's trigger state (x0, v0) is reached at x0) -> trigger -> STAGE1
(tau_ref indexed by time since the trigger) -> STAGE2 when the measured tau reaches tau_s
(docs/errata.md §9; tau_ref = X / V_hold: the speed held inside the window) ->
CONTACT (the post-contact action for POST_CONTACT_S) -> DONE.

Every tick first asks the end rules (flight/endrules.py); the references each phase aims at
are flight/references.py's. The trigger itself may end the flight (TRIGGER_REFUSED): what it
flies or refuses is flight/trigger.py's decision; what the flight knows of the vehicle's
response and feeds forward is flight/response.py's.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from dataclasses import dataclass

from perchd.core.envelope import MARGIN_M
from perchd.core.types import EndReason, Phase, Setpoint, State
from perchd.flight.config import FlightConfig, PostContact
from perchd.flight.control import AxisController, Controller, FeedForward
from perchd.flight.endrules import Conditions, ContactEstimate, EndRules, Progress
from perchd.flight.frame import PerchFrame
from perchd.flight.hover import RATIO, REL_TOL, SETTLE_S, Z_TOL_M, HoverLearner
from perchd.flight.planner_worker import Planner
from perchd.flight.references import NO_REFS, References, Refs
from perchd.flight.response import VehicleResponse, feed_forward
from perchd.flight.takeoff import TakeoffProfile
from perchd.flight.trigger import TriggerDesk
from perchd.logs.flightlog import LogEvent
from perchd.tau.plan import Plan

APPROACH_KV = 3.0
"""[1/s] the approach's speed-tracking gain along X."""
APPROACH_KI_V = 8.0
"""[1/s^2] its integral gain: drag and the attitude lag otherwise leave the speed at the
trigger short of v0 (~0.09 m/s on the Crazyflie firmware); the trigger hands the integral
to the tau PID's."""
APPROACH_I_LIMIT_MPS2 = 1.0
"""[m/s^2] the clamp of that integral's contribution (frozen while the mapping saturates)."""
REFIT_S = 0.25
"""[s] period of the identification's refits during the approach (its own feed-forward
meets the drag found so far); the fit at the trigger is the one logged and flown."""
POST_CONTACT_S = 0.2
"""[s] the post-contact action (FlightConfig.post_contact) is held this long."""

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


class Supervisor:
    """planner: where the trigger's ROBUST and REPLAN get their plans (TriggerDesk); None:
    solved in the tick. The caller owns it (starts and closes it)."""

    def __init__(
        self, plan: Plan, cfg: FlightConfig, frame: PerchFrame, planner: Planner | None = None
    ) -> None:
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
        self._t_prev: float | None = None
        self._t_phase = 0.0
        self._t_end: float | None = None
        self._hold: tuple[float, float, float] | None = None
        self._hold_x: AxisController | None = None  # the X position loop of the hold
        self._t_moving = 0.0  # [s] when the approach began moving the vehicle
        self._z_ref = 0.0
        self._takeoff: TakeoffProfile | None = None  # the TAKEOFF phase's height reference
        self.desk = TriggerDesk(plan, cfg, planner, self.events)
        self.hover = HoverLearner(cfg.hover, cfg.vehicle.hover_guess_n, cfg.vehicle.g)
        self.hover_learned_n: float | None = None  # [N] once the hold's estimate settled
        self._hover_waiting = False
        self._v_int = 0.0  # [m/s] integral of the approach's speed error
        self.response = VehicleResponse(cfg.tau_gains, cfg.lag_id, self.events)
        self._t_refit = -math.inf  # [s] the approach's last refit
        self.refs = References(plan, cfg, self.desk, self.response)
        self.rules = EndRules(cfg, frame)

    @property
    def plan(self) -> Plan:
        """The plan flown: the one given until the trigger, then the trigger's choice."""
        return self.refs.plan

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
        if self.end is None:
            self._check(t, state, cond)
        if self.end is not None:
            return self._ended(t, state)
        if state is None:  # waiting for the first pose (bounded by the stale-mocap rule)
            return TickReport(self.phase, None, None, False, NO_REFS, NO_U, None)
        return self._fly(t, dt, state)

    def _check(self, t: float, state: State | None, cond: Conditions) -> None:
        """Ends the flight if an end rule says so (flight/endrules.py)."""
        line = None if self._hold is None else (self._hold[1], self._z_ref)
        x = None if state is None else state.x
        progress = Progress(
            self.phase,
            t if self.t_start is None else self.t_start,
            self._t_moving,
            line,
            None if self.trigger is None else self.trigger.t,
            self.plan.duration,
            lambda: self._refs(t, x).tau_ref,
        )
        ending = self.rules.check(t, state, cond, progress)
        if ending is None:
            return
        if ending.contact is not None and state is not None:
            self.contact = ending.contact
            self._enter(Phase.CONTACT, t, "contact", speed=state.xdot, x=state.x)
        self._finish(ending.reason, t, ending.detail)

    # --- ends -------------------------------------------------------------------------------
    def _ended(self, t: float, state: State | None) -> TickReport:
        seq = state.pose_seq if state else -1
        if self.end is not EndReason.CONTACT:
            if self.phase is not Phase.ABORT:
                self._enter(Phase.ABORT, t, self.end.value)
            return TickReport(Phase.ABORT, None, self.end, True, NO_REFS, NO_U, None)
        done = t - self._t_end >= POST_CONTACT_S
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
            refs = self._refs(t, st.x)
            tau_aim = refs.tau_ref
            if self.phase is Phase.STAGE1:
                tau_aim = self.refs.scale_corrected(t, st, refs)
            hold = self.refs.hold if self.phase is Phase.STAGE2 else None
            kp = hold.kp_mps2 if hold is not None else None
            ux = self.ctl.tau.step(st, tau_aim, refs.a, dt, self.ctl.saturated, kp)
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
        """Stage 2 from the tick the measured tau reaches tau_s (docs/errata.md §9)."""
        tau_s, tau = self.refs.tau_s, st.tau
        if tau_s is None or tau is None or tau < tau_s:
            return
        self.refs.t_stage2 = t
        self._enter(
            Phase.STAGE2,
            t,
            "measured tau reached tau_s",
            tau=tau,
            since_trigger=t - self.trigger.t,
        )
        self._enter_hold(t)

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
        self.refs.a_app, self._t_moving, self._v_int = need, t, 0.0
        self._enter(Phase.APPROACH, t, "", accel=need)

    def _approach_accel(self, t: float, st: State, dt: float) -> float:
        """Feed-forward (with the drag identified so far) + PI on the speed reference; the
        integral takes up what the feed-forward misses (APPROACH_KI_V), frozen while
        the mapping saturates."""
        v_ref, a_ff = self.refs.approach(st.x, self.response.ff.lead_s)
        err = v_ref - st.xdot
        if not self.ctl.saturated:
            bound = APPROACH_I_LIMIT_MPS2 / APPROACH_KI_V
            self._v_int = min(max(self._v_int + err * dt, -bound), bound)
        return a_ff + APPROACH_KV * err + APPROACH_KI_V * self._v_int

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
        """True once the hover thrust is known; says in the log what the hold waits for.
        After hover.timeout_s in HOLD unsettled (an autopilot's height loop keeps the thrust
        moving by a few percent), a vehicle holding its height flies on the estimate it has;
        one that does not hold it ends HOVER_UNLEARNED."""
        h, v = self.cfg.hover, self.cfg.vehicle
        if not h.learn or self.hover_learned_n is not None:
            return True
        z_err = st.z - self._z_ref
        status = self.hover.status(t, z_err, st.zdot)
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
        if t - self._t_phase <= h.timeout_s:
            return False
        unsettled = (
            f"hover thrust unsettled after {t - self._t_phase:.1f} s in hold: estimate "
            f"{status.estimate_n:.4f} N ({ratio:.3f} x the weight of {v.mass_kg:g} kg), spread "
            f"{status.spread:.1%} over {status.steady_s:.2f} s steady (settled: {REL_TOL:.1%} "
            f"over {SETTLE_S:g} s)"
        )
        if abs(z_err) > Z_TOL_M:
            self._finish(
                EndReason.HOVER_UNLEARNED,
                t,
                f"{unsettled}, and the vehicle is {z_err:+.2f} m off its hold height",
            )
            return False
        self.events.append(LogEvent(t, "hover-unsettled", f"{unsettled}: flying the estimate"))
        return self._hover_settled(t, status.estimate_n, ratio)

    def _hover_settled(self, t: float, hover_n: float, ratio: float) -> bool:
        v = self.cfg.vehicle
        if not RATIO[0] <= ratio <= RATIO[1]:
            self._finish(
                EndReason.HOVER_UNLEARNED,
                t,
                (
                    f"learned hover thrust {hover_n:.4f} N is {ratio:.3f} x the weight of "
                    f"vehicle.mass_kg = {v.mass_kg:g} kg, outside {RATIO[0]:g}..{RATIO[1]:g}:"
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
        d = self.desk.approach_tick(t, dt, st, self.refs.v_ref(st.x))
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
        self.refs.start(plan, t0)
        self.trigger = Trigger(t0, x, v, plan.x0, plan.v0, action)
        # What the approach's integral took up, a push the feed-forward misses, does not end
        # at x0: stage 1's integral starts with it (docs/errata.md §10).
        self.ctl.tau.reset(APPROACH_KI_V * self._v_int)
        self._enter(Phase.STAGE1, t, action, x=x, v=v, plan_x0=plan.x0, plan_v0=plan.v0)

    def _refs(self, t: float, x: float | None) -> Refs:
        """The references at tick time t [s] for the vehicle at X = x [m]; the first, at the
        trigger, waits for the trigger's fit (VehicleResponse.identify)."""
        if self.response.identified is None and self.cfg.tau_gains.identify:
            self._identify(t)
        return self.refs.for_tick(t, x)

    def _identify(self, t: float) -> None:
        """The trigger's fit (VehicleResponse.identify). The integral handed over at the
        trigger may hold what that fit now feeds forward: it gives that back, as at every
        refit."""
        before = self.response.ff
        self.response.identify(t)
        p = self.refs.now(t)
        a = p.a if p.stage == 1 else 0.0
        self.ctl.tau.give_back(self.response.ff.step_from(before, a, p.v))

    def _observe_response(self, t: float, st: State) -> None:
        """Record the ticks for the lag identification (the stages' commands feed its
        prediction), and refit every REFIT_S of the approach so the approach's
        own feed-forward meets the drag."""
        if not self.cfg.tau_gains.identify or self.phase not in _OBSERVED:
            return
        self.response.record(t, self.ctl.last_ux_sent, st.x, st.xdot)
        self.response.record_lean(t, self.ctl.last_lean_sent, t - st.age, st.lean_x)
        if self.phase is not Phase.APPROACH or t - self._t_refit < REFIT_S:
            return
        self._t_refit = t
        model = self.response.refit()
        if model is not None:
            self._hand_over_integral(st, feed_forward(model))
            self.response.adopt(model)

    def _hand_over_integral(self, st: State, ff: FeedForward) -> None:
        """What a new feed-forward adds (the drag), the approach's integral, which was
        taking it up, gives back: the command does not step and nothing counts twice."""
        v_ref = self.refs.v_ref(st.x)
        step = ff.step_from(self.response.ff, self.refs.a_app, v_ref)
        bound = APPROACH_I_LIMIT_MPS2 / APPROACH_KI_V
        self._v_int = min(max(self._v_int - step / APPROACH_KI_V, -bound), bound)

    def _enter_hold(self, t: float) -> None:
        """Stage 2's loop fixed for the lag flown (References.fix_hold): its integral's gain
        set without a step in the command, and the `hold-loop` event."""
        hold = self.refs.fix_hold()
        self.ctl.tau.retune(hold.ki_mps3)
        push = self.cfg.tau_gains.wall_push_mps2
        self.events.append(
            LogEvent(
                t,
                "hold-loop",
                f"stage 2 holds {hold.v_hold_mps:.3f} m/s, {hold.margin_mps:.3f} m/s inside the "
                f"window for a {push:g} m/s^2 push; gains {hold.kp_mps2:.2f} m/s^2, "
                f"{hold.ki_mps3:.2f} m/s^3",
                dataclasses.asdict(hold),
            )
        )
