"""One flight: source -> estimator -> supervisor/controller -> driver, on the fixed-rate loop.

`fly` opens nothing: the caller (perchd fly, the daemon, a test) opens and connects the
driver and starts the pose source, and closes them afterwards. `fly` engages the driver
(Driver.engage: the vehicle is taken only when a flight starts, docs/architecture.md
"Connect and engage"), writes the flight log as it goes and returns a FlightResult. Any end
other than contact, and any exception, ends in driver.failsafe(reason) with the log closed;
an exception is re-raised after that (a vehicle that will not be taken: LOST_LINK).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from perchd.core.clock import Clock, MonotonicClock
from perchd.core.errors import ConfigError, LinkError
from perchd.core.ports import Driver, PoseSource
from perchd.core.realtime import below_loop
from perchd.core.types import EndReason, Phase, State
from perchd.flight.config import FlightConfig, TriggerPolicy
from perchd.flight.endrules import Conditions
from perchd.flight.estimator import Estimator, EstimatorConfig
from perchd.flight.frame import PerchFrame
from perchd.flight.lagid import LagModel
from perchd.flight.loop import LoopSummary, make_loop
from perchd.flight.planguard import check_flight_plan
from perchd.flight.planner_worker import Planner, WorkerPlanner
from perchd.flight.supervisor import (
    FlightAbort,
    Supervisor,
    TickReport,
    Trigger,
)
from perchd.logs.flightlog import FlightLogWriter, LogRow, jsonable
from perchd.logs.nolog import NoLog
from perchd.tau.plan import Plan

__all__ = ["FlightAbort", "FlightResult", "TickStatus", "bind_vehicle", "fly", "plan_summary"]


@dataclass(frozen=True, slots=True)
class TickStatus:
    """What a live display needs after each tick: t [s] since the flight started, phase,
    x [m], xdot [m/s], tau and tau_ref [s] (None when undefined)."""

    t: float
    phase: Phase
    x: float | None
    xdot: float | None
    tau: float | None
    tau_ref: float | None


@dataclass(frozen=True)
class FlightResult:
    """outcome: the EndReason; detail: why, in words. contact_speed [m/s] and perch_time
    [s, trigger to contact] as the agent estimated them (None without contact);
    plan_duration [s] and v_contact_plan [m/s] of the plan flown (retargeted if it was);
    trigger: the measured trigger state; true_contact_speed / true_perch_time: the
    simulator's own figures when flying in simulation (None otherwise); log: the log path;
    loop: timing statistics; failsafe_sent: driver.failsafe was called; hover_n [N]: the
    hover thrust the hold learned (None if it did not settle or learning is off),
    hover_guess_n [N] the guess it started from; log_lost: why the flight log stopped being written (a full disk; None: it was kept),
    which ends the flight as a software error; lag_model: the lag and drag the hold and
    approach identified (None: refused or not identified), kept in the vehicle's profile;
    v_hold_mps [m/s]: the speed stage 2 held (references.hold_loop; None before stage 2)."""

    outcome: EndReason
    detail: str
    contact_speed: float | None
    perch_time: float | None
    plan_duration: float
    v_contact_plan: float
    trigger: Trigger | None
    true_contact_speed: float | None
    true_perch_time: float | None
    log: str
    loop: LoopSummary
    failsafe_sent: bool
    hover_n: float | None = None
    hover_guess_n: float | None = None
    log_lost: str | None = None
    lag_model: LagModel | None = None
    v_hold_mps: float | None = None

    def to_json(self) -> dict[str, Any]:
        """The `perchd fly --json` object (docs/contracts.md §2 keys first)."""
        return {
            "outcome": self.outcome.name,
            "message": self.outcome.value,
            "detail": self.detail,
            "contact_speed": self.contact_speed,
            "perch_time": self.perch_time,
            "plan_duration": self.plan_duration,
            "v_contact_plan": self.v_contact_plan,
            "log": self.log,
            "true_contact_speed": self.true_contact_speed,
            "true_perch_time": self.true_perch_time,
            "trigger": jsonable(self.trigger),
            "loop": jsonable(self.loop),
            "failsafe_sent": self.failsafe_sent,
            "hover_n": self.hover_n,
            "hover_guess_n": self.hover_guess_n,
            "v_hold_mps": self.v_hold_mps,
            "log_lost": self.log_lost,
        }


def plan_summary(plan: Plan) -> dict[str, Any]:
    """The plan's defining figures for the log header (Plan API attributes)."""
    keys = ("strategy", "x0", "v0", "tau_s", "t_switch", "duration", "v_contact", "robust")
    out = {k: jsonable(getattr(plan, k, None)) for k in keys}
    out["limits"] = jsonable(getattr(plan, "limits", None))
    for extra in ("c", "k"):
        if hasattr(plan, extra):
            out[extra] = jsonable(getattr(plan, extra))
    return out


@dataclass(frozen=True, slots=True)
class _NoState:
    """What a log row records before the estimator has a state: nothing measured."""

    x: None = None
    xdot: None = None
    tau: None = None
    y: None = None
    z: None = None
    age: None = None
    pose_seq: int = -1


_NO_STATE = _NoState()


class _Run:
    """The per-tick wiring, kept apart from `fly` so the tick is one short method."""

    def __init__(
        self,
        plan: Plan,
        driver: Driver,
        source: PoseSource,
        clock: Clock,
        cfg: FlightConfig,
        abort: FlightAbort,
        on_tick: Callable[[TickStatus], None] | None,
        planner: Planner | None = None,
    ) -> None:
        self.frame = PerchFrame.from_surface(cfg.surface.point, cfg.surface.normal)
        self.est = Estimator(EstimatorConfig(), self.frame)
        self.sup = Supervisor(plan, cfg, self.frame, planner)
        self.loop = make_loop(cfg.sync.value, clock, cfg.rate_hz, source)
        self.clock = clock
        self.driver, self.source = driver, source
        self.log: FlightLogWriter | None = None  # opened once the supervisor accepts the plan
        self.abort, self.on_tick = abort, on_tick
        self.failsafe_sent = False
        self.t0: float | None = None
        self._events = 0
        self._sent_seq = -1  # newest pose a setpoint has been sent for (latency is per pose)

    def tick(self, k: int, t: float) -> bool:
        self.t0 = t if self.t0 is None else self.t0
        health = self.driver.health()
        pose = self.source.latest()
        if pose is not None:
            self.driver.observe_pose(pose)  # before send: a yaw loop wants the newest yaw
        w0 = time.perf_counter()
        self.est.offer(pose)
        state = self.est.state(t)
        last = self.est.last_pose
        arrival_age = None if last is None else t - (last.t + last.latency)
        rep = self.sup.tick(
            t,
            state,
            Conditions(
                health,
                self.loop.stats.streak,
                self.abort.reason,
                self.est.mocap_period,
                arrival_age,
            ),
        )
        self.loop.stats.agent.append(time.perf_counter() - w0)
        if rep.end is not None and rep.end is not EndReason.CONTACT:
            self.failsafe(rep.end)
        elif rep.setpoint is not None:
            self.driver.send(rep.setpoint)
            if last is not None and last.seq != self._sent_seq:
                self._sent_seq = last.seq
                self.loop.stats.latency.append(self.clock.now() - (last.t + last.latency))
        self._log(k, t, state, rep)
        if self.on_tick is not None:
            self.on_tick(
                TickStatus(
                    t - self.t0,
                    rep.phase,
                    state and state.x,
                    state and state.xdot,
                    state and state.tau,
                    rep.refs.tau_ref,
                )
            )
        return not rep.finished

    def failsafe(self, reason: EndReason) -> None:
        if not self.failsafe_sent:
            self.failsafe_sent = True
            self.driver.failsafe(reason)

    def _log(self, k: int, t: float, st: State | None, rep: TickReport) -> None:
        if isinstance(self.log, NoLog):  # no record kept: no row built either
            return
        for ev in self.sup.events[self._events :]:
            self.log.event(ev)
        self._events = len(self.sup.events)
        st = st if st is not None else _NO_STATE
        self._log_row(k, t, st, rep)
        if self.log.lost is not None:  # a flight leaves a record or ends: failsafe next tick
            self.abort.request(EndReason.SOFTWARE_ERROR)

    def _log_row(self, k: int, t: float, st: State | _NoState, rep: TickReport) -> None:
        sp, timing = rep.setpoint, self.loop.last
        self.log.row(
            LogRow(
                t=t,
                k=k,
                phase=rep.phase.value,
                x=st.x,
                xdot=st.xdot,
                tau=st.tau,
                tau_ref=rep.refs.tau_ref,
                x_plan=rep.refs.x,
                v_plan=rep.refs.v,
                a_plan=rep.refs.a,
                y=st.y,
                z=st.z,
                roll=sp.roll if sp else 0.0,
                pitch=sp.pitch if sp else 0.0,
                yaw=sp.yaw if sp else 0.0,
                thrust=sp.thrust if sp else 0.0,
                ux=rep.u[0],
                uy=rep.u[1],
                uz=rep.u[2],
                e=rep.e,
                age=st.age,
                pose_seq=st.pose_seq,
                jitter_s=timing.jitter_s if timing else 0.0,
                compute_s=timing.compute_s if timing else 0.0,
                end=rep.end.name if rep.finished and rep.end else None,
            )
        )


class TrueContact(Protocol):
    """A simulator's own record of the contact: t [s] on the flight's clock, speed [m/s]."""

    t: float
    speed: float


class GroundTruth(Protocol):
    """What a simulated vehicle knows that the agent can only estimate (sim.world.SimWorld)."""

    contact: TrueContact | None


def bind_vehicle(driver: Driver, cfg: FlightConfig) -> FlightConfig:
    """Give the driver the flight's vehicle (its mass: Driver.bind_mass, which refuses a URI
    mass= that disagrees) and cap the thrust at the driver's ceiling, so saturation and
    anti-windup act where the vehicle really stops (VehicleConfig.thrust_max_n). The
    session binds the same mass before connect (perchd/session.py); binding it again here
    refuses a config whose mass changed since."""
    v = cfg.vehicle
    driver.bind_mass(v.mass_kg)
    ceiling = driver.thrust_ceiling_n()
    if ceiling is None or ceiling >= v.thrust_max_n:
        return cfg
    if ceiling < v.hover_guess_n:
        raise ConfigError(
            f"{driver.uri}: its thrust ceiling "
            f"{ceiling:.4f} N is below the hover thrust {v.hover_guess_n:.4f} N "
            f"of vehicle.mass_kg = {v.mass_kg:g} kg"
        )
    return dataclasses.replace(cfg, vehicle=dataclasses.replace(v, thrust_max_n=ceiling))


def needs_worker(cfg: FlightConfig, clock: Clock) -> bool:
    """The trigger solves in a worker process: its policy retargets and the clock is real
    (on a simulated clock a solve in the tick takes no simulated time, and is reproducible;
    docs/architecture.md "Planning in flight")."""
    return cfg.trigger.policy in (TriggerPolicy.REPLAN, TriggerPolicy.ROBUST) and isinstance(
        clock, MonotonicClock
    )


def fly(
    plan: Plan,
    driver: Driver,
    source: PoseSource,
    clock: Clock,
    log_path: str | Path | None,
    cfg: FlightConfig = FlightConfig(),
    abort: FlightAbort | None = None,
    on_tick: Callable[[TickStatus], None] | None = None,
    world: GroundTruth | None = None,
    header: dict[str, Any] | None = None,
    planner: Planner | None = None,
    log_force: bool = False,
) -> FlightResult:
    """Fly `plan` (a perchd.tau.Plan) with a connected driver and a started pose source;
    a plan that fails check_flight_plan is refused (PlanError) before anything engages.

    clock: the loop's clock (the Runtime's). abort: the external hook (see FlightAbort).
    on_tick: called after every tick with a TickStatus (live display). world: the SimWorld
    when simulated, for the true contact figures. header: extra header fields for the log;
    log_path None keeps no log (NoLog).
    planner: the trigger's planner (flight/planner_worker.py), owned and closed here; None:
    a worker process when needs_worker(), else the supervisor solves in the tick.
    log_force: the log may replace an existing file (--force; safefile.Stream).
    """
    check_flight_plan(plan, cfg)  # the last line of defence: the commands checked it already
    abort = abort or FlightAbort()
    cfg = bind_vehicle(driver, cfg)  # before the log: a refused vehicle never flies
    if planner is None and needs_worker(cfg, clock):
        planner = WorkerPlanner(plan, cfg.trigger.library)  # loads while the vehicle holds
        below_loop(planner.pid)  # a solve must never hold the loop's CPU (docs/safety.md)
    try:
        return _fly(
            plan,
            driver,
            source,
            clock,
            log_path,
            cfg,
            abort,
            on_tick,
            world,
            header,
            planner,
            log_force,
        )
    finally:
        if planner is not None:
            planner.close()  # every way out: the worker never outlives its flight


def _fly(
    plan, driver, source, clock, log_path, cfg, abort, on_tick, world, header, planner, log_force
) -> FlightResult:
    run = _Run(plan, driver, source, clock, cfg, abort, on_tick, planner)  # may refuse
    log = run.log = (
        NoLog()
        if log_path is None
        else FlightLogWriter(
            log_path,
            {
                "plan": plan_summary(plan),
                "config": jsonable(cfg),
                "driver": driver.uri,
                "mocap_body": source.body,
                **(header or {}),
            },
            log_force,
        )
    )
    try:
        engage(driver, source)
        run.loop.run(run.tick)
    except BaseException as err:
        reason = (
            EndReason.SIGNAL
            if isinstance(err, KeyboardInterrupt)
            else EndReason.LOST_LINK
            if isinstance(err, LinkError)
            else EndReason.SOFTWARE_ERROR
        )
        try:
            run.failsafe(reason)
        finally:
            log.close({"outcome": reason.name, "detail": f"{type(err).__name__}: {err}"})
        raise
    result = _result(run, world, "" if log_path is None else str(log_path))
    log.close(
        {"outcome": result.outcome.name, "detail": result.detail, "summary": result.to_json()}
    )
    # the end line or the rename may be what failed
    return dataclasses.replace(result, log_lost=log.lost) if log.lost else result


def engage(driver: Driver, source: PoseSource) -> None:
    """Take the vehicle for this flight, handing the driver the pose source to forward
    from while it waits (an autopilot's EKF may need mocap before it arms)."""
    driver.engage(source.latest)


def _result(run: _Run, world: GroundTruth | None, log_path: str) -> FlightResult:
    sup = run.sup
    trig, contact = sup.trigger, sup.contact
    perch = contact.t - trig.t if contact and trig else None
    true_speed = true_perch = None
    if world is not None and world.contact is not None:
        true_speed = world.contact.speed
        true_perch = world.contact.t - trig.t if trig else None
    lost = run.log.lost
    detail = f"the flight log was lost: {lost}" if lost and not sup.end_detail else sup.end_detail
    return FlightResult(
        sup.end or EndReason.SOFTWARE_ERROR,
        detail,
        contact.speed if contact else None,
        perch,
        float(sup.plan.duration),
        float(sup.plan.v_contact),
        trig,
        true_speed,
        true_perch,
        log_path,
        run.loop.summary(),
        run.failsafe_sent,
        sup.hover_learned_n,
        sup.hover.guess_n,
        lost,
        sup.response.identified.model if sup.response.identified else None,
        sup.refs.hold.v_hold_mps if sup.refs.hold is not None else None,
    )
