"""PX4 SIH's ground truth into perchd's world, without PX4: HIL_STATE_QUATERNION (lat/lon/alt,
NED velocity, FRD-in-NED quaternion, sometimes sent as -q) -> ENU, Z up, metres, (x, y, z, w);
and the frames the driver sends in agree with the frame the harness publishes."""

from __future__ import annotations

import math
import random
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from perchd.core.errors import UriError
from perchd.core.types import Phase, Setpoint
from perchd.drivers.mavlink import ned_attitude
from perchd.sim.firmware.px4 import (
    EARTH_RADIUS_M,
    Px4Params,
    Px4Vehicle,
    cm_s,
    enu_from_geodetic,
    enu_quat,
    surface_ahead,
    truth_from_hil,
)
from perchd.sim.firmware.quadrotor import euler_zyx

ORIGIN = (47.397743, 8.545594, 489.4)  # SIH_LOC_LAT0/LON0/H0
ROOT = Path(__file__).parents[2]


def rotate(q, v):
    """v rotated by the (x, y, z, w) quaternion q."""
    x, y, z, w = q
    r = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return tuple(sum(r[i][j] * v[j] for j in range(3)) for i in range(3))


def ned_q(roll, pitch, yaw):
    """(w, x, y, z) of FRD-in-NED Z-Y-X angles, as PX4 sends them."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def test_lat_lon_alt_become_east_north_up_metres_from_the_origin():
    lat0, lon0, h0 = ORIGIN
    p = enu_from_geodetic(lat0 + 1e-5, lon0 + 2e-5, h0 + 2.5, ORIGIN)
    north = math.radians(1e-5) * EARTH_RADIUS_M
    east = math.radians(2e-5) * EARTH_RADIUS_M * math.cos(math.radians(lat0))
    assert p == pytest.approx((east, north, 2.5), abs=1e-9)
    assert north == pytest.approx(1.112, abs=1e-3) and east == pytest.approx(1.506, abs=1e-3)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_level_facing_north_is_enu_yaw_90_and_minus_q_is_the_same_attitude(sign):
    q = enu_quat(tuple(sign * c for c in ned_q(0.0, 0.0, 0.0)))
    assert q[3] >= 0.0  # w >= 0 whichever sign PX4 sent
    assert euler_zyx(q) == pytest.approx((0.0, 0.0, math.pi / 2), abs=1e-9)


@pytest.mark.parametrize(
    "ned_yaw_deg, enu_yaw_deg", [(0, 90), (90, 0), (180, -90), (-90, 180), (30, 60)]
)
def test_headings_map_from_north_clockwise_to_east_anticlockwise(ned_yaw_deg, enu_yaw_deg):
    yaw = euler_zyx(enu_quat(ned_q(0.0, 0.0, math.radians(ned_yaw_deg))))[2]
    assert math.degrees(yaw) % 360 == pytest.approx(enu_yaw_deg % 360, abs=1e-6)


def test_the_body_axes_land_where_they_should():
    # NED: facing east, nose up 10 deg, right wing down 20 deg
    q = enu_quat(ned_q(math.radians(20), math.radians(10), math.radians(90)))
    nose = rotate(q, (1.0, 0.0, 0.0))
    left = rotate(q, (0.0, 1.0, 0.0))
    assert nose[0] > 0.9 and nose[2] == pytest.approx(math.sin(math.radians(10)), abs=1e-9)
    assert left[2] > 0.0  # right wing down: the left wing (FLU +y) is up
    assert left[1] > 0.0  # facing east, left is north


def test_a_hil_message_becomes_truth_in_the_enu_world():
    lat0, lon0, h0 = ORIGIN
    msg = SimpleNamespace(
        lat=round((lat0 + 1e-5) * 1e7),
        lon=round(lon0 * 1e7),
        alt=round((h0 + 2.0) * 1e3),
        vx=100,
        vy=-50,
        vz=-30,
        rollspeed=0.1,
        pitchspeed=0.2,
        yawspeed=0.3,
        attitude_quaternion=[-1.0, 0.0, 0.0, 0.0],
    )
    origin = (round(lat0 * 1e7) * 1e-7, round(lon0 * 1e7) * 1e-7, round(h0 * 1e3) * 1e-3)
    t = truth_from_hil(msg, 12.5, origin)
    assert t.t == 12.5
    assert t.p == pytest.approx((0.0, 1.112, 2.0), abs=2e-3)
    # east, north, up (climbing: vz < 0 in NED), each the centre of its truncated cm/s step
    assert t.v == pytest.approx((-0.505, 1.005, 0.305))
    assert t.w == pytest.approx((0.1, -0.2, -0.3))  # FRD -> FLU rates
    assert t.q == pytest.approx((0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)))


@pytest.mark.parametrize("rpy", [(0.0, 0.0, 1.2), (0.1, -0.2, 2.0), (-0.3, 0.25, -2.5)])
def test_what_the_driver_sends_with_yaw0_90_comes_back_as_the_same_enu_attitude(rpy):
    roll, pitch, yaw = rpy
    sent = ned_attitude(Setpoint(0.0, roll, pitch, yaw, 1.0, 0, Phase.HOLD), math.pi / 2)
    assert euler_zyx(enu_quat(sent)) == pytest.approx(rpy, abs=1e-9)


def test_the_surface_is_put_ahead_along_the_heading_and_contact_is_its_crossing():
    s = surface_ahead((1.0, 2.0, 2.5), math.pi / 2, 4.5)
    assert s.point == pytest.approx((1.0, 6.5, 2.5)) and s.normal == pytest.approx(
        (0, 1, 0), abs=1e-12
    )
    assert s.gap((1.0, 2.0, 2.5)) == pytest.approx(-4.5)
    assert s.speed((0.3, 0.8, 0.0)) == pytest.approx(0.8)


def test_a_folder_without_px4_is_refused_by_name(tmp_path):
    with pytest.raises(UriError, match="not a PX4 SITL build folder"):
        Px4Vehicle(Px4Params(str(tmp_path)))


@pytest.mark.parametrize(("count", "speed"), [(0, 0.0), (99, 0.995), (-99, -0.995), (1, 0.015)])
def test_a_velocity_count_stands_for_the_centre_of_its_truncated_step(count, speed):
    """PX4 fills HIL_STATE_QUATERNION's int16 velocity with m/s x 100 cast, truncated
    towards zero: 0.999 m/s comes as 99, -0.999 as -99, anything within 1 cm/s of rest as 0.
    Read as c / 100 the truth was 5 mm/s slow on average on each axis."""
    assert cm_s(count) == pytest.approx(speed)
    assert int(speed * 100.0) == count  # the cast that made the count


def test_the_cli_takes_px4_or_cf2_not_both(tmp_path):
    run = subprocess.run(
        [sys.executable, "-m", "perchd", "sim", "firmware", "--px4", str(tmp_path), "--cf2", "x"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert run.returncode != 0 and "not allowed with argument" in run.stderr
    run = subprocess.run(
        [sys.executable, "-m", "perchd", "sim", "firmware", "--px4", str(tmp_path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert run.returncode != 0 and "not a PX4 SITL build folder" in run.stderr


@pytest.mark.parametrize(
    ("extra", "said"),
    [
        (["--heading", "400"], "--heading 400 deg is outside -360..360 deg"),
        (["--heading", "60", "--vision"], "with --vision it waits on the ground"),
        (["--sim-speed", "3"], "--sim-speed 3 is outside 0.5..2"),
    ],
)
def test_a_heading_px4_cannot_turn_to_is_one_line_and_exit_2(tmp_path, extra, said):
    run = subprocess.run(
        [sys.executable, "-m", "perchd", "sim", "firmware", "--px4", fake_build(tmp_path), *extra],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert run.returncode == 2 and said in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1 and "Traceback" not in run.stderr


class Poses:
    """A PoseOutput that keeps what it is given."""

    def __init__(self) -> None:
        self.sent: list = []

    def publish(self, pose) -> None:
        self.sent.append(pose)


def fake_build(tmp_path: Path) -> str:
    (tmp_path / "bin").mkdir()
    (tmp_path / "etc").mkdir()
    (tmp_path / "bin" / "px4").write_text("#!/bin/sh\n")
    (tmp_path / "bin" / "px4").chmod(0o755)
    return str(tmp_path)


def hil_east(x_m: float, speed_mps: float) -> SimpleNamespace:
    """SIH's HIL_STATE_QUATERNION for a vehicle x_m east of ORIGIN at speed_mps east, level,
    facing east: lat/lon in 1e-7 deg (1.1 cm, 0.75 cm steps here), velocity in cm/s."""
    lat0, lon0, h0 = ORIGIN
    lon = lon0 + math.degrees(x_m / (EARTH_RADIUS_M * math.cos(math.radians(lat0))))
    return SimpleNamespace(
        lat=round(lat0 * 1e7),
        lon=round(lon * 1e7),
        alt=round((h0 + 2.5) * 1e3),
        vx=0,
        vy=int(speed_mps * 100),
        vz=0,
        rollspeed=0.0,
        pitchspeed=0.0,
        yawspeed=0.0,
        attitude_quaternion=[math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)],
    )


def test_the_speed_perchd_measures_from_sih_truth_is_steady(tmp_path):
    """SIH streams its truth at 100 Hz of sim time on its 250 Hz step (8 and 12 ms apart),
    received with a millisecond of jitter; the harness publishes at 100 Hz of its own. The
    speed perchd's estimator makes of the poses stays within 0.015 m/s of the truth's 1.5 m/s
    (stamped at publication, on the raw 1e-7 deg lat/lon, it swung by +-0.1 m/s and more;
    refined at a 0.05 gain, by 0.018)."""
    from perchd.core.clock import ManualClock
    from perchd.flight.estimator import Estimator, EstimatorConfig
    from perchd.flight.frame import PerchFrame
    from perchd.sim.firmware.harness import TruthPublisher
    from perchd.sim.world import MocapParams

    clock, out, rng = ManualClock(100.0), Poses(), random.Random(3)
    vehicle = Px4Vehicle(Px4Params(fake_build(tmp_path)), clock)
    publisher = TruthPublisher(vehicle, out, MocapParams(rate_hz=100.0, latency_s=0.0), clock)
    est = Estimator(EstimatorConfig(), PerchFrame.from_surface((10.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    speed, sim_t, arrivals = 1.5, 0.0, []
    for k in range(300):  # 3 s of SIH truth: (arrival [s], message)
        arrivals.append((100.0 + sim_t + rng.uniform(0.0, 0.0015), hil_east(speed * sim_t, speed)))
        sim_t += 0.008 if k % 2 else 0.012
    errors, tick = [], 100.0
    while arrivals:
        while arrivals and arrivals[0][0] <= tick:
            t, msg = arrivals.pop(0)
            clock.sleep_until(t)
            vehicle._on_truth(msg)
        clock.sleep_until(tick)
        publisher.step()
        for pose in out.sent:
            est.offer(pose)
        out.sent.clear()
        state = est.state(tick)
        if tick > 101.0:  # the filter has converged from its first pose
            errors.append(state.xdot - speed)
        tick += 0.01
    assert max(map(abs, errors)) < 0.015, (min(errors), max(errors))


def test_px4s_heading_estimate_is_measured_against_the_truth(tmp_path):
    """ATTITUDE's yaw (NED) minus the true heading: facing east (NED 90 deg), PX4 saying
    93 deg is +3 deg; the summary gives the span since ready."""
    vehicle = Px4Vehicle(Px4Params(fake_build(tmp_path)))
    vehicle._on_truth(hil_east(0.0, 0.0))
    vehicle._ready_t = vehicle._truth.t
    for yaw_deg in (93.0, 88.5):
        vehicle._on_attitude(SimpleNamespace(yaw=math.radians(yaw_deg), time_boot_ms=0))
    assert vehicle.summary()["heading_estimate_error_deg"] == pytest.approx([-1.5, 3.0], abs=0.01)


def test_sih_falling_behind_the_wall_clock_is_measured(tmp_path):
    """ATTITUDE every 0.1 s of wall time carrying 99 ms more of PX4's time each: 0.99. The
    rate is not given from less than 5 s of it."""
    from perchd.core.clock import ManualClock

    clock = ManualClock(100.0)
    vehicle = Px4Vehicle(Px4Params(fake_build(tmp_path)), clock)
    vehicle._on_truth(hil_east(0.0, 0.0))
    vehicle._ready_t = vehicle._truth.t
    for k in range(80):
        vehicle._on_attitude(SimpleNamespace(yaw=math.radians(90.0), time_boot_ms=60000 + 99 * k))
        if k == 40:
            assert vehicle.summary()["sim_clock_rate"] is None
        clock.sleep_until(clock.now() + 0.1)
    assert vehicle.summary()["sim_clock_rate"] == pytest.approx(0.99, abs=1e-6)


class HeadingPx4:
    """PX4's side of the harness link on loopback: ATTITUDE at 50 Hz with heading_deg (settable),
    and every COMMAND_LONG it receives kept."""

    def __init__(self, port: int) -> None:
        from pymavlink import mavutil

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.02)
        self.port, self.heading_deg, self.commands = port, 0.0, []
        self.mav = mavutil.mavlink.MAVLink(None, 1, 1)
        self._parser = mavutil.mavlink.MAVLink(None)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            yaw = math.radians(self.heading_deg)
            msg = self.mav.attitude_encode(
                int(time.monotonic() * 1e3) & 0xFFFFFFFF, 0.0, 0.0, yaw, 0.0, 0.0, 0.0
            )
            self.sock.sendto(msg.pack(self.mav), ("127.0.0.1", self.port))
            try:
                data = self.sock.recv(512)
            except TimeoutError:
                continue
            self.commands += [
                m for m in self._parser.parse_buffer(data) or [] if m.get_type() == "COMMAND_LONG"
            ]

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.sock.close()


def test_px4_is_turned_in_hold_until_its_heading_estimate_has_held_there(tmp_path):
    """DO_REPOSITION (192) with only a yaw, in radians as PX4 reads it, position and height
    left NaN (kept); done once ATTITUDE's heading has stayed within 2 deg for 1 s."""
    from pymavlink import mavutil
    from ticks import wait_for

    from perchd.drivers.mavlink import Connection

    vehicle = Px4Vehicle(Px4Params(fake_build(tmp_path)))
    vehicle._link = Connection(mavutil.mavlink_connection("udpin:127.0.0.1:0"))
    vehicle._on_truth(hil_east(0.0, 0.0))  # ATTITUDE is read once the truth flows
    receiver = threading.Thread(target=vehicle._receive, daemon=True)
    receiver.start()
    px4 = HeadingPx4(vehicle._link.conn.port.getsockname()[1])
    try:
        assert wait_for(lambda: vehicle._ekf_heading is not None)  # PX4 heard: answered
        done = threading.Event()
        turner = threading.Thread(
            target=lambda: (vehicle._turn(math.radians(60.0), threading.Event()), done.set())
        )
        turner.start()
        time.sleep(0.3)
        assert not done.is_set()
        px4.heading_deg = 61.5
        turner.join(5.0)
        assert done.is_set()
    finally:
        vehicle.close()
        px4.close()
    command = px4.commands[0]
    assert command.command == 192 and command.param4 == pytest.approx(math.radians(60.0))
    assert all(math.isnan(p) for p in (command.param5, command.param6, command.param7))


def test_the_push_px4s_attitude_estimate_puts_on_the_vehicle_is_averaged_before_contact(tmp_path):
    """Truly level, facing the surface (east), while PX4's estimate says 0.02 rad nose down
    (thrust leaning toward the wall): PX4 believes it pushes g sin 0.02 more than it does,
    -0.196 m/s^2 along the normal. Only the 0.5 s before contact count."""
    from perchd.core.clock import ManualClock
    from perchd.sim.world import Contact

    clock = ManualClock(99.0)
    vehicle = Px4Vehicle(Px4Params(fake_build(tmp_path)), clock)
    vehicle.surface = surface_ahead((0.0, 0.0, 0.0), 0.0, 5.0)
    for t, pitch in ((99.0, 0.05), (100.0, -0.02), (100.1, -0.02)):
        clock.sleep_until(t)
        vehicle._on_truth(hil_east(0.0, 0.0))
        vehicle._on_attitude(
            SimpleNamespace(roll=0.0, pitch=pitch, yaw=math.pi / 2, time_boot_ms=0)
        )
    assert vehicle.attitude_push() is None  # no contact yet
    vehicle._contact = Contact(100.2, 1.0, (5.0, 0.0, 2.5))
    assert vehicle.summary()["attitude_push_mps2"] == pytest.approx(
        -9.81 * math.sin(0.02), rel=1e-3
    )
