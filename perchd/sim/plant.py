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
from collections.abc import Callable
from dataclasses import dataclass

from perchd.core.types import Setpoint, Vec3
from perchd.core.vehicle import CRAZYFLIE_MASS_KG, G_M_S2


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


Touch = tuple[Vec3, Vec3, Callable[[float, Vec3, float], None]]
"""(point [m], unit normal, fn) of a plane Plant.step_to reports reaching."""


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

    def step_to(self, t: float, touch: Touch | None = None) -> None:
        """Integrate up to time t [s] in steps of step_s (the last one shorter). touch =
        (point, unit normal, fn): after each step that ends with the vehicle at or beyond
        that plane (point-to-vehicle along the normal >= 0), fn(t_prev, p_prev, t)."""
        h = self.params.step_s
        end = t - 1e-12
        tt = self.t
        if not tt < end:
            return
        # One loop with the state in locals (the campaign's hottest code, ~10 steps a tick);
        # the arithmetic and its order are fixed: a campaign's table is pinned to the bit.
        prm = self.params
        tau_a, tau_m, t_max, mass, g = (
            prm.attitude_tau_s,
            prm.motor_tau_s,
            prm.thrust_max_n,
            prm.mass_kg,
            prm.g,
        )
        drag0, qdrag, push_x, push_a = (
            prm.drag_per_s,
            prm.qdrag_per_m,
            prm.draught_x_m,
            prm.draught_mps2,
        )
        stick = not prm.stick_s <= 0.0
        a_h, m_h = h / (tau_a + h), h / (tau_m + h)
        sin, cos, sqrt = math.sin, math.cos, math.sqrt
        if touch is not None:
            (s0, s1, s2), (n0, n1, n2), fn = touch
        queue = self._queue
        due = queue[0][0] if queue else math.inf
        c0, c1, c2, c3 = self.cmd
        target = min(max(c3, 0.0), t_max)
        px, py, pz = self.p
        vx, vy, vz = self.v
        r, pi, y = self.att
        thrust = self.thrust
        frozen = self.frozen
        while tt < end:
            dt = t - tt
            if not dt < h:  # min(h, t - tt)
                dt = h
            if due <= tt + 1e-12:
                self._apply_due(tt)
                due = queue[0][0] if queue else math.inf
                c0, c1, c2, c3 = self.cmd
                target = min(max(c3, 0.0), t_max)
            if frozen:
                tt += dt
                continue
            if dt == h:
                a_att = a_h
                a_mot = m_h
            else:
                a_att = dt / (tau_a + dt)
                a_mot = dt / (tau_m + dt)
            r += a_att * (c0 - r)
            pi += a_att * (c1 - pi)
            y += a_att * (c2 - y)
            thrust += a_mot * (target - thrust)
            sr = sin(r)
            cr = cos(r)
            sp = sin(pi)
            cp = cos(pi)
            if y == 0.0:  # sin(+-0) is +-0, cos(+-0) is 1: the same bits, two calls fewer
                sy = y
                cy = 1.0
            else:
                sy = sin(y)
                cy = cos(y)
            f = thrust / mass
            drag = drag0 + qdrag * sqrt(vx * vx + vy * vy + vz * vz)
            ax = f * (cy * sp * cr + sy * sr) - drag * vx + (push_a if px >= push_x else 0.0)
            ay = f * (sy * sp * cr - cy * sr) - drag * vy
            az = f * (cp * cr) - g - drag * vz
            ox, oy, oz = px, py, pz
            if not (stick and not pz > 0.0 and self._held(az, dt)):
                vx += ax * dt
                px += vx * dt
                vy += ay * dt
                py += vy * dt
                vz += az * dt
                pz += vz * dt
                if pz <= 0.0 and vz <= 0.0:  # on the floor
                    pz, vx, vy, vz = 0.0, 0.0, 0.0, 0.0
            tt += dt
            if touch is not None and not (px - s0) * n0 + (py - s1) * n1 + (pz - s2) * n2 < 0.0:
                self.t, self.thrust = tt, thrust
                self.p[:], self.v[:], self.att[:] = (px, py, pz), (vx, vy, vz), (r, pi, y)
                fn(tt - dt, (ox, oy, oz), tt)
                frozen = self.frozen
                px, py, pz = self.p
                vx, vy, vz = self.v
        self.t, self.thrust = tt, thrust
        self.p[:], self.v[:], self.att[:] = (px, py, pz), (vx, vy, vz), (r, pi, y)

    def freeze(self) -> None:
        """Stuck to the surface (perched): nothing moves any more."""
        self.frozen = True
        self.v = [0.0, 0.0, 0.0]

    def _held(self, az: float, dt: float) -> bool:
        """On the floor: held there until an upward az [m/s^2] has lasted stick_s."""
        self._lifting_s = self._lifting_s + dt if az > 0.0 else 0.0
        return self._lifting_s < self.params.stick_s

    def _apply_due(self, t: float) -> None:
        while self._queue and self._queue[0][0] <= t + 1e-12:
            _, sp = self._queue.popleft()
            self.applied = sp
            self.cmd = (sp.roll, sp.pitch, sp.yaw, sp.thrust)
