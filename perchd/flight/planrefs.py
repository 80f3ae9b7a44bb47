"""A plan's references at one instant, in float math, for the control tick.

The Plan API (perchd.tau.plan) evaluates any shape of time through numpy; on one scalar an
IPTS plan costs about 80 us per tick for tau_ref, X, V and A (polyval and polyint per call),
which is most of a 100 Hz agent's compute. PlanSampler evaluates the same closed forms
(perchd.tau.profiles) at one time with Horner's rule and `math`, and hands anything it does
not know (another profile, a test's reference plan) back to the plan's own methods.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

from numpy.polynomial import polynomial as npp

from perchd.tau.plan import Plan
from perchd.tau.profiles import ConstantTauDot, InversePolynomial


class PlanPoint(NamedTuple):
    """At s [s] since the trigger: stage (1 or 2), tau_ref [s], x [m], v [m/s], a [m/s^2]."""

    stage: int
    tau_ref: float
    x: float
    v: float
    a: float


def _horner(coeffs: tuple[float, ...], t: float) -> float:
    """sum c_i t^i, evaluated in numpy polyval's order (so both agree to the last bit)."""
    acc = coeffs[-1]
    for c in coeffs[-2::-1]:
        acc = c + acc * t
    return acc


class PlanSampler:
    def __init__(self, plan: Plan) -> None:
        self.plan = plan
        self._stage1 = self._fast_stage1(plan)

    @staticmethod
    def _fast_stage1(plan: Plan):
        """The float evaluator of the plan's stage 1, or None to use the plan's methods."""
        if type(plan) is not Plan:
            return None
        profile = plan.stage1
        if type(profile) is InversePolynomial:
            return _InversePolynomial(profile)
        if type(profile) is ConstantTauDot:
            return _ConstantTauDot(profile)
        return None

    def at(self, s: float) -> PlanPoint:
        plan = self.plan
        if self._stage1 is None or (s >= plan.t_switch and plan.tau_s is None):
            return PlanPoint(
                int(plan.stage(s)),
                float(plan.tau_ref(s)),
                float(plan.x(s)),
                float(plan.v(s)),
                float(plan.a(s)),
            )
        if s < plan.t_switch:
            return PlanPoint(1, *self._stage1(s))
        return PlanPoint(
            2,
            plan.tau_s + (s - plan.t_switch),
            -plan.v_contact * (plan.duration - s),
            plan.v_contact,
            0.0,
        )


class _InversePolynomial:
    """tau = 1/p, X = x0 exp(P), Xdot = X p, Xddot = X (p' + p^2) (profiles.InversePolynomial)."""

    def __init__(self, profile: Any) -> None:
        self.x0 = profile.x0
        self.k = tuple(float(c) for c in profile.k)
        self.dk = tuple(float(c) for c in npp.polyder(self.k))
        self.ik = tuple(float(c) for c in npp.polyint(self.k))

    def __call__(self, t: float) -> tuple[float, float, float, float]:
        p = _horner(self.k, t)
        x = self.x0 * math.exp(_horner(self.ik, t))
        return 1.0 / p, x, x * p, x * (_horner(self.dk, t) + p * p)


class _ConstantTauDot:
    """tau = c t + tau0 and X, Xdot, Xddot as powers of 1 + c t / tau0 (profiles.ConstantTauDot)."""

    def __init__(self, profile: Any) -> None:
        self.x0, self.v0, self.c, self.tau0 = profile.x0, profile.v0, profile.c, profile.tau0
        self.a_scale = self.v0**2 / self.x0 * (1.0 - self.c)

    def __call__(self, t: float) -> tuple[float, float, float, float]:
        c = self.c
        base = max(1.0 + c * t / self.tau0, 0.0)
        return (
            c * t + self.tau0,
            self.x0 * _power(base, 1.0 / c),
            self.v0 * _power(base, 1.0 / c - 1.0),
            self.a_scale * _power(base, 1.0 / c - 2.0),
        )


def _power(base: float, exponent: float) -> float:
    """base ** exponent, infinite (as numpy has it) where a negative power meets 0."""
    return math.inf if base == 0.0 and exponent < 0.0 else base**exponent
