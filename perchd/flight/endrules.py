"""The end rules, checked on every tick, in this order: operator abort, signal, stale mocap,
lost link, geofence, tilt, speed limit, tau divergence, deadline overrun streak, timeout,
contact, plan complete. Each says why the flight ends now, or nothing; the supervisor
(flight/supervisor.py) ends it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

from perchd.core.types import EndReason, LinkHealth, Phase, State
from perchd.flight.config import FlightConfig
from perchd.flight.frame import PerchFrame

STALE_PERIODS = 3.0
"""Mocap is stale after this many mocap periods without a valid pose (unless
[safety] stale_timeout_s says how long)."""
OVERRUN_STREAK = 10
"""Consecutive missed loop deadlines that end the flight DEADLINE_OVERRUN."""
TAU_ERROR_MAX_S = 0.5
"""[s] |tau - tau_ref| beyond max(this, TAU_ERROR_REL x |tau_ref|) for TAU_ERROR_HOLD_S
(or tau undefined that long) ends the flight TAU_DIVERGENCE."""
TAU_ERROR_REL = 0.5
"""See TAU_ERROR_MAX_S."""
TAU_ERROR_HOLD_S = 0.3
"""[s] see TAU_ERROR_MAX_S."""
PLAN_GRACE_S = 1.0
"""[s] past the plan's duration without contact ends the flight PLAN_COMPLETE."""
CONTACT_MARGIN_M = 0.005
"""[m] contact is declared within one tick of travel plus this of X = 0."""

FROZEN_MAX_S = 0.3
"""[s] once the approach has begun, poses with a bit-identical position for longer than this
are a stuck tracker re-sending its last position with fresh stamps, not a vehicle (noise
alone moves a real measurement; a commanded vehicle moves a noiseless simulated one within
its command latency and attitude response, well under this)."""
_MOVING = (Phase.APPROACH, Phase.STAGE1, Phase.STAGE2)
_STAGES = (Phase.STAGE1, Phase.STAGE2)


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


@dataclass(frozen=True, slots=True)
class Progress:
    """Where the flight stands, as the rules read it: phase; t_start [s] its first tick;
    t_moving [s] when the approach began moving the vehicle; line: (Y [m], Z [m]) of the
    approach line, None before the hold; t_trigger [s] the flown plan's t = 0, None before
    the trigger; plan_s [s] that plan's duration; tau_ref: the tick's tau reference [s],
    asked only in the stages."""

    phase: Phase
    t_start: float
    t_moving: float
    line: tuple[float, float] | None
    t_trigger: float | None
    plan_s: float
    tau_ref: Callable[[], float | None]


@dataclass(frozen=True, slots=True)
class ContactEstimate:
    """t [s] estimated time at X = 0; speed [m/s] estimated Xdot then."""

    t: float
    speed: float


class Ending(NamedTuple):
    """Why the flight ends: the reason, in words, and the contact when it is one."""

    reason: EndReason
    detail: str = ""
    contact: ContactEstimate | None = None


class EndRules:
    """The rules on one flight's settings and frame; the tau watch remembers since when the
    tau error has been too large."""

    def __init__(self, cfg: FlightConfig, frame: PerchFrame) -> None:
        self.cfg = cfg
        self.frame = frame
        self._t_bad_tau: float | None = None

    def check(self, t: float, state: State | None, cond: Conditions, p: Progress) -> Ending | None:
        """The first rule that ends the flight at tick time t [s], or None."""
        s = self.cfg.safety
        if cond.abort is not None:
            return Ending(cond.abort)
        why = self._stale(t, state, cond, p) or _link(cond.health, s.link_rtt_max_s)
        if why is None and state is not None:
            why = self._limits(state, p) or self._tau_watch(t, state, p)
        if why is not None:
            return why
        if cond.overrun_streak >= OVERRUN_STREAK:
            return Ending(
                EndReason.DEADLINE_OVERRUN, f"{cond.overrun_streak} deadlines missed in a row"
            )
        if t - p.t_start > s.timeout_s:
            return Ending(
                EndReason.TIMEOUT,
                f"flying {t - p.t_start:.3f} s, longer than [safety] timeout_s = {s.timeout_s:g} s",
            )
        if state is None:  # before the first pose: no contact, no trigger
            return None
        return self._contact(t, state, p) or self._plan_complete(t, state, p)

    def _stale(self, t: float, state: State | None, cond: Conditions, p: Progress) -> Ending | None:
        s, arrival_age = self.cfg.safety, cond.arrival_age_s
        limit = s.stale_timeout_s or STALE_PERIODS * (cond.mocap_period_s or 0.01)
        if state is None:
            if t - p.t_start > max(limit, 0.5):
                return Ending(EndReason.STALE_MOCAP, f"no pose in {t - p.t_start:.3f} s")
        elif arrival_age is not None and arrival_age > limit:
            return Ending(
                EndReason.STALE_MOCAP, f"newest pose arrived {arrival_age * 1000:.0f} ms ago"
            )
        elif p.phase in _MOVING and min(state.frozen_s, t - p.t_moving) > FROZEN_MAX_S:
            return Ending(
                EndReason.STALE_MOCAP,
                f"mocap frozen: the same position for {state.frozen_s * 1000:.0f} ms while flying",
            )
        return None

    def _limits(self, st: State, p: Progress) -> Ending | None:
        """The geofence (X range, the approach line, floor, ceiling), tilt and speed."""
        s = self.cfg.safety
        airborne = p.phase not in (Phase.IDLE, Phase.TAKEOFF)
        height = self.frame.point[2] + self.frame.rotate_out((st.x, st.y, st.z))[2]
        if not s.x_min_m <= st.x <= s.x_max_m:
            return Ending(
                EndReason.GEOFENCE, f"X = {st.x:.3f} m outside {s.x_min_m:g}..{s.x_max_m:g} m"
            )
        if p.line is not None:
            dy, dz = st.y - p.line[0], st.z - p.line[1]
            if airborne and max(abs(dy), abs(dz)) > s.lateral_max_m:
                return Ending(
                    EndReason.GEOFENCE,
                    f"{math.hypot(dy, dz):.2f} m off the approach line "
                    f"(limit {s.lateral_max_m:g} m)",
                )
        if airborne and height < s.floor_m:
            return Ending(
                EndReason.GEOFENCE, f"height {height:.3f} m below the floor limit {s.floor_m:g} m"
            )
        if height > s.ceiling_m:
            return Ending(
                EndReason.GEOFENCE, f"height {height:.3f} m above the ceiling {s.ceiling_m:g} m"
            )
        if st.tilt > s.tilt_max_rad:
            return Ending(
                EndReason.TILT_LIMIT,
                f"tilt {math.degrees(st.tilt):.1f} deg > {math.degrees(s.tilt_max_rad):.1f} deg",
            )
        speed = math.sqrt(st.xdot**2 + st.ydot**2 + st.zdot**2)
        if speed > s.speed_max_mps:
            return Ending(EndReason.SPEED_LIMIT, f"{speed:.2f} m/s > {s.speed_max_mps:g} m/s")
        return None

    def _tau_watch(self, t: float, st: State, p: Progress) -> Ending | None:
        """TAU_DIVERGENCE once tau has been off its reference (or undefined) for
        TAU_ERROR_HOLD_S."""
        if p.phase not in _STAGES:
            return None
        ref = p.tau_ref()
        assert ref is not None  # the stages' references are all set
        bad = st.tau is None or abs(st.tau - ref) > max(TAU_ERROR_MAX_S, TAU_ERROR_REL * abs(ref))
        if not bad:
            self._t_bad_tau = None
            return None
        self._t_bad_tau = self._t_bad_tau if self._t_bad_tau is not None else t
        if t - self._t_bad_tau >= TAU_ERROR_HOLD_S:
            got = "undefined" if st.tau is None else f"{st.tau:.3f} s"
            return Ending(EndReason.TAU_DIVERGENCE, f"tau {got} vs tau_ref {ref:.3f} s")
        return None

    def _contact(self, t: float, st: State, p: Progress) -> Ending | None:
        """CONTACT once the vehicle is within a tick's travel and the margin of X = 0."""
        if p.phase not in _MOVING:
            return None
        reach = max(st.xdot, 0.0) / self.cfg.rate_hz + CONTACT_MARGIN_M
        if st.x + reach < 0.0:
            return None
        lead = -st.x / st.xdot if st.xdot > 0 and st.x < 0 else 0.0
        contact = ContactEstimate(t + lead, st.xdot)
        return Ending(EndReason.CONTACT, f"at {contact.speed:.3f} m/s", contact)

    def _plan_complete(self, t: float, st: State, p: Progress) -> Ending | None:
        if p.t_trigger is None:
            return None
        since = t - p.t_trigger
        if since > p.plan_s + PLAN_GRACE_S:
            return Ending(
                EndReason.PLAN_COMPLETE, f"{since:.2f} s after the trigger, X = {st.x:.3f} m"
            )
        return None


def _link(health: LinkHealth, rtt_max_s: float) -> Ending | None:
    """LOST_LINK when the driver says so, or its round trip is slower than rtt_max_s [s]."""
    if not health.ok:
        return Ending(EndReason.LOST_LINK, health.detail)
    if health.rtt_s is not None and health.rtt_s > rtt_max_s:
        return Ending(
            EndReason.LOST_LINK,
            f"link too slow: round trip {health.rtt_s * 1000:.0f} ms > {rtt_max_s * 1000:.0f} ms",
        )
    return None
