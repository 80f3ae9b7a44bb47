"""Independent re-derivation of a plan: integrate dX/dt = X / tau_ref(t) numerically.

Shares nothing with perchd.tau's closed forms but the tau reference itself."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp


def fly_tau(tau_ref, x0: float, t_end: float, n: int = 4001):
    """(t, X, V, A) from integrating the tau reference; V = X / tau, A by differentiation."""
    t = np.linspace(0.0, t_end, n)
    sol = solve_ivp(
        lambda s, x: x / tau_ref(s),
        (0.0, t_end),
        [x0],
        t_eval=t,
        rtol=1e-11,
        atol=1e-13,
        method="DOP853",
    )
    x = sol.y[0]
    v = x / np.array([tau_ref(s) for s in t])
    a = np.gradient(v, t)
    return t, x, v, a


def ipts_tau(k):
    return lambda s: 1.0 / np.polyval(list(reversed(k)), s)
