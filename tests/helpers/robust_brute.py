"""Independent brute-force check of an IPTS stage 1 from one trigger state.

Shares no code with perchd.tau: tau(t) = 1 / sum k_i t^i is scanned on a fine grid for
the switch, X' = X / tau is integrated with solve_ivp (not the closed form exp(P)), and
the acceleration is the numerical derivative of V = X / tau.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp


@dataclass(frozen=True)
class Flight:
    reaches: bool  # tau reached tau_s with tau finite and negative on the way
    t_s: float  # [s]
    v_peak: float  # [m/s]
    a_peak: float  # [m/s^2] max |acceleration|
    v_contact: float  # [m/s] speed at t_s


def fly(k, x0: float, v0: float, tau_s: float, horizon: float = 30.0) -> Flight:
    coeffs = [v0 / x0, *k]

    def p(t):
        return sum(c * t**i for i, c in enumerate(coeffs))

    t = np.linspace(0.0, horizon, 300_001)
    pt = p(t)
    hit = np.flatnonzero(pt <= 1.0 / tau_s)
    first_zero = np.flatnonzero(pt >= 0.0)
    if not len(hit) or (len(first_zero) and first_zero[0] < hit[0]):
        return Flight(False, np.nan, np.nan, np.nan, np.nan)
    lo, hi = t[hit[0] - 1], t[hit[0]]
    for _ in range(60):  # bisection on the grid bracket
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if p(mid) > 1.0 / tau_s else (lo, mid)
    t_s = hi
    sol = solve_ivp(
        lambda tt, x: p(tt) * x, (0.0, t_s), [x0], dense_output=True, rtol=1e-11, atol=1e-12
    )
    tt = np.linspace(0.0, t_s, 20_001)
    v = sol.sol(tt)[0] * p(tt)
    a = np.gradient(v, tt, edge_order=2)
    return Flight(True, t_s, float(v.max()), float(np.abs(a).max()), float(v[-1]))


def worst_over_box(k, x0_range, v0_range, tau_s, n: int = 9) -> dict:
    """Extremes over an n x n grid of trigger states (edges included)."""
    out = {"reaches": True, "v_peak": 0.0, "a_peak": 0.0, "vc_lo": np.inf, "vc_hi": 0.0}
    for x0 in np.linspace(*x0_range, n):
        for v0 in np.linspace(*v0_range, n):
            f = fly(k, x0, v0, tau_s)
            if not f.reaches:
                out["reaches"] = False
                continue
            out["v_peak"] = max(out["v_peak"], f.v_peak)
            out["a_peak"] = max(out["a_peak"], f.a_peak)
            out["vc_lo"] = min(out["vc_lo"], f.v_contact)
            out["vc_hi"] = max(out["vc_hi"], f.v_contact)
    return out
