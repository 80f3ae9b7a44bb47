"""Certify one IPTS k_1..k_n for a whole box of trigger states (x0, v0).

Structure used (each step is checked by tests/robust):
  With k_0 = v0/x0 = 1/tau0 and p(t) = k_0 + q(t), q(t) = sum_{i>=1} k_i t^i,
  X = x0 exp(P), V = X p, A = X (p' + p^2) with P = k_0 t + Q(t), Q' = q.
  So t_s (first root of p = 1/tau_s) depends only on k_0, and for a fixed k_0 every
  quantity scales linearly in s = |x0|:
      V = s f1,  f1 = -e^P p;     A = s f2,  f2 = e^P (p' + p^2);
      V(t_s) = s e^{g} / |tau_s|,  g(k_0) = P(t_s(k_0); k_0).
  A box x0 in [xlo, xhi], v0 in [vlo, vhi] is the union over k_0 in
  [-vhi/|xhi|, -vlo/|xlo|] of the segments s in [s_lo(k_0), s_hi(k_0)] =
  [max(|xhi|, vlo/|k_0|), min(|xlo|, vhi/|k_0|)].  Upper limits bind at s_hi, the lower
  contact-speed limit at s_lo.

Method (what `certify_box` implements, nothing sampled is trusted):
  1. tau reaches tau_s and stays negative and finite: p(t; k_0) is increasing in k_0,
     so t_s(k_0) is nondecreasing and p(t; k_0) <= p(t; k_max).  One exact check at
     k_max (p < 0 on [0, t_s(k_max)], by the critical points of q) covers the box, and
     t_s(K) lies in [t_s(a), t_s(b)] for every k_0-cell K = [a, b].
  2. Contact speed: on each k_0-cell, g(K) is enclosed by the mean-value form
     g(c) + g'(K) [-h, h] with g' = t_s + t_s'/tau_s = t_s - 1/(tau_s p'(t_s)) (implicit
     differentiation of p(t_s) = 1/tau_s), g' enclosed by interval arithmetic over t in
     [t_s(a), t_s(b)]; cells that do not prove V_l <= V(t_s) <= V_u are bisected.
  3. Speed and acceleration: 2-D cells K x [t1, t2] tile {(k_0, t): t <= t_s(b)}.
     On each cell sup f <= f(centre) + sup|df/dk_0| h_k + sup|df/dt| h_t (mean-value
     theorem on a convex cell); the derivative bounds come from interval arithmetic
     (t >= 0 makes t^i monotone).  Cells where p < 1/tau_s throughout lie after t_s and
     are dropped.  A cell that fails is split along the dimension contributing most.
  Before a failing cell is split its centre is evaluated exactly (at the largest |x0| of
  its ray, or both segment ends for the contact speed): a real violation there is reported
  at once with its state, limit and time.  A cell still undecided at the minimum size
  (within the slack of a limit) leaves the box not certified.  Floating point: every
  bound carries a relative slack of 1e-9 (no directed rounding); t_s values come from
  numpy's polynomial roots refined by Newton steps.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import TypedDict, cast, overload

import numpy as np
from numpy.polynomial import polynomial as npoly
from numpy.typing import NDArray

from perchd.core.errors import PlanError
from perchd.tau.profiles import Coefficients, FloatArray, Times

SLACK = 1e-9  # relative slack on every proven bound (floating point)
MAX_CELLS = 4_000_000  # total 2-D cells examined before giving up (not certified)

Interval = tuple[Times, Times]
"""(lo, hi) enclosures, elementwise over arrays of cells."""
KCell = tuple[float, float, float, float]
"""(a, b, t_s(a), t_s(b)): a k0-cell [a, b] [1/s] and its switch times [s]."""
Centre = tuple[FloatArray, FloatArray, FloatArray, FloatArray]
"""(k0, t, f1, f2) at the centres of 2-D cells."""


@dataclass(frozen=True)
class Box:
    """Trigger states: x0 [m] in (lo, hi) with lo < hi < 0; v0 [m/s] in (lo, hi), 0 < lo < hi."""

    x0: tuple[float, float]
    v0: tuple[float, float]

    @property
    def area(self) -> float:
        """[m * m/s]"""
        return (self.x0[1] - self.x0[0]) * (self.v0[1] - self.v0[0])

    @property
    def k0_range(self) -> tuple[float, float]:
        """k_0 = v0/x0 [1/s] over the box (both negative)."""
        return (-self.v0[1] / -self.x0[1], -self.v0[0] / -self.x0[0])

    @overload
    def segment(self, k0: float) -> tuple[float, float]: ...
    @overload
    def segment(self, k0: FloatArray) -> tuple[FloatArray, FloatArray]: ...
    def segment(self, k0: Times) -> tuple[Times, Times]:
        """s = |x0| range [m] of the box states with v0/x0 = k0 (vectorised)."""
        r = np.abs(k0)
        return (np.maximum(-self.x0[1], self.v0[0] / r), np.minimum(-self.x0[0], self.v0[1] / r))

    def scaled(self, factor: float, about: tuple[float, float] | None = None) -> Box:
        """The box shrunk (factor < 1) or grown about `about` (x0, v0), default its centre."""
        xc, vc = about if about is not None else (sum(self.x0) / 2, sum(self.v0) / 2)

        def edge(e: float, centre: float) -> float:
            return float(centre + (e - centre) * factor)

        return Box(
            (edge(self.x0[0], xc), edge(self.x0[1], xc)),
            (edge(self.v0[0], vc), edge(self.v0[1], vc)),
        )

    def contains(self, x0: float, v0: float) -> bool:
        return self.x0[0] <= x0 <= self.x0[1] and self.v0[0] <= v0 <= self.v0[1]


@dataclass(frozen=True)
class Violation:
    """A state of the box where a limit fails; `limit` names it."""

    limit: str  # "tau_s" | "tau" | "v_contact_low" | "v_contact_high" | "v_max" | "a_max"
    x0: float  # [m]
    v0: float  # [m/s]
    t: float  # [s] since trigger
    value: float  # the quantity at that state and time
    bound: float  # the limit it breaks

    def __str__(self) -> str:
        if self.limit in ("tau_s", "tau"):
            return (
                f"{self.message()} at x0={self.x0:.4f} m, v0={self.v0:.4f} m/s "
                f"(tau0={self.x0 / self.v0:.4f} s, tau_s={self.bound:g} s)"
            )
        return (
            f"{self.message()}: {self.value:.6g} vs {self.bound:.6g} at x0={self.x0:.4f} m, "
            f"v0={self.v0:.4f} m/s, t={self.t:.4f} s"
        )

    def message(self) -> str:
        return {
            "tau_s": "tau never reaches tau_s",
            "tau": "tau turns positive/infinite before tau_s",
            "v_contact_low": "contact speed below V_l",
            "v_contact_high": "contact speed above V_u",
            "v_max": "speed above v_max",
            "a_max": "|acceleration| above a_max",
        }[self.limit]


class Bounds(TypedDict, total=False):
    """What a certificate proves over its box [SI]."""

    v_peak: float
    a_peak: float
    v_contact: tuple[float, float]


@dataclass(frozen=True)
class Certificate:
    """Outcome of `certify_box`.  Bounds are proven upper/lower bounds over the whole box."""

    certified: bool
    violation: Violation | None
    reason: str
    bounds: Bounds = field(default_factory=Bounds)  # v_peak, a_peak, v_contact (lo, hi) [SI]
    duration: tuple[float, float] = (float("nan"), float("nan"))  # [s] min, max over box
    cells: int = 0


def first_switch(k: FloatArray, k0: float, tau_s: float) -> tuple[float | None, str]:
    """t_s [s]: first t > 0 with p(t) = 1/tau_s, or (None, limit name) if tau never gets there
    or p reaches 0 (tau infinite, then positive) first.  k = (k_1..k_n).

    Stricter than InversePolynomial.first_switch, as a proof needs: a near-real root pair
    counts only if p really gets to the level, and p < 0 on [0, t_s] is shown by p's maximum
    there (ends and critical points), so a tangential touch of 0 is caught too."""
    q = np.concatenate(([0.0], k))
    poly = q.copy()
    poly[0] = k0 - 1.0 / tau_s
    roots = npoly.polyroots(poly) if np.any(poly[1:]) else np.array([])
    near = sorted(r.real for r in roots if abs(r.imag) <= 1e-7 * (1 + abs(r)) and r.real > 0)
    # a near-real pair counts only if p really gets to the level there (not a near miss)
    real = [t for t in (_polish(poly, r) for r in near) if npoly.polyval(t, poly) <= 1e-12]
    if not real:
        return None, "tau_s"
    ts = min(real)
    crit = [
        r.real
        for r in (npoly.polyroots(npoly.polyder(q)) if len(k) > 1 else [])
        if abs(r.imag) <= 1e-9 and 0 < r.real < ts
    ]
    pmax = max(npoly.polyval(np.array([0.0, ts] + crit), q)) + k0
    return (ts, "") if pmax < 0 else (None, "tau")


def _polish(poly: FloatArray, t: float) -> float:
    d = npoly.polyder(poly)
    for _ in range(3):
        slope = npoly.polyval(t, d)
        if slope == 0:
            break
        t -= float(npoly.polyval(t, poly) / slope)
    return t


# --- point evaluation -------------------------------------------------------------


@overload
def scale_functions(k: FloatArray, k0: float, t: float) -> tuple[float, float, float]: ...
@overload
def scale_functions(
    k: FloatArray, k0: FloatArray, t: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]: ...
def scale_functions(k: FloatArray, k0: Times, t: Times) -> tuple[Times, Times, Times]:
    """(p, f1, f2) at k0, t (broadcast): V = |x0| f1, A = |x0| f2 (see module docstring).
    Vectorised over k0 too (one per cell centre), which InversePolynomial (one k) is not."""
    q = np.concatenate(([0.0], k))
    big_q = np.concatenate(([0.0, 0.0], np.asarray(k) / np.arange(2, len(k) + 2)))
    p = k0 + npoly.polyval(t, q)
    e = np.exp(k0 * t + npoly.polyval(t, big_q))
    # numpy types polyval's result as floating[Any] whatever the input; here it is float64
    return cast(
        tuple[Times, Times, Times], (p, -e * p, e * (npoly.polyval(t, npoly.polyder(q)) + p * p))
    )


# --- interval arithmetic on arrays (lo, hi) ----------------------------------------


def _ipoly(c: FloatArray, t1: FloatArray, t2: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Enclosure of sum c_i t^i over [t1, t2] with t1 >= 0 (t^i monotone)."""
    i = np.arange(len(c))
    a, b = c * t1[:, None] ** i, c * t2[:, None] ** i
    return np.minimum(a, b).sum(1), np.maximum(a, b).sum(1)


def _imul(x: Interval, y: Interval) -> tuple[FloatArray, FloatArray]:
    prods = np.stack([x[0] * y[0], x[0] * y[1], x[1] * y[0], x[1] * y[1]])
    return prods.min(0), prods.max(0)


def _iadd(*xs: Interval) -> Interval:
    return sum(x[0] for x in xs), sum(x[1] for x in xs)


def _iscale(c: float, x: Interval) -> Interval:
    return (c * x[0], c * x[1]) if c >= 0 else (c * x[1], c * x[0])


def _isq(x: Interval) -> tuple[FloatArray, FloatArray]:
    lo2, hi2 = x[0] ** 2, x[1] ** 2
    lo = np.where((x[0] <= 0) & (x[1] >= 0), 0.0, np.minimum(lo2, hi2))
    return lo, np.maximum(lo2, hi2)


def _absmax(x: Interval) -> FloatArray:
    return np.maximum(np.abs(x[0]), np.abs(x[1]))


class _Poly:
    """Coefficient vectors of q, q', q'', Q for k = (k_1..k_n)."""

    def __init__(self, k: FloatArray) -> None:
        self.q: FloatArray = np.concatenate(([0.0], k))
        self.dq: FloatArray = np.asarray(npoly.polyder(self.q), np.float64)
        self.ddq: FloatArray = np.asarray(
            npoly.polyder(self.q, 2) if len(k) > 1 else np.zeros(1), np.float64
        )
        self.big_q: FloatArray = np.concatenate(([0.0, 0.0], k / np.arange(2, len(k) + 2)))


def _cell_bounds(
    poly: _Poly, ka: FloatArray, kb: FloatArray, t1: FloatArray, t2: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, Centre]:
    """Upper bounds of f1 and |f2| on cells [ka,kb] x [t1,t2], the upper bound of p, and the
    two excess terms (k-direction, t-direction) of the f2 bound, used to pick a split."""
    kc, tc, hk, ht = (ka + kb) / 2, (t1 + t2) / 2, (kb - ka) / 2, (t2 - t1) / 2
    qi, dq, ddq, big_q = (_ipoly(c, t1, t2) for c in (poly.q, poly.dq, poly.ddq, poly.big_q))
    p = (ka + qi[0], kb + qi[1])
    big_p = (ka * t2 + big_q[0], kb * t1 + big_q[1])
    e = (np.exp(big_p[0]), np.exp(big_p[1]))
    t = (t1, t2)
    psq = _isq(p)
    acc = _iadd(dq, psq)  # p' + p^2
    dk_f1 = _imul(e, _iadd(_imul(t, p), (1.0, 1.0)))  # -(df1/dk0), same |.|
    f2 = _imul(e, acc)  # = -(df1/dt)
    dk_f2 = _imul(e, _iadd(_imul(t, acc), _iscale(2.0, p)))
    dt_f2 = _imul(e, _iadd(ddq, _iscale(3.0, _imul(p, dq)), (p[0] ** 3, p[1] ** 3)))
    _, f1c, f2c = scale_functions(poly.q[1:], kc, tc)
    ub1 = f1c + _absmax(dk_f1) * hk + _absmax(f2) * ht
    ek, et = _absmax(dk_f2) * hk, _absmax(dt_f2) * ht
    ub2 = np.abs(f2c) + ek + et
    ek1, et1 = _absmax(dk_f1) * hk, _absmax(f2) * ht
    return ub1, ub2, p[1], np.maximum(ek, ek1), np.maximum(et, et1), (kc, tc, f1c, f2c)


# --- the certifier --------------------------------------------------------------
CERTIFIED_KEPT = 256
"""Certificates remembered (the inputs are a few floats; a certificate a few more)."""


def certify_box(
    k: Coefficients,
    box: Box,
    v_contact: tuple[float, float],
    v_max: float | None,
    a_max: float | None,
    tau_s: float,
    *,
    min_width: float = 1e-9,
) -> Certificate:
    """Prove that k = (k_1..k_n) meets every limit for every trigger state in `box`
    (method in the module docstring), or return the violation found. Remembered per
    process: every flight of a robust campaign re-certifies the same box (check_plan)."""
    key = Box((float(box.x0[0]), float(box.x0[1])), (float(box.v0[0]), float(box.v0[1])))
    return _certify_box(
        tuple(float(x) for x in np.ravel(k)),
        key,
        (float(v_contact[0]), float(v_contact[1])),
        v_max,
        a_max,
        tau_s,
        min_width,
    )


@functools.lru_cache(maxsize=CERTIFIED_KEPT)
def _certify_box(
    k_: tuple[float, ...],
    box: Box,
    v_contact: tuple[float, float],
    v_max: float | None,
    a_max: float | None,
    tau_s: float,
    min_width: float,
) -> Certificate:
    k = np.asarray(k_, dtype=float)
    kmin, kmax = box.k0_range
    if kmin <= 1.0 / tau_s:
        return _fail(
            Violation("tau_s", box.x0[1], box.v0[1], 0.0, box.x0[1] / box.v0[1], tau_s),
            "not certified",
        )
    ts_max, why = first_switch(k, kmax, tau_s)
    if ts_max is None:
        s = box.segment(kmax)[0]
        return _fail(
            Violation(why, -s, s * abs(kmax), float("nan"), float("nan"), tau_s), "not certified"
        )
    ts_min = _switch_in_box(k, kmin, tau_s)
    contact = _contact_cells(k, box, v_contact, tau_s, kmin, kmax, min_width)
    if not isinstance(contact, tuple):
        return (
            _fail(contact, "not certified")
            if contact
            else Certificate(
                False,
                None,
                "not certified: contact speed within 1e-9 of a limit somewhere (undecided)",
            )
        )
    cells_k, vc = contact
    peaks = _peak_cells(k, box, cells_k, v_max, a_max, tau_s, min_width)
    if not isinstance(peaks, tuple):
        return (
            _fail(peaks, "not certified")
            if peaks
            else Certificate(
                False,
                None,
                "not certified: speed/acceleration undecided (within 1e-9 of a limit or cell budget spent)",
            )
        )
    v_peak, a_peak, n = peaks
    return Certificate(
        True,
        None,
        "certified",
        {"v_peak": v_peak, "a_peak": a_peak, "v_contact": vc},
        (ts_min + abs(tau_s), ts_max + abs(tau_s)),
        n,
    )


def _fail(v: Violation, reason: str) -> Certificate:
    return Certificate(False, v, f"{reason}: {v}")


def _switch_in_box(k: FloatArray, k0: float, tau_s: float) -> float:
    """t_s at a k0 of the box, which has one once k_max has (step 1 of the method)."""
    ts, why = first_switch(k, k0, tau_s)
    if ts is None:  # only by round-off at a root of p's own level
        raise PlanError(
            f"certify: no switch time at k0 = {k0:g} 1/s ({why}) although "
            f"there is one at the box's largest k0"
        )
    return ts


def _contact_cells(
    k: FloatArray,
    box: Box,
    v_contact: tuple[float, float],
    tau_s: float,
    kmin: float,
    kmax: float,
    min_width: float,
    n0: int = 32,
) -> tuple[list[KCell], tuple[float, float]] | Violation | None:
    """Step 2: returns (list of (a, b, ts_a, ts_b) covering [kmin, kmax], (V_c lo, V_c hi)
    proven), or a Violation, or None (undecided)."""
    poly = _Poly(k)
    ts: dict[float, float] = {}

    def t_s(k0: float) -> float:
        if k0 not in ts:
            ts[k0] = _switch_in_box(k, k0, tau_s)
        return ts[k0]

    edges = list(np.linspace(kmin, kmax, n0 + 1))
    todo = [(a, b) for a, b in zip(edges[:-1], edges[1:])]
    done: list[KCell] = []
    lo_all, hi_all, undecided = np.inf, -np.inf, False
    v_l, v_u = v_contact
    while todo:
        a, b = todo.pop()
        ta, tb = t_s(a), t_s(b)
        c, h = (a + b) / 2, (b - a) / 2
        tc = t_s(c)
        gc = c * tc + npoly.polyval(tc, poly.big_q)
        dlo, dhi = _ipoly(poly.dq, np.array([ta]), np.array([tb]))
        if dhi[0] < 0:  # g' = t_s - 1/(tau_s p'(t_s)), p' < 0 on the cell
            inv = sorted((-1.0 / (tau_s * dlo[0]), -1.0 / (tau_s * dhi[0])))
            slope = max(abs(ta + inv[0]), abs(tb + inv[1]))
            g = (gc - slope * h, gc + slope * h)
        else:  # fall back to the plain enclosure of P over K x [ta, tb]
            bq = _ipoly(poly.big_q, np.array([ta]), np.array([tb]))
            g = (a * tb + bq[0][0], b * ta + bq[1][0])
        s_lo_min = min(box.segment(np.array([a, b]))[0])
        s_hi_max = max(box.segment(np.array([a, b]))[1])
        vc_hi = s_hi_max * np.exp(g[1]) / abs(tau_s) * (1 + SLACK)
        vc_lo = s_lo_min * np.exp(g[0]) / abs(tau_s) * (1 - SLACK)
        if vc_hi <= v_u and vc_lo >= v_l:
            done.append((a, b, ta, tb))
            lo_all, hi_all = min(lo_all, vc_lo), max(hi_all, vc_hi)
            continue
        witness = _contact_witness(k, box, (c,), v_contact, tau_s)
        if witness:
            return witness
        if 2 * h < min_width * max(1.0, abs(kmin)):
            witness = _contact_witness(k, box, (a, b), v_contact, tau_s)
            if witness:
                return witness
            undecided = True  # within SLACK of a limit: keep looking for a real violation
            continue
        todo += [(a, c), (c, b)]
    return None if undecided else (done, (lo_all, hi_all))


def _contact_witness(
    k: FloatArray, box: Box, k0s: tuple[float, ...], v_contact: tuple[float, float], tau_s: float
) -> Violation | None:
    for k0 in k0s:
        ts = _switch_in_box(k, k0, tau_s)
        for s, lim, bound in zip(box.segment(k0), ("v_contact_low", "v_contact_high"), v_contact):
            vc = s * scale_functions(k, k0, ts)[1]
            if (lim == "v_contact_low" and vc < bound) or (lim == "v_contact_high" and vc > bound):
                return Violation(lim, -s, s * abs(k0), ts, float(vc), bound)
    return None


def _peak_cells(
    k: FloatArray,
    box: Box,
    cells_k: list[KCell],
    v_max: float | None,
    a_max: float | None,
    tau_s: float,
    min_width: float,
    m0: int = 16,
) -> tuple[float, float, int] | Violation | None:
    """Step 3: (v_peak, a_peak, cells examined) proven, or a Violation, or None (undecided)."""
    poly = _Poly(k)
    v_lim = np.inf if v_max is None else v_max
    a_lim = np.inf if a_max is None else a_max
    cka: list[float] = []
    ckb: list[float] = []
    ct1: list[float] = []
    ct2: list[float] = []
    ctsb: list[float] = []
    for a, b, _, tb in cells_k:
        edges = np.linspace(0.0, tb, m0 + 1)
        cka += [a] * m0
        ckb += [b] * m0
        ct1 += list(edges[:-1])
        ct2 += list(edges[1:])
        ctsb += [tb] * m0
    ka, kb, t1, t2, tsb = map(np.array, (cka, ckb, ct1, ct2, ctsb))
    v_peak = a_peak = 0.0
    examined, undecided = 0, False
    kspan = box.k0_range[1] - box.k0_range[0]
    while len(ka):
        examined += len(ka)
        if examined > MAX_CELLS:
            return None
        s_hi = box.segment(kb)[1]  # largest s on the cell: v_hi/|k0| grows with k0
        s_hi = np.maximum(s_hi, box.segment(ka)[1])
        ub1, ub2, p_hi, ek, et, centre = _cell_bounds(poly, ka, kb, t1, t2)
        live = p_hi >= 1.0 / tau_s  # else the whole cell lies after t_s
        v_ub, a_ub = s_hi * ub1 * (1 + SLACK), s_hi * ub2 * (1 + SLACK)
        ok = (~live) | ((v_ub <= v_lim) & (a_ub <= a_lim))
        v_peak = max(v_peak, float(np.max(v_ub[ok & live], initial=0.0)))
        a_peak = max(a_peak, float(np.max(a_ub[ok & live], initial=0.0)))
        bad = ~ok
        if not bad.any():
            break
        witness = _centre_witness(k, box, centre, bad, v_lim, a_lim, tau_s)
        if witness:
            return witness
        ka, kb, t1, t2, tsb, ek, et = (x[bad] for x in (ka, kb, t1, t2, tsb, ek, et))
        tiny = ((kb - ka) < min_width * kspan) & ((t2 - t1) < min_width * 10)
        if tiny.any():
            witness = _peak_witness(
                k, box, ka[tiny], kb[tiny], t1[tiny], t2[tiny], v_lim, a_lim, tau_s
            )
            if witness:
                return witness
            undecided = True  # within SLACK of a limit: keep looking for a real violation
            ka, kb, t1, t2, tsb, ek, et = (x[~tiny] for x in (ka, kb, t1, t2, tsb, ek, et))
        ka, kb, t1, t2, tsb = _split(k, tau_s, ka, kb, t1, t2, tsb, ek >= et)
    return None if undecided else (v_peak, a_peak, examined)


def _split(
    k: FloatArray,
    tau_s: float,
    ka: FloatArray,
    kb: FloatArray,
    t1: FloatArray,
    t2: FloatArray,
    tsb: FloatArray,
    along_k: NDArray[np.bool_],
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Halve each cell along k0 (where along_k) or t; drop children after t_s(b)."""
    kc, tc = (ka + kb) / 2, (t1 + t2) / 2
    ts_c = np.array([_switch_in_box(k, c, tau_s) if ak else 0.0 for c, ak in zip(kc, along_k)])
    ka_n = np.concatenate([np.where(along_k, ka, ka), np.where(along_k, kc, ka)])
    kb_n = np.concatenate([np.where(along_k, kc, kb), np.where(along_k, kb, kb)])
    t1_n = np.concatenate([t1, np.where(along_k, t1, tc)])
    t2_n = np.concatenate([np.where(along_k, t2, tc), t2])
    ts_n = np.concatenate([np.where(along_k, ts_c, tsb), tsb])
    t2_n = np.minimum(t2_n, ts_n)
    keep = t1_n < t2_n
    return ka_n[keep], kb_n[keep], t1_n[keep], t2_n[keep], ts_n[keep]


def _centre_witness(
    k: FloatArray,
    box: Box,
    centre: Centre,
    bad: NDArray[np.bool_],
    v_lim: float,
    a_lim: float,
    tau_s: float,
) -> Violation | None:
    """The worst real violation at the centre of a failing cell (largest s of its ray), if any."""
    kc, tc, f1c, f2c = (x[bad] for x in centre)
    s = box.segment(kc)[1]
    ratio = np.maximum(s * f1c / v_lim, s * np.abs(f2c) / a_lim)
    for j in np.argsort(-ratio)[:8]:
        if ratio[j] <= 1.0:
            break
        ts, _ = first_switch(k, kc[j], tau_s)
        if ts is not None and tc[j] <= ts:
            if s[j] * f1c[j] > v_lim:
                return Violation("v_max", -s[j], s[j] * abs(kc[j]), tc[j], s[j] * f1c[j], v_lim)
            return Violation("a_max", -s[j], s[j] * abs(kc[j]), tc[j], s[j] * f2c[j], a_lim)
    return None


def _peak_witness(
    k: FloatArray,
    box: Box,
    ka: FloatArray,
    kb: FloatArray,
    t1: FloatArray,
    t2: FloatArray,
    v_lim: float,
    a_lim: float,
    tau_s: float,
) -> Violation | None:
    for a, b, ta, tb in zip(ka, kb, t1, t2):
        for k0 in (a, b, (a + b) / 2):
            ts = _switch_in_box(k, k0, tau_s)
            t = min((ta + tb) / 2, ts)
            s = box.segment(k0)[1]
            _, f1, f2 = scale_functions(k, k0, t)
            if s * f1 > v_lim:
                return Violation("v_max", -s, s * abs(k0), t, float(s * f1), v_lim)
            if s * abs(f2) > a_lim:
                return Violation("a_max", -s, s * abs(k0), t, float(s * f2), a_lim)
    return None
