"""The controllers, SI throughout: tau PID (eqs. 17, 20), Y/Z PID (eq. 18), and the mapping
(eq. 19) of a perching-frame acceleration to roll, pitch, yaw and thrust with the saturations
of eqs. 25-26. Gains and their paper equivalents: perchd.flight.config (docs/errata.md §8).

Anti-windup: each integral is clamped so its contribution stays within i_limit, and it does
not integrate on a tick after the mapping saturated (tilt or thrust) in the direction the
error would push further.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from perchd.core.types import Phase, Setpoint, State, Vec3
from perchd.flight.config import AxisGains, FlightConfig, TauGains
from perchd.flight.frame import PerchFrame, body_z

TAU_I_LIMIT_MPS2 = 1.0
"""[m/s^2] the tau PID's integral contribution is clamped to this."""
TAU_D_FILTER_S = 0.03
"""[s] time constant of the low-pass on the tau error's derivative."""
TAU_ERROR_RANGE = (-1.5, 1.0)
"""The tau error is clamped to this range (it grows without bound as tau -> 0 at contact)."""
AXIS_I_LIMIT_MPS2 = 1.0
"""[m/s^2] a lateral axis PID's integral contribution is clamped to this (its derivative,
of the estimated velocity, is unfiltered: that is already smooth)."""


@dataclass(frozen=True, slots=True)
class Attitude:
    """roll, pitch, yaw [rad] (world, Z-Y-X); thrust [N]; saturated: tilt or thrust clipped."""

    roll: float
    pitch: float
    yaw: float
    thrust: float
    saturated: bool


@dataclass(frozen=True, slots=True)
class FeedForward:
    """What the tau controller feeds forward besides its PID: the plan's acceleration lead_s
    [s] early (the vehicle answers that late), plus the drag at the plan's speed then,
    drag_per_s [1/s] x v + qdrag_per_m [1/m] x v |v| (the drag the vehicle will meet), minus
    bias_mps2 [m/s^2] (a constant push along X). flight/lagid.py identifies them in flight."""

    lead_s: float
    drag_per_s: float = 0.0
    bias_mps2: float = 0.0
    qdrag_per_m: float = 0.0

    def accel(self, a_plan: float, v_plan: float) -> float:
        """[m/s^2] the feed-forward for the plan's a_plan [m/s^2], v_plan [m/s] lead_s ahead."""
        drag = self.drag_per_s * v_plan + self.qdrag_per_m * v_plan * abs(v_plan)
        return a_plan + drag - self.bias_mps2

    def step_from(self, old: FeedForward, a_plan: float, v_plan: float) -> float:
        """[m/s^2] what this feed-forward adds over `old` at the plan's a_plan, v_plan: the
        step an integral that was taking it up gives back."""
        return self.accel(a_plan, v_plan) - old.accel(a_plan, v_plan)


def tau_error(tau_ref: float, tau: float | None) -> float:
    """e = 1 - tau_ref/tau (eq. 17). tau None (Xdot ~ 0) is the limit tau -> -inf: e = 1."""
    if tau is None or tau >= 0.0:
        return 1.0
    return 1.0 - tau_ref / tau


class Pid:
    """One PID with clamped integral, filtered derivative and conditional integration."""

    def __init__(self, ki: float, kd: float, i_limit: float, d_filter_s: float) -> None:
        self.ki, self.kd = ki, kd
        self.i_limit = i_limit
        self.d_filter_s = d_filter_s
        self.integral = 0.0
        self._prev: float | None = None
        self._d = 0.0

    def reset(self) -> None:
        self.integral, self._prev, self._d = 0.0, None, 0.0

    def step(
        self, kp: float, e: float, dt: float, freeze: bool = False, de: float | None = None
    ) -> float:
        """Output for error e over dt [s]; `de` is a known error rate (else differenced)."""
        if de is None:
            raw = 0.0 if self._prev is None or dt <= 0 else (e - self._prev) / dt
            alpha = dt / (self.d_filter_s + dt) if dt > 0 else 0.0
            self._d += alpha * (raw - self._d)
            de = self._d
        self._prev = e
        if not freeze and self.ki > 0.0:
            bound = self.i_limit / self.ki
            self.integral = min(max(self.integral + e * dt, -bound), bound)
        return kp * e + self.ki * self.integral + self.kd * de


class TauController:
    """u_x [m/s^2] along the perching normal from the tau error, plus the plan's acceleration."""

    def __init__(self, gains: TauGains) -> None:
        self.gains = gains
        self.pid = Pid(gains.ki, gains.kd, TAU_I_LIMIT_MPS2, TAU_D_FILTER_S)
        self.last_error = 0.0
        self.last_kp = gains.kp_slow

    def reset(self, held: float = 0.0) -> None:
        """Start afresh, the integral supplying held [m/s^2] (within TAU_I_LIMIT_MPS2)."""
        self.pid.reset()
        if self.gains.ki > 0.0:
            self.pid.integral = min(max(held, -TAU_I_LIMIT_MPS2), TAU_I_LIMIT_MPS2) / self.gains.ki

    def give_back(self, step: float) -> None:
        """A feed-forward grows by step [m/s^2]: the integral gives back what it holds of
        it (at most all it holds, never turning it the other way), so the command does not
        step by what the integral was already supplying."""
        if self.gains.ki <= 0.0:
            return
        held = self.gains.ki * self.pid.integral
        give = max(min(step, held), 0.0) if step > 0.0 else min(max(step, held), 0.0)
        self.pid.integral -= give / self.gains.ki

    def retune(self, ki: float) -> None:
        """The integral's gain becomes ki [m/s^3], what the integral supplies unchanged."""
        if ki > 0.0 and self.pid.ki > 0.0:
            self.pid.integral *= self.pid.ki / ki
            self.pid.ki = ki

    def step(
        self,
        state: State,
        tau_ref: float,
        a_plan: float,
        dt: float,
        saturated: bool = False,
        kp_hold: float | None = None,
    ) -> float:
        """kp_hold [m/s^2]: a speed reference's gain (stage 2, both ways: eq. 20's argument,
        a shrinking |X| under a tau reference, does not hold for a speed). None: eq. 20's
        schedule."""
        g = self.gains
        e = min(max(tau_error(tau_ref, state.tau), TAU_ERROR_RANGE[0]), TAU_ERROR_RANGE[1])
        if kp_hold is not None:
            kp = kp_hold
        else:  # eq. 20: tau_ref/tau > 1 <=> e < 0
            kp = g.kp_fast if e < 0.0 else g.kp_slow
        self.last_error, self.last_kp = e, kp
        u = self.pid.step(kp, e, dt, freeze=saturated)
        return u + (a_plan if g.feedforward else 0.0)


class AxisController:
    """Position PID of one lateral axis (eq. 18), derivative on the estimated velocity."""

    def __init__(self, gains: AxisGains) -> None:
        self.gains = gains
        self.pid = Pid(gains.ki, gains.kd, AXIS_I_LIMIT_MPS2, 0.0)

    def step(
        self,
        ref: float,
        pos: float,
        vel: float,
        dt: float,
        saturated: bool = False,
        vel_ref: float = 0.0,
    ) -> float:
        return self.pid.step(self.gains.kp, ref - pos, dt, saturated, de=vel_ref - vel)


def map_attitude(
    a: Vec3,
    yaw: float,
    mass_kg: float,
    g: float,
    tilt_max: float,
    thrust_min: float,
    thrust_max: float,
) -> Attitude:
    """Eq. 19: world-frame acceleration command a [m/s^2] -> roll, pitch, thrust at `yaw`,
    with eq. 25 (|roll|, |pitch| <= tilt_max) and eq. 26 (thrust in thrust_min..thrust_max)."""
    ux, uy = a[0], a[1]
    uz = max(a[2], -0.8 * g)  # keep u_z + g > 0: never command upside down
    s, c = math.sin(yaw), math.cos(yaw)
    norm = math.sqrt(ux * ux + uy * uy + (uz + g) ** 2)
    roll = math.asin(max(-1.0, min(1.0, (ux * s - uy * c) / norm)))
    pitch = math.atan((ux * c + uy * s) / (uz + g))
    sat_roll = min(max(roll, -tilt_max), tilt_max)
    sat_pitch = min(max(pitch, -tilt_max), tilt_max)
    bz = body_z(sat_roll, sat_pitch, yaw)
    thrust = mass_kg * (ux * bz[0] + uy * bz[1] + (uz + g) * bz[2])
    sat_thrust = min(max(thrust, thrust_min), thrust_max)
    saturated = sat_roll != roll or sat_pitch != pitch or sat_thrust != thrust
    return Attitude(sat_roll, sat_pitch, yaw, sat_thrust, saturated)


class Controller:
    """Perching-frame acceleration commands -> Setpoint; holds the three PIDs' state.

    hover_n [N]: the thrust that holds the vehicle level, in the driver's newtons (the hold
    phase learns it: flight/hover.py). The mapping scales accelerations by hover_n / g, the
    vehicle's mass as the thrust path sees it, so a wrong mass or thrust calibration is
    corrected for feed-forward and gains alike. last_thrust_z [N]: the vertical component
    of the last setpoint's thrust. last_ux_sent [m/s^2]: the acceleration along X the last
    setpoint commands after the saturations. last_lean_sent: the X component of the body z
    axis that setpoint asks for.
    """

    def __init__(self, cfg: FlightConfig, frame: PerchFrame) -> None:
        self.cfg = cfg
        self.frame = frame
        self.tau = TauController(cfg.tau_gains)
        self.y = AxisController(cfg.lateral.y)
        self.z = AxisController(cfg.lateral.z)
        self.saturated = False
        self.last_u: Vec3 = (0.0, 0.0, 0.0)
        self.hover_n = cfg.vehicle.hover_guess_n
        self.last_thrust_z: float | None = None
        self.last_ux_sent = 0.0
        self.last_lean_sent = 0.0
        self._yaw = frame.yaw_facing

    def lateral(
        self, state: State, y_ref: float, z_ref: float, dt: float, vz_ref: float = 0.0
    ) -> tuple[float, float]:
        uy = self.y.step(y_ref, state.y, state.ydot, dt, self.saturated)
        uz = self.z.step(z_ref, state.z, state.zdot, dt, self.saturated, vz_ref)
        return uy, uz

    def setpoint(self, u: Vec3, t: float, pose_seq: int, phase: Phase) -> Setpoint:
        """Map the perching-frame acceleration u [m/s^2] to an attitude/thrust setpoint."""
        v = self.cfg.vehicle
        att = map_attitude(
            self.frame.rotate_out(u),
            self._yaw,
            self.hover_n / v.g,
            v.g,
            self.cfg.tilt_limit_rad,
            v.thrust_min_n,
            v.thrust_max_n,
        )
        self.saturated = att.saturated
        self.last_u = u
        bz = body_z(att.roll, att.pitch, att.yaw)
        self.last_thrust_z = att.thrust * bz[2]
        # The acceleration along X this setpoint asks for once flown, saturations included:
        # what the lag identification (flight/lagid.py) compares the response with.
        self.last_lean_sent = self.frame.rotate_in(bz)[0]
        self.last_ux_sent = self.last_lean_sent * att.thrust * v.g / self.hover_n
        return Setpoint(t, att.roll, att.pitch, att.yaw, att.thrust, pose_seq, phase)
