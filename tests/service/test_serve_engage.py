"""`perchd serve` with a MAVLink vehicle (the double, pymavlink at both ends on loopback;
mocap a ZMQ publisher of a vehicle standing still): the service connects at start-up and
changes nothing on the vehicle; only a flight engages it (docs/safety.md "When a flight
takes the vehicle"). A vehicle the failsafe put in LAND stays there, across a restart."""

import signal
import time

import pytest

pytest.importorskip("pymavlink")

from mavlink_double import ARDUPILOT, VehicleDouble
from still_poses import StillPoses
from svc import PLAN, Serve, ctl

LOITER, GUIDED_NOGPS, LAND = 5, 20, 9


@pytest.fixture
def vehicle():
    v = VehicleDouble(ARDUPILOT, airborne=True)
    v.switch_mode_by_pilot(LOITER)  # the pilot's, until perchd flies it
    yield v
    v.close()


@pytest.fixture
def poses():
    p = StillPoses((-4.5, 0.0, 1.0))
    yield p
    p.close()


def taken(v: VehicleDouble, since: float = 0.0) -> list:
    """Everything that would move the vehicle: mode and arming commands, attitude targets."""
    return [c for t, c, _ in v.commands if c in (176, 400) and t > since] + [
        x for x in v.targets if x.t > since
    ]


def serve(tmp_path, notify, v: VehicleDouble, poses: StillPoses) -> Serve:
    s = Serve(tmp_path, notify, "--driver", v.uri, "--mocap", poses.uri)
    notify.wait_for("READY=1", 20.0)
    return s


def fly_and_abort(s: Serve, v: VehicleDouble) -> None:
    """A flight engaged, aborted in its hold or approach: the failsafe's LAND, then idle."""
    assert ctl(s.sock, "fly", str(PLAN))["ok"]
    assert v.wait_for(lambda: v.custom_mode == GUIDED_NOGPS and v.targets)
    s.wait_phase({"hold", "approach"})
    assert ctl(s.sock, "abort")["aborting"]
    assert v.wait_for(lambda: v.custom_mode == LAND)
    deadline = time.monotonic() + 5
    while ctl(s.sock, "status")["state"] == "flying" and time.monotonic() < deadline:
        time.sleep(0.05)
    assert ctl(s.sock, "status")["state"] == "idle"


def test_an_idle_service_sends_no_mode_change_and_no_attitude_target(
    tmp_path, notify, vehicle, poses
):
    s = serve(tmp_path, notify, vehicle, poses)
    try:
        vehicle.wait_for(lambda: False, timeout=1.5)
        assert ctl(s.sock, "status")["link_ok"] is True
        assert vehicle.gcs_heartbeats  # connected: it hears perchd
        assert taken(vehicle) == [] and vehicle.custom_mode == LOITER
    finally:
        s.proc.send_signal(signal.SIGTERM)
        s.stop()
        s.kill()
    assert taken(vehicle) == [] and vehicle.custom_mode == LOITER  # stopping idle: nothing


def test_a_flight_engages_and_after_its_failsafe_land_stays_across_a_restart(
    tmp_path, notify, vehicle, poses
):
    s = serve(tmp_path, notify, vehicle, poses)
    try:
        fly_and_abort(s, vehicle)
        landed = time.monotonic()
        vehicle.wait_for(lambda: False, timeout=1.0)
        assert taken(vehicle, landed) == [] and vehicle.custom_mode == LAND  # idle again
        s.proc.kill()  # a crash: Restart=on-failure starts it again
        s.proc.communicate()
    finally:
        s.kill()
    restarted = time.monotonic()
    notify.messages.clear()
    again = serve(tmp_path, notify, vehicle, poses)
    try:
        vehicle.wait_for(lambda: False, timeout=1.5)
        assert ctl(again.sock, "status")["link_ok"] is True
        assert taken(vehicle, restarted) == [] and vehicle.custom_mode == LAND
    finally:
        again.proc.send_signal(signal.SIGTERM)
        again.stop()
        again.kill()
    assert vehicle.custom_mode == LAND


def visions_within(v: VehicleDouble, seconds: float) -> int:
    start = time.monotonic()
    v.wait_for(lambda: False, timeout=seconds)
    return sum(1 for t, _ in v.visions if t > start)


def test_the_mocap_reaches_the_vehicle_between_flights_each_pose_once(
    tmp_path, notify, vehicle, poses
):
    """An EKF on mocap alone needs it while a failsafe's LAND descends after the flight,
    and before the next (docs/safety.md "Between flights")."""
    s = serve(tmp_path, notify, vehicle, poses)
    rate = 1.0 / poses.period
    try:
        assert visions_within(vehicle, 1.0) >= 0.6 * rate  # idle, before any flight
        fly_and_abort(s, vehicle)
        assert visions_within(vehicle, 1.0) >= 0.6 * rate  # the landing, after the flight
    finally:
        s.proc.send_signal(signal.SIGTERM)
        s.stop()
        s.kill()
    stamps = [m.usec for _, m in vehicle.visions]
    assert stamps == sorted(set(stamps))  # one feeder at a time, each pose once
