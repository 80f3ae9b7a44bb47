"""The firmware harness's physics (perchd.sim.firmware.quadrotor): hover, signs, ground, lag."""

from __future__ import annotations

import math

import pytest

from perchd.sim.firmware.quadrotor import QuadModel, Quadrotor, euler_zyx

M = QuadModel()
HOVER = M.hover_pwm


def spun_up(pwm: list[float], start=(0.0, 0.0, 1.0)) -> Quadrotor:
    """In the air with the rotors already at the speed `pwm` asks for."""
    q = Quadrotor(M, start)
    q.rotor = [M.omega_ref(u) for u in pwm]
    return q


def run(q: Quadrotor, pwm, seconds: float) -> Quadrotor:
    for _ in range(round(seconds / 0.001)):
        q.step(0.001, pwm)
    return q


def test_the_model_hovers_at_its_hover_pwm_near_38800():
    # w = sqrt(m g / 4 k_f) = sqrt(0.0282 * 9.80665 / (4 * 1.7965e-8)) = 1961.74 rad/s
    # pwm = (w - 380.8359) / 0.04076521 = 38780.7
    assert HOVER == pytest.approx(38780.7, abs=0.5)
    assert 4 * M.thrust(HOVER) == pytest.approx(M.mass_kg * M.gravity, rel=1e-9)
    q = run(spun_up([HOVER] * 4), [HOVER] * 4, 1.0)
    assert abs(q.v[2]) < 1e-9 and q.p[2] == pytest.approx(1.0, abs=1e-9)
    assert q.specific_force() == pytest.approx((0.0, 0.0, M.gravity))


def test_more_than_hover_climbs_at_the_thrust_over_mass():
    pwm = [45000] * 4
    q = run(spun_up(pwm), pwm, 0.2)
    expected = 4 * M.thrust(45000) / M.mass_kg - M.gravity
    assert q.v[2] == pytest.approx(expected * 0.2, rel=1e-3)


def test_rotor_speed_below_pwm_min_is_zero_and_saturates_at_omega_max():
    assert M.omega_ref(999) == 0.0
    assert M.omega_ref(1000) == pytest.approx(0.04076521 * 1000 + 380.8359)
    assert M.omega_ref(65535) == 3052.0  # 3052.4 unclamped


@pytest.mark.parametrize(
    "pattern, axis, sign",
    [
        ([HOVER - 500, HOVER - 500, HOVER + 500, HOVER + 500], 0, +1),  # left rotors up: roll right
        ([HOVER + 500, HOVER + 500, HOVER - 500, HOVER - 500], 0, -1),
        ([HOVER - 500, HOVER + 500, HOVER + 500, HOVER - 500], 1, +1),  # rear rotors up: nose down
        ([HOVER + 500, HOVER - 500, HOVER - 500, HOVER + 500], 1, -1),
        ([HOVER - 500, HOVER + 500, HOVER - 500, HOVER + 500], 2, +1),  # cw rotors up: turns ccw
        ([HOVER + 500, HOVER - 500, HOVER + 500, HOVER - 500], 2, -1),
    ],
    ids=["roll+", "roll-", "pitch+", "pitch-", "yaw+", "yaw-"],
)
def test_each_motor_pattern_turns_the_body_about_its_own_axis_only(pattern, axis, sign):
    q = run(spun_up(pattern), pattern, 0.05)
    w = q.gyro()
    assert sign * w[axis] > 0.02  # [rad/s] after 50 ms (yaw, the weakest: 0.059)
    assert all(abs(w[i]) < 1e-6 for i in range(3) if i != axis)
    assert sign * euler_zyx(tuple(q.q))[axis] > 0


def test_a_right_roll_moves_right_and_a_nose_down_pitch_moves_forward():
    right = run(
        spun_up([HOVER - 300, HOVER - 300, HOVER + 300, HOVER + 300]),
        [HOVER - 300, HOVER - 300, HOVER + 300, HOVER + 300],
        0.1,
    )
    right = run(right, [HOVER + 200] * 4, 0.3)
    assert right.v[1] < -0.05 and abs(right.v[0]) < 1e-6  # body y is left: right is -y
    down = run(
        spun_up([HOVER - 300, HOVER + 300, HOVER + 300, HOVER - 300]),
        [HOVER - 300, HOVER + 300, HOVER + 300, HOVER - 300],
        0.1,
    )
    down = run(down, [HOVER + 200] * 4, 0.3)
    assert down.v[0] > 0.05 and abs(down.v[1]) < 1e-6


def test_the_yaw_torque_is_the_drag_of_the_rotors_k_m_T():
    pattern = [HOVER - 1000, HOVER + 1000, HOVER - 1000, HOVER + 1000]
    q = run(spun_up(pattern), pattern, 0.01)
    t_ccw, t_cw = M.thrust(HOVER - 1000), M.thrust(HOVER + 1000)
    mz = 2 * M.k_m * (t_cw - t_ccw)
    assert q.w[2] == pytest.approx(mz / M.inertia_kgm2[2] * 0.01, rel=1e-6)


def test_the_motors_lag_faster_up_than_down():
    q = Quadrotor(M, (0.0, 0.0, 0.0))
    ref = M.omega_ref(50000)
    run(q, [50000] * 4, 0.0125)  # one up time constant: 1 - 1/e
    assert q.rotor[0] / ref == pytest.approx(1 - math.exp(-1), abs=0.01)
    q.rotor = [ref] * 4
    run(q, [0] * 4, 0.025)  # one down time constant
    assert q.rotor[0] / ref == pytest.approx(math.exp(-1), abs=0.01)


def test_it_starts_on_the_floor_and_stays_there_until_thrust_exceeds_weight():
    q = Quadrotor(M, (1.0, 2.0, 0.0))
    run(q, [0] * 4, 0.5)
    assert q.grounded and q.p == [1.0, 2.0, 0.0]
    assert q.specific_force() == pytest.approx((0.0, 0.0, M.gravity))  # the floor holds it
    run(q, [HOVER - 2000, HOVER - 2000, HOVER + 2000, HOVER + 2000], 0.5)  # below weight, uneven
    assert q.grounded and q.gyro() == (0.0, 0.0, 0.0) and q.p[2] == 0.0
    run(q, [HOVER + 3000] * 4, 0.3)
    assert not q.grounded and q.p[2] > 0.01 and q.v[2] > 0
    run(q, [0] * 4, 2.0)  # falls back: stopped dead on the floor
    assert q.grounded and q.p[2] == 0.0 and q.v == [0.0, 0.0, 0.0]


def test_rotor_drag_slows_a_sideways_drift():
    q = spun_up([HOVER] * 4)
    q.v = [1.0, 0.0, 0.0]
    run(q, [HOVER] * 4, 0.5)
    assert 0.7 < q.v[0] < 0.95  # 4 * 1962 rad/s * 9.18e-7 / 0.0282 kg = 0.26 /s


def test_perched_it_stays_put_whatever_the_motors_do():
    q = spun_up([HOVER + 5000] * 4)
    q.perch()
    run(q, [HOVER + 5000] * 4, 0.2)
    assert q.p == [0.0, 0.0, 1.0] and q.v == [0.0, 0.0, 0.0]
    assert q.specific_force() == pytest.approx((0.0, 0.0, M.gravity))
