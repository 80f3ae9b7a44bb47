"""The Plan: a tau reference from trigger to contact, and what it implies (X, V, A, peaks).

Stage 1 follows the strategy's closed form (perchd.tau.profiles); stage 2 (two-stage plans)
holds the contact speed V_c for |tau_s| seconds, so tau_ref = tau_s + (t - t_switch).
Times t are seconds since trigger; every method accepts scalars or numpy arrays.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, TypeVar, overload

import numpy as np

from perchd.core.errors import PlanError
from perchd.tau.limits import Limits
from perchd.tau.profiles import Coefficients, ConstantTauDot, FloatArray, InversePolynomial, Times

T = TypeVar("T")

STRATEGIES = ("ctds", "ctdts", "ipts")
PEAK_SAMPLES = 4001  # coarse scan of stage 1, then refined around the peak

RobustBox = tuple[tuple[float, float], tuple[float, float]]
"""((x0_lo, x0_hi), (v0_lo, v0_hi)) [m, m/s]: the trigger states a robust plan holds."""


@dataclass(frozen=True)
class Peaks:
    """v: [m/s] peak closing speed.  a: [m/s^2] peak |acceleration| along X."""

    v: float
    a: float


@dataclass(frozen=True)
class Plan:
    """A perching plan (docs/contracts.md §1). Build it with perchd.tau.make_plan or a strategy.

    x0 [m] < 0 and v0 [m/s] > 0: trigger state.  tau_s [s]: stage switch (None for ctds).
    c: tau-dot of ctds/ctdts.  k: (k_0..k_n) of ipts.  t_switch, duration [s] from trigger.
    v_contact [m/s].  robust: ((x0_lo, x0_hi), (v0_lo, v0_hi)) box k_1..k_n is certified for.
    """

    strategy: str
    x0: float
    v0: float
    tau_s: float | None
    c: float | None
    k: tuple[float, ...] | None
    t_switch: float
    duration: float
    v_contact: float
    limits: Limits
    peaks: Peaks
    robust: RobustBox | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)

    @cached_property
    def stage1(self) -> ConstantTauDot | InversePolynomial:
        return stage1_profile(self.strategy, self.x0, self.v0, self.c, self.k)

    @property
    def order(self) -> int | None:
        return None if self.k is None else len(self.k) - 1

    def stage(self, t: float) -> int:
        return 1 if float(t) < self.t_switch else 2

    def _split(
        self,
        t: Times,
        first: Callable[[FloatArray], FloatArray],
        second: Callable[[FloatArray], FloatArray],
    ) -> Times:
        ts = np.asarray(t, float)
        one = ts < self.t_switch
        out = np.where(one, first(np.where(one, ts, 0.0)), second(ts))
        return out if out.ndim else float(out)

    @overload
    def tau_ref(self, t: float) -> float: ...
    @overload
    def tau_ref(self, t: FloatArray) -> FloatArray: ...
    def tau_ref(self, t: Times) -> Times:
        # stage 2 starts at the switch; ctds switches at contact, where tau is 0
        tau_s = 0.0 if self.tau_s is None else self.tau_s
        return self._split(t, self.stage1.tau, lambda s: tau_s + (s - self.t_switch))

    @overload
    def x(self, t: float) -> float: ...
    @overload
    def x(self, t: FloatArray) -> FloatArray: ...
    def x(self, t: Times) -> Times:
        return self._split(t, self.stage1.x, lambda s: -self.v_contact * (self.duration - s))

    @overload
    def v(self, t: float) -> float: ...
    @overload
    def v(self, t: FloatArray) -> FloatArray: ...
    def v(self, t: Times) -> Times:
        return self._split(t, self.stage1.v, lambda s: np.full_like(s, self.v_contact))

    @overload
    def a(self, t: float) -> float: ...
    @overload
    def a(self, t: FloatArray) -> FloatArray: ...
    def a(self, t: Times) -> Times:
        return self._split(t, self.stage1.a, np.zeros_like)


def stage1_profile(
    strategy: str, x0: float, v0: float, c: float | None, k: Coefficients | None
) -> ConstantTauDot | InversePolynomial:
    if strategy in ("ctds", "ctdts"):
        if c is None or not (math.isfinite(c) and c > 0):  # also keeps 1/c defined
            raise PlanError(
                f"stage1.c must be a positive tau-dot (with c <= 0 the vehicle "
                f"never arrives), got {c!r}"
            )
        return ConstantTauDot(x0, v0, c)
    if k is None:
        raise PlanError("stage1.k: ipts needs its coefficients k_0..k_n")
    return InversePolynomial(x0, tuple(k))


def peak_abs(f: Callable[[FloatArray], FloatArray], t_end: float) -> float:
    """max |f| over [0, t_end], scanned densely and refined around the coarse maximum."""
    t = np.linspace(0.0, t_end, PEAK_SAMPLES)
    y = np.abs(f(t))
    i = int(np.argmax(y))
    step = t_end / (PEAK_SAMPLES - 1)
    fine = np.linspace(max(0.0, t[i] - step), min(t_end, t[i] + step), 201)
    return float(max(y[i], np.abs(f(fine)).max()))


def given(value: T | None, name: str) -> T:
    """A plan field its strategy sets (k for ipts, c for ctds/ctdts, tau_s for two-stage
    plans), or PlanError naming it if a plan built by hand left it out."""
    if value is None:
        raise PlanError(f"{name}: missing")
    return value


def check_trigger(x0: float, v0: float) -> None:
    if not (math.isfinite(x0) and x0 < 0):
        raise PlanError(f"x0 must be a negative gap [m] (surface at X = 0), got {x0:g}")
    if not (math.isfinite(v0) and v0 > 0):
        raise PlanError(f"v0 must be a positive closing speed [m/s], got {v0:g}")


def make_plan(
    strategy: str,
    x0: float,
    v0: float,
    tau_s: float | None,
    limits: Limits,
    *,
    c: float | None = None,
    k: Coefficients | None = None,
    robust: RobustBox | None = None,
) -> Plan:
    """Derive every figure of a plan from its parameters (used by planners and the loader)."""
    if strategy not in STRATEGIES:
        raise PlanError(f"strategy must be one of {', '.join(STRATEGIES)}, got {strategy!r}")
    check_trigger(x0, v0)
    profile = stage1_profile(strategy, x0, v0, c, k)
    if strategy == "ctds" and isinstance(profile, ConstantTauDot):  # ctds: always one
        t_switch = duration = -profile.tau0 / profile.c
        v_contact = 0.0
    else:
        hold = checked_tau_s(tau_s)
        t_switch = switch_time(profile, hold)
        v_contact = float(profile.v(t_switch))
        duration = t_switch - hold
    if not (math.isfinite(duration) and 0 < t_switch <= duration):
        raise PlanError(
            f"stage1: switch at {t_switch:g} s and contact at {duration:g} s "
            "after the trigger; both must be positive and in that order"
        )
    peaks = Peaks(peak_abs(profile.v, t_switch), peak_abs(profile.a, t_switch))
    return Plan(
        strategy,
        x0,
        v0,
        tau_s,
        c,
        None if k is None else tuple(map(float, k)),
        float(t_switch),
        float(duration),
        v_contact,
        limits,
        peaks,
        robust,
    )


def checked_tau_s(tau_s: float | None) -> float:
    if tau_s is None or not (math.isfinite(tau_s) and tau_s < 0):
        raise PlanError(f"tau_s must be a negative number of seconds, got {tau_s!r}")
    return tau_s


def switch_time(profile: ConstantTauDot | InversePolynomial, tau_s: float) -> float:
    if isinstance(profile, ConstantTauDot):
        return (tau_s - profile.tau0) / profile.c
    t_s = profile.first_switch(tau_s)
    if t_s is None:
        raise PlanError(f"stage1.k: tau never reaches tau_s = {tau_s:g} s from the trigger")
    return t_s
