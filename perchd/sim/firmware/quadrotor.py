"""A rigid-body quadrotor driven by motor PWM, with the Crazyflie model CrazySim flies.

The constants are those of CrazySim's Gazebo model of a Crazyflie 2.1 (the model the cf2
firmware's SITL build is tuned against, docs/firmware.md): PWM -> rotor speed (the plugin's
linear map), a first-order motor lag, thrust k_f w^2, yaw drag torque k_m T and rotor drag
on the in-plane airspeed. Body frame FLU (x forward, y left, z up); world Z up.

Plain floats, no numpy: one step is a few dozen multiplications and must take well under
the 1 ms it simulates (docs/firmware.md, "timing").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from perchd.core.ned import euler_zyx  # noqa: F401  (re-exported: tests and the harness use it here)
from perchd.core.types import Quat, Vec3


@dataclass(frozen=True, slots=True)
class QuadModel:
    """The Crazyflie 2.1 of CrazySim (all SI).

    mass_kg [kg] (body 0.025 + 4 propellers 0.0008); inertia_kgm2 [kg m^2] diagonal;
    rotor_xy_m [m] rotor positions m1..m4 (front-right, back-right, back-left, front-left);
    turning: +1 counter-clockwise (m1, m3), -1 clockwise (m2, m4), seen from above;
    k_f [N/(rad/s)^2] thrust per rotor speed squared; k_m [N m / N] yaw drag torque per
    thrust; tau_up_s, tau_down_s [s] motor lag speeding up / down; omega_max [rad/s];
    pwm_slope [rad/s per PWM], pwm_offset [rad/s], pwm_min: rotor speed = slope pwm + offset
    above pwm_min, 0 below; rotor_drag [N s/m per rad/s]; gravity [m/s^2].
    """

    mass_kg: float = 0.0282
    inertia_kgm2: Vec3 = (1.6572e-5, 1.6656e-5, 2.9262e-5)
    rotor_xy_m: tuple[tuple[float, float], ...] = (
        (0.031, -0.031),
        (-0.031, -0.031),
        (-0.031, 0.031),
        (0.031, 0.031),
    )
    turning: tuple[int, int, int, int] = (1, -1, 1, -1)
    k_f: float = 1.7965e-8
    k_m: float = 0.005964552
    tau_up_s: float = 0.0125
    tau_down_s: float = 0.025
    omega_max: float = 3052.0
    pwm_slope: float = 0.04076521
    pwm_offset: float = 380.8359
    pwm_min: int = 1000
    rotor_drag: float = 9.1785e-7
    gravity: float = 9.80665

    def omega_ref(self, pwm: float) -> float:
        """[rad/s] rotor speed a PWM command settles at."""
        if pwm < self.pwm_min:
            return 0.0
        return min(self.pwm_slope * pwm + self.pwm_offset, self.omega_max)

    def thrust(self, pwm: float) -> float:
        """[N] steady thrust of one rotor at a PWM."""
        return self.k_f * self.omega_ref(pwm) ** 2

    @property
    def hover_pwm(self) -> float:
        """PWM at which four rotors carry the weight."""
        omega = math.sqrt(self.mass_kg * self.gravity / (4.0 * self.k_f))
        return (omega - self.pwm_offset) / self.pwm_slope


@dataclass(frozen=True, slots=True)
class BodyState:
    """p [m] world, v [m/s] world, q (x, y, z, w) body -> world, w [rad/s] body rates,
    rotor [rad/s] m1..m4, grounded: resting on the floor, perched: stuck to the surface."""

    p: Vec3
    v: Vec3
    q: Quat
    w: Vec3
    rotor: tuple[float, float, float, float]
    grounded: bool
    perched: bool


class Quadrotor:
    """Integrates with semi-implicit Euler; the floor is z = floor_z (it starts there)."""

    def __init__(
        self, model: QuadModel, start: Vec3, yaw: float = 0.0, floor_z: float = 0.0
    ) -> None:
        self.m = model
        self.floor_z = floor_z
        self.p = list(start)
        self.v = [0.0, 0.0, 0.0]
        self.q = [0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)]  # x, y, z, w
        self.w = [0.0, 0.0, 0.0]
        self.rotor = [0.0, 0.0, 0.0, 0.0]
        self.grounded = start[2] <= floor_z
        if self.grounded:
            self.p[2] = floor_z
        self.perched = False
        self._f_body = (0.0, 0.0, model.gravity)  # specific force the IMU reads [m/s^2]

    # -- the body ----------------------------------------------------------------------
    def rotation(self) -> tuple[float, ...]:
        """Body -> world rotation matrix, row-major (9 floats)."""
        x, y, z, w = self.q
        return (
            1 - 2 * (y * y + z * z),
            2 * (x * y - w * z),
            2 * (x * z + w * y),
            2 * (x * y + w * z),
            1 - 2 * (x * x + z * z),
            2 * (y * z - w * x),
            2 * (x * z - w * y),
            2 * (y * z + w * x),
            1 - 2 * (x * x + y * y),
        )

    def step(self, dt: float, pwm: tuple[int, int, int, int] | list[int]) -> None:
        """Advance dt [s] with the motors commanded to `pwm` (m1..m4)."""
        m = self.m
        thrusts = [0.0] * 4
        spin = 0.0  # sum of |rotor speed|, for rotor drag
        for i in range(4):
            ref = m.omega_ref(pwm[i])
            tau = m.tau_up_s if ref >= self.rotor[i] else m.tau_down_s
            om = self.rotor[i] + (ref - self.rotor[i]) * min(dt / tau, 1.0)
            self.rotor[i] = om
            thrusts[i] = m.k_f * om * om
            spin += abs(om)
        if self.perched:
            return
        r = self.rotation()
        vx, vy, vz = self.v
        # rotor drag acts on the airspeed in the rotor plane (body x, y)
        vbx = r[0] * vx + r[3] * vy + r[6] * vz
        vby = r[1] * vx + r[4] * vy + r[7] * vz
        fx, fy, fz = -m.rotor_drag * spin * vbx, -m.rotor_drag * spin * vby, sum(thrusts)
        inv_m = 1.0 / m.mass_kg
        ax = (r[0] * fx + r[1] * fy + r[2] * fz) * inv_m
        ay = (r[3] * fx + r[4] * fy + r[5] * fz) * inv_m
        az = (r[6] * fx + r[7] * fy + r[8] * fz) * inv_m - m.gravity
        if self.grounded and az <= 0.0:  # the floor carries it: nothing moves
            self._f_body = (r[6] * m.gravity, r[7] * m.gravity, r[8] * m.gravity)
            return
        self.grounded = False
        self.v = [vx + ax * dt, vy + ay * dt, vz + az * dt]
        self.p = [
            self.p[0] + self.v[0] * dt,
            self.p[1] + self.v[1] * dt,
            self.p[2] + self.v[2] * dt,
        ]
        self._f_body = (fx * inv_m, fy * inv_m, fz * inv_m)
        if self.p[2] <= self.floor_z:  # touchdown: the floor stops it dead, level as it was
            self.p[2] = self.floor_z
            self.v = [0.0, 0.0, 0.0]
            self.w = [0.0, 0.0, 0.0]
            self.grounded = True
            return
        # torques: roll from the left/right thrust difference, pitch from front/back, yaw from
        # the rotors' drag (a counter-clockwise rotor pushes the body clockwise)
        mx = my = mz = 0.0
        for i in range(4):
            x_i, y_i = m.rotor_xy_m[i]
            mx += y_i * thrusts[i]
            my -= x_i * thrusts[i]
            mz -= m.turning[i] * m.k_m * thrusts[i]
        jx, jy, jz = m.inertia_kgm2
        wx, wy, wz = self.w
        # Euler's equations, diagonal inertia: J dw/dt = M - w x (J w)
        wx, wy, wz = (
            wx + (mx - wy * wz * (jz - jy)) / jx * dt,
            wy + (my - wz * wx * (jx - jz)) / jy * dt,
            wz + (mz - wx * wy * (jy - jx)) / jz * dt,
        )
        self.w = [wx, wy, wz]
        self._rotate(wx * dt, wy * dt, wz * dt)

    def _rotate(self, ax: float, ay: float, az: float) -> None:
        """q <- q * exp(angle / 2) for a small body-frame rotation vector [rad]."""
        x, y, z, w = self.q
        hx, hy, hz = ax / 2.0, ay / 2.0, az / 2.0
        nx = x + w * hx + y * hz - z * hy
        ny = y + w * hy + z * hx - x * hz
        nz = z + w * hz + x * hy - y * hx
        nw = w - x * hx - y * hy - z * hz
        n = math.sqrt(nx * nx + ny * ny + nz * nz + nw * nw)
        self.q = [nx / n, ny / n, nz / n, nw / n]

    def perch(self) -> None:
        """Stuck to the surface: it stays where it touched, whatever the motors do."""
        self.perched = True
        self.v = [0.0, 0.0, 0.0]
        self.w = [0.0, 0.0, 0.0]
        r = self.rotation()
        self._f_body = (r[6] * self.m.gravity, r[7] * self.m.gravity, r[8] * self.m.gravity)

    # -- what the sensors see ------------------------------------------------------------
    def specific_force(self) -> Vec3:
        """[m/s^2] body frame: what an accelerometer reads (+g on z at rest, level)."""
        return self._f_body

    def gyro(self) -> Vec3:
        return (self.w[0], self.w[1], self.w[2])

    def state(self) -> BodyState:
        return BodyState(
            tuple(self.p),
            tuple(self.v),
            tuple(self.q),
            tuple(self.w),  # type: ignore[arg-type]
            tuple(self.rotor),
            self.grounded,
            self.perched,
        )  # type: ignore[arg-type]
