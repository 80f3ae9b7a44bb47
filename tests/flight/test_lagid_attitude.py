"""The lag fitted to the attitude the mocap measures (LagIdentifier.lean_response): the
setpoints' lean answered through a delay and a first-order lag, as an autopilot's attitude
loop does, and measured a little later, with noise and a trim offset."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from perchd.core.types import Pose
from perchd.flight.config import LagIdGains
from perchd.flight.estimator import Estimator, EstimatorConfig
from perchd.flight.frame import PerchFrame, body_z
from perchd.flight.lagid import LagIdentifier, _model_at

DT, G = 0.01, 9.81


def lean_command(t: float) -> float:
    """A hold, a run-up at about 4 deg, easing off, then a brake: the lean a perch sends."""
    if t < 1.0:
        return 0.0
    if t < 3.0:
        return 0.075 - 0.02 * (t - 1.0)
    return -0.1 if t < 4.0 else 0.02


def fly(
    delay_s: float,
    tc_s: float,
    noise: float = 0.0,
    offset: float = 0.0,
    seen_as: float = 1.0,
    drag: float = 0.25,
    seconds: float = 4.5,
    seed: int = 0,
    cfg: LagIdGains | None = None,
    lean_per_mps: float = 0.0,
) -> LagIdentifier:
    """Record a flight whose lean answers the lean sent `delay_s` [s] late through a
    first-order lag `tc_s` [s] (integrated in 1 ms steps), Xddot = g lean - drag Xdot.
    The mocap measures each tick's lean 4 ms before the tick, with `noise` added, `offset`
    (the markers' trim) and scaled by seen_as (-1: a rigid body turned half round; 0: one
    whose X sees none of the lean). lean_per_mps: the vehicle holds
    this much more lean per m/s of speed than it answers (an autopilot whose attitude
    estimate errs the more the faster it flies; the mocap sees the lean held)."""
    rng = random.Random(seed)
    ident = LagIdentifier(cfg or LagIdGains())
    sent: list[float] = []
    lean, x, v = 0.0, -4.5, 0.0
    history: list[float] = []  # the true lean at every 1 ms from 0
    for k in range(int(seconds / DT)):
        t = k * DT
        sent.append(lean_command(t))
        measured_at = t - 0.004
        seen = history[round(measured_at / (DT / 10))] if k else 0.0
        ident.record(t, G * sent[-1], x + rng.gauss(0.0, 0.001), v)
        ident.record_lean(t, sent[-1], measured_at, seen_as * seen + offset + rng.gauss(0.0, noise))
        for n in range(10):  # to the next tick, the command sent at t held from t
            held = lean + lean_per_mps * v
            history.append(held)
            late = math.floor((t + n * DT / 10 - delay_s) / DT + 1e-9)
            cmd = sent[max(late, 0)]
            lean += (cmd - lean) * (1.0 - math.exp(-DT / 10 / tc_s)) if tc_s > 0 else cmd - lean
            v += (G * held - drag * v) * DT / 10
            x += v * DT / 10
    return ident


@pytest.mark.parametrize(
    "delay_s, tc_s",
    [(0.11, 0.24), (0.115, 0.235), (0.025, 0.14), (0.135, 0.16), (0.0, 0.07), (0.037, 0.113)],
)
def test_the_attitude_fit_finds_the_delay_and_the_time_constant(delay_s, tc_s):
    """Delays off the 10 ms ticks as well: no half-tick bias."""
    found = fly(delay_s, tc_s).lean_response()
    assert found is not None
    assert found[0] == pytest.approx(delay_s, abs=0.003)
    assert found[1] == pytest.approx(tc_s, abs=0.005)
    assert sum(found) == pytest.approx(delay_s + tc_s, abs=0.003)


def test_a_pure_delay_is_found_within_a_tick():
    """Without a first-order lag the lean steps once a tick, and the fit's interval means
    read between midpoints resolve it to a few ms."""
    found = fly(0.2, 0.0).lean_response()
    assert found is not None and found[1] == 0.0
    assert found[0] == pytest.approx(0.2, abs=0.006)


@pytest.mark.parametrize("seed", range(4))
def test_mocap_noise_and_a_trim_offset_leave_the_lag_within_a_few_milliseconds(seed):
    """0.2 deg of noise on each frame's attitude and a 1 deg trim (the markers)."""
    found = fly(
        0.11, 0.24, noise=math.radians(0.2), offset=math.radians(1.0), seed=seed
    ).lean_response()
    assert found is not None
    assert sum(found) == pytest.approx(0.35, abs=0.008)


@pytest.mark.parametrize("seen_as", [-1.0, 0.0, 0.7, 1.4])
def test_a_rigid_body_whose_axes_are_not_the_vehicles_is_refused(seen_as):
    """Turned half round, seeing none of the lean, or a swing of another size (a body
    turned about 45 deg from the vehicle sees 0.7 of it)."""
    assert fly(0.11, 0.24, seen_as=seen_as, noise=math.radians(0.2)).lean_response() is None


def test_a_lean_seen_a_little_large_or_small_still_fits():
    """A rigid body yawed a little off the vehicle's axes sees the swing a little small;
    the fit holds gain 1, so the lag found grows a little (LEAN_GAIN)."""
    small, large = (fly(0.11, 0.24, seen_as=g).lean_response() for g in (0.95, 1.05))
    assert small is not None and large is not None
    assert 0.35 < sum(small) < 0.375 and 0.325 < sum(large) < 0.35


def test_non_finite_leans_are_not_kept():
    ident = fly(0.11, 0.24)
    before = ident.lean_response()
    ident.record_lean(4.5, math.nan, 4.496, 0.0)
    ident.record_lean(4.51, 0.0, 4.506, math.inf)
    assert ident.lean_response() == before


def test_a_lean_that_swept_too_little_is_refused():
    ident = LagIdentifier(LagIdGains())
    for k in range(300):
        ident.record_lean(k * DT, 0.01 * math.sin(k * DT), k * DT, 0.0)
    assert ident.lean_response() is None


def test_the_fit_flies_the_attitudes_lag_and_fits_drag_to_the_positions():
    fit = fly(0.11, 0.24).fit()
    assert fit.model is not None and fit.model.from_attitude, fit.why
    assert fit.model.lag_s == pytest.approx(0.35, abs=0.006)
    assert fit.model.time_constant_s == pytest.approx(0.24, abs=0.012)
    assert fit.model.drag_per_s == pytest.approx(0.25, abs=0.01)


def test_the_drag_is_fitted_to_the_lean_held_not_the_one_sent():
    """A vehicle that leans 0.003 more per m/s than it is sent meets the drag 0.25 /s
    with up to g x 0.003 = 0.029 /s less net of that lean: fitted to the commands, the
    drag reads low (0.230; stage 2, slower than stage 1, then meets less push than the
    refit carries); fitted to the lean measured, it is the drag."""
    ident = fly(0.11, 0.24, lean_per_mps=0.003, noise=math.radians(0.1))
    fit = ident.fit()
    assert fit.model is not None and fit.model.from_attitude, fit.why
    assert fit.model.drag_from_attitude
    assert fit.model.drag_per_s == pytest.approx(0.25, abs=0.005)
    t, u, x, v = (np.array(c) for c in zip(*ident._rows))
    lean = ident.lean_response()
    assert lean is not None
    commands = _model_at(t, u, x, v, *lean, fit.model.speed_span_mps, (None, 0.0))
    assert commands.drag_per_s < 0.25 - 0.5 * G * 0.003


def test_the_positions_lag_is_fitted_when_the_attitude_is_not_used():
    for ident in (
        fly(0.11, 0.24, seen_as=0.0),
        fly(0.11, 0.24, cfg=LagIdGains(from_attitude=False)),
    ):
        fit = ident.fit()
        assert fit.model is not None and not fit.model.from_attitude, fit.why


def quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of Z-Y-X angles, from scipy (a derivation apart from perchd's)."""
    return tuple(Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat())


@pytest.mark.parametrize("normal", [(1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.6, 0.8, 0.0)])
@pytest.mark.parametrize("angles", [(0.0, 0.1, 0.0), (0.05, -0.2, 1.0), (-0.1, 0.0, 2.5)])
def test_the_estimator_measures_the_lean_the_setpoint_would_send(normal, angles):
    """The lean of a pose's quaternion is the one controller's body_z gives the same
    angles, in any perching frame."""
    frame = PerchFrame.from_surface((0.0, 0.0, 0.0), normal)
    est = Estimator(EstimatorConfig(), frame)
    est.offer(Pose("cf", 1, 0.0, (0.0, 0.0, 1.0), quaternion(*angles)))
    sent = frame.rotate_in(body_z(*angles))[0]
    assert est.state(0.0).lean_x == pytest.approx(sent, abs=1e-12)
