"""Robust IPTS: one k_1..k_n for a whole box of trigger states, found then certified.

Search (sampled, never trusted on its own):
  * For a fixed k every limit is, per k_0 = v0/x0, an interval [L(k_0), U(k_0)] of
    admissible |x0| (see perchd.tau.certify).  `admissible` samples it on a k_0 grid.
  * `largest_box` runs differential evolution over k; each k is scored by the largest
    axis-aligned box inside {(|x0|, v0): L(-v0/|x0|) <= |x0| <= U(-v0/|x0|)} on a grid,
    then polishes box and k together (Nelder-Mead, box boundary sampled: limits are
    linear in |x0| along each ray v0/x0 = const, so the boundary of a box decides it).
  * `fastest_k` minimises the worst-case duration t_s(k_max) + |tau_s| over the box
    (t_s is nondecreasing in k_0, so the worst state is the box's largest k_0).
Every result is then shrunk (about its centre, or about the state it must hold) until
`certify_box` proves it; only certified boxes are returned.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import differential_evolution, minimize

from perchd.core.errors import PlanError
from perchd.tau.certify import Box, Certificate, certify_box, first_switch
from perchd.tau.profiles import Coefficients, FloatArray, InversePolynomial

Progress = Callable[[int, int], None]
"""progress(done, total): steps of a long search done so far."""

T_SAMPLES = 97  # time samples per trajectory in the search (certifier bounds between)
SEARCH_MARGIN = 2e-3  # relative slack the search keeps from every limit


@dataclass(frozen=True)
class RobustLimits:
    """tau_s [s] < 0, v_contact (V_l, V_u) [m/s], v_max [m/s], a_max [m/s^2]."""

    tau_s: float
    v_contact: tuple[float, float]
    v_max: float
    a_max: float

    def certify(self, k: Coefficients, box: Box) -> Certificate:
        return certify_box(k, box, self.v_contact, self.v_max, self.a_max, self.tau_s)


@dataclass(frozen=True)
class RobustResult:
    """k = (k_1..k_n), its certified box and certificate."""

    k: tuple[float, ...]
    box: Box
    certificate: Certificate


def admissible(
    k: Coefficients, k0s: FloatArray, lim: RobustLimits, margin: float = SEARCH_MARGIN
) -> tuple[FloatArray, FloatArray]:
    """Sampled (L, U) [m] of admissible |x0| for each k_0 (nan where tau misses tau_s)."""

    lo, hi = np.full(len(k0s), np.nan), np.full(len(k0s), np.nan)
    u = np.linspace(0.0, 1.0, T_SAMPLES)
    for j, k0 in enumerate(k0s):
        unit = InversePolynomial(-1.0, (float(k0), *map(float, k)))  # |x0| = 1 m
        ts = unit.first_switch(lim.tau_s)
        if ts is None:
            continue
        f1, f2 = unit.v(u * ts), unit.a(u * ts)
        vc = f1[-1]
        lo[j] = lim.v_contact[0] / vc * (1 + margin)
        hi[j] = min(lim.v_contact[1] / vc, lim.v_max / f1.max(), lim.a_max / np.abs(f2).max()) * (
            1 - margin
        )
    return lo, hi


def box_margin(k: Coefficients, box: Box, lim: RobustLimits, n_edge: int = 16) -> float:
    """Worst relative margin over sampled box-boundary states (< 0: some limit broken)."""
    xs = np.linspace(box.x0[0], box.x0[1], n_edge)
    vs = np.linspace(box.v0[0], box.v0[1], n_edge)
    pts = np.concatenate(
        [np.stack([xs, np.full_like(xs, v)], 1) for v in box.v0]
        + [np.stack([np.full_like(vs, x), vs], 1) for x in box.x0]
    )
    s, k0s = -pts[:, 0], pts[:, 1] / pts[:, 0]
    lo, hi = admissible(k, k0s, lim, margin=0.0)
    if np.isnan(lo).any() or k0s.min() <= 1 / lim.tau_s:
        return -1.0
    return float(min(np.min(1 - lo / s), np.min(hi / s - 1)))


def _largest_rectangle(mask: NDArray[np.bool_]) -> tuple[int, int, int, int, int]:
    """(cells, i0, i1, j0, j1) of the largest all-True rectangle mask[i0:i1, j0:j1]."""
    best = (0, 0, 0, 0, 0)
    heights = np.zeros(mask.shape[1], int)
    for i in range(mask.shape[0]):
        heights = np.where(mask[i], heights + 1, 0)
        stack: list[int] = []
        for j in range(len(heights) + 1):
            h = heights[j] if j < len(heights) else 0
            while stack and heights[stack[-1]] >= h:
                top = stack.pop()
                left = stack[-1] + 1 if stack else 0
                area = heights[top] * (j - left)
                if area > best[0]:
                    best = (area, i - heights[top] + 1, i + 1, left, j)
            stack.append(j)
    return best


@dataclass(frozen=True)
class SearchDomain:
    """Where boxes are looked for: |x0| in s_range [m], v0 in v_range [m/s]; `contains`
    an (x0, v0) the box must hold (grow-a-box mode)."""

    s_range: tuple[float, float] = (0.5, 4.0)
    v_range: tuple[float, float] = (0.2, 2.5)
    contains: tuple[float, float] | None = None
    grid: int = 60


def grid_box(k: Coefficients, lim: RobustLimits, dom: SearchDomain) -> Box | None:
    """Largest box (on dom's grid) whose grid states all pass the sampled limits."""
    s = np.linspace(*dom.s_range, dom.grid)
    v = np.linspace(*dom.v_range, dom.grid)
    kgrid = np.linspace(-v[-1] / s[0], -v[0] / s[-1], 160)
    kgrid = kgrid[kgrid > 1 / lim.tau_s]
    if len(kgrid) < 2:
        return None
    lo, hi = admissible(k, kgrid, lim)
    ss, vv = np.meshgrid(s, v, indexing="ij")
    k0 = -vv / ss
    L = np.interp(k0, kgrid, np.nan_to_num(lo, nan=np.inf), left=np.inf, right=np.inf)
    U = np.interp(k0, kgrid, np.nan_to_num(hi, nan=-np.inf), left=-np.inf, right=-np.inf)
    mask = (L <= ss) & (ss <= U)
    if dom.contains is not None:
        return _box_containing(mask, s, v, dom.contains)
    cells, i0, i1, j0, j1 = _largest_rectangle(mask)
    if cells == 0 or i1 - i0 < 2 or j1 - j0 < 2:
        return None
    return Box((-s[i1 - 1], -s[i0]), (v[j0], v[j1 - 1]))


def _box_containing(
    mask: NDArray[np.bool_], s: FloatArray, v: FloatArray, state: tuple[float, float]
) -> Box | None:
    """Grow a box cell by cell around the grid point nearest `state` while it stays feasible."""
    i = int(np.clip(np.searchsorted(s, -state[0]) - 1, 0, len(s) - 2))
    j = int(np.clip(np.searchsorted(v, state[1]) - 1, 0, len(v) - 2))
    i0, i1, j0, j1 = i, i + 2, j, j + 2  # the grid cell holding the state
    if not mask[i0:i1, j0:j1].all():
        return None
    grown = True
    while grown:
        grown = False
        for d in ((-1, 0, 0, 0), (0, 1, 0, 0), (0, 0, -1, 0), (0, 0, 0, 1)):
            a, b, c, e = i0 + d[0], i1 + d[1], j0 + d[2], j1 + d[3]
            if a >= 0 and c >= 0 and b <= len(s) and e <= len(v) and mask[a:b, c:e].all():
                i0, i1, j0, j1, grown = a, b, c, e, True
    if i1 - i0 < 2 or j1 - j0 < 2:
        return None
    return Box((-s[i1 - 1], -s[i0]), (v[j0], v[j1 - 1]))


def _score(k: FloatArray, lim: RobustLimits, dom: SearchDomain) -> float:
    """-area of the grid box; when a required state is infeasible, how far it is (> 0)."""
    box = grid_box(k, lim, dom)
    if box is not None:
        return -box.area
    if dom.contains is None:
        return 0.0
    x0, v0 = dom.contains
    lo, hi = admissible(k, np.array([v0 / x0]), lim)
    if np.isnan(lo[0]):
        return 10.0
    return float(max(lo[0] + x0, -x0 - hi[0], 0.0)) + 1e-3


def polish(
    k: Coefficients, box: Box, lim: RobustLimits, dom: SearchDomain, evals: int | None = None
) -> tuple[FloatArray, Box]:
    """Grow the box and adjust k together (Nelder-Mead; sampled boundary must keep a margin)."""

    n = len(k)
    z0 = np.concatenate([k, [box.x0[0], box.x0[1], box.v0[0], box.v0[1]]])

    def unpack(z: FloatArray) -> tuple[FloatArray, Box]:
        return z[:n], Box((z[n], z[n + 1]), (z[n + 2], z[n + 3]))

    def cost(z: FloatArray) -> float:
        kk, b = unpack(z)
        if not (b.x0[0] < b.x0[1] < 0 < b.v0[0] < b.v0[1]) or (
            dom.contains
            and not (
                b.x0[0] <= dom.contains[0] <= b.x0[1] and b.v0[0] <= dom.contains[1] <= b.v0[1]
            )
        ):
            return 1.0
        return -b.area if box_margin(kk, b, lim) >= SEARCH_MARGIN else 1.0

    res = minimize(
        cost,
        z0,
        method="Nelder-Mead",
        options={"maxfev": evals or 600 * (n + 4), "xatol": 1e-6, "fatol": 1e-7, "adaptive": True},
    )
    z = res.x if res.fun < cost(z0) else z0
    kk, b = unpack(z)
    return np.asarray(kk), b


def shrink_until_certified(
    k: Coefficients,
    box: Box,
    lim: RobustLimits,
    about: tuple[float, float] | None = None,
    steps: int = 40,
) -> RobustResult:
    """Largest (within 0.1 %) shrink of `box` about `about` (default its centre) that
    `certify_box` proves."""
    cert = lim.certify(k, box)
    if cert.certified:
        return RobustResult(tuple(map(float, k)), box, cert)
    lo, hi, best = 0.0, 1.0, None
    for _ in range(steps):
        mid = (lo + hi) / 2
        c = lim.certify(k, box.scaled(mid, about))
        if c.certified:
            lo, best = mid, (box.scaled(mid, about), c)
        else:
            hi = mid
        if hi - lo < 1e-3 and best:
            break
    if best is None:
        raise PlanError(f"no certified box around the one found ({cert.reason})")
    return RobustResult(tuple(map(float, k)), best[0], best[1])


def _inside(k: np.ndarray, bounds: list[tuple[float, float]]) -> np.ndarray:
    """k clipped into the search's bounds: differential evolution refuses a seed outside
    them (a start whose k a polish carried beyond them still seeds the search)."""
    lo, hi = np.array(bounds).T
    return np.asarray(np.clip(k, lo, hi), dtype=float)


def largest_box(
    order: int,
    lim: RobustLimits,
    dom: SearchDomain = SearchDomain(),
    *,
    seed: int = 0,
    maxiter: int = 60,
    popsize: int = 12,
    k_bound: float = 2.0,
    start: RobustResult | None = None,
    polish_evals: int | None = None,
    progress: Progress | None = None,
) -> RobustResult:
    """k_1..k_n (n = order) and the largest certified box for them (see module docstring).
    `start` (e.g. the order n-1 result, padded with zeros) seeds the search, so a higher
    order never does worse than the lower one it contains. progress(generation, maxiter)
    is called after each generation of the search."""

    if order < 1:
        raise PlanError(f"order must be >= 1, got {order}")
    bounds = [(-3.0, 1.0)] + [(-k_bound, k_bound)] * (order - 1)
    guess = None if start is None else np.pad(start.k, (0, order - len(start.k)))[:order]
    de = differential_evolution(
        _score,
        bounds,
        args=(lim, dom),
        seed=seed,
        maxiter=maxiter,
        popsize=popsize,
        tol=1e-8,
        polish=False,
        x0=None if guess is None else _inside(guess, bounds),
        callback=_generations(progress, maxiter),
    )
    candidates = [(de.x, grid_box(de.x, lim, dom))]
    if start is not None:
        candidates.append((guess, start.box))
    found = []
    for k, box in candidates:
        if box is not None:
            k, box = polish(k, box, lim, dom, polish_evals)
            try:
                found.append(shrink_until_certified(k, box, lim, dom.contains))
            except PlanError:
                pass
    if not found:
        raise PlanError(f"no order-{order} k found that keeps any box inside the limits")
    return max(found, key=lambda r: r.box.area)


def fastest_k(
    order: int,
    box: Box,
    lim: RobustLimits,
    *,
    seed: int = 0,
    maxiter: int = 60,
    start: tuple[float, ...] | None = None,
    progress: Progress | None = None,
) -> RobustResult:
    """k_1..k_n certified over `box` with the least worst-case duration: first the k with the
    widest sampled margin over the box (differential evolution), then the worst duration
    t_s(k_max) + |tau_s| minimised under a sampled margin (COBYLA), then certified.
    `start` (k_1..k_m of order m <= n, e.g. a lower-order result) seeds the first search,
    padded with zeros and clipped into its bounds; that search keeps its best member, so the
    margin it ends with is never below the seed's.
    progress(generation, maxiter) is called after each generation of the first search."""

    if order < 1:
        raise PlanError(f"order must be >= 1, got {order}")
    if start is not None and not 1 <= len(start) <= order:
        raise PlanError(f"a start k of order {len(start)} cannot seed an order-{order} search")
    ratio, k0 = contact_ratio(box)
    if ratio > lim.v_contact[1] / lim.v_contact[0]:
        raise PlanError(
            f"no k of any order holds x0 {box.x0[0]:g}..{box.x0[1]:g} m, v0 "
            f"{box.v0[0]:g}..{box.v0[1]:g} m/s: along v0/x0 = {k0:.4g}/s the box spans "
            f"|x0| by a factor {ratio:.4f} > V_u/V_l = "
            f"{lim.v_contact[1] / lim.v_contact[0]:.4f}, and contact speed scales with |x0|"
        )
    k_max = box.k0_range[1]
    bounds = [(-3.0, 1.0)] + [(-2.0, 2.0)] * (order - 1)
    guess = None
    if start is not None:
        guess = _inside(np.pad(np.asarray(start, dtype=float), (0, order - len(start))), bounds)
    de = differential_evolution(
        lambda k: -box_margin(k, box, lim),
        bounds,
        seed=seed,
        maxiter=maxiter,
        popsize=12,
        tol=1e-8,
        polish=False,
        x0=guess,
        callback=_generations(progress, maxiter),
    )
    if -de.fun < SEARCH_MARGIN:
        cert = lim.certify(de.x, box)
        raise PlanError(
            f"no order-{order} k holds over x0 {box.x0[0]:g}..{box.x0[1]:g} m, "
            f"v0 {box.v0[0]:g}..{box.v0[1]:g} m/s: the best one breaks a limit by "
            f"{-100 * de.fun:.3g} % ({cert.reason})"
        )

    def worst(k: FloatArray) -> float:
        ts, _ = first_switch(np.asarray(k), k_max, lim.tau_s)
        return 1e3 if ts is None else ts

    best = de.x
    for margin in (SEARCH_MARGIN, 4 * SEARCH_MARGIN, 16 * SEARCH_MARGIN):
        cons = {"type": "ineq", "fun": lambda k, m=margin: box_margin(k, box, lim) - m}
        res = minimize(
            worst,
            de.x,
            method="COBYLA",
            constraints=[cons],
            options={"maxiter": 500 * order, "rhobeg": 0.05},
        )
        k = res.x if box_margin(res.x, box, lim) >= 0 else de.x
        cert = lim.certify(k, box)
        if cert.certified:
            return RobustResult(tuple(map(float, k)), box, cert)
    cert = lim.certify(best, box)
    if cert.certified:
        return RobustResult(tuple(map(float, best)), box, cert)
    raise PlanError(f"order-{order} k for the box could not be certified: {cert.reason}")


def _generations(progress: Progress | None, maxiter: int) -> Callable[[Any], None] | None:
    """A differential_evolution callback counting generations into `progress` (or None)."""
    if progress is None:
        return None
    done = [0]

    def callback(intermediate_result: Any) -> None:  # scipy passes the result by this name
        done[0] += 1
        progress(done[0], maxiter)

    return callback


def contact_ratio(box: Box) -> tuple[float, float]:
    """(max over rays v0/x0 = const of s_hi/s_lo, the k_0 where it occurs).  V(t_s) is
    linear in |x0| along a ray, so no k of any order holds a box whose ratio exceeds
    V_u/V_l.  The ratio is piecewise monotone in k_0 with breaks where a segment end
    changes edge, so its maximum is at one of those breaks or an end."""
    kmin, kmax = box.k0_range
    ends = [kmin, kmax, -box.v0[1] / -box.x0[0], -box.v0[0] / -box.x0[1]]
    cands = np.array([c for c in ends if kmin <= c <= kmax])
    lo, hi = box.segment(cands)
    j = int(np.argmax(hi / lo))
    return float(hi[j] / lo[j]), float(cands[j])


def retarget_k(k: Coefficients, box: Box, x0: float, v0: float) -> FloatArray:
    """(k_0, k_1..k_n) for a measured trigger state: k_1..k_n kept, k_0 = v0/x0.
    PlanError if (x0, v0) lies outside the certified box."""
    if not box.contains(x0, v0):
        raise PlanError(
            f"trigger state x0 = {x0:.3f} m, v0 = {v0:.3f} m/s is outside the "
            f"robust box x0 {box.x0[0]:g}..{box.x0[1]:g} m, v0 {box.v0[0]:g}..{box.v0[1]:g} m/s"
        )
    return np.concatenate(([v0 / x0], np.asarray(k, float)))
