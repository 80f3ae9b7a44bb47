"""Closed-form stage-1 profiles (X, Xdot, Xddot, tau against time since trigger).

Perching frame: X < 0 before contact, Xdot > 0, tau = X / Xdot < 0. All functions take
t [s] as a scalar or a numpy array and return the same shape.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import overload

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
Times = float | FloatArray
"""A time [s] or an array of times; each profile returns a value of the same shape."""
Coefficients = Sequence[float] | FloatArray
"""Polynomial coefficients (k_0..k_n or k_1..k_n) as a tuple, list or array."""


@dataclass(frozen=True)
class ConstantTauDot:
    """CTDS, paper eqs. 2-5: tau(t) = c t + tau_0 from X(0) = x0 [m], Xdot(0) = v0 [m/s]."""

    x0: float
    v0: float
    c: float

    @property
    def tau0(self) -> float:
        return self.x0 / self.v0

    def _base(self, t: Times) -> Times:
        # 1 + c t / tau_0 reaches 0 at contact; clip the round-off just past it.
        return np.maximum(1.0 + self.c * np.asarray(t, float) / self.tau0, 0.0)

    @overload
    def tau(self, t: float) -> float: ...
    @overload
    def tau(self, t: FloatArray) -> FloatArray: ...
    def tau(self, t: Times) -> Times:
        return self.c * np.asarray(t, float) + self.tau0

    @overload
    def x(self, t: float) -> float: ...
    @overload
    def x(self, t: FloatArray) -> FloatArray: ...
    def x(self, t: Times) -> Times:
        return self.x0 * self._base(t) ** (1.0 / self.c)

    @overload
    def v(self, t: float) -> float: ...
    @overload
    def v(self, t: FloatArray) -> FloatArray: ...
    def v(self, t: Times) -> Times:
        return self.v0 * self._base(t) ** (1.0 / self.c - 1.0)

    @overload
    def a(self, t: float) -> float: ...
    @overload
    def a(self, t: FloatArray) -> FloatArray: ...
    def a(self, t: Times) -> Times:
        return self.v0**2 / self.x0 * (1.0 - self.c) * self._base(t) ** (1.0 / self.c - 2.0)


@dataclass(frozen=True)
class InversePolynomial:
    """IPTS, paper eqs. 12-15 (docs/errata.md §3): tau(t) = 1 / p(t), p(t) = sum k_i t^i, k_0 = 1/tau_0.

    X = x0 exp(P(t)) with P the antiderivative of p, Xdot = X p, Xddot = X (p' + p^2).
    """

    x0: float
    k: tuple[float, ...]

    def _p(self, t: Times) -> Times:
        p: Times = np.polynomial.polynomial.polyval(np.asarray(t, float), self.k)
        return p

    def _dp(self, t: Times) -> Times:
        dp: Times = np.polynomial.polynomial.polyval(
            np.asarray(t, float), np.polynomial.polynomial.polyder(self.k)
        )
        return dp

    def _P(self, t: Times) -> Times:
        big_p: Times = np.polynomial.polynomial.polyval(
            np.asarray(t, float), np.polynomial.polynomial.polyint(self.k)
        )
        return big_p

    @overload
    def tau(self, t: float) -> float: ...
    @overload
    def tau(self, t: FloatArray) -> FloatArray: ...
    def tau(self, t: Times) -> Times:
        return 1.0 / self._p(t)

    @overload
    def x(self, t: float) -> float: ...
    @overload
    def x(self, t: FloatArray) -> FloatArray: ...
    def x(self, t: Times) -> Times:
        return self.x0 * np.exp(self._P(t))

    @overload
    def v(self, t: float) -> float: ...
    @overload
    def v(self, t: FloatArray) -> FloatArray: ...
    def v(self, t: Times) -> Times:
        return self.x(t) * self._p(t)

    @overload
    def a(self, t: float) -> float: ...
    @overload
    def a(self, t: FloatArray) -> FloatArray: ...
    def a(self, t: Times) -> Times:
        p = self._p(t)
        return self.x(t) * (self._dp(t) + p * p)

    def first_switch(self, tau_s: float) -> float | None:
        """[s] first t > 0 where tau(t) = tau_s, with tau negative and finite before it;
        None if tau never gets there (or passes through infinity first)."""
        poly = np.array(self.k, float)
        poly[0] -= 1.0 / tau_s
        candidates = [
            r.real
            for r in np.polynomial.polynomial.polyroots(poly)
            if abs(r.imag) < 1e-9 and r.real > 0
        ]
        zeros = [
            r.real
            for r in np.polynomial.polynomial.polyroots(self.k)
            if abs(r.imag) < 1e-9 and r.real > 0
        ]
        if not candidates:
            return None
        t_s = min(candidates)
        return None if any(z <= t_s for z in zeros) else float(t_s)
