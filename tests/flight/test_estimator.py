"""The Kalman filter: perching-frame state from timed poses, latency, outliers, staleness."""

from __future__ import annotations

import math
import random

import pytest

from perchd.core.types import Pose
from perchd.flight.estimator import Estimator, EstimatorConfig
from perchd.flight.frame import PerchFrame

WALL_X = PerchFrame.from_surface((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
T = 1 / 120


def pose(seq, t, p, valid=True, latency=0.0):
    return Pose("cf1", seq, t, p, (0.0, 0.0, 0.0, 1.0), valid, latency)


def track(est, x_of_t, n=240, noise=0.0, seed=0, frame_y=0.0):
    rng = random.Random(seed)
    for k in range(n):
        t = k * T
        est.offer(pose(k + 1, t, (x_of_t(t) + rng.gauss(0, noise), frame_y, 1.0)))
    return (n - 1) * T


def test_a_constant_speed_approach_gives_x_xdot_and_tau_in_the_perching_frame():
    est = Estimator(EstimatorConfig(), WALL_X)
    t = track(est, lambda t: -3.0 + 1.5 * t)
    st = est.state(t)
    assert st.x == pytest.approx(-3.0 + 1.5 * t, abs=1e-4)
    assert st.xdot == pytest.approx(1.5, abs=1e-3)
    assert st.tau == pytest.approx(st.x / 1.5, rel=1e-3)
    assert st.z == pytest.approx(1.0) and st.y == pytest.approx(0.0)


def test_a_surface_facing_minus_y_turns_world_y_into_the_approach_axis():
    frame = PerchFrame.from_surface((1.0, 2.0, 0.0), (0.0, -1.0, 0.0))
    est = Estimator(EstimatorConfig(), frame)
    for k in range(120):
        t = k * T
        est.offer(pose(k + 1, t, (1.5, 4.0 - 1.0 * t, 1.2)))
    st = est.state(119 * T)
    assert st.x == pytest.approx(-(4.0 - 119 * T - 2.0), abs=1e-4)
    assert st.xdot == pytest.approx(1.0, abs=1e-3)
    assert abs(st.y) == pytest.approx(0.5, abs=1e-6) and st.z == pytest.approx(1.2)
    assert frame.yaw_facing == pytest.approx(-math.pi / 2)


def test_the_state_is_predicted_to_the_control_tick_not_left_at_the_pose_time():
    est = Estimator(EstimatorConfig(), WALL_X)
    t = track(est, lambda t: -3.0 + 1.5 * t)
    later = est.state(t + 0.030)  # a pose 30 ms old at the tick
    assert later.x == pytest.approx(-3.0 + 1.5 * (t + 0.030), abs=1e-4)
    assert later.age == pytest.approx(0.030)


def test_a_constant_deceleration_is_tracked_without_lag():
    est = Estimator(EstimatorConfig(), WALL_X)
    t = track(est, lambda t: -3.0 + 2.0 * t - 0.7 * t * t)
    st = est.state(t)
    assert st.xdot == pytest.approx(2.0 - 1.4 * t, abs=2e-3)
    assert st.xddot == pytest.approx(-1.4, abs=0.05)


def test_millimetre_noise_leaves_the_speed_within_centimetres_per_second():
    est = Estimator(EstimatorConfig(), WALL_X)
    errors = []
    for k in range(600):
        t = k * T
        est.offer(pose(k + 1, t, (-3.0 + 1.5 * t + random.Random(k).gauss(0, 0.001), 0.0, 1.0)))
        if k > 120:
            errors.append(est.state(t).xdot - 1.5)
    rms = math.sqrt(sum(e * e for e in errors) / len(errors))
    assert rms < 0.02


def test_a_jump_no_vehicle_can_make_is_rejected_and_the_track_kept():
    est = Estimator(EstimatorConfig(), WALL_X)
    t = track(est, lambda t: -3.0 + 1.5 * t, n=120)
    assert not est.offer(pose(500, t + T, (-1.0, 0.0, 1.0)))  # 2 m in 8 ms
    assert est.rejected == 1
    assert est.state(t + T).x == pytest.approx(-3.0 + 1.5 * (t + T), abs=1e-3)


def test_a_run_of_consistent_jumps_means_the_old_track_was_wrong_and_the_filter_restarts():
    cfg = EstimatorConfig(outlier_max_rejects=3)
    est = Estimator(cfg, WALL_X)
    t = track(est, lambda t: -3.0, n=60)
    results = [est.offer(pose(100 + i, t + (i + 1) * T, (-1.0, 0.0, 1.0))) for i in range(4)]
    assert results == [False, False, False, True]
    assert est.state(t + 4 * T).x == pytest.approx(-1.0)


def test_invalid_repeated_and_out_of_order_poses_are_ignored():
    est = Estimator(EstimatorConfig(), WALL_X)
    assert est.state(0.0) is None
    assert not est.offer(pose(1, 0.0, (0.0, 0.0, 0.0), valid=False))
    assert not est.offer(None)
    assert est.offer(pose(2, 0.1, (-2.0, 0.0, 1.0)))
    assert not est.offer(pose(2, 0.1, (-2.0, 0.0, 1.0)))
    assert not est.offer(pose(3, 0.05, (-2.0, 0.0, 1.0)))
    assert est.accepted == 1


def test_tau_is_undefined_at_or_below_the_minimum_speed_and_when_receding():
    for speed in (0.0, 0.04, -0.5):
        est = Estimator(EstimatorConfig(min_speed_mps=0.05), WALL_X)
        t = track(est, lambda t: -2.0 + speed * t)
        assert est.state(t).tau is None


def test_tilt_and_yaw_come_from_the_pose_quaternion():
    est = Estimator(EstimatorConfig(), WALL_X)
    half = math.radians(30.0) / 2
    q = (math.sin(half), 0.0, 0.0, math.cos(half))  # 30 deg roll
    est.offer(Pose("cf1", 1, 0.0, (-2.0, 0.0, 1.0), q))
    st = est.state(0.0)
    assert math.degrees(st.tilt) == pytest.approx(30.0)
    assert st.yaw == pytest.approx(0.0, abs=1e-12)
