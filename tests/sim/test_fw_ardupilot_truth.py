"""ArduCopter SITL harness without SITL: SIM_STATE -> perchd's world frame, the command
line it is started with, the driver URI, option checks (perchd.sim.firmware.ardupilot)."""

from __future__ import annotations

import argparse
import math
from types import SimpleNamespace

import pytest

from perchd.commands.sim.firmware import arducopter_params, register_under
from perchd.core.errors import UriError
from perchd.sim.firmware.ardupilot import (
    DEG7_M,
    VISION_BOOT_PARAMS,
    ArduPilotParams,
    GeoOrigin,
    SimState,
    TruthFilter,
    boot_parm,
    crossing,
    driver_uri_for,
    find_defaults,
    in_dir,
    ned_offset,
    sitl_argv,
    world_quat,
    world_vec,
)
from perchd.sim.firmware.harness import Truth
from perchd.sim.firmware.quadrotor import euler_zyx

ORIGIN = GeoOrigin(-353632610, 1491652300, 584.0)


def ned_quat(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(w, x, y, z) of FRD -> NED Z-Y-X angles, as SIM_STATE's q1..q4."""
    cr, sr, cp, sp = (
        math.cos(roll / 2),
        math.sin(roll / 2),
        math.cos(pitch / 2),
        math.sin(pitch / 2),
    )
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def state(
    lat=ORIGIN.lat_e7,
    lon=ORIGIN.lon_e7,
    alt=ORIGIN.alt_m,
    q=(1.0, 0.0, 0.0, 0.0),
    v=(0.0, 0.0, 0.0),
) -> SimState:
    return SimState(q, lat, lon, alt, v, (0.0, 0.0, 0.0))


def test_north_east_down_offsets_from_the_origin():
    n, e, d = ned_offset(ORIGIN.lat_e7 + 100, ORIGIN.lon_e7 + 100, 586.5, ORIGIN)
    assert n == pytest.approx(100 * DEG7_M)  # 1.11 m
    assert e == pytest.approx(100 * DEG7_M * math.cos(math.radians(-35.363261)), rel=1e-6)
    assert d == pytest.approx(-2.5)


@pytest.mark.parametrize("frame, expect", [("nwu", (1.0, -2.0, -3.0)), ("enu", (2.0, 1.0, -3.0))])
def test_vectors_rotate_into_a_z_up_world(frame, expect):
    assert world_vec((1.0, 2.0, 3.0), frame) == pytest.approx(expect, abs=1e-12)


@pytest.mark.parametrize(
    "roll, pitch, yaw", [(0.2, 0.0, 0.0), (0.0, 0.3, 0.0), (0.0, 0.0, 0.7), (0.1, -0.2, 2.5)]
)
def test_nwu_attitude_keeps_roll_and_negates_pitch_and_yaw(roll, pitch, yaw):
    """NED nose-up pitch is perchd's nose-up too: perchd's pitch is positive nose down
    about +Y (left), ArduPilot's positive nose up about +Y (right) - the driver's map
    (drivers/mavlink.py: ned_attitude) inverted."""
    r, p, y = euler_zyx(world_quat(ned_quat(roll, pitch, yaw), "nwu"))
    assert (r, p, y) == pytest.approx((roll, -pitch, -yaw), abs=1e-9)


def test_enu_heading_is_measured_from_east_counter_clockwise():
    _, _, y = euler_zyx(world_quat(ned_quat(0.0, 0.0, 0.0), "enu"))  # facing north
    assert y == pytest.approx(math.pi / 2)
    _, _, y = euler_zyx(world_quat(ned_quat(0.0, 0.0, math.pi / 2), "enu"))  # facing east
    assert y == pytest.approx(0.0, abs=1e-9)


def test_quaternion_is_unit_x_y_z_w_with_w_non_negative():
    q = world_quat(ned_quat(0.3, 0.2, -3.0), "nwu")
    assert sum(c * c for c in q) == pytest.approx(1.0)
    assert q[3] >= 0.0


def test_truth_starts_at_start_and_climbs_with_the_altitude():
    f = TruthFilter(ORIGIN, (-4.5, 0.0, 0.0), "nwu")
    assert f.update(0.0, state()).p == pytest.approx((-4.5, 0.0, 0.0))
    t = f.update(0.01, state(alt=ORIGIN.alt_m + 0.01, v=(0.0, 0.0, -1.0)))
    assert t.p[2] == pytest.approx(0.01, abs=1e-3)
    assert t.v == pytest.approx((0.0, 0.0, 1.0))


def test_quantised_position_is_smoothed_by_the_velocity():
    """Flying north at 0.5 m/s, lat_int moves in 1.1 cm steps; the truth moves in mm."""
    f = TruthFilter(ORIGIN, (0.0, 0.0, 0.0), "nwu")
    xs = []
    for k in range(200):
        t = k * 0.01
        lat = ORIGIN.lat_e7 + int(0.5 * t / DEG7_M)  # truncated: the step
        xs.append(f.update(t, state(lat=lat, v=(0.5, 0.0, 0.0))).p[0])
    steps = [b - a for a, b in zip(xs, xs[1:])]
    assert max(steps) < 0.006 and min(steps) > 0.004
    assert xs[-1] == pytest.approx(0.5 * 1.99, abs=0.012)


def test_sim_state_lat_int_is_preferred_to_the_float():
    m = SimpleNamespace(
        q1=1.0,
        q2=0.0,
        q3=0.0,
        q4=0.0,
        lat=-353632608.0,
        lon=1491652352.0,
        lat_int=-353632610,
        lon_int=1491652300,
        alt=584.0,
        vn=0.0,
        ve=0.0,
        vd=0.0,
        xgyro=0.0,
        ygyro=0.0,
        zgyro=0.0,
    )
    s = SimState.from_msg(m)
    assert (s.lat_e7, s.lon_e7) == (-353632610, 1491652300)


def test_crossing_the_virtual_surface_is_a_contact_with_the_normal_speed():
    surface = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    a = Truth(1.0, (-0.01, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    b = Truth(1.01, (0.0, 0.0, 1.0), (0.98, 0.1, 0.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    c = crossing(surface, a, b)
    assert c is not None and c.speed == pytest.approx(0.98) and c.t == 1.01
    assert crossing(surface, b, b) is None


def test_sitl_runs_on_loopback_udp_only_in_its_own_directory(tmp_path):
    p = ArduPilotParams("/fw/arducopter", boot_speedup=10.0)
    argv = sitl_argv(p, str(tmp_path / "copter.parm"), 40001, 40002)
    assert argv[:2] == ["/fw/arducopter", "--model"]
    assert argv[argv.index("--serial0") + 1] == "udpclient:127.0.0.1:40001"
    assert argv[argv.index("--serial1") + 1] == "udpclient:127.0.0.1:40002"
    assert argv[argv.index("--serial2") + 1] == "none:"  # no TCP listener on 0.0.0.0
    assert "-w" in argv and argv[argv.index("--defaults") + 1] == str(tmp_path / "copter.parm")
    assert argv[argv.index("--home") + 1] == "-35.3632610,149.1652300,584,0"
    assert argv[argv.index("--speedup") + 1] == "10" and "-I0" in argv
    assert in_dir(tmp_path, argv)[:3] == ["env", "-C", str(tmp_path)]


def test_driver_uri_listens_where_serial1_sends_and_arms():
    # with GPS the SITL vehicle has its own position: no mocap to its EKF
    assert driver_uri_for(40002) == "mavlink:udpin:127.0.0.1:40002?arm=1&vision=0"
    assert driver_uri_for(40002, vision=True) == "mavlink:udpin:127.0.0.1:40002?arm=1"


def test_instance_vision_and_stock_params_reach_sitl(tmp_path):
    top = argparse.ArgumentParser()
    register_under(top.add_subparsers().add_parser("sim"))
    args = top.parse_args(
        ["sim", "firmware", "--arducopter", "/fw/arducopter", "--instance", "1", "--vision"]
    )
    p = arducopter_params(args)
    assert "-I1" in sitl_argv(p, "a.parm,b.parm", 1, 2) and p.vision
    assert dict(p.params)["ATC_ANGLE_BOOST"] == 0.0 and dict(p.params)["FS_GCS_ENABLE"] == 5.0
    stock = arducopter_params(
        top.parse_args(["sim", "firmware", "--arducopter", "x", "--stock-params"])
    )
    assert stock.params == (("GUID_OPTIONS", 8.0),)
    parm = boot_parm(tmp_path, VISION_BOOT_PARAMS).read_text()
    assert "VISO_TYPE 1\n" in parm and "GPS1_TYPE 0\n" in parm and "EK3_SRC1_YAW 6\n" in parm
    px4 = top.parse_args(["sim", "firmware", "--px4", "/b", "--px4-instance", "2"])
    assert px4.instance == 2  # the old spelling is the same option
    with pytest.raises(UriError, match="instance 10"):
        ArduPilotParams("/fw/arducopter", instance=10)


def test_defaults_are_found_in_the_binary_s_source_tree(tmp_path):
    exe = tmp_path / "build" / "sitl" / "bin" / "arducopter"
    parm = tmp_path / "Tools" / "autotest" / "default_params" / "copter.parm"
    exe.parent.mkdir(parents=True)
    parm.parent.mkdir(parents=True)
    exe.write_text("")
    parm.write_text("FRAME_CLASS 1\n")
    link = tmp_path / "bin-arducopter"
    link.symlink_to(exe)  # a symlink elsewhere resolves to the build tree
    assert find_defaults(str(link)) == parm
    with pytest.raises(UriError, match="--defaults"):
        find_defaults("/nonexistent-perchd/bin/arducopter")


@pytest.mark.parametrize("kw", [{"frame": "ned"}, {"truth_hz": 0.5}, {"boot_speedup": 100.0}])
def test_bad_options_are_refused(kw):
    with pytest.raises(UriError):
        ArduPilotParams("/fw/arducopter", **kw)


def test_command_line_takes_arducopter_defaults_and_frame(tmp_path):
    top = argparse.ArgumentParser()
    sim = top.add_subparsers().add_parser("sim")
    register_under(sim)
    args = top.parse_args(
        [
            "sim",
            "firmware",
            "--arducopter",
            "/fw/arducopter",
            "--defaults",
            str(tmp_path / "x.parm"),
            "--frame",
            "enu",
        ]
    )
    p = arducopter_params(args)
    assert (p.binary, p.defaults, p.frame) == ("/fw/arducopter", str(tmp_path / "x.parm"), "enu")
    assert p.start == (-4.5, 0.0, 0.0) and p.surface == ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    with pytest.raises(SystemExit):  # one firmware at a time
        top.parse_args(["sim", "firmware", "--arducopter", "a", "--cf2", "b"])


@pytest.mark.parametrize("yaw0", [0.0, math.pi / 2, 1.0, -2.5])
def test_ned_undoes_the_world_rotation_at_any_yaw0(yaw0):
    """One rotation both ways: truth into the world (harnesses), mocap back to NED (driver)."""
    from perchd.core.ned import ned_quat, ned_vec
    from perchd.sim.plant import quaternion

    v = (0.3, -1.2, 2.0)
    assert world_vec(ned_vec(v, yaw0), yaw0) == pytest.approx(v, abs=1e-12)
    q = quaternion(0.1, -0.2, 0.7)
    assert world_quat(ned_quat(q, yaw0), yaw0) == pytest.approx(q, abs=1e-12)
