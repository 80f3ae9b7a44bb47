"""Closed-form reference plans for the closed-loop tests, independent of perchd.tau.

The paper's case 1 (x0 = -3 m, v0 = 1.5 m/s, tau_s = -0.5 s, V_c in [0.7, 1.0] m/s,
v_max 2.5 m/s, a_max 1.4 m/s^2) as CTDTS (corrected eq. 7, docs/errata.md §1-2) and as IPTS n = 3
with the paper's k (docs/errata.md §5). They expose the Plan API's attributes and functions, so the
flight code cannot tell them from perchd.tau plans; the acceptance tests prefer perchd.tau.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RefLimits:
    v_contact: tuple[float, float] = (0.7, 1.0)
    v_max: float | None = 2.5
    a_max: float | None = 1.4


@dataclass(frozen=True)
class _TwoStage:
    x0: float
    v0: float
    tau_s: float
    t_switch: float
    v_contact: float
    limits: RefLimits = RefLimits()
    robust: tuple | None = None

    @property
    def duration(self) -> float:
        return self.t_switch + abs(self.tau_s)

    def stage(self, t):
        return np.where(np.asarray(t) <= self.t_switch, 1, 2)

    def tau_ref(self, t):
        t = np.asarray(t, float)
        return np.where(
            t <= self.t_switch,
            self._tau1(np.minimum(t, self.t_switch)),
            self.tau_s + (t - self.t_switch),
        )

    def x(self, t):
        t = np.asarray(t, float)
        return np.where(
            t <= self.t_switch,
            self._x1(np.minimum(t, self.t_switch)),
            -self.v_contact * (self.duration - t),
        )

    def v(self, t):
        t = np.asarray(t, float)
        return np.where(t <= self.t_switch, self._v1(np.minimum(t, self.t_switch)), self.v_contact)

    def a(self, t):
        t = np.asarray(t, float)
        return np.where(t <= self.t_switch, self._a1(np.minimum(t, self.t_switch)), 0.0)


@dataclass(frozen=True)
class RefCtdts(_TwoStage):
    c: float = 0.0
    strategy: str = "ctdts"

    def _base(self, t):
        return 1.0 + self.c * self.v0 / self.x0 * t

    def _tau1(self, t):
        return self.c * t + self.x0 / self.v0

    def _x1(self, t):
        return self.x0 * self._base(t) ** (1 / self.c)

    def _v1(self, t):
        return self.v0 * self._base(t) ** (1 / self.c - 1)

    def _a1(self, t):
        return self.v0**2 / self.x0 * (1 - self.c) * self._base(t) ** (1 / self.c - 2)


def ctdts(x0=-3.0, v0=1.5, tau_s=-0.5, v_c=1.0) -> RefCtdts:
    tau0 = x0 / v0
    c = math.log(tau_s / tau0) / (math.log(v_c / v0) + math.log(tau_s / tau0))
    return RefCtdts(x0, v0, tau_s, (tau_s - tau0) / c, v_c, c=c)


@dataclass(frozen=True)
class RefIpts(_TwoStage):
    k: tuple[float, ...] = ()
    strategy: str = "ipts"

    def _p(self, t):
        return sum(ki * t**i for i, ki in enumerate(self.k))

    def _P(self, t):
        return sum(ki / (i + 1) * t ** (i + 1) for i, ki in enumerate(self.k))

    def _tau1(self, t):
        return 1.0 / self._p(t)

    def _x1(self, t):
        return self.x0 * np.exp(self._P(t))

    def _v1(self, t):
        return self._x1(t) * self._p(t)

    def _a1(self, t):
        dp = sum(i * ki * t ** (i - 1) for i, ki in enumerate(self.k) if i)
        return self._x1(t) * (dp + self._p(t) ** 2)


def ipts(x0=-3.0, v0=1.5, tau_s=-0.5, k123=(-0.7166, -0.1907, 0.0067)) -> RefIpts:
    from scipy.optimize import brentq

    k = (v0 / x0, *k123)
    p = lambda t: sum(ki * t**i for i, ki in enumerate(k)) - 1.0 / tau_s  # noqa: E731
    grid = np.linspace(0.0, 10.0, 2001)
    i = int(np.argmax(np.sign(p(grid)) != np.sign(p(grid[0]))))
    t_s = brentq(p, grid[i - 1], grid[i])
    plan = RefIpts(x0, v0, tau_s, t_s, 0.0, k=k)
    return RefIpts(x0, v0, tau_s, t_s, float(plan._v1(t_s)), k=k)
