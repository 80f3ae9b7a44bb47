"""A quadrotor plant driven by attitude/thrust setpoints: what the loopback driver flies.

The onboard attitude controller is modelled as a first-order response of roll, pitch and yaw
to their setpoints (time constant attitude_tau_s), the motors as a first-order lag of the
collective thrust (motor_tau_s) clamped to 0..thrust_max_n, and the radio as a pure delay
(latency_s) before a setpoint reaches the vehicle. Translational dynamics are rigid-body with
optional linear drag. The floor (world z = 0) stops a falling vehicle; with stick_s > 0 it
also holds a vehicle standing on it until its thrust has lifted for that long (an
autopilot's land detector and motor spool-up: ArduCopter SITL sits ~0.7 s at 1.1 x its
hover thrust, then surges). Pure Python floats:
a 1 ms step costs a few microseconds, so simulated seconds take milliseconds.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from perchd.core.types import Setpoint, Vec3
from perchd.core.vehicle import CRAZYFLIE_MASS_KG, G_M_S2
from perchd.flight.frame import body_z


@dataclass(frozen=True)
class PlantParams:
    """mass_kg [kg] (30 g Crazyflie 2.0 with markers); thrust_max_n [N] collective (four CF2.0
    motors give about 0.6 N); attitude_tau_s, motor_tau_s [s] first-order time constants;
    latency_s [s] command delay; drag_per_s [1/s] linear drag coefficient; qdrag_per_m
    [1/m] quadratic drag coefficient (deceleration qdrag_per_m |v| v); draught_mps2
    [m/s^2] a constant acceleration along world X where x >= draught_x_m [m]; g [m/s^2];
    step_s [s] integration step; stick_s [s] on the floor, how long the thrust must lift
    (exceed the weight) before the vehicle leaves it (0: at once)."""

    mass_kg: float = CRAZYFLIE_MASS_KG
    thrust_max_n: float = 0.60
    attitude_tau_s: float = 0.07
    motor_tau_s: float = 0.03
    latency_s: float = 0.0
    drag_per_s: float = 0.0
    qdrag_per_m: float = 0.0
    draught_x_m: float = math.inf
    draught_mps2: float = 0.0
    g: float = G_M_S2
    step_s: float = 0.001
    stick_s: float = 0.0


@dataclass(frozen=True, slots=True)
class PlantState:
    """p [m], v [m/s] world frame; roll, pitch, yaw [rad] (Z-Y-X); thrust [N]."""

    p: Vec3
    v: Vec3
    roll: float
    pitch: float
    yaw: float
    thrust: float


def quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of Z-Y-X Euler angles."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


class Plant:
    """Integrates the vehicle; `command` queues a setpoint, `step_to` advances time."""

    def __init__(self, params: PlantParams, start: Vec3, t0: float, hover: bool = True) -> None:
        self.params = params
        self.t = t0
        self.p = list(start)
        self.v = [0.0, 0.0, 0.0]
        self.att = [0.0, 0.0, 0.0]
        weight = params.mass_kg * params.g
        airborne = hover and start[2] > 0.0
        self.thrust = weight if airborne else 0.0
        self.cmd = (0.0, 0.0, 0.0, self.thrust)
        self.applied: Setpoint | None = None
        self._queue: deque[tuple[float, Setpoint]] = deque()
        self.frozen = False
        self._lifting_s = 0.0  # [s] the thrust has lifted while on the floor (stick_s)

    def command(self, sp: Setpoint, now: float) -> None:
        """The setpoint reaches the vehicle latency_s after `now`."""
        self._queue.append((now + self.params.latency_s, sp))

    def state(self) -> PlantState:
        return PlantState(tuple(self.p), tuple(self.v), *self.att, self.thrust)

    def step_to(self, t: float, on_step=None) -> None:
        """Integrate up to time t [s]; on_step(t_prev, p_prev, t, p, v) after each step."""
        h = self.params.step_s
        while self.t < t - 1e-12:
            dt = min(h, t - self.t)
            self._apply_due(self.t)
            p_prev = tuple(self.p)
            if not self.frozen:
                self._integrate(dt)
            self.t += dt
            if on_step is not None:
                on_step(self.t - dt, p_prev, self.t)

    def freeze(self) -> None:
        """Stuck to the surface (perched): nothing moves any more."""
        self.frozen = True
        self.v = [0.0, 0.0, 0.0]

    def _apply_due(self, t: float) -> None:
        while self._queue and self._queue[0][0] <= t + 1e-12:
            _, sp = self._queue.popleft()
            self.applied = sp
            self.cmd = (sp.roll, sp.pitch, sp.yaw, sp.thrust)

    def _integrate(self, dt: float) -> None:
        # Unrolled by hand (the campaign's hottest function, ~10 calls a tick); the
        # arithmetic and its order are the loops' own, so the flights are unchanged.
        prm, att, cmd, v, p = self.params, self.att, self.cmd, self.v, self.p
        a_att = dt / (prm.attitude_tau_s + dt)
        att[0] += a_att * (cmd[0] - att[0])
        att[1] += a_att * (cmd[1] - att[1])
        att[2] += a_att * (cmd[2] - att[2])
        target = min(max(cmd[3], 0.0), prm.thrust_max_n)
        self.thrust += dt / (prm.motor_tau_s + dt) * (target - self.thrust)
        bx, by, bz = body_z(att[0], att[1], att[2])
        f = self.thrust / prm.mass_kg
        drag = prm.drag_per_s + prm.qdrag_per_m * math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        push = prm.draught_mps2 if p[0] >= prm.draught_x_m else 0.0
        ax = f * bx - drag * v[0] + push
        ay = f * by - drag * v[1]
        az = f * bz - prm.g - drag * v[2]
        if self._stuck(az, dt):
            return
        v[0] += ax * dt
        p[0] += v[0] * dt
        v[1] += ay * dt
        p[1] += v[1] * dt
        v[2] += az * dt
        p[2] += v[2] * dt
        if p[2] <= 0.0 and v[2] <= 0.0:  # on the floor
            p[2] = 0.0
            self.v = [0.0, 0.0, 0.0]

    def _stuck(self, az: float, dt: float) -> bool:
        """On the floor, held there until an upward az [m/s^2] has lasted stick_s."""
        if self.params.stick_s <= 0.0 or self.p[2] > 0.0:
            return False
        self._lifting_s = self._lifting_s + dt if az > 0.0 else 0.0
        return self._lifting_s < self.params.stick_s
