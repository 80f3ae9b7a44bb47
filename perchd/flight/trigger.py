"""The trigger at x0 and the plans it may fly (docs/architecture.md "Planning in flight").

A plan is never flown from a state it was not made for, except within the configured
tolerance (REFUSE policy, and the PLAN fallback) or after being retargeted to the measured
state (ROBUST, REPLAN): by a planner that never blocks the tick, planned ahead during the
approach, waited for no longer than a deadline and replaced by the configured fallback
past it. The desk decides; the supervisor flies what it decides.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from perchd.core.errors import ConfigError
from perchd.core.types import State
from perchd.flight.config import AHEAD_V_TOL_MPS, FlightConfig, TriggerFallback, TriggerPolicy
from perchd.flight.planner_worker import InlinePlanner, Planner, PlanReply
from perchd.logs.flightlog import LogEvent
from perchd.tau.library import load_library
from perchd.tau.plan import Plan

AHEAD_FILTER_S = 0.2
"""[s] time constant of the low-pass on the approach's speed error that predicts the speed at
the trigger: the plan ahead follows the error's trend, not the estimator's noise."""
_RETARGETS = (TriggerPolicy.ROBUST, TriggerPolicy.REPLAN)


@dataclass(frozen=True, slots=True)
class ReplanWait:
    """A replan asked for at the trigger: request id; t [s] the triggering tick; x [m],
    v [m/s] measured then (the state asked for; the speed held meanwhile); deadline [s] on
    the clock past which the fallback flies (TriggerConfig.deadline_s)."""

    id: int
    t: float
    x: float
    v: float
    deadline: float


@dataclass(frozen=True, slots=True)
class ReplanState:
    """The trigger state a replan was asked for, as the refuse rule reads a State:
    x [m], xdot [m/s]."""

    x: float
    xdot: float


@dataclass(frozen=True, slots=True)
class Decision:
    """What the trigger decided: fly `plan` from the state x [m], v [m/s] measured at
    t_meas [s] (`action` says how it was chosen), or, plan None, refuse (`action` says why)."""

    plan: Plan | None
    t_meas: float
    x: float
    v: float
    action: str


class TriggerDesk:
    """planner: where ROBUST and REPLAN get their plans (flight/planner_worker.py); None: an
    InlinePlanner, solving in the tick (a simulated clock: a solve takes no simulated time).
    The caller owns it (starts and closes it). events: where the desk logs."""

    def __init__(
        self, plan: Plan, cfg: FlightConfig, planner: Planner | None, events: list[LogEvent]
    ) -> None:
        self.plan, self.cfg, self.events = plan, cfg, events
        self.library = _open_library(cfg.trigger.library, plan)
        self.planner: Planner | None = planner
        if planner is None and cfg.trigger.policy in _RETARGETS:
            self.planner = InlinePlanner(plan, self.library)
        # The newest plan made ahead for the trigger, and the speed [m/s] last asked for: a
        # REPLAN flight's own plan is the one for (x0, v0) until the prediction drifts.
        replan = cfg.trigger.policy is TriggerPolicy.REPLAN
        self._ahead: Plan | None = plan if replan else None
        self._ahead_asked_v: float | None = plan.v0 if replan else None
        self._v_err = 0.0  # [m/s] low-passed approach speed error (measured - profile)
        self.wait: ReplanWait | None = None  # the trigger's replan, while awaited
        self._planner_waiting = False
        self._late_id: int | None = None  # a replan given up on, still solving (logged when in)

    def ready(self, t: float) -> bool:
        """The approach waits in the hold for the trigger's planner to have loaded (a worker
        process takes seconds on a busy PC), or it could not plan ahead; the flight's
        timeout bounds the wait."""
        if self.planner is None or self.planner.ready:
            return True
        if not self._planner_waiting:
            self._planner_waiting = True
            self.events.append(
                LogEvent(
                    t, "planner-wait", "waiting for the planner worker to load before the approach"
                )
            )
        return False

    def approach_tick(self, t: float, dt: float, st: State, v_ref: float) -> Decision | None:
        """Per approach tick, v_ref [m/s] the approach's speed reference here: plan ahead,
        trigger at x0, or wait for the trigger's replan. None: nothing decided yet."""
        if self.wait is not None:
            return self._await_replan(t)
        if st.x >= self.plan.x0:
            return self._trigger(t, st)
        self._plan_ahead(t, dt, st, v_ref)
        return None

    def note_late(self, t: float) -> None:
        """After the trigger: log the solve time of a replan given up on, when it comes in."""
        if self._late_id is None:
            return
        reply = self.planner.poll()
        if reply is not None:
            self._late_id = None
            self.events.append(
                LogEvent(
                    t,
                    "trigger-late-solve",
                    "the replan given up on came in",
                    {"solve_s": reply.solve_s},
                )
            )

    def _plan_ahead(self, t: float, dt: float, st: State, v_ref: float) -> None:
        """Keep a plan ready for the predicted trigger state (x0, v0 + the approach's speed
        error, low-passed): asked again only when the prediction drifts by more than half
        AHEAD_V_TOL_MPS from the last one asked for. Needs a planner that takes time."""
        if self.planner is None or self.planner.instant:
            return
        reply = self.planner.poll()
        if reply is not None:
            self._took_ahead(t, reply)
        self._v_err += (st.xdot - v_ref - self._v_err) * min(1.0, dt / AHEAD_FILTER_S)
        v_pred = self.plan.v0 + self._v_err
        asked = self._ahead_asked_v
        # Re-asked at half the tolerance the trigger accepts: the other half is for the
        # drift between the newest plan and the trigger.
        if not self.planner.busy and (asked is None or abs(v_pred - asked) > 0.5 * AHEAD_V_TOL_MPS):
            self._ahead_asked_v = v_pred
            self.planner.request(self.plan.x0, v_pred)

    def _took_ahead(self, t: float, reply: PlanReply) -> None:
        values = {"v0": reply.v0_mps, "solve_s": reply.solve_s}
        if reply.plan is not None:
            self._ahead = reply.plan
            self.events.append(
                LogEvent(t, "plan-ahead", f"made for v0 = {reply.v0_mps:.3f} m/s", values)
            )
        else:
            self.events.append(LogEvent(t, "plan-ahead", f"failed: {reply.error}", values))

    def _trigger(self, t: float, st: State) -> Decision | None:
        tr = self.cfg.trigger
        if tr.policy is TriggerPolicy.REFUSE or self._outside_box(st) is not None:
            plan, action, why = self._refuse_rule(st)
            return Decision(plan, t, st.x, st.xdot, action if plan is not None else why)
        if self.planner.instant:  # the solve takes no time on this clock: fly it now
            self.planner.request(st.x, st.xdot)
            return self._take_reply(t, ReplanWait(0, t, st.x, st.xdot, t), self.planner.poll())
        ahead = self._ahead
        if ahead is not None and abs(st.xdot - ahead.v0) <= AHEAD_V_TOL_MPS:
            return Decision(
                ahead,
                t,
                st.x,
                st.xdot,
                (
                    f"{self._how()}: planned ahead for v0 = {ahead.v0:.3f} m/s, flown from "
                    f"x = {st.x:.3f} m, v = {st.xdot:.3f} m/s"
                ),
            )
        deadline = t + tr.deadline_s(float(self.plan.peaks.a))
        self.wait = ReplanWait(self.planner.request(st.x, st.xdot), t, st.x, st.xdot, deadline)
        self.events.append(
            LogEvent(
                t,
                "trigger-wait",
                "replan asked for the measured state",
                {"x": st.x, "v": st.xdot, "deadline_s": deadline - t},
            )
        )
        return None

    def _await_replan(self, t: float) -> Decision | None:
        w = self.wait
        reply = self.planner.poll()
        if reply is not None:
            return self._take_reply(t, w, reply)
        if t >= w.deadline:
            self._late_id = w.id
            return self._fallback(
                t,
                w,
                f"replan not in after {t - w.t:.3f} s (deadline {w.deadline - w.t:.3f} s)",
                t - w.t,
            )
        return None

    def _take_reply(self, t: float, w: ReplanWait, reply: PlanReply) -> Decision:
        """Fly the replan from the trigger state it was made for; its clock starts at the
        triggering tick (docs/architecture.md: a plan is time-invariant in X)."""
        self.wait = None
        if reply.plan is None:
            return self._fallback(
                t,
                w,
                f"no plan from x = {w.x:.3f} m, v = {w.v:.3f} m/s: {reply.error}",
                reply.solve_s,
            )
        if w.id:
            self.events.append(
                LogEvent(
                    t, "trigger-solve", "replan in", {"solve_s": reply.solve_s, "waited_s": t - w.t}
                )
            )
        return Decision(
            reply.plan,
            w.t,
            w.x,
            w.v,
            (f"{self._how()}: retargeted to x0 = {w.x:.3f} m, v0 = {w.v:.3f} m/s"),
        )

    def _fallback(self, t: float, w: ReplanWait, why: str, solve_s: float) -> Decision:
        self.wait = None
        fb = self.cfg.trigger.fallback
        values = {"solve_s": solve_s, "deadline_s": w.deadline - w.t}
        if fb is TriggerFallback.PLAN:
            plan, action, refused = self._refuse_rule(ReplanState(w.x, w.v), self._ahead)
            if plan is not None:
                self.events.append(LogEvent(t, "trigger-fallback", f"{why}: {action}", values))
                return Decision(plan, w.t, w.x, w.v, f"fallback plan ({why}); {action}")
            why = f"{why}; fallback plan: {refused}"
        self.events.append(LogEvent(t, "trigger-fallback", f"{why}: refused", values))
        return Decision(None, w.t, w.x, w.v, f"{why} (fallback {fb.value})")

    def _how(self) -> str:
        return f"{self.cfg.trigger.policy.value}{' (library)' if self.library else ''}"

    def _outside_box(self, st: State) -> str | None:
        """Why ROBUST cannot fly from this state (no box, or outside it), or None."""
        if self.cfg.trigger.policy is not TriggerPolicy.ROBUST:
            return None
        box = getattr(self.plan, "robust", None)
        if box is None:
            return "trigger policy 'robust' but the plan has no robust box"
        (xl, xh), (vl, vh) = box
        if not (xl <= st.x <= xh and vl <= st.xdot <= vh):
            return (
                f"measured x = {st.x:.3f} m, v = {st.xdot:.3f} m/s outside the "
                f"plan's robust box x0 {xl:g}..{xh:g}, v0 {vl:g}..{vh:g}"
            )
        return None

    def _refuse_rule(self, st: Any, ahead: Plan | None = None) -> tuple[Any, str, str]:
        """(plan, what was done, why not): the nearest of the flight's plan and `ahead` in
        speed, flown as made if the state is within tolerance of it (REFUSE; the PLAN
        fallback). A ROBUST state outside the box is refused here."""
        boxed = self._outside_box(st)
        if boxed is not None:
            return None, "", boxed
        tr = self.cfg.trigger
        plan = min(
            (p for p in (ahead, self.plan) if p is not None), key=lambda p: abs(st.xdot - p.v0)
        )
        dx, dv = st.x - plan.x0, st.xdot - plan.v0
        if abs(dx) <= tr.x_tol_m and abs(dv) <= tr.v_tol_mps:
            return plan, f"flown as made (dx {dx:+.3f} m, dv {dv:+.3f} m/s within tolerance)", ""
        return (
            None,
            "",
            (
                f"measured x = {st.x:.3f} m, v = {st.xdot:.3f} m/s differ from the "
                f"plan's x0 = {plan.x0:g}, v0 = {plan.v0:g} by {dx:+.3f} m, "
                f"{dv:+.3f} m/s (tolerance {tr.x_tol_m:g} m, {tr.v_tol_mps:g} m/s)"
            ),
        )


def _open_library(path: str | None, plan: Plan) -> Any:
    """The trigger's plan library, loaded before the flight and checked against its plan."""
    if path is None:
        return None
    lib = load_library(path)
    why = lib.matches(plan)
    if why:
        raise ConfigError(f"trigger.library {path}: {why}")
    return lib
