"""IPTS minimum-time planning (paper eq. 16): a multistart of SLSQP with analytic gradients.

Formulation. In scaled time u = t / t_s in [0, 1] the stage-1 polynomial is
q(u) = p(t_s u) = sum m_i u^i with m_i = k_i t_s^i. Then m_0 = 1/tau_0 is fixed, reaching
tau_s at the switch is the *linear* equality sum m_i = 1/tau_s, the objective t_s is linear,
and with S = |X| = |x0| exp(t_s Q(u)) (Q the antiderivative of q):
    V = -S q,    A = -S (q'/t_s + q^2),    V_c = S(1) / |tau_s|.
Variables z = (m_1..m_n, t_s); every constraint gradient is analytic. On a grid of u:
  * the limits, each row divided by its own scale: V/v_max <= 1, |A|/a_max <= 1,
    V_l <= V(1) <= V_u (rows O(1) whatever the limits);
  * tau negative (q <= 0) and tau_s not reached before the switch, with a margin:
    q(u) - 1/tau_s >= SWITCH_MARGIN |1/tau_s| (1 - u), and -q'(1) >= SWITCH_MARGIN |1/tau_s|.
    The margin is what keeps loose limits solvable: there the optimum presses against this
    constraint, and without it SLSQP returned polynomials that reach tau_s *between* grid
    nodes (mid-flight, or tangentially just before u = 1); the real first switch was then
    earlier, at another contact speed, and every candidate was rejected. With it, tau
    crosses tau_s once, with a slope (a simple root that the dense check finds at u = 1).
The result is verified densely in t (perchd.tau.plan.make_plan: first switch by polynomial
roots, peaks by peak_abs) and re-solved with tightened limits or a wider margin if the grid
let a peak or the crossing slip between nodes.

Why the search is global, in terms a reader can check:
  1. Nested feasible sets. Limits enter only as right-hand sides (V/v_max <= 1,
     |A|/a_max <= 1, V_l <= V(1) <= V_u); the grid, the margin and the dense check do not
     depend on them. So any z feasible for tighter limits is feasible for looser ones, and
     the optimum of the looser problem is no slower.
  2. Limit-free starts. The RANDOM_SEEDS random polynomials and their t_s spread depend on
     the trigger state, tau_s and the contact window only (_random_seeds), so every limit
     set is searched from the same starts; the bang-bang-bound fits are added per limits.
  3. Every start is solved to a KKT point of the grid problem and the fastest CANDIDATES
     are verified densely; the reported plan is the fastest verified one.
  4. Independent checks: `perchd plan check` prints duration / bang-bang lower bound
     (perchd.tau.bound); tests/tau/test_ipts_properties.py checks monotonicity in every
     limit and re-derives each plan's X, V, A without this module.
It is a multistart, not a proof: a basin no start reaches can be missed. When nothing is
found, InfeasiblePlan carries a certificate: either a limit no trajectory of any order can
meet (v_max below v0 or V_l; a_max below the braking the gap needs), or the closest plan
of this order (least common factor on v_max, a_max) whose dense peaks say which limit is
short and by how much; a higher order is suggested only once one is shown to plan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from perchd.core.errors import PlanError
from perchd.tau.limits import Limits
from perchd.tau.plan import Plan, check_trigger, given, make_plan
from perchd.tau.profiles import FloatArray

MAX_ORDER = 9  # the paper stops at 7; orders 8-9 reach duration/bound <= 1.01 in both cases
GRID = 96  # constraint nodes in u, clustered at both ends where peaks sit
RANDOM_SEEDS = 24  # random starts beside the bound-fitted ones
CANDIDATES = 4  # best grid solutions tried through dense verification
VERIFY_TOL = 1e-9  # relative overshoot of a limit accepted by the dense check
TIGHTEN_MARGIN = 1e-8  # extra relative tightening when a peak slipped between grid nodes
UNBOUNDED = 1e3  # stands in for an unset v_max [m/s] or a_max [m/s^2]
SWITCH_MARGIN = 1e-3  # how far (relative to 1/|tau_s|) q keeps from 1/tau_s before the switch

Profiles = tuple[
    FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray
]
"""On the u-grid: q, dq/dz, V, dV/dz, A, dA/dz, q', dq'/dz."""


@dataclass(frozen=True)
class Problem:
    """One IPTS minimum-time problem; lengths in m, speeds m/s, accelerations m/s^2."""

    x0: float
    v0: float
    tau_s: float
    limits: Limits
    order: int

    @property
    def m0(self) -> float:
        return self.v0 / self.x0

    @property
    def m_sum(self) -> float:
        return 1.0 / self.tau_s - self.m0


def _grid(n: int = GRID) -> FloatArray:
    return 0.5 - 0.5 * np.cos(np.linspace(0.0, math.pi, n))


class _Model:
    """Vectorised profiles on the u-grid and their Jacobians w.r.t. z = (m_1..m_n, t_s).

    Every constraint row is divided by its own scale (v_max, a_max, V_u, |1/tau_s|), so all
    rows are O(1) whatever the limits: SLSQP's merit function weighs them alike, and a loose
    limit neither swamps nor vanishes beside the others."""

    def __init__(
        self,
        prob: Problem,
        u: FloatArray,
        a_max: float,
        v_max: float,
        switch_margin: float = SWITCH_MARGIN,
    ) -> None:
        self.p, self.u, self.a_max, self.v_max = prob, u, a_max, v_max
        self.switch_margin = switch_margin
        i = np.arange(1, prob.order + 1)
        self.U = u[:, None] ** i  # d q / d m_i
        self.dU = i * u[:, None] ** (i - 1)  # d q' / d m_i
        self.IU = u[:, None] ** (i + 1) / (i + 1)  # d Q / d m_i
        self.ln_s0 = math.log(-prob.x0)
        # the z last assembled, and what it gave (SLSQP asks for value and gradient at the
        # same z in turn)
        self._key: bytes | None = None
        self._val: tuple[FloatArray, FloatArray] | None = None

    def eval(self, z: FloatArray) -> Profiles:
        m, ts = z[:-1], z[-1]
        p = self.p
        q = p.m0 + self.U @ m
        dq = self.dU @ m
        Q = p.m0 * self.u + self.IU @ m
        S = np.exp(np.minimum(self.ln_s0 + ts * Q, 50.0))  # far-off seeds must not overflow
        dS = S[:, None] * np.hstack([ts * self.IU, Q[:, None]])  # d S / d z
        dq_z = np.hstack([self.U, np.zeros((len(q), 1))])
        ddq_z = np.hstack([self.dU, np.zeros((len(q), 1))])
        V = -S * q
        dV = -(dS * q[:, None] + S[:, None] * dq_z)
        g = dq / ts + q * q
        dg = ddq_z / ts + 2 * q[:, None] * dq_z
        dg[:, -1] -= dq / ts**2
        A = -S * g
        dA = -(dS * g[:, None] + S[:, None] * dg)
        return q, dq_z, V, dV, A, dA, dq, ddq_z

    def constraints(self, z: FloatArray) -> FloatArray:
        return self._both(z)[0]

    def jacobian(self, z: FloatArray) -> FloatArray:
        return self._both(z)[1]

    def _both(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        key = z.tobytes()
        if self._key != key or self._val is None:
            self._key, self._val = key, self._assemble(z)
        return self._val

    def _assemble(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        q, dq, V, dV, A, dA, slope, dslope = self.eval(z)
        lo, hi = self.p.limits.v_contact
        q_s = -1.0 / self.p.tau_s  # |q| at the switch: the scale of q
        margin = self.switch_margin * (1.0 - self.u[:-1])
        v_c = max(hi, self.p.v0)  # a speed scale that is never 0
        rows = [
            ((self.v_max - V) / self.v_max, -dV / self.v_max),
            ((self.a_max - A) / self.a_max, -dA / self.a_max),
            ((self.a_max + A) / self.a_max, dA / self.a_max),
            (-q / q_s, -dq / q_s),  # closing, tau negative
            # tau_s is not reached before t_s, by a margin shrinking to 0 at the switch ...
            ((q[:-1] - 1.0 / self.p.tau_s) / q_s - margin, dq[:-1] / q_s),
            # ... where tau crosses tau_s with a slope, not tangentially (a simple root).
            (-slope[-1:] / q_s - self.switch_margin, -dslope[-1:] / q_s),
            ((V[-1:] - lo) / v_c, dV[-1:] / v_c),  # V(t_s) = V_c within limits
            ((hi - V[-1:]) / v_c, -dV[-1:] / v_c),
        ]
        return np.concatenate([r[0] for r in rows]), np.vstack([r[1] for r in rows])


def _seed_from_bound(prob: Problem, v_c: float, a_max: float, v_max: float) -> FloatArray | None:
    """Fit q(u) to the tau of the bang-bang profile ending at V_c: a start near the optimum."""
    hold = -prob.tau_s
    gap = -prob.x0 - v_c * hold
    profile = _bang_bang(gap, prob.v0, v_c, a_max, v_max)
    if profile is None:
        return None
    t, x, v = profile
    ts = t[-1]
    u = t / ts
    return _fit(prob, u, v / (prob.x0 + x), ts)  # p = V / X along the profile


def _bang_bang(
    gap: float, v0: float, v_c: float, a: float, v_max: float, n: int = 200
) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """(t [s], x [m], v [m/s]) of the bang-bang profile, or None if the gap is too short."""
    brake = (v0 * v0 - v_c * v_c) / (2 * a)
    if gap < brake:
        return None
    vp = min(math.sqrt((2 * a * gap + v0 * v0 + v_c * v_c) / 2), v_max)
    t1, t3 = (vp - v0) / a, (vp - v_c) / a
    d1, d3 = (vp * vp - v0 * v0) / (2 * a), (vp * vp - v_c * v_c) / (2 * a)
    t2 = (gap - d1 - d3) / vp
    t = np.linspace(0.0, t1 + t2 + t3, n)
    v = np.where(t < t1, v0 + a * t, np.where(t < t1 + t2, vp, vp - a * (t - t1 - t2)))
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    return t, x, v


def _fit(prob: Problem, u: FloatArray, target: FloatArray, ts: float) -> FloatArray:
    """Least squares for m_1..m_n with the switch equality sum m_i = m_sum enforced."""
    U = u[:, None] ** np.arange(1, prob.order + 1)
    r = target - prob.m0
    # Eliminate m_n through the equality: m_n = m_sum - sum_{i<n} m_i.
    B = U[:, :-1] - U[:, -1:]
    rhs = r - U[:, -1] * prob.m_sum
    head = np.linalg.lstsq(B, rhs, rcond=None)[0] if prob.order > 1 else np.zeros(0)
    m = np.append(head, prob.m_sum - head.sum())
    return np.append(m, ts)


def _random_seeds(prob: Problem, count: int, rng: np.random.Generator) -> list[FloatArray]:
    """Random polynomials on the switch equality, t_s spread about a time scale of the state
    alone: the same starts for any limits, so loosening a limit never loses a start."""
    lo, hi = prob.limits.v_contact
    gap = -prob.x0 + prob.tau_s * (lo + hi) / 2
    ts_free = gap / max(prob.v0, (lo + hi) / 2)
    seeds = []
    for _ in range(count):
        m = rng.normal(0.0, 2.0 * abs(prob.m_sum), prob.order)
        m[-1] = prob.m_sum - m[:-1].sum()
        seeds.append(np.append(m, ts_free * rng.uniform(0.5, 1.5)))
    return seeds


def _solve_from(model: _Model, z0: FloatArray, prob: Problem) -> FloatArray | None:

    n = prob.order
    eq = {
        "type": "eq",
        "fun": lambda z: np.array([z[:-1].sum() - prob.m_sum]),
        "jac": lambda z: np.append(np.ones(n), 0.0)[None, :],
    }
    ineq = {"type": "ineq", "fun": model.constraints, "jac": model.jacobian}
    obj_grad = np.append(np.zeros(n), 1.0)
    bounds = [(None, None)] * n + [(1e-3, 60.0)]
    res = minimize(
        lambda z: z[-1],
        z0,
        jac=lambda z: obj_grad,
        method="SLSQP",
        bounds=bounds,
        constraints=[eq, ineq],
        options={"maxiter": 300, "ftol": 1e-12},
    )
    ok = res.success and model.constraints(res.x).min() > -1e-7
    return res.x if ok else None


def _to_plan(prob: Problem, z: FloatArray) -> Plan | None:
    m, ts = z[:-1], z[-1]
    k = [prob.m0] + [mi / ts**i for i, mi in enumerate(m, start=1)]
    try:
        plan = make_plan("ipts", prob.x0, prob.v0, prob.tau_s, prob.limits, k=k)
    except PlanError:
        return None
    lo, hi = prob.limits.v_contact
    return plan if lo - 1e-9 <= plan.v_contact <= hi + 1e-9 else None


def plan_ipts(
    x0: float,
    v0: float,
    tau_s: float,
    v_contact: tuple[float, float],
    v_max: float | None,
    a_max: float | None,
    order: int = 3,
    *,
    seed: int = 0,
    starts: int = RANDOM_SEEDS,
    probe_orders: bool = True,
) -> Plan:
    """The minimum-time IPTS plan of `order` (1..MAX_ORDER) meeting every limit, verified
    densely. Otherwise InfeasiblePlan, naming the limit that is short and by how much, and
    (probe_orders) the lowest higher order that does plan, if one up to MAX_ORDER does."""
    prob = _problem(x0, v0, tau_s, v_contact, v_max, a_max, order)
    a_lim = a_max if a_max is not None else UNBOUNDED
    v_lim = v_max if v_max is not None else UNBOUNDED
    short = _any_plan_shortfalls(prob, a_lim, v_lim)
    if short:
        why = "; ".join(map(str, short))
        raise InfeasiblePlan(f"no plan of any order can meet the limits: {why}", short, True)
    seeds = _seeds(prob, a_lim, v_lim, starts, seed)
    model = _Model(prob, _grid(), a_lim, v_lim)
    plan = _search(prob, model, seeds)
    if plan is not None:
        return plan
    near = _least_relaxed(prob, a_lim, v_lim, seeds)
    if near is not None and _meets(near, a_lim, v_lim):
        # The starts missed, but the least-relaxed plan fits: descend in time from it.
        z = _solve_from(model, _z_of(near), prob)
        return (None if z is None else _verified(prob, z, a_lim, v_lim)) or near
    higher = _lowest_order_that_plans(prob, a_lim, v_lim, seed, starts) if probe_orders else None
    raise _infeasible(prob, a_lim, v_lim, near, higher, probe_orders)


def _search(prob: Problem, model: _Model, seeds: list[FloatArray]) -> Plan | None:
    """SLSQP from every start; the fastest grid optima are verified densely, best first."""
    found = sorted(
        (z for z0 in seeds if (z := _solve_from(model, z0, prob)) is not None), key=lambda z: z[-1]
    )
    for z in found[:CANDIDATES]:
        plan = _verified(prob, z, model.a_max, model.v_max)
        if plan is not None:
            return plan
    return None


def _meets(plan: Plan, a_lim: float, v_lim: float) -> bool:
    return plan.peaks.a <= a_lim * (1 + VERIFY_TOL) and plan.peaks.v <= v_lim * (1 + VERIFY_TOL)


def _z_of(plan: Plan) -> FloatArray:
    ts = plan.t_switch
    return np.array([k * ts**i for i, k in enumerate(given(plan.k, "stage1.k"))][1:] + [ts])


def plan_ipts_from(
    x0: float,
    v0: float,
    tau_s: float,
    v_contact: tuple[float, float],
    v_max: float | None,
    a_max: float | None,
    k_start: list[float],
    t_switch_start: float,
) -> Plan | None:
    """Warm start: one local solve from a nearby optimum's k and t_s (a plan library's
    neighbours), verified densely like plan_ipts; None if it does not converge."""
    prob = _problem(x0, v0, tau_s, v_contact, v_max, a_max, len(k_start) - 1)
    a_lim = a_max if a_max is not None else UNBOUNDED
    v_lim = v_max if v_max is not None else UNBOUNDED
    z0 = np.array([ki * t_switch_start**i for i, ki in enumerate(k_start)][1:] + [t_switch_start])
    z0[-2] += prob.m_sum - z0[:-1].sum()  # onto the equality: reach tau_s at the switch
    z = _solve_from(_Model(prob, _grid(), a_lim, v_lim), z0, prob)
    return None if z is None else _verified(prob, z, a_lim, v_lim)


def _verified(prob: Problem, z: FloatArray, a_lim: float, v_lim: float) -> Plan | None:
    """Check the grid solution densely; where a peak slipped between nodes, tighten that
    limit by the overshoot, and where tau reached tau_s between nodes before the switch,
    widen the switch margin; then re-solve from here, a few times at most."""
    a_eff, v_eff, margin = a_lim, v_lim, SWITCH_MARGIN
    for _ in range(6):
        plan = _to_plan(prob, z)
        if plan is None:
            margin *= 4
        else:
            over_a, over_v = plan.peaks.a / a_lim, plan.peaks.v / v_lim
            if over_a <= 1 + VERIFY_TOL and over_v <= 1 + VERIFY_TOL:
                return plan
            # A margin of 1e-8 past the overshoot: the next solve lands inside, rather than
            # creeping up on the limit in steps SLSQP can no longer resolve (fails near 1e-9).
            a_eff /= max(over_a, 1.0) * (1 + TIGHTEN_MARGIN)
            v_eff /= max(over_v, 1.0) * (1 + TIGHTEN_MARGIN)
        solved = _solve_from(_Model(prob, _grid(), a_eff, v_eff, margin), z, prob)
        if solved is None:
            return None
        z = solved
    return None


def _problem(
    x0: float,
    v0: float,
    tau_s: float,
    v_contact: tuple[float, float],
    v_max: float | None,
    a_max: float | None,
    order: int,
) -> Problem:
    check_trigger(x0, v0)
    if not 1 <= order <= MAX_ORDER:
        raise PlanError(f"order must be 1..{MAX_ORDER}, got {order}")
    tau0 = x0 / v0
    if not (math.isfinite(tau_s) and tau0 < tau_s < 0):
        raise PlanError(f"tau_s = {tau_s:g} s must lie in (tau_0, 0) = ({tau0:g}, 0)")
    lo, hi = v_contact
    if -x0 - lo * -tau_s <= 0:
        raise PlanError(
            f"x0 = {x0:g} m is too close: stage 2 alone at V_l = {lo:g} m/s "
            f"for |tau_s| = {-tau_s:g} s covers {lo * -tau_s:g} m"
        )
    return Problem(x0, v0, tau_s, Limits((lo, hi), v_max, a_max), order)


def _seeds(prob: Problem, a_lim: float, v_lim: float, starts: int, seed: int) -> list[FloatArray]:
    lo, hi = prob.limits.v_contact
    seeds = [
        s
        for v_c in np.linspace(lo, hi, 4)
        if (s := _seed_from_bound(prob, float(v_c), a_lim, v_lim)) is not None
    ]
    return seeds + _random_seeds(prob, starts, np.random.default_rng(seed))


@dataclass(frozen=True)
class Shortfall:
    """A limit that no plan (or no plan of this order) can meet: `limit` is 'v_max' [m/s]
    or 'a_max' [m/s^2]; `given` is the value asked for, `needed` the least that works
    (for an order-specific shortfall: the peak of a verified plan that meets the rest)."""

    limit: str
    given: float
    needed: float

    @property
    def unit(self) -> str:
        return "m/s" if self.limit == "v_max" else "m/s^2"

    def __str__(self) -> str:
        return (
            f"{self.limit} = {self.given:g} {self.unit}: short by "
            f"{self.needed - self.given:.4g} {self.unit} (needs {self.needed:.4f})"
        )


class InfeasiblePlan(PlanError):
    """No plan found, with its certificate: the shortfalls, whether they bind every plan
    (`any_order`) or this order only, and the lowest higher order that does plan, if any."""

    def __init__(
        self,
        message: str,
        shortfalls: tuple[Shortfall, ...],
        any_order: bool,
        higher_order: int | None = None,
    ) -> None:
        super().__init__(message)
        self.shortfalls, self.any_order, self.higher_order = shortfalls, any_order, higher_order


def _infeasible(
    prob: Problem,
    a_lim: float,
    v_lim: float,
    near: Plan | None,
    higher: tuple[int, float] | None,
    probed: bool,
) -> InfeasiblePlan:
    """Why no order-n plan was found: the closest plan's shortfalls, and what order helps."""
    lo, hi = prob.limits.v_contact
    unset = " (unset)"
    head = (
        f"no order-{prob.order} IPTS plan meets v_contact [{lo:g}, {hi:g}] m/s, v_max "
        f"{v_lim:g} m/s{unset * (prob.limits.v_max is None)} and a_max {a_lim:g} m/s^2"
        f"{unset * (prob.limits.a_max is None)} from x0 = {prob.x0:g} m, v0 = "
        f"{prob.v0:g} m/s"
    )
    if near is None:
        short: tuple[Shortfall, ...] = ()
        why = "no polynomial of this order reaches the contact window at all"
    else:
        short = tuple(
            Shortfall(name, given, peak)
            for name, given, peak in (
                ("v_max", v_lim, near.peaks.v),
                ("a_max", a_lim, near.peaks.a),
            )
            if peak > given
        )
        why = (
            f"the closest order-{prob.order} plan found ({near.duration:.4f} s, peak "
            f"speed {near.peaks.v:.4f} m/s, peak |accel| {near.peaks.a:.4f} m/s^2) "
            f"breaks " + " and ".join(map(str, short))
        )
    if higher is not None:
        why += f"; order {higher[0]} meets every limit ({higher[1]:.4f} s): use --order {higher[0]}"
    elif probed and prob.order < MAX_ORDER:
        why += f"; no order up to {MAX_ORDER} meets them either"
    return InfeasiblePlan(f"{head}: {why}", short, False, higher and higher[0])


def _any_plan_shortfalls(prob: Problem, a_lim: float, v_lim: float) -> tuple[Shortfall, ...]:
    """Limits no trajectory at all can meet: speed limits below the trigger or contact speed,
    or too little deceleration to brake to V_u over the gap (the bang-bang bound is inf)."""
    lo, hi = prob.limits.v_contact
    if v_lim < max(prob.v0, lo):
        return (Shortfall("v_max", v_lim, max(prob.v0, lo)),)
    v_c = np.linspace(lo, hi, 201)
    gap = -prob.x0 + prob.tau_s * v_c
    need = float(np.min(np.maximum(prob.v0**2 - v_c**2, 0.0) / (2 * gap)))
    return (Shortfall("a_max", a_lim, need),) if need > a_lim else ()


def _least_relaxed(
    prob: Problem, a_lim: float, v_lim: float, seeds: list[FloatArray]
) -> Plan | None:
    """The plan of this order needing the least common factor on v_max and a_max, every
    other constraint met: minimise lam with V <= lam v_max, |A| <= lam a_max. Its dense
    peaks are what the limits would have to be; the plan itself is the witness."""
    model = _Model(prob, _grid(), a_lim, v_lim)
    found = sorted(
        (w for z0 in seeds if (w := _relax_from(model, z0, prob)) is not None), key=lambda w: w[-1]
    )
    return next((plan for w in found[:CANDIDATES] if (plan := _to_plan(prob, w[:-1]))), None)


def _relax_from(model: _Model, z0: FloatArray, prob: Problem) -> FloatArray | None:
    from scipy.optimize import minimize

    n, g = prob.order, len(model.u)
    on_limits = np.zeros(len(model.constraints(z0)))
    on_limits[: 3 * g] = 1.0  # the v_max and both a_max rows come first
    lam0 = 1.0 + max(0.0, -float(model.constraints(z0)[: 3 * g].min()))
    eq = {
        "type": "eq",
        "fun": lambda w: np.array([w[:n].sum() - prob.m_sum]),
        "jac": lambda w: np.append(np.ones(n), [0.0, 0.0])[None, :],
    }
    ineq = {
        "type": "ineq",
        "fun": lambda w: model.constraints(w[:-1]) + (w[-1] - 1.0) * on_limits,
        "jac": lambda w: np.hstack([model.jacobian(w[:-1]), on_limits[:, None]]),
    }
    res = minimize(
        lambda w: w[-1],
        np.append(z0, lam0),
        jac=lambda w: np.append(np.zeros(n + 1), 1.0),
        method="SLSQP",
        bounds=[(None, None)] * n + [(1e-3, 60.0), (1.0, None)],
        constraints=[eq, ineq],
        options={"maxiter": 300, "ftol": 1e-12},
    )
    return res.x if res.success else None


def _lowest_order_that_plans(
    prob: Problem, a_lim: float, v_lim: float, seed: int, starts: int
) -> tuple[int, float] | None:
    """(order, duration [s]) of the lowest order above prob's that meets every limit."""
    for order in range(prob.order + 1, MAX_ORDER + 1):
        higher = Problem(prob.x0, prob.v0, prob.tau_s, prob.limits, order)
        plan = _search(
            higher,
            _Model(higher, _grid(), a_lim, v_lim),
            _seeds(higher, a_lim, v_lim, starts, seed),
        )
        if plan is not None:
            return order, plan.duration
    return None
