"""The lag and drag identification (flight/lagid.py) on data from a known response: a hold,
then an approach at constant commanded acceleration, flown through a delay and linear drag."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from perchd.core.types import Pose
from perchd.flight import lagid
from perchd.flight.config import LagIdGains
from perchd.flight.estimator import Estimator, EstimatorConfig
from perchd.flight.frame import PerchFrame
from perchd.flight.lagid import LagIdentifier, _solve

DT = 0.01


def fly(
    lag_s: float,
    drag: float,
    bias: float = 0.0,
    accel: float = 0.75,
    hold_s: float = 1.0,
    approach_s: float = 2.0,
    noise_m: float = 0.0,
    seed: int = 0,
    cfg: LagIdGains = LagIdGains(),
    estimated: bool = False,
    time_constant_s: float = 0.0,
) -> LagIdentifier:
    """Record a hold and an approach of the model Xddot = u(t - lag) - drag Xdot + bias, the
    command holding position until the approach, then `accel` plus drag at the speed
    reached; X measured with noise_m [m] of noise, Xdot with 10 noise_m / s (about the
    estimator's velocity scatter on millimetre mocap noise). estimated: X and Xdot are instead
    perchd's estimator's, from mocap poses of X with noise_m of noise, as in flight.
    time_constant_s: the delayed command reaches the vehicle through a first-order lag."""
    rng = random.Random(seed)
    ident = LagIdentifier(cfg)
    # over the estimator's 1 mm of noise, a frame off the track is noise, not a glitch to hold
    cfg_est = EstimatorConfig(glitch_speed_mps=math.inf) if noise_m > 0.001 else EstimatorConfig()
    est = Estimator(cfg_est, PerchFrame.from_surface((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    x, v, reached, sent = -4.5, 0.0, -bias, []
    n_hold, n_app = int(hold_s / DT), int((hold_s + approach_s) / DT)
    for k in range(n_app):
        t = k * DT
        u = -bias if k < n_hold else accel + drag * v - bias
        sent.append(u)
        if estimated:
            est.offer(Pose("cf", k + 1, t, (x + rng.gauss(0.0, noise_m), 0.0, 1.0), (0, 0, 0, 1)))
            st = est.state(t)
            ident.record(t, u, st.x, st.xdot)
        else:
            ident.record(t, u, x + rng.gauss(0.0, noise_m), v + rng.gauss(0.0, 10 * noise_m))
        late = k - round(lag_s / DT)
        u_now = sent[late] if late >= 0 else sent[0]
        for _ in range(10):  # 1 ms steps
            reached += (u_now - reached) * min(1.0, DT / 10 / max(time_constant_s, 1e-9))
            a = reached - drag * v + bias
            v += a * DT / 10
            x += v * DT / 10
    return ident


@pytest.mark.parametrize("lag_s, drag", [(0.0, 0.0), (0.08, 0.0), (0.15, 0.22), (0.3, 1.0)])
def test_the_fit_finds_the_delay_and_the_drag_it_was_flown_with(lag_s, drag):
    fit = fly(lag_s, drag).fit()
    assert fit.model is not None, fit.why
    assert fit.model.lag_s == pytest.approx(lag_s, abs=0.012)
    assert fit.model.drag_per_s == pytest.approx(drag, abs=0.02)


@pytest.mark.parametrize("delay_s, time_constant_s", [(0.1, 0.2), (0.05, 0.1), (0.15, 0.05)])
def test_a_first_order_lag_behind_the_delay_is_flown_as_delay_plus_time_constant(
    monkeypatch, delay_s, time_constant_s
):
    """An attitude loop's time constant T behind a delay: after a step the speed ends
    delay + T late. With first-order lags tried (lagid.TIME_CONSTANT_MAX_S), the fit
    finds both, and the drag."""
    monkeypatch.setattr(lagid, "TIME_CONSTANT_MAX_S", 0.3)
    fit = fly(
        delay_s,
        0.3,
        time_constant_s=time_constant_s,
        noise_m=0.001,
        estimated=True,
    ).fit()
    assert fit.model is not None, fit.why
    assert fit.model.lag_s == pytest.approx(delay_s + time_constant_s, abs=0.01)
    assert fit.model.time_constant_s == pytest.approx(time_constant_s, abs=0.03)
    assert fit.model.drag_per_s == pytest.approx(0.3, abs=0.03)


def test_a_pure_delay_fitted_to_a_first_order_response_pays_in_drag():
    """The default, one pure delay, on 0.1 s + 0.2 s: the lag comes out near 0.3 s, but
    the sharper answer it assumes is made up by a drag 0.05 /s high and a push."""
    m = fly(0.1, 0.3, time_constant_s=0.2, noise_m=0.001, estimated=True).fit().model
    assert m.lag_s == pytest.approx(0.3, abs=0.01)
    assert m.drag_per_s > 0.34 and m.bias_mps2 > 0.01


def test_a_constant_push_is_told_from_drag():
    fit = fly(0.15, 0.3, bias=0.2).fit()
    assert fit.model.bias_mps2 == pytest.approx(0.2, abs=0.03)
    assert fit.model.drag_per_s == pytest.approx(0.3, abs=0.03)


def drag_free_bias(rows, lag_s: float) -> float:
    """[m/s^2] least squares of X(t) - X(0) - int_0^t int_0^r u(q - lag) dq dr
    = bias t^2 / 2 + Xdot(0) t + c, the command held between ticks and before the first
    (integrated here on a 0.1 ms grid, not as the fit does)."""
    t, u, x, _ = (np.array(c) for c in zip(*rows))
    fine = np.arange(t[0] - lag_s, t[-1] - lag_s, 1e-4)
    held = u[np.clip(np.searchsorted(t, fine, side="right") - 1, 0, None)]
    big_u = np.cumsum(held) * 1e-4
    big_w = np.cumsum(big_u) * 1e-4
    y = (x - x[0]) - np.interp(t - lag_s, fine, big_w)
    return float(2.0 * np.polyfit(t - t[0], y, 2)[0])


@pytest.mark.parametrize("seed", [17, 18])
def test_a_drag_that_noise_makes_negative_is_fitted_as_none_with_its_own_bias(monkeypatch, seed):
    """No drag, no push, a short approach under 4 mm of noise: the joint fit's linear drag
    (the quadratic one held at none, as a negative one is) comes out slightly negative with
    a bias beside it. Clipping only the drag kept that bias; the fit is the drag-free one
    instead."""
    monkeypatch.setattr(lagid, "SPEED_SPAN_MIN_MPS", 0.3)
    ident = fly(
        0.15,
        0.0,
        hold_s=0.3,
        approach_s=1.0,
        noise_m=0.004,
        seed=seed,
        estimated=True,
    )
    fit = ident.fit()
    m = fit.model
    assert m is not None, fit.why
    t, u, x, v = (np.array(c) for c in zip(*ident._rows))
    lags = np.array([m.lag_s])
    joint = _solve(t, u[None], x, v, lags, (None, 0.0))[1][0, :, 0]  # (drag, qdrag, bias, ...)
    assert -0.2 < joint[0] < 0.0
    assert m.drag_per_s == 0.0 and m.qdrag_per_m == 0.0
    assert m.bias_mps2 == pytest.approx(drag_free_bias(ident._rows, m.lag_s), abs=0.003)
    assert abs(m.bias_mps2 - joint[2]) > 0.015  # not the bias fitted beside it


@pytest.mark.parametrize("lag_s", [0.13, 0.25, 0.35])
def test_millimetre_mocap_noise_through_the_estimator_leaves_the_lag_within_a_tick(lag_s):
    """The estimator's speed carries the mocap noise differentiated and correlated over
    tens of ticks; fitted on it, the lag moved by up to 0.02 s between seeds. The fit on
    positions stays within a tick over eight (the estimator's own smoothing adds 0-5 ms)."""
    for seed in range(8):
        m = fly(lag_s, 0.3, noise_m=0.001, seed=seed, estimated=True).fit().model
        assert m is not None
        assert m.lag_s == pytest.approx(lag_s, abs=0.01), seed
        assert m.drag_per_s == pytest.approx(0.3, abs=0.03), seed


def test_millimetre_mocap_noise_leaves_the_lag_within_two_ticks():
    for seed in range(3):
        fit = fly(0.2, 0.3, noise_m=0.001, seed=seed).fit()
        assert fit.model is not None, fit.why
        assert fit.model.lag_s == pytest.approx(0.2, abs=0.02)
        assert fit.model.drag_per_s == pytest.approx(0.3, abs=0.06)


def test_too_little_motion_is_refused_with_the_reason():
    fit = fly(0.1, 0.0, accel=0.1, approach_s=2.0).fit()
    assert fit.model is None
    assert "changed speed by 0.19 m/s, less than the 0.5 m/s" in fit.why  # 0.1 x (2 - 0.1 s)


def test_a_lag_beyond_the_bound_is_refused_not_clipped(monkeypatch):
    monkeypatch.setattr(lagid, "LAG_MAX_S", 0.2)
    fit = fly(0.3, 0.0).fit()
    assert fit.model is None
    assert "bound 0.2 s" in fit.why


def test_an_absurd_drag_is_refused(monkeypatch):
    monkeypatch.setattr(lagid, "DRAG_MAX_PER_S", 1.0)
    fit = fly(0.1, 1.5).fit()
    assert fit.model is None
    assert "drag" in fit.why and "outside 0..1 1/s" in fit.why


@pytest.mark.parametrize("seed", range(40))
def test_any_window_fits_or_refuses_never_raises(seed):
    """Windows of held speeds, steps and clock jumps (a loop descheduled for a second): the
    drags' columns may then be one with the bias's (v s, v^2 s^2 / 2, s^2 / 2 alike over a
    held speed). The fit answers either way."""
    rng = random.Random(seed)
    ident = LagIdentifier(LagIdGains())
    t, x, v = 0.0, -4.0, 0.0
    for _ in range(rng.randrange(30, 900)):
        dt = 0.01 + (rng.choice([0.0, 0.3, 1.0, 2.5]) if rng.random() < 0.01 else 0.0)
        if rng.random() < 0.02:
            v = rng.choice([0.0, 0.4, 1.0, 1.5, 2.0])
        t, x = t + dt, x + v * dt
        ident.record(t, rng.choice([0.0, 0.5, v]), x, v)
    fit = ident.fit()
    assert fit.model is not None or fit.why
    if fit.model is not None:
        m = fit.model
        assert np.isfinite([m.lag_s, m.drag_per_s, m.qdrag_per_m, m.bias_mps2]).all()


def test_a_hold_then_one_tick_after_a_clock_jump_fits_or_refuses():
    """At rest for 0.5 s, then one tick a second later already moving: every column but the
    bias's and the speed's is zero until that tick (the singular case a descheduled loop
    met at the approach's start)."""
    ident = LagIdentifier(LagIdGains())
    for k in range(1, 51):
        ident.record(0.01 * k, 0.0, -4.5, 0.0)
    ident.record(0.51, 0.75, -4.5, 0.0)
    ident.record(1.51, 0.19, -4.17, 0.75)
    fit = ident.fit()
    assert fit.model is not None or fit.why
