"""The brake a killed agent leaves the MAVLink sentinel (drivers/mavlink/brake.py): a lean that
decelerates the vehicle's horizontal velocity at BRAKE_ACCEL_MPS2 while thrust holds its
height, for as long as stopping takes. Checked here against the attitude's own thrust
vector, not against the formula that made it."""

from __future__ import annotations

import dataclasses
import math

import pytest

from perchd.core.ned import euler_zyx, rotate
from perchd.drivers.mavlink.brake import (
    BRAKE_ACCEL_MPS2,
    BRAKE_MIN_MPS,
    VELOCITY_WINDOW_S,
    Brake,
    VelocityTracker,
    brake_for,
)

G = 9.81
HOVER = 0.42


def acceleration_ned(brake: Brake) -> tuple[float, float, float]:
    """[m/s^2] of a vehicle at the brake's attitude and thrust (thrust linear through
    hover, as the driver's model): along body -Z (FRD), plus gravity (NED: down +)."""
    up = rotate(brake.q_ned, (0.0, 0.0, -1.0))
    f = G * brake.thrust / HOVER
    return (f * up[0], f * up[1], f * up[2] + G)


@pytest.mark.parametrize("heading_deg", [0.0, 60.0, -135.0, 180.0])
@pytest.mark.parametrize("v_ned", [(1.0, 0.0, 0.0), (0.3, -0.4, 0.2), (-2.0, 1.0, 0.0)])
def test_the_brake_decelerates_the_horizontal_velocity_at_any_heading(heading_deg, v_ned):
    heading = math.radians(heading_deg)
    brake = brake_for(v_ned, heading, HOVER, 12.5)
    a = acceleration_ned(brake)
    speed = math.hypot(v_ned[0], v_ned[1])
    for i in (0, 1):
        assert a[i] == pytest.approx(-BRAKE_ACCEL_MPS2 * v_ned[i] / speed, abs=1e-9)
    assert a[2] == pytest.approx(0.0, abs=1e-9)  # height held
    w, x, y, z = brake.q_ned
    assert euler_zyx((x, y, z, w))[2] == pytest.approx(math.remainder(heading, math.tau))
    assert brake.duration_s == pytest.approx(speed / BRAKE_ACCEL_MPS2)
    assert brake.v_ne == v_ned[:2]
    assert brake.t_s == 12.5


def test_slower_than_the_threshold_there_is_nothing_to_brake():
    brake = brake_for((0.6 * BRAKE_MIN_MPS, 0.0, 0.5), 1.0, HOVER, 0.0)
    assert brake.duration_s == 0.0
    assert acceleration_ned(brake) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)


def test_after_the_lean_it_is_level_at_the_heading_at_hover_thrust():
    brake = brake_for((1.0, 1.0, 0.0), 2.0, HOVER, 0.0)
    level = dataclasses.replace(brake, q_ned=brake.level[0], thrust=brake.level[1])
    assert acceleration_ned(level) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    w, x, y, z = level.q_ned
    assert euler_zyx((x, y, z, w))[2] == pytest.approx(2.0)


def test_a_brake_survives_its_wire_form():
    brake = brake_for((1.2, -0.3, 0.0), 0.7, HOVER, 1234.5678)
    back = Brake.unpack(brake.pack())
    assert back.q_ned == pytest.approx(brake.q_ned, abs=1e-6)
    assert (back.thrust, back.duration_s) == pytest.approx((brake.thrust, brake.duration_s))
    assert back.v_ne == pytest.approx(brake.v_ne)
    assert (back.heading_ned, back.hover) == pytest.approx((0.7, HOVER))
    assert back.t_s == brake.t_s  # a monotonic time, to the microsecond and beyond


def test_braking_again_keeps_the_heading_and_hover_thrust():
    brake = brake_for((1.0, 0.0, 0.0), 0.4, HOVER, 3.0).again((0.0, -0.5, 0.0))
    assert (brake.v_ne, brake.heading_ned, brake.hover, brake.t_s) == ((0.0, -0.5), 0.4, HOVER, 3.0)
    assert brake.duration_s == pytest.approx(0.5 / BRAKE_ACCEL_MPS2)


def test_stopped_means_no_faster_than_the_threshold_along_the_velocity_braked():
    brake = brake_for((0.6, -0.8, 0.0), 0.3, HOVER, 0.0)
    assert not brake.stopped((0.06, -0.08 - 0.2, 0.0))
    assert brake.stopped((0.06, -0.08, 0.0))  # BRAKE_DONE_MPS along it
    assert brake.stopped((-0.3, 0.4, 0.0))  # reversed
    assert brake.stopped((0.8, 0.6, 0.5))  # sideways: nothing along it


def test_the_velocity_is_the_displacement_over_the_window():
    track = VelocityTracker()
    v = (0.8, -0.2, 0.1)
    seen = [track.update(i / 100, tuple(c * i / 100 for c in v)) for i in range(20)]
    first = next(i for i, s in enumerate(seen) if s is not None)
    assert first == round(VELOCITY_WINDOW_S * 100)  # nothing before a window has passed
    assert all(s == pytest.approx(v) for s in seen[first:])
    assert track.update(0.19, (9.0, 9.0, 9.0)) is None  # a repeated stamp: ignored
    assert track.update(0.20, tuple(c * 0.2 for c in v)) == pytest.approx(v)
