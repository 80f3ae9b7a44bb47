"""Closed-form stage-1 profiles (X, Xdot, Xddot, tau against time since trigger).

Perching frame: X < 0 before contact, Xdot > 0, tau = X / Xdot < 0. All functions take
t [s] as a scalar or a numpy array and return the same shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ConstantTauDot:
    """CTDS, paper eqs. 2-5: tau(t) = c t + tau_0 from X(0) = x0 [m], Xdot(0) = v0 [m/s]."""

    x0: float
    v0: float
    c: float

    @property
    def tau0(self) -> float:
        return self.x0 / self.v0

    def _base(self, t):
        # 1 + c t / tau_0 reaches 0 at contact; clip the round-off just past it.
        return np.maximum(1.0 + self.c * np.asarray(t, float) / self.tau0, 0.0)

    def tau(self, t):
        return self.c * np.asarray(t, float) + self.tau0

    def x(self, t):
        return self.x0 * self._base(t) ** (1.0 / self.c)

    def v(self, t):
        return self.v0 * self._base(t) ** (1.0 / self.c - 1.0)

    def a(self, t):
        return self.v0 ** 2 / self.x0 * (1.0 - self.c) * self._base(t) ** (1.0 / self.c - 2.0)


@dataclass(frozen=True)
class InversePolynomial:
    """IPTS, paper eqs. 12-15 (docs/errata.md §3): tau(t) = 1 / p(t), p(t) = sum k_i t^i, k_0 = 1/tau_0.

    X = x0 exp(P(t)) with P the antiderivative of p, Xdot = X p, Xddot = X (p' + p^2).
    """

    x0: float
    k: tuple[float, ...]

    def _p(self, t):
        return np.polynomial.polynomial.polyval(np.asarray(t, float), self.k)

    def _dp(self, t):
        return np.polynomial.polynomial.polyval(np.asarray(t, float),
                                                np.polynomial.polynomial.polyder(self.k))

    def _P(self, t):
        return np.polynomial.polynomial.polyval(np.asarray(t, float),
                                                np.polynomial.polynomial.polyint(self.k))

    def tau(self, t):
        return 1.0 / self._p(t)

    def x(self, t):
        return self.x0 * np.exp(self._P(t))

    def v(self, t):
        return self.x(t) * self._p(t)

    def a(self, t):
        p = self._p(t)
        return self.x(t) * (self._dp(t) + p * p)

    def first_switch(self, tau_s: float) -> float | None:
        """[s] first t > 0 where tau(t) = tau_s, with tau negative and finite before it;
        None if tau never gets there (or passes through infinity first)."""
        poly = np.array(self.k, float)
        poly[0] -= 1.0 / tau_s
        candidates = [r.real for r in np.polynomial.polynomial.polyroots(poly)
                      if abs(r.imag) < 1e-9 and r.real > 0]
        zeros = [r.real for r in np.polynomial.polynomial.polyroots(self.k)
                 if abs(r.imag) < 1e-9 and r.real > 0]
        if not candidates:
            return None
        t_s = min(candidates)
        return None if any(z <= t_s for z in zeros) else float(t_s)
