"""The vehicle's response along the approach, identified from the hold and the approach.

Every vehicle answers an acceleration command late: the command's trip over the link, the
autopilot's attitude loop (a firmware shapes its attitude input with a time constant of
0.1-0.25 s) and the motors. It also loses speed to drag. Neither is in the plan, and both
make a perch late and slow (docs/errata.md §10). Along the perching normal X the flight is
modelled as

    Xddot(t) = a(t - delay) - drag * Xdot(t) + bias,    T da/dt = u - a

u [m/s^2] the acceleration the setpoint commanded (after the saturations), a the
acceleration the vehicle reaches, a delay [s] (the link, the shaping) and a first-order lag
T [s] (an attitude loop) behind it; drag [1/s] linear and qdrag [1/m] quadratic drag per
unit mass (the drag at speed v is drag v + qdrag v |v|), bias [m/s^2] a constant push (a
trim error, a draught). The gain is 1: the hold has calibrated the thrust
(flight/hover.py). The lead flown is lag = delay + T. Fitted to the positions, T is by
none (one pure delay for the whole chain, TIME_CONSTANT_MAX_S); fitted
to the attitude (below) it is always tried. Fitted to a first-order response,
a pure delay finds about delay + T but pays for its sharper answer in drag and bias (0.353
/s and +0.016 m/s^2 for 0.3 and 0 behind 0.1 + 0.2 s, tests/flight/test_lagid.py); the
first-order fit finds all four. Flown, it perched the Crazyflie firmware closest to the
held speed, the autopilots fast (docs/firmware.md, "Positions, not speeds").

Integrated twice from a reference tick s, the model is linear in drag, bias and the speed at
s for a given delay and T:

    X(t) - X(s) - W(t - delay) + W(s - delay) + A(s - delay)(t - s)
        = -drag * int_s^t (X - X(s)) + bias (t - s)^2 / 2 + Xdot(s) (t - s)

with A the running integral of a and W that of A. Positions, not speeds: the mocap measures
X to a millimetre and independently frame to frame, while the estimator's Xdot carries that
noise differentiated and correlated over tens of ticks, which moved the lag found by
+-0.02 s between flights of one plant. (delay, T) are those, on a grid, with the smallest
residual (the delay refined between grid points, T not); drag, bias and Xdot(s) are their
least-squares solution. The fit refuses (and the
flight falls back to the configured lead, no drag term) when the approach moved too little,
the best delay sits on the grid's edge, the drag is out of bounds or the speed it predicts
strays from the speed measured.

Where the mocap measures the attitude, delay and T come from it instead (lean_response):
the X component of the body z axis, the lean, that the setpoints sent against the one
measured. The attitude is measured directly to a fraction of a degree, where the positions
carry it only integrated twice beside drag and bias, so one vehicle's lag comes out within
a few ms from flight to flight (the positions' fit scattered by 0.06 s on the autopilots);
drag and bias are then fitted to the positions at that delay and T (docs/errata.md §10).
A lean that swept too little, fits poorly or swings by another size than the one sent (a
rigid body whose axes are not the vehicle's), or a model refused at its lag, leaves the
positions' fit to serve.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import lfilter

from perchd.core.vehicle import G_M_S2
from perchd.flight.config import LagIdGains

WINDOW_S = 8.0
"""[s] the last this many seconds of the hold and the approach are fitted."""
LAG_MAX_S = 0.5
"""[s] the longest lag (delay + T) tried; a best lag at this bound is refused (the vehicle
is slower than any tried)."""
LAG_STEP_S = 0.02
"""[s] the positions' fit's delay grid (refined between points)."""
TIME_CONSTANT_MAX_S = 0.0
"""[s] the first-order lags the positions' fit tries behind its delay: none (one pure
delay; the attitude's fit tells T from the delay, the positions' cannot)."""
DRAG_MAX_PER_S = 2.0
"""[1/s] an identified linear drag above this is refused."""
SPEED_SPAN_MIN_MPS = 0.5
"""[m/s] the fitted ticks must cover this speed range (the approach's)."""
RMS_MAX_MPS = 0.1
"""[m/s] a fit whose predicted speed strays further from the measured one is refused."""
FREE: tuple[None, None] = (None, None)
"""Both drags fitted (neither held)."""
QUADRATIC_DRAG = True
"""Fit the quadratic drag beside the linear one (benchmarks/ablation.py turns it off to
measure what it earns)."""
QDRAG_MAX_PER_M = 1.0
"""[1/m] the largest quadratic drag a fit accepts (the family's plants: up to 0.4)."""
FIT_POINTS = 200
"""Ticks the regression samples at most (evenly spread over the window)."""
LEAN_COARSE_S = (0.02, 0.04)
"""[s] the attitude fit's first grid: its delay step and its time-constant step."""
LEAN_FINE_S = (0.005, 0.01)
"""[s] its second grid, four steps each way about the first grid's best (then refined
between points)."""
LEAN_POINTS = (60, 100)
"""Measured leans each grid samples at most (evenly spread over the window)."""
LEAN_TC_MAX_S = 0.4
"""[s] the largest time constant the attitude's fit tries."""
LEAN_SPAN_MIN = 0.03
"""The lean the setpoints must have swept (about 1.7 deg of tilt) for its fit."""
LEAN_RMS_MAX = 0.25
"""The attitude's fit is refused when its residual exceeds this share of the lean's sweep."""
LEAN_GAIN = (0.8, 1.25)
"""The measured lean's swing over the predicted one's that the attitude's fit accepts (the
firmwares: 1.04-1.07); outside, the mocap's axes are not the vehicle's. Inside, a swing
seen small lengthens the lag found (0.9: by about 0.04 s; a rigid body yawed 10 deg off
the vehicle's axes sees 0.985)."""


@dataclass(frozen=True, slots=True)
class LagModel:
    """lag_s [s] the delay plus the time constant: the lead flown; drag_per_s [1/s];
    bias_mps2 [m/s^2]; rms_mps [m/s] how far the speed predicted strays from the speed
    measured; samples: ticks fitted; speed_span_mps [m/s] the speed range they covered;
    time_constant_s [s] T, the part of the lag that is a first-order lag; from_attitude:
    delay and T were fitted to the attitude the mocap measured (LagIdentifier.lean_response),
    not to the positions; drag_from_attitude: the drag to the acceleration that attitude
    makes (LagIdentifier.lean_drag), not to the commands'; qdrag_per_m [1/m] the quadratic
    drag (the push is bias - drag Xdot - qdrag Xdot |Xdot|)."""

    lag_s: float
    drag_per_s: float
    bias_mps2: float
    rms_mps: float
    samples: int
    speed_span_mps: float
    time_constant_s: float = 0.0
    from_attitude: bool = False
    drag_from_attitude: bool = False
    qdrag_per_m: float = 0.0

    def drag_at(self, xdot: float) -> float:
        """[m/s^2] the drag at the speed xdot [m/s]."""
        return self.drag_per_s * xdot + self.qdrag_per_m * xdot * abs(xdot)

    @property
    def delay_s(self) -> float:
        """[s] the pure delay in front of the first-order lag."""
        return self.lag_s - self.time_constant_s


@dataclass(frozen=True, slots=True)
class LagFit:
    """model: the identified response, None when refused; why: the refusal, in words."""

    model: LagModel | None
    why: str = ""


class LagIdentifier:
    """Collects (t, u, X, Xdot) once per tick; `fit` identifies the response from them."""

    def __init__(self, cfg: LagIdGains) -> None:
        self.cfg = cfg
        self._rows: deque[tuple[float, float, float, float]] = deque()
        self._lean: deque[tuple[float, float, float, float]] = deque()

    def record(self, t: float, u_x: float, x: float, xdot: float) -> None:
        """One tick: t [s], u_x [m/s^2] commanded at t, x [m] and xdot [m/s] measured at t."""
        self._rows.append((t, u_x, x, xdot))
        _keep_window(self._rows, t - WINDOW_S)

    def record_lean(self, t: float, sent: float, t_measured: float, measured: float) -> None:
        """One tick's lean (the body z axis's X component): the setpoint's, sent at t [s],
        and the mocap's, measured at t_measured [s]. A non-finite one is not kept."""
        if not all(map(math.isfinite, (t, sent, t_measured, measured))):
            return
        self._lean.append((t, sent, t_measured, measured))
        _keep_window(self._lean, t - WINDOW_S)

    def lean_response(self) -> tuple[float, float] | None:
        """(delay [s], T [s]) of the attitude's answer to the setpoints' lean, fitted to
        the lean the mocap measured, on a coarse grid and then a fine one about its best (a
        few ms in all); None when the lean swept too little, the best sits on a bound, the lag
        (delay + T) reaches lag_max_s, or the fit is poor: a residual above LEAN_RMS_MAX of
        the sweep or the measured lean not the sent one's size (LEAN_GAIN: a rigid body
        whose axes are not the vehicle's)."""
        if len(self._lean) < 20:
            return None
        data = tuple(np.array(col) for col in zip(*self._lean))
        sweep = float(np.ptp(data[1]))  # of the lean sent
        if sweep < LEAN_SPAN_MIN:
            return None
        bounds = (LAG_MAX_S, LEAN_TC_MAX_S)
        axes = [np.arange(0.0, top + 1e-9, step) for top, step in zip(bounds, LEAN_COARSE_S)]
        mse, gain, j, i = _lean_best(data, axes, LEAN_POINTS[0])
        if i == len(axes[0]) - 1 or j == len(axes[1]) - 1 or not np.isfinite(mse[j, i]):
            return None
        # One fine grid about the coarse best: its residual's valley runs along delay + T
        # (the two trade), and the coarse best keeps the fit where the hold's and the
        # approach's swings put it from flight to flight (docs/firmware.md).
        axes = [
            np.unique(np.clip(ax[k] + np.arange(-4, 5) * step, 0.0, top))
            for ax, k, step, top in zip(axes, (i, j), LEAN_FINE_S, bounds)
        ]
        mse, gain, j, i = _lean_best(data, axes, LEAN_POINTS[1])
        if (
            not np.sqrt(mse[j, i]) <= LEAN_RMS_MAX * sweep
            or not LEAN_GAIN[0] <= gain[j, i] <= LEAN_GAIN[1]
        ):
            return None
        delay, tc = _refine(axes[0], mse[j], i), max(_refine(axes[1], mse[:, i], j), 0.0)
        return (delay, tc) if delay + tc < bounds[0] else None

    def fit(self) -> LagFit:
        c = self.cfg
        if len(self._rows) < 20:
            return LagFit(None, f"{len(self._rows)} ticks recorded, too few to fit")
        t, u, x, v = (np.array(col) for col in zip(*self._rows))
        span = float(v.max() - v.min())
        if span < SPEED_SPAN_MIN_MPS:
            return LagFit(
                None,
                f"the approach changed speed by {span:.2f} m/s, less than "
                f"the {SPEED_SPAN_MIN_MPS:g} m/s needed to fit the lag",
            )
        lean = self.lean_response() if c.from_attitude else None
        if lean is not None:
            drag = self.lean_drag(t, x, v)
            m = replace(
                _model_at(t, u, x, v, *lean, span, drag or FREE),
                from_attitude=True,
                drag_from_attitude=drag is not None,
            )
            fit = _checked(m)
            if fit.model is not None:
                return fit  # refused at the attitude's lag: the positions' own may serve
        delays = np.arange(0.0, LAG_MAX_S + 1e-9, LAG_STEP_S)
        taus = np.arange(0.0, TIME_CONSTANT_MAX_S + 1e-9, LAG_STEP_S)
        # The delay is chosen on one linear drag: a free quadratic one trades with it.
        mse = _solve(t, _first_order(t, u, taus), x, v, delays, (None, 0.0))[0]
        j, i = np.unravel_index(int(np.argmin(mse)), mse.shape)
        if i == len(delays) - 1:
            return LagFit(None, f"the best lag is at the bound {LAG_MAX_S:g} s or beyond")
        delay = _refine(delays, mse[j], int(i))
        return _checked(_model_at(t, u, x, v, delay, float(taus[j]), span))

    def lean_drag(self, t: np.ndarray, x: np.ndarray, v: np.ndarray) -> tuple[float, float] | None:
        """(drag [1/s], qdrag [1/m]) fitted to the positions x [m] (speeds v [m/s]) at the
        ticks t [s] against the acceleration the lean the mocap measured makes (g tan of
        it, the height held), a constant push beside it; None without leans or outside
        the bounds (_drags). An
        autopilot flies its own attitude estimate, and PX4 SIH's leaned further than sent
        the faster it flew: fitted to the commands, that reads as less drag (0.88-0.98 /s
        where SIH's is 1.0) and stage 2, slower than stage 1, meets less push than stage
        1's refit carries into it (docs/firmware.md, "The drag the attitude makes")."""
        if len(self._lean) < 20:
            return None
        tm, lean = (np.array(col) for col in list(zip(*self._lean))[2:])
        # Each tick's acceleration is held to the next (_integrals): the lean at the
        # interval's midpoint (5 ms off moved the drag found by 5 %).
        mid = np.append(0.5 * (t[1:] + t[:-1]), t[-1])
        s = np.clip(np.interp(mid, tm, lean), -0.9, 0.9)
        a = G_M_S2 * s / np.sqrt(1.0 - s * s)
        sol = _fixed_drags(t, a[None, :], x, v, np.zeros(1), FREE)
        drag, qdrag = float(sol[0]), float(sol[1])
        ok = 0.0 <= drag <= DRAG_MAX_PER_S and 0.0 <= qdrag <= QDRAG_MAX_PER_M
        return (drag, qdrag) if ok else None


def _keep_window(rows: deque, since_t: float) -> None:
    """Drop the rows (time first) older than since_t [s]."""
    while rows and rows[0][0] < since_t:
        rows.popleft()


def _model_at(
    t,
    u,
    x,
    v,
    delay_s: float,
    tc_s: float,
    span: float,
    drag: tuple[float | None, float | None] = (None, None),
) -> LagModel:
    """Drag, quadratic drag (each unless given) and bias at delay_s [s] and time constant
    tc_s [s]; rms_mps is how far the speed they predict from the fitted Xdot(s) strays from
    the speed measured (_drags has the signs' rule)."""
    a, delay = _first_order(t, u, np.array([tc_s])), np.array([delay_s])
    sol = _fixed_drags(t, a, x, v, delay, drag)
    m = LagModel(
        delay_s + tc_s,
        float(sol[0]),
        float(sol[2]),
        0.0,
        len(t),
        span,
        tc_s,
        qdrag_per_m=float(sol[1]),
    )
    err = _speed_errors(t, u, x, v, m, float(sol[3]))
    return replace(m, rms_mps=float(np.sqrt(np.mean(err * err))))


Drags = tuple[float | None, float | None]
"""(linear [1/s], quadratic [1/m]) drag: a number is held, None is fitted."""


def _fixed_drags(
    t: np.ndarray,
    a: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    lags: np.ndarray,
    drag: Drags,
) -> np.ndarray:
    """(drag, qdrag, bias, Xdot(s), offset) of the fit at the first input and lag. The two
    drags trade over an approach's speeds, so a negative one is noise about none, or the
    other's trade: a negative quadratic drag is solved again as none; then a negative linear
    one beside a positive quadratic one, or slightly negative alone (down to a tenth of
    DRAG_MAX_PER_S; below, _checked refuses it), is solved again as none. Clipping one alone
    would keep the others fitted beside it, off by the clipped term's push."""
    if not QUADRATIC_DRAG and drag[1] is None:
        drag = (drag[0], 0.0)
    sol = _solve(t, a, x, v, lags, drag)[1][0, :, 0]
    if drag[1] is None and sol[1] < 0.0:
        drag = (drag[0], 0.0)
        sol = _solve(t, a, x, v, lags, drag)[1][0, :, 0]
    if drag[0] is None and sol[0] < 0.0 and (sol[1] > 0.0 or sol[0] >= -0.1 * DRAG_MAX_PER_S):
        drag = (0.0, drag[1])
        sol = _solve(t, a, x, v, lags, drag)[1][0, :, 0]
        if drag[1] is None and sol[1] < 0.0:
            sol = _solve(t, a, x, v, lags, (0.0, 0.0))[1][0, :, 0]
    return sol


def _checked(m: LagModel) -> LagFit:
    """The fit, refused when its drag is out of bounds or its residual large."""
    if not 0.0 <= m.drag_per_s <= DRAG_MAX_PER_S:
        return LagFit(
            None, f"identified drag {m.drag_per_s:.3f} 1/s outside 0..{DRAG_MAX_PER_S:g} 1/s"
        )
    if not 0.0 <= m.qdrag_per_m <= QDRAG_MAX_PER_M:
        return LagFit(
            None,
            f"identified quadratic drag {m.qdrag_per_m:.3f} 1/m outside 0..{QDRAG_MAX_PER_M:g} 1/m",
        )
    if m.rms_mps > RMS_MAX_MPS:
        return LagFit(None, f"the fit's residual {m.rms_mps:.3f} m/s exceeds {RMS_MAX_MPS:g} m/s")
    return LagFit(m)


def _speed_errors(t, u, x, v, m: LagModel, v_0: float) -> np.ndarray:
    """[m/s] the speed measured at each tick, less the speed m predicts from v_0 [m/s] at
    the first."""
    a = _first_order(t, u, np.array([m.time_constant_s]))
    big_a = _delayed(t, _integrals(t, a)[0], t[None, :] - m.delay_s, a, 1)[0, 0]
    q1 = _quadratic_integrals(t, v)[0]
    return (
        (v - v_0)
        - (big_a - big_a[0])
        + m.drag_per_s * (x - x[0])
        + m.qdrag_per_m * (q1 - q1[0])
        - m.bias_mps2 * (t - t[0])
    )


def _quadratic_integrals(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Q1, Q2) at the ticks: the integral from t[0] of Xdot |Xdot| (trapezoids), and of Q1:
    what the quadratic drag takes from the speed and from the position."""
    dt = np.diff(t)
    vq = v * np.abs(v)
    q1 = np.concatenate(([0.0], np.cumsum(0.5 * (vq[1:] + vq[:-1]) * dt)))
    q2 = np.concatenate(([0.0], np.cumsum(0.5 * (q1[1:] + q1[:-1]) * dt)))
    return q1, q2


def _first_order(
    t: np.ndarray, u: np.ndarray, tc_s: np.ndarray, dt: float | None = None
) -> np.ndarray:
    """The commands u through first-order lags of time constants tc_s [s] (one row each):
    each tick's mean over the interval to the next (the command held across it), settled
    on the first command before t[0] (the hold's commands are steady); the ticks taken as
    evenly spaced at dt [s], by default their median interval (the loop's jitter is a few
    percent of it)."""
    if dt is None:
        dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    rows = []
    for tc in tc_s:
        if tc <= 0.0 or dt <= 0.0:
            rows.append(u)
            continue
        keep = float(np.exp(-dt / tc))
        end = lfilter([1.0 - keep], [1.0, -keep], u, zi=[keep * u[0]])[0]
        start = np.concatenate(([u[0]], end[:-1]))
        rows.append(u + (start - u) * tc / dt * (1.0 - keep))
    return np.array(rows)


def _integrals(t: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A, W) at the ticks for each row of a (inputs, ticks): A the integral of the
    zero-order-held acceleration from t[0], W the integral of A (exact at the ticks)."""
    dt = np.diff(t)
    zero = np.zeros((len(a), 1))
    big_a = np.cumsum(np.concatenate((zero, a[:, :-1] * dt), axis=1), axis=1)
    big_w = np.cumsum(
        np.concatenate((zero, (big_a[:, :-1] + 0.5 * a[:, :-1] * dt) * dt), axis=1), axis=1
    )
    return big_a, big_w


def _delayed(
    t: np.ndarray, big: np.ndarray, times: np.ndarray, a: np.ndarray, order: int
) -> np.ndarray:
    """big (inputs, ticks), the order-th integral of a (1: A, 2: W), at times (lags,
    points), shaped (inputs, lags, points): linear between ticks (W's error there is
    a dt^2 / 8, micrometres) and, before t[0], what a held at its first value adds. The
    weights depend on the times alone, so every input shares them."""
    q = np.clip(times, t[0], t[-1])
    i = np.clip(np.searchsorted(t, q, side="right") - 1, 0, len(t) - 2)
    w = (q - t[i]) / (t[i + 1] - t[i])
    held = np.minimum(times - t[0], 0.0) ** order / order * a[:, :1, None]
    return big[:, i] * (1.0 - w) + big[:, i + 1] * w + held


def _solve(
    t,
    a,
    x,
    v,
    lags: np.ndarray,
    drag: tuple[float | None, float | None] = (None, None),
) -> tuple[np.ndarray, np.ndarray]:
    """For each row of a (inputs, ticks) and each lag (its delay): the mean squared
    residual [m^2], shaped (inputs, lags), and the least-squares (drag, qdrag, bias,
    Xdot(s), offset), shaped (inputs, 5, lags), integrated from the first tick (a drag
    given in `drag` = (linear [1/s], quadratic [1/m]) is held). The regressors depend on
    neither, so one pseudo-inverse serves all; the integrals take every tick, the regression
    at most FIT_POINTS of them (a fit stays a few ms)."""
    at = np.unique(np.linspace(0, len(t) - 1, min(len(t), FIT_POINTS)).astype(int))
    big_a, big_w = _integrals(t, a)
    times = t[at][None, :] - lags[:, None]
    w, a_s = _delayed(t, big_w, times, a, 2), _delayed(t, big_a, times[:, :1], a, 1)
    s = t[at] - t[0]  # at[0] is the first tick
    x_s = x[0]
    area = np.concatenate(([0.0], np.cumsum(0.5 * (x[1:] + x[:-1] - 2.0 * x_s) * np.diff(t))))[at]
    quad = _quadratic_integrals(t, v)[1][at]  # it starts at 0, as does area
    y = (x[at] - x_s) - (w - w[..., :1] - a_s * s)
    # The speed column takes Xdot(s); the ones column the noise of X(s) itself.
    cols = np.column_stack((-area, -quad, 0.5 * s * s, s, np.ones_like(s)))
    free = [k for k in (0, 1) if drag[k] is None] + [2, 3, 4]
    for k, held in ((0, area), (1, quad)):
        if drag[k] is not None:
            y = y + drag[k] * held
    q, r = np.linalg.qr(cols[:, free])
    proj = y @ q  # the residual is what the columns' span leaves of y
    mse = (np.einsum("...p,...p->...", y, y) - np.einsum("...k,...k->...", proj, proj)) / len(s)
    try:
        fitted = np.linalg.solve(r, np.moveaxis(proj, -1, -2))
    except np.linalg.LinAlgError:  # columns that are not independent (a speed held constant)
        fitted = np.linalg.pinv(r) @ np.moveaxis(proj, -1, -2)
    sol = np.zeros(fitted.shape[:1] + (5,) + fitted.shape[2:])
    sol[:, free] = fitted
    for k in (0, 1):
        if drag[k] is not None:
            sol[:, k] = drag[k]
    return np.maximum(mse, 0.0), sol


def _lean_best(data, axes: list[np.ndarray], points: int):
    """(mse, gain, j, i) of the attitude's fit on the grid axes = (delays, taus): the
    residuals and gains (_lean_mse) and the best's indices, T first."""
    mse, gain = _lean_mse(*data, axes[0], axes[1], points)
    j, i = np.unravel_index(int(np.argmin(mse)), mse.shape)
    return mse, gain, int(j), int(i)


def _lean_mse(
    t, sent, tm, lean, delays: np.ndarray, taus: np.ndarray, points: int
) -> tuple[np.ndarray, np.ndarray]:
    """Mean squared residual, shaped (taus, delays), of the lean measured at tm against the
    lean sent at t through each first-order lag and delay, a constant offset (the markers'
    trim) removed; and the gain by which the measured lean's swing
    regresses on the predicted one's (about 1 for a rigid body aligned with the vehicle).
    The filtered lean is each tick's interval mean, read at the intervals' midpoints."""
    f = _first_order(t, sent, taus)
    mid = np.append(0.5 * (t[1:] + t[:-1]), t[-1])
    keep = tm - delays[-1] >= mid[0]
    if keep.sum() < 20 or len(mid) < 3 or np.any(np.diff(mid) <= 0.0):
        return np.full((len(taus), len(delays)), np.inf), np.zeros((len(taus), len(delays)))
    at = np.unique(np.linspace(0, keep.sum() - 1, min(int(keep.sum()), points)).astype(int))
    tm, lean = tm[keep][at], lean[keep][at]
    q = tm[None, :] - delays[:, None]
    i = np.clip(np.searchsorted(mid, q, side="right") - 1, 0, len(mid) - 2)
    w = np.clip((q - mid[i]) / (mid[i + 1] - mid[i]), 0.0, 1.0)
    pred = f[:, i] * (1.0 - w) + f[:, i + 1] * w  # (taus, delays, points)
    pred = pred - pred.mean(axis=-1, keepdims=True)
    seen = lean - lean.mean()
    swing = np.einsum("...p,...p->...", pred, pred)
    gain = np.einsum("...p,p->...", pred, seen) / np.maximum(swing, 1e-12)
    # The residual at gain 1: an attitude loop holds the lean it is sent, and how much a
    # fast swing shrinks is what tells T from the delay (a free gain lets them trade).
    return ((seen - pred) ** 2).mean(axis=-1), gain


def _refine(lags: np.ndarray, mse: np.ndarray, i: int) -> float:
    """The parabola's vertex through the grid minimum and its neighbours (the minimum
    itself at the grid's ends)."""
    if i == 0 or i == len(lags) - 1:
        return float(lags[i])
    y0, y1, y2 = mse[i - 1], mse[i], mse[i + 1]
    den = y0 - 2.0 * y1 + y2
    step = float(lags[1] - lags[0])
    shift = 0.5 * (y0 - y2) / den if den > 0 else 0.0
    return float(lags[i] + max(-1.0, min(1.0, shift)) * step)
