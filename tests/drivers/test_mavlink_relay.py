"""The mocap relayed after the agent's death (drivers/mavlink/relay.py): an agent killed while it
flies a vehicle on mocap alone leaves its sentinel sending the flight's own mocap on to the
EKF, in the agent's frame and stamps, with TIMESYNC answered, until the landing is over.
Real processes, ZMQ and MAVLink on loopback."""

from __future__ import annotations

import math
import subprocess
import textwrap
import time

import pytest
from mavlink_double import PX4, VehicleDouble, agent_process
from still_poses import StillPoses

from perchd.core.types import Pose
from perchd.drivers.mavlink.relay import DISARMED_GRACE_S
from perchd.drivers.mavlink.sentinel import FOLLOW_PERIOD_S, LAND_REPEATS, VEHICLE_SILENT_S
from perchd.drivers.mavlink.vision import POS_STD_M, vision_estimate, vision_message
from perchd.session import open_links

YAW0_DEG = 60.0
SPEED_MPS = 0.5
RATE_HZ = 100.0
POSCTL = 3 << 16  # PX4 POSITION: the pilot takes the vehicle
OFFBOARD = 6 << 16  # PX4 OFFBOARD: a new agent takes it
LAND_PX4 = (4 << 16) | (6 << 24)  # PX4 AUTO.LAND


pytestmark = pytest.mark.solo  # real-time bounds: see tests/conftest.py


def agent(
    vehicle_uri: str,
    mocap_uri: str,
    query: str = "",
    fly_s: float = 1e9,
    serving: bool = False,
    relayed: str | None = None,
) -> subprocess.Popen:
    """`perchd fly`'s driver wiring in a process of its own: mocap bound, connected,
    engaged on the poses, then each new pose observed and a pitched setpoint sent at 100 Hz
    until it is killed, or for fly_s [s] and then closed (the driver's own LAND) and
    exited; says "ready" once engaged. serving: after fly_s, as `perchd serve` between
    flights: the driver's failsafe, then only the poses observed until it is killed.
    relayed: the mocap URI the driver is told to relay, if not the one it flies on."""
    code = textwrap.dedent(f"""
        import time
        from perchd.core.runtime import Runtime
        from perchd.core.types import EndReason, Phase, Setpoint
        from perchd.drivers.base import open_driver
        from perchd.mocap.base import open_source
        rt = Runtime.real()
        d = open_driver({vehicle_uri!r} + "?mass=0.5&yaw0={YAW0_DEG}" + {query!r}, rt)
        d.bind_mocap({relayed or mocap_uri!r})
        source = open_source({mocap_uri!r}, rt)
        source.start()
        d.connect()
        d.engage(source.latest)
        print("ready", flush=True)
        seq, end = None, time.monotonic() + {fly_s}
        while time.monotonic() < end:
            pose = source.latest()
            if pose is not None and pose.seq != seq:
                seq = pose.seq
                d.observe_pose(pose)
            d.send(Setpoint(0.0, 0.0, 0.2, 0.0, 5.0, 1, Phase.STAGE1))
            time.sleep(0.01)
        if {serving}:
            d.failsafe(EndReason.OPERATOR_ABORT)
            print("between flights", flush=True)
            while True:
                pose = source.wait(seq, 0.05)
                if pose is not None:
                    seq = pose.seq
                    d.observe_pose(pose)
        d.close()
        source.close()
    """)
    return agent_process(code)


def ned(p: tuple[float, ...], yaw0_deg: float) -> tuple[float, float, float]:
    """World (Z up) to NED with world X at heading yaw0: world Y is 90 deg to its left."""
    c, s = math.cos(math.radians(yaw0_deg)), math.sin(math.radians(yaw0_deg))
    x, y, z = p
    return (x * c + y * s, x * s - y * c, -z)


def killed_agent(vehicle: VehicleDouble, mocap: StillPoses, **kw) -> float:
    """An agent flying `vehicle` on `mocap`, SIGKILLed after 0.6 s: time.monotonic() then."""
    proc = agent(vehicle.uri, mocap.uri, **kw)
    try:
        time.sleep(0.6)
        killed = time.monotonic()
        proc.kill()
        proc.wait()
        return killed
    finally:
        proc.kill()


@pytest.fixture(params=["zmq", "natnet"])
def flown(request):
    """A PX4 double in the air (MAVLink 2, TIMESYNC requests on), mocap (ZMQ, or NatNet
    unicast) moving at SPEED_MPS along world X, and an agent flying it on that mocap, killed
    after 0.6 s; yields (vehicle, mocap, time.monotonic() of the kill)."""
    vehicle = VehicleDouble(PX4, airborne=True, timesync=True, mavlink2=True)
    mocap = StillPoses(
        p=(-3.0, 0.2, 1.0),
        body="v",
        rate_hz=RATE_HZ,
        velocity=(SPEED_MPS, 0.0, 0.0),
        natnet=request.param == "natnet",
    )
    try:
        yield vehicle, mocap, killed_agent(vehicle, mocap)
    finally:
        mocap.close()
        vehicle.die()


def visions_between(vehicle: VehicleDouble, start: float, end: float) -> list:
    return [msg for t, msg in list(vehicle.visions) if start < t <= end]


def test_after_the_kill_the_mocap_goes_on_to_the_ekf_in_the_agents_frame(flown):
    """Through the brake and the LAND: each pose relayed carries its stamp and its
    position in NED at the agent's yaw0, re-derived here from the pose published. A ZMQ
    pose carries its stamp through; a NatNet one is re-timed by the client's clock sync."""
    vehicle, mocap, killed = flown
    stamp_tol_us = 3000 if mocap.uri.startswith("natnet") else 2
    time.sleep(3.0)  # past the brake and the LAND repeats: TIMESYNC is answered again
    relayed = visions_between(vehicle, killed + 0.2, killed + 1.5)
    assert len(relayed) >= 0.5 * 1.3 * RATE_HZ  # a loaded machine may lose some
    published = mocap.snapshot()
    stamps = sorted(published)
    for msg in relayed:
        usec = min(stamps, key=lambda s: abs(s - msg.usec))
        assert abs(usec - msg.usec) <= stamp_tol_us
        assert (msg.x, msg.y, msg.z) == pytest.approx(ned(published[usec], YAW0_DEG), abs=1e-5)
        assert msg.yaw == pytest.approx(math.radians(YAW0_DEG), abs=1e-6)
        assert msg.covariance[0] == pytest.approx(POS_STD_M**2)
    assert [m.usec for m in relayed] == sorted({m.usec for m in relayed})
    replies = [(t, tc1) for t, tc1, _ in list(vehicle.timesync_replies) if t > killed + 0.2]
    assert len(replies) >= 5
    assert all(abs(tc1 * 1e-9 - t) < 0.05 for t, tc1 in replies)  # the monotonic clock


@pytest.mark.parametrize("ending", ["disarmed", "new agent", "silent"])
def test_the_relay_ends_with_the_landing(flown, ending):
    """A pilot's mode keeps it going (a vehicle on mocap alone has no other position); it
    stops DISARMED_GRACE_S after a disarm, at once when the vehicle is back in the offboard
    mode (a new agent has it), VEHICLE_SILENT_S after the vehicle falls silent."""
    vehicle, _, killed = flown
    assert vehicle.wait_for(lambda: any(t > killed for t, _ in vehicle.modes), 3.0)
    time.sleep(LAND_REPEATS * 0.1 + 0.2)
    vehicle.switch_mode_by_pilot(POSCTL)
    time.sleep(0.3)
    assert visions_between(vehicle, time.monotonic() - 0.2, time.monotonic())
    ended = time.monotonic()
    if ending == "disarmed":
        vehicle.armed = False
        vehicle.switch_mode_by_pilot(vehicle.custom_mode)  # its heartbeat, at once
        after = DISARMED_GRACE_S
    elif ending == "new agent":
        vehicle.switch_mode_by_pilot(OFFBOARD)
        after = 0.0
    else:
        vehicle.mute()
        after = VEHICLE_SILENT_S
    time.sleep(after + 1.0)
    last = max(t for t, _ in list(vehicle.visions))
    assert last - ended == pytest.approx(after, abs=2 * FOLLOW_PERIOD_S + 0.25)
    time.sleep(0.3)
    assert max(t for t, _ in list(vehicle.visions)) == last


def test_with_vision_off_nothing_is_relayed():
    vehicle = VehicleDouble(PX4, airborne=True)
    mocap = StillPoses(body="v")
    proc = agent(vehicle.uri, mocap.uri, "&vision=0")
    try:
        time.sleep(0.3)
        killed = time.monotonic()
        proc.kill()
        proc.wait()
        time.sleep(1.0)
        assert vehicle.modes, "the sentinel did not act"
        assert not visions_between(vehicle, killed - 1.0, killed + 1.0)
    finally:
        mocap.close()
        vehicle.die()


def test_the_flights_links_hand_the_driver_its_mocap():
    """`perchd fly` and `perchd serve` open their links through open_links: the driver
    knows the mocap URI before it connects, so its sentinel can relay it."""
    vehicle, mocap = VehicleDouble(PX4), StillPoses(body="v")
    try:
        links = open_links(f"{vehicle.uri}?mass=0.5", mocap.uri)
        try:
            assert links.driver.mocap_uri == mocap.uri
        finally:
            links.close()
    finally:
        mocap.close()
        vehicle.die()


def test_an_agent_that_ends_normally_hands_its_landing_vehicle_to_the_relay():
    """A flight's end lands the vehicle with the driver's own LAND, and `perchd fly` exits
    while it descends: the sentinel relays the mocap on until the vehicle has disarmed,
    commanding nothing itself."""
    vehicle = VehicleDouble(PX4, airborne=True, mavlink2=True)
    mocap = StillPoses(body="v")
    try:
        proc = agent(vehicle.uri, mocap.uri, fly_s=0.5)
        assert proc.wait(10) == 0
        exited = time.monotonic()
        time.sleep(1.0)
        assert len(visions_between(vehicle, exited + 0.2, exited + 1.0)) >= 0.5 * 0.8 * RATE_HZ
        assert [mode for _, mode in vehicle.modes][-2:] == [LAND_PX4] * 2  # the driver's
        assert all(t < exited for t, _ in vehicle.modes)  # none from the sentinel
        vehicle.armed = False
        vehicle.switch_mode_by_pilot(vehicle.custom_mode)
        time.sleep(DISARMED_GRACE_S + 0.5)
        last = max(t for t, _ in list(vehicle.visions))
        time.sleep(0.3)
        assert max(t for t, _ in list(vehicle.visions)) == last  # ended after the disarm
    finally:
        mocap.close()
        vehicle.die()


def test_an_agent_killed_between_flights_leaves_the_relay_and_no_command():
    """`perchd serve` after a flight's failsafe: the vehicle descends in the driver's LAND
    while the service feeds it the mocap (perchd/service/idle_feed.py). Killed then, the
    agent's sentinel relays the mocap and commands nothing: the vehicle is no longer
    perchd's to fly, and the EKF keeps its position."""
    vehicle = VehicleDouble(PX4, airborne=True, mavlink2=True)
    mocap = StillPoses(body="v")
    proc = agent(vehicle.uri, mocap.uri, fly_s=0.5, serving=True)
    try:
        assert proc.stdout.readline().strip() == "between flights"
        assert vehicle.wait_for(lambda: vehicle.custom_mode == LAND_PX4, 2.0)
        time.sleep(1.5)  # the keep-alive has seen the LAND taken: not flying any more
        killed = time.monotonic()
        proc.kill()
        proc.wait()
        time.sleep(2.0)
        assert len(visions_between(vehicle, killed + 0.2, killed + 2.0)) >= 0.5 * 1.8 * RATE_HZ
        assert all(t < killed for t, _ in vehicle.modes)  # no brake, no LAND from it
        assert all(t < killed for t in (x.t for x in vehicle.targets))
    finally:
        proc.kill()
        mocap.close()
        vehicle.die()


def test_a_mavlink1_encoder_relays_each_pose_without_the_covariance():
    """The relay's frames come from vision_message in whichever protocol its encoder
    speaks; pymavlink picks that per process (a MAVLink 2 vehicle switches it), so the
    MAVLink 1 path is checked on the v1 dialect itself: a v1 frame, no covariance field,
    the position in NED by yaw0 and the pose's stamp."""
    from pymavlink.dialects.v10 import common as v10

    pose = Pose("v", 7, 12.5, (-3.0, 0.2, 1.0), (0.0, 0.0, 0.0, 1.0))
    encoder = v10.MAVLink(None, 255, 190)
    frame = vision_message(encoder, vision_estimate(pose, math.radians(YAW0_DEG))).pack(encoder)
    assert frame[0] == 0xFE
    msg = v10.MAVLink(None).parse_char(frame)
    assert msg.get_type() == "VISION_POSITION_ESTIMATE" and msg.usec == 12_500_000
    assert (msg.x, msg.y, msg.z) == pytest.approx(ned(pose.p, YAW0_DEG), abs=1e-5)
    assert not hasattr(msg, "covariance") or not any(msg.covariance)


def test_a_mocap_the_sentinel_cannot_start_costs_the_relay_not_the_land():
    """The relay's source fails to start at the death (a NatNet server that does not
    answer): the brake and LAND are flown as ever, and nothing is relayed."""
    vehicle = VehicleDouble(PX4, airborne=True, mavlink2=True)
    mocap = StillPoses(body="v", rate_hz=RATE_HZ)
    silent = "natnet://127.0.0.1:9?body=v&transport=unicast&timeout=0.5"
    try:
        killed = killed_agent(vehicle, mocap, relayed=silent)
        assert vehicle.wait_for(lambda: [m for t, m in vehicle.modes if t > killed], 3.0)
        time.sleep(2.0)
        assert next(m for t, m in vehicle.modes if t > killed) == LAND_PX4
        assert not visions_between(vehicle, killed + 0.1, time.monotonic())
    finally:
        mocap.close()
        vehicle.die()


def test_a_close_without_hand_over_leaves_nothing_relaying():
    """`perchd serve` replacing its links to the same vehicle (a reload): the new links feed
    it, so the old driver's close releases its sentinel instead of handing it the landing.
    The default close of the same flight hands over (the test above)."""
    vehicle = VehicleDouble(PX4, airborne=True, mavlink2=True)
    mocap = StillPoses(body="v", rate_hz=RATE_HZ)
    links = open_links(f"{vehicle.uri}?mass=0.5&yaw0={YAW0_DEG}", mocap.uri)
    try:
        links.driver.engage(links.source.latest)
        end, seq = time.monotonic() + 0.5, -1
        while time.monotonic() < end:
            pose = links.source.wait(seq, 0.05)
            if pose is not None:
                seq = pose.seq
                links.driver.observe_pose(pose)
        assert vehicle.armed and visions_between(vehicle, end - 0.3, end)
        links.close(hand_over=False)
        closed = time.monotonic()
        time.sleep(1.5)
        assert not visions_between(vehicle, closed + 0.2, closed + 1.5)
        assert [mode for _, mode in vehicle.modes][-2:] == [LAND_PX4] * 2  # its own LAND
    finally:
        links.close()
        mocap.close()
        vehicle.die()
