"""The vehicle's response along the approach, identified from the hold and the approach.

Every vehicle answers an acceleration command late: the command's trip over the link, the
autopilot's attitude loop (a firmware shapes its attitude input with a time constant of
0.1-0.25 s) and the motors. It also loses speed to drag. Neither is in the plan, and both
make a perch late and slow (docs/errata.md §10). Along the perching normal X the flight is
modelled as

    Xddot(t) = u(t - lag) - drag * Xdot(t) + bias

u [m/s^2] the acceleration the setpoint commanded (after the saturations), lag [s] one
delay standing for the whole chain, drag [1/s] linear drag per unit mass, bias [m/s^2] a
constant push (a trim error, a draught). The gain is 1: the hold has calibrated the thrust
(flight/hover.py). Integrated from a reference tick s, it is linear in drag and bias for a
given lag:

    Xdot(t) - Xdot(s) - [U(t - lag) - U(s - lag)] = -drag * (X(t) - X(s)) + bias * (t - s)

with U the running integral of u. Integrals, not derivatives: millimetre mocap noise
differentiated twice would swamp the fit. The lag is the one, on a grid, with the smallest
residual; drag and bias are its least-squares solution. The fit refuses (and the flight
falls back to the configured lead, no drag term) when the approach moved too little, the
best lag sits on the grid's edge, the drag is out of bounds or the residual is large.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from perchd.flight.config import LagIdGains

FIT_POINTS = 200
"""Ticks the regression samples at most (evenly spread over the window)."""
HOLDOUT = 0.4
"""The share of a refit's ticks, the last, that its candidate is not fitted to but judged on."""


@dataclass(frozen=True, slots=True)
class LagModel:
    """lag_s [s]; drag_per_s [1/s]; bias_mps2 [m/s^2]; rms_mps [m/s] residual of the fit;
    samples: ticks fitted; speed_span_mps [m/s] the speed range they covered."""

    lag_s: float
    drag_per_s: float
    bias_mps2: float
    rms_mps: float
    samples: int
    speed_span_mps: float


@dataclass(frozen=True, slots=True)
class LagFit:
    """model: the identified response, None when refused; why: the refusal, in words."""

    model: LagModel | None
    why: str = ""


class Response(Protocol):
    """What a prediction needs of the response: lag_s [s], drag_per_s [1/s], bias_mps2
    [m/s^2] (a LagModel, or the feed-forward built from one)."""

    lag_s: float
    drag_per_s: float
    bias_mps2: float


class LagIdentifier:
    """Collects (t, u, X, Xdot) once per tick; `fit` identifies the response from them."""

    def __init__(self, cfg: LagIdGains) -> None:
        self.cfg = cfg
        self._rows: deque[tuple[float, float, float, float]] = deque()

    def record(self, t: float, u_x: float, x: float, xdot: float) -> None:
        """One tick: t [s], u_x [m/s^2] commanded at t, x [m] and xdot [m/s] measured at t."""
        self._rows.append((t, u_x, x, xdot))
        while self._rows and self._rows[0][0] < t - self.cfg.window_s:
            self._rows.popleft()

    def fit(self) -> LagFit:
        c = self.cfg
        if len(self._rows) < 20:
            return LagFit(None, f"{len(self._rows)} ticks recorded, too few to fit")
        t, u, x, v = (np.array(col) for col in zip(*self._rows))
        span = float(v.max() - v.min())
        if span < c.speed_span_min_mps:
            return LagFit(None, f"the approach changed speed by {span:.2f} m/s, less than "
                                f"the {c.speed_span_min_mps:g} m/s needed to fit the lag")
        lags = np.arange(0.0, c.lag_max_s + 1e-9, c.lag_step_s)
        sse, _ = _solve(t, u, x, v, lags)
        i = int(np.argmin(sse))
        if i == len(lags) - 1:
            return LagFit(None, f"the best lag is at the bound {c.lag_max_s:g} s or beyond")
        lag = _refine(lags, sse, i)
        return _checked(_model_at(t, u, x, v, lag, span, c), c)

    def refit_bias(self, base: Response, since_t: float) -> LagFit:
        """The bias again, base's lag and drag kept, from the ticks since since_t [s]: what
        the perch's stage 1 shows beyond the approach's model is a push stage 2 meets too
        (docs/errata.md §10). Drag and bias together are not told apart over stage 1's
        narrow speed range (the approach's 0-to-v0 tells the drag). Flown only if it
        predicts better: fitted to all but the last HOLDOUT of the ticks, it must predict
        the speed over those, the nearest to stage 2, closer than base does (a drag that
        grows with speed shows in stage 1's faster part as a push stage 2 does not meet).
        Refused otherwise, on too few ticks, or on a large residual."""
        t, u, x, v = (np.array(col) for col in zip(*self._rows)) if self._rows else ([],) * 4
        first = int(np.searchsorted(t, since_t))
        n = len(t) - first
        if n < 40:
            return LagFit(None, f"{n} ticks since {since_t:.3f} s, too few to fit")
        # The ticks before since_t stay in: the commands still in flight at since_t.
        lag, drag, k = np.array([base.lag_s]), base.drag_per_s, first + int(n * (1 - HOLDOUT))
        trained = float(_solve(t[:k], u[:k], x[:k], v[:k], lag, drag, first)[1][1, 0])
        new, old = (_holdout_rms(t, u, x, v, base, b, k) for b in (trained, base.bias_mps2))
        if new >= old:
            return LagFit(None, f"the approach's model predicts the last {HOLDOUT:.0%} of "
                                f"the ticks as well or better ({old:.3f} m/s rms, the "
                                f"refit {new:.3f})")
        mse, sol = _solve(t, u, x, v, lag, drag, first)
        return _checked(LagModel(base.lag_s, drag, float(sol[1, 0]), float(np.sqrt(mse[0])),
                                 n, float(v[first:].max() - v[first:].min())), self.cfg)

    def predict(self, t: float, x: float, xdot: float, model: Response,
                horizon_s: float) -> tuple[float, float]:
        """(X [m], Xdot [m/s]) horizon_s (<= the lag) after t, from the state measured at t
        and the commands recorded that the vehicle answers within the horizon: those sent
        between lag and lag - horizon_s ago (a Smith predictor)."""
        lag = model.lag_s
        dv = dx = 0.0
        rows = self._rows
        for i in range(len(rows) - 1, -1, -1):
            t_k, u_k = rows[i][0], rows[i][1]
            if t_k < t - lag:
                break
            if t_k >= t - lag + horizon_s:
                continue
            held = min(rows[i + 1][0] if i + 1 < len(rows) else t, t - lag + horizon_s) - t_k
            dv += u_k * held
            dx += u_k * held * (t + horizon_s - (t_k + lag + 0.5 * held))
        push = model.bias_mps2 - model.drag_per_s * xdot
        return (x + xdot * horizon_s + dx + 0.5 * push * horizon_s ** 2,
                xdot + dv + push * horizon_s)


def _model_at(t, u, x, v, lag_s: float, span: float, c: LagIdGains) -> LagModel:
    """Drag and bias at lag_s [s]. A slightly negative drag (noise about none; down to a
    tenth of drag_max_per_s, below is refused) is solved again as none: clipping it alone
    would keep the bias fitted beside it, and the push the two predict together
    (bias - drag Xdot) would be off by the clipped drag times the speed."""
    lag = np.array([lag_s])
    mse, sol = _solve(t, u, x, v, lag)
    if -0.1 * c.drag_max_per_s <= sol[0, 0] < 0.0:
        mse, sol = _solve(t, u, x, v, lag, drag=0.0)
    return LagModel(lag_s, float(sol[0, 0]), float(sol[1, 0]), float(np.sqrt(mse[0])),
                    len(t), span)


def _checked(m: LagModel, c: LagIdGains) -> LagFit:
    """The fit, refused when its drag is out of bounds or its residual large."""
    if not 0.0 <= m.drag_per_s <= c.drag_max_per_s:
        return LagFit(None, f"identified drag {m.drag_per_s:.3f} 1/s outside "
                            f"0..{c.drag_max_per_s:g} 1/s")
    if m.rms_mps > c.rms_max_mps:
        return LagFit(None, f"the fit's residual {m.rms_mps:.3f} m/s exceeds "
                            f"{c.rms_max_mps:g} m/s")
    return LagFit(m)


def _holdout_rms(t, u, x, v, m: Response, bias: float, k: int) -> float:
    """[m/s] rms error of the speed predicted from tick k on by m's lag and drag with
    `bias`, against the speed measured."""
    big_u = _shifted_integrals(t, u, np.array([m.lag_s]), np.arange(k, len(t)))[0]
    dv = (v[k:] - v[k]) - (big_u - big_u[0]) + m.drag_per_s * (x[k:] - x[k]) \
        - bias * (t[k:] - t[k])
    return float(np.sqrt(np.mean(dv * dv)))


def _shifted_integrals(t: np.ndarray, u: np.ndarray, lags: np.ndarray,
                       at: np.ndarray) -> np.ndarray:
    """U(t[at] - lag) for each lag (rows): the integral of the zero-order-held command from
    t[0], delayed by lag (held at its first value before t[0]: the hold's commands are
    steady)."""
    big_u = np.concatenate(([0.0], np.cumsum(u[:-1] * np.diff(t))))
    shifted = t[at][None, :] - lags[:, None]
    before = np.minimum(shifted - t[0], 0.0) * u[0]
    return np.interp(shifted.ravel(), t, big_u).reshape(shifted.shape) + before


def _solve(t, u, x, v, lags: np.ndarray, drag: float | None = None, start: int = 0
           ) -> tuple[np.ndarray, np.ndarray]:
    """For each lag: the mean squared residual [m^2/s^2] and the least-squares (drag,
    bias, offset) as columns, integrated from tick `start` (a given drag [1/s] is held;
    the ticks before start only supply the commands in flight). The regressors do not
    depend on the lag, so one pseudo-inverse serves every lag; the integrals take every
    tick, the regression at most FIT_POINTS of them (a refit stays about a millisecond)."""
    n = len(t) - start
    at = np.unique(np.linspace(start, len(t) - 1, min(n, FIT_POINTS)).astype(int))
    big_u = _shifted_integrals(t, u, lags, at)
    t, x, v = t[at], x[at], v[at]
    y = (v - v[0])[:, None] - (big_u - big_u[:, :1]).T
    # The ones column absorbs the noise of the reference tick's own speed.
    a = np.column_stack((-(x - x[0]), t - t[0], np.ones_like(t)))
    if drag is not None:
        y = y + drag * (x - x[0])[:, None]
        a[:, 0] = 0.0
    sol = np.linalg.pinv(a) @ y
    r = y - a @ sol
    if drag is not None:
        sol[0] = drag
    return np.einsum("ij,ij->j", r, r) / len(t), sol


def _refine(lags: np.ndarray, sse: np.ndarray, i: int) -> float:
    """The parabola's vertex through the grid minimum and its neighbours."""
    if i == 0:
        return float(lags[0])
    y0, y1, y2 = sse[i - 1], sse[i], sse[i + 1]
    den = y0 - 2.0 * y1 + y2
    step = float(lags[1] - lags[0])
    shift = 0.5 * (y0 - y2) / den if den > 0 else 0.0
    return float(lags[i] + max(-1.0, min(1.0, shift)) * step)
