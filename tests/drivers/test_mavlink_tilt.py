"""The autopilot's tilt error sent back into the setpoints (drivers/mavlink/tilt.py): paired in
time through the autopilot's boot clock, only its change, bounded; and through the MAVLink
driver over real pymavlink on loopback against the vehicle double."""

from __future__ import annotations

import math
import random
import time

import pytest

pytest.importorskip("pymavlink")

from mavlink_double import PX4, VehicleDouble, connected
from pymavlink.quaternion import Quaternion

from perchd.core.types import Phase, Pose, Setpoint
from perchd.drivers.mavlink.tilt import MAX_RAD, STALE_S, BootClock, TiltCorrection

DEG = math.radians(1.0)
ATT_PERIOD_S, POSE_PERIOD_S = 0.02, 0.01  # ATTITUDE at 50 Hz, mocap at 100 Hz


def test_the_boot_clock_finds_the_least_delayed_message_not_the_average():
    rng = random.Random(1)
    clock, offset, errors = BootClock(), 1234.5, []
    for k in range(500):
        boot = 0.02 * k
        delay = 0.001 + rng.uniform(0.0, 0.015)  # queueing: 1-16 ms
        errors.append(clock.local(boot, boot + offset + delay) - (boot + offset))
    assert max(abs(e) for e in errors[50:]) < 0.004  # the least delay, ~1 ms, not ~9 ms


def test_the_boot_clock_follows_a_clock_running_1_percent_slow():
    clock, errors = BootClock(), []
    for k in range(3000):  # 60 s
        arrival = 0.02 * k
        boot = 0.99 * arrival  # the autopilot's (a lockstep simulator's) clock runs slow
        errors.append(clock.local(boot, arrival + 0.002) - arrival)
    assert max(abs(e) for e in errors) < 0.012  # 1 % of the 1 s window


def fly(error_rad, *, swing_rad_s=0.0, delays=lambda k: 0.0, seconds=4.0, fix=None):
    """Poses at 100 Hz (roll swinging at swing_rad_s), ATTITUDE at 50 Hz reporting the true
    roll plus error_rad(t) and arriving delays(k) late; the correction after each pose."""
    tilt, out = TiltCorrection(), []
    offset = 500.0  # the autopilot booted 500 s before perchd's clock's zero
    pending = []
    for k in range(int(seconds / POSE_PERIOD_S)):
        t = k * POSE_PERIOD_S
        if k % 2 == 0:
            n = k // 2
            pending.append((t + delays(n), t, swing_rad_s * t + error_rad(t)))
        for arrival, te, roll in [p for p in pending if p[0] <= t]:
            tilt.on_estimate(te + offset, arrival, roll, 0.5 * roll)
            pending.remove((arrival, te, roll))
        tilt.on_pose(t, swing_rad_s * t, 0.0)
        out.append((t, tilt.correction(t)))
    return out


def test_an_error_that_appears_is_sent_back_within_a_few_messages():
    out = fly(lambda t: 1.5 * DEG if t >= 2.0 else 0.0)
    before = [c for t, c in out if t < 2.0]
    after = [c for t, c in out if 2.2 <= t <= 2.6]  # the baseline takes it over 10 s
    assert all(abs(c.roll_rad) < 1e-9 for c in before)
    assert min(c.roll_rad for c in after) > 1.4 * DEG  # estimate - true: lean the setpoint by it
    assert min(c.pitch_rad for c in after) > 0.5 * 1.4 * DEG  # pitch error here is 0.5 x roll's


def test_an_error_present_from_the_start_is_the_outer_loops():
    """A rigid body defined off the vehicle's axes, or a trimmed accelerometer: constant."""
    out = fly(lambda t: 2.0 * DEG)
    assert max(abs(c.roll_rad) for _, c in out) < 1e-9


def test_a_swing_read_through_jittered_arrivals_is_no_error():
    """40 deg/s of roll (a stage switch), estimates exact but arriving 1-16 ms late: paired
    at arrival that reads as up to 0.6 deg of error; paired on the boot clock, none."""
    rng = random.Random(2)
    jitter = [0.001 + rng.uniform(0.0, 0.015) for _ in range(400)]
    out = fly(lambda t: 0.0, swing_rad_s=40 * DEG, delays=lambda n: jitter[n])
    assert max(abs(c.roll_rad) for t, c in out if t > 1.0) < 0.06 * DEG


def test_the_correction_is_bounded_and_ends_when_the_estimates_stop():
    out = fly(lambda t: 10 * DEG if t >= 1.5 else 0.0, seconds=2.0)
    assert out[-1][1].roll_rad == pytest.approx(MAX_RAD)
    tilt = TiltCorrection()
    for k in range(200):
        t = k * POSE_PERIOD_S
        if k % 2 == 0:
            tilt.on_estimate(t + 9.0, t, (DEG if t > 1.5 else 0.0), 0.0)
        tilt.on_pose(t, 0.0, 0.0)
    assert tilt.correction(1.99).roll_rad > 0.5 * DEG
    assert tilt.correction(1.99 + STALE_S + 0.02).roll_rad == 0.0


def stream_poses(drv, seconds: float, seq0: int) -> int:
    """Level poses facing world X at 100 Hz on the driver's clock; the next seq."""
    k = seq0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        drv.observe_pose(Pose("b", k, time.monotonic(), (0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0)))
        k += 1
        time.sleep(POSE_PERIOD_S)
    return k


@pytest.mark.parametrize("tilt", ["", "&tilt=0"])
def test_the_driver_leans_each_setpoint_by_the_change_in_the_autopilots_tilt_error(tilt):
    """PX4 at heading 60 deg, its estimate level, then 0.02 rad pitched up where the mocap
    still sees it level: a level setpoint goes out pitched 0.02 rad up, so that PX4, flying
    its estimate there, holds the vehicle level. tilt=0 sends it as it is."""
    v = VehicleDouble(PX4, yaw_deg=60.0)
    v.boot_s = time.monotonic() - 100.0  # ATTITUDE in its own boot time
    drv = connected(v, "&yaw0=auto" + tilt)
    try:
        k = stream_poses(drv, 1.3, 0)  # the boot clock's window, then a baseline
        v.pitch = 0.02
        stream_poses(drv, 0.3, k)
        drv.send(Setpoint(time.monotonic(), 0.0, 0.0, 0.0, 0.5 * 9.81, 1, Phase.STAGE2))
        assert v.wait_for(lambda: v.targets[-1].thrust > 0.3)
        roll, pitch, yaw = Quaternion(list(v.targets[-1].q)).euler
        assert math.degrees(yaw) == pytest.approx(60.0, abs=0.01)
        assert roll == pytest.approx(0.0, abs=0.001)
        assert pitch == pytest.approx(0.0 if tilt else 0.02, abs=0.002)
    finally:
        drv.close()
        v.close()


def test_a_new_connection_learns_the_autopilots_clock_anew():
    """Another connect() may reach another boot of the autopilot: nothing paired before it
    carries over."""
    v = VehicleDouble(PX4)
    v.boot_s = time.monotonic() - 100.0
    drv = connected(v, "&yaw0=auto", engage=False)
    try:
        stream_poses(drv, 1.3, 0)
        assert drv.tilt.paired > 0
        drv.close()
        drv.connect()
        assert drv.tilt.paired == 0
    finally:
        drv.close()
        v.close()
