"""The MAVLink sentinel (drivers/mavlink/sentinel.py): an agent killed while it flies the vehicle
has it in LAND within a tenth of a second, over the very link it flew on; a normal end, a
vehicle not yet taken and one handed back say nothing."""

from __future__ import annotations

import itertools
import math
import socket
import subprocess
import textwrap
import threading
import time

import pytest
from lateness import LATE_S, assert_lasted
from mavlink_double import (
    ARDUPILOT,
    PX4,
    SAFE_PARAMS,
    VehicleDouble,
    agent_process,
    connected,
)
from pymavlink import mavutil

from perchd.core.ned import euler_zyx
from perchd.drivers.mavlink import Connection, dialect_for
from perchd.drivers.mavlink.brake import (
    BRAKE_ACCEL_MPS2,
    BRAKE_DONE_MPS,
    BRAKE_ROUNDS,
    LEVEL_MAX_S,
)
from perchd.drivers.mavlink.relay import RELAY_MAX_S
from perchd.drivers.mavlink.sentinel import (
    BRAKE_PERIOD_S,
    LAND_REPEATS,
    Sentinel,
    agent_death,
    follow_landing,
)

LAND = {ARDUPILOT: 9, PX4: (4 << 16) | (6 << 24)}  # the double's custom_mode for LAND


pytestmark = pytest.mark.solo  # real-time bounds: see tests/conftest.py


@pytest.fixture
def airborne():
    """make(autopilot) -> an airborne VehicleDouble, closed after the test."""
    made: list[VehicleDouble] = []

    def make(autopilot: int = ARDUPILOT) -> VehicleDouble:
        made.append(VehicleDouble(autopilot, airborne=True))
        return made[-1]

    yield make
    for vehicle in made:
        vehicle.die()


def agent(
    uri: str, engage: bool, speed: float | None = None, poses_for_s: float = 1e9
) -> subprocess.Popen:
    """A process that connects perchd's driver to `uri` (engaging it when asked), says
    "ready" and then streams a pitched setpoint at 100 Hz until it is killed; with a
    `speed` [m/s], mocap poses moving along world X (north: yaw0 = 0) go to the driver
    beside it, for the first poses_for_s [s]."""
    code = textwrap.dedent(f"""
        import time
        from perchd.core.runtime import Runtime
        from perchd.core.types import Phase, Pose, Setpoint
        from perchd.drivers.base import open_driver
        d = open_driver({uri!r} + "?mass=0.5&vision=0", Runtime.real())
        d.connect()
        if {engage}:
            d.engage()
        print("ready", flush=True)
        t0, i = time.monotonic(), 0
        while True:
            now, i = time.monotonic(), i + 1
            if {speed} is not None and now - t0 < {poses_for_s}:
                d.observe_pose(Pose("v", i, now, ({speed} * now, 0.0, 1.0), (0, 0, 0, 1)))
            d.send(Setpoint(0.0, 0.0, 0.2, 0.0, 5.0, 1, Phase.STAGE1))
            time.sleep(0.01)
    """)
    return agent_process(code)


def modes_after_kill(
    vehicle: VehicleDouble, engage: bool = True, flown_s: float = 0.3, **poses: float
) -> list[tuple[float, int]]:
    """(seconds after the SIGKILL, custom mode) of every mode the vehicle was switched to;
    the agent is killed flown_s [s] after it says ready."""
    killed = kill_agent(vehicle, engage, flown_s, **poses)
    return [(t - killed, mode) for t, mode in vehicle.modes if t > killed]


def kill_agent(
    vehicle: VehicleDouble, engage: bool, flown_s: float, then=None, **poses: float
) -> float:
    """time.monotonic() of the SIGKILL; returns once the sentinel has had time to act;
    then(): called right after the kill."""
    proc = agent(vehicle.uri, engage, **poses)
    time.sleep(flown_s)
    killed = time.monotonic()
    proc.kill()
    if then is not None:
        then()
    proc.wait()
    time.sleep(LAND_REPEATS * 0.1 + 0.5)
    return killed


@pytest.mark.parametrize("autopilot", [ARDUPILOT, PX4], ids=["ardupilot", "px4"])
def test_a_killed_agent_has_the_vehicle_landing_within_a_tenth_of_a_second(airborne, autopilot):
    """Before, the vehicle flew the last pitched setpoint for GUID_TIMEOUT / COM_OF_LOSS_T
    and only then took its own failsafe."""
    after = modes_after_kill(airborne(autopilot))
    assert after, "nothing was commanded after the kill"
    assert after[0][0] < 0.1
    assert {mode for _, mode in after} == {LAND[autopilot]}
    assert len(after) == LAND_REPEATS  # repeated: a datagram may be lost


@pytest.mark.parametrize("autopilot", [ARDUPILOT, PX4], ids=["ardupilot", "px4"])
def test_a_vehicle_killed_at_speed_is_braked_levelled_then_landed(airborne, autopilot):
    """At 0.9 m/s north the sentinel first leans it back (nose up, level in roll, at the
    heading flown) at BRAKE_ACCEL_MPS2 for 0.3 s (0.9 / 3), then holds it level at the
    hover thrust for LEVEL_MAX_S (this vehicle sends no velocity of its own to end that
    sooner), then commands LAND."""
    vehicle = airborne(autopilot)
    killed = kill_agent(vehicle, True, 0.5, speed=0.9)
    land = next(t for t, _ in vehicle.modes if t > killed)
    sent = [t for t in vehicle.targets if killed + 0.005 < t.t < land]
    lean = [t for t in sent if t.q != (1.0, 0.0, 0.0, 0.0)]
    level = sent[len(lean) :]
    assert len(lean) >= 10 and all(t.q == lean[0].q for t in lean)
    assert lean[0].t - killed < 0.1  # braking at once
    assert_lasted(lean[-1].t - lean[0].t, 0.3, early_s=2 * BRAKE_PERIOD_S)
    w, x, y, z = lean[0].q
    roll, pitch, yaw = euler_zyx((x, y, z, w))
    assert pitch == pytest.approx(math.atan2(BRAKE_ACCEL_MPS2, 9.81), abs=1e-5)
    assert (roll, yaw) == pytest.approx((0.0, 0.0), abs=1e-5)
    hover = SAFE_PARAMS[autopilot][dialect_for(autopilot).hover_param]
    assert len(level) >= 10 and all(t.thrust == pytest.approx(hover) for t in level)
    assert_lasted(land - lean[-1].t, LEVEL_MAX_S)
    assert {mode for t, mode in vehicle.modes if t > killed} == {LAND[autopilot]}


def nose_up(q: tuple[float, float, float, float]) -> float:
    """[rad] NED pitch of a (w, x, y, z) attitude."""
    w, x, y, z = q
    return euler_zyx((x, y, z, w))[1]


def land_after_braking(vehicle: VehicleDouble, slowed_after_s: float) -> float:
    """[s] from the kill at 0.9 m/s to the first LAND, the vehicle's own velocity (north)
    0.9 m/s until slowed_after_s after the kill, then BRAKE_DONE_MPS / 2."""
    vehicle.velocity_ned = (0.9, 0.0, 0.0)

    def slow() -> None:
        vehicle.velocity_ned = (BRAKE_DONE_MPS / 2, 0.0, 0.0)

    killed = kill_agent(
        vehicle, True, 0.5, lambda: threading.Timer(slowed_after_s, slow).start(), speed=0.9
    )
    deadline = time.monotonic() + 3.0
    while not any(t > killed for t, _ in vehicle.modes) and time.monotonic() < deadline:
        time.sleep(0.05)
    return next(t - killed for t, _ in vehicle.modes if t > killed)


def test_the_level_phase_ends_when_the_vehicle_says_it_has_stopped(airborne):
    """PX4's LAND lands where its own braking would end from the speed it has: LAND waits
    for the vehicle's velocity, and for no longer."""
    assert_lasted(land_after_braking(airborne(PX4), 0.45), 0.45)


def test_a_vehicle_still_moving_is_braked_again_against_its_own_velocity(airborne):
    """The mocap's 0.9 m/s was too little (the vehicle says 0.9 still after the level
    phase): a second lean against that, and LAND once it says stopped."""
    vehicle = airborne(PX4)
    land = land_after_braking(vehicle, 1.0)  # in the second lean, which is flown whole
    assert_lasted(land, 1.1)
    leans = [t.t for t in vehicle.targets if nose_up(t.q) > 0.25]  # the agent's is down
    starts = [b for a, b in itertools.pairwise(leans) if b - a > 0.2]
    assert len(starts) == 1
    assert_lasted(starts[0] - leans[0], 0.3 + LEVEL_MAX_S, early_s=BRAKE_PERIOD_S)


def test_braking_ends_after_its_rounds_whatever_the_vehicle_says(airborne):
    rounds = BRAKE_ROUNDS * (0.3 + LEVEL_MAX_S)
    # six phases, each ending on a wakeup that may be late
    assert_lasted(land_after_braking(airborne(PX4), 9.0), rounds, late_s=2 * LATE_S)


def test_the_lean_is_flown_whole_whatever_the_vehicle_says(airborne):
    """The lean takes off the velocity measured; the attitude's lag delays the stop, so a
    velocity that reads stopped early (a lag of its own) does not cut the lean short."""
    assert_lasted(land_after_braking(airborne(PX4), 0.1), 0.3)


def test_a_brake_left_before_the_mocap_stopped_is_not_flown(airborne):
    """Poses stopped 0.5 s before the kill: the velocity is not known, LAND at once."""
    after = modes_after_kill(airborne(PX4), flown_s=0.6, speed=0.9, poses_for_s=0.1)
    assert after and after[0][0] < 0.1


def test_a_vehicle_not_yet_taken_is_left_alone(airborne):
    assert modes_after_kill(airborne(), engage=False) == []


def test_a_normal_close_lands_once_and_the_sentinel_adds_nothing(airborne):
    vehicle = airborne()
    drv = connected(vehicle)
    closed = time.monotonic()
    drv.close()
    time.sleep(1.0)
    after = [mode for t, mode in vehicle.modes if t >= closed]
    assert after == [LAND[ARDUPILOT]] * 2  # the driver's own close(): LAND, twice


def died(*messages: bytes) -> str:
    """What the sentinel does when the driver's end closes after `messages`."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    for msg in messages:
        ours.send(msg)
    ours.close()
    death = agent_death(theirs)
    return "nothing" if death is None else "relay" if death.handover else "land"


def test_the_sentinel_lands_only_on_a_death_while_flying():
    assert died(b"F") == "land"
    assert died(b"D", b"F") == "land"
    assert died() == "nothing"  # never flown: not ours
    assert died(b"D") == "nothing"
    assert died(b"F", b"D") == "relay"  # LAND taken, or the pilot's mode: only the mocap
    assert died(b"F", b"R") == "nothing"
    assert died(b"F", b"L") == "relay"


def test_over_a_stream_link_the_land_command_is_one_whole_frame():
    """TCP (ArduPilot SITL's link) and serial: written on the same stream."""
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    got: list[bytes] = []

    def serve() -> None:
        peer, _ = server.accept()
        peer.settimeout(3.0)
        try:
            while chunk := peer.recv(4096):
                got.append(chunk)
        except TimeoutError:
            pass

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255)
    sentinel = Sentinel(Connection(conn), (1, 1), (9, 0))
    sentinel.flying(True)
    sentinel._sock.close()  # the driver's end gone without a release, as on SIGKILL
    thread.join(5.0)
    conn.close()
    parser = mavutil.mavlink.MAVLink(None)
    msgs = [m for m in (parser.parse_buffer(b"".join(got)) or [])]
    assert len(msgs) == LAND_REPEATS
    assert all(
        m.get_type() == "COMMAND_LONG"
        and m.command == 176
        and m.param2 == 9
        and (m.target_system, m.target_component) == (1, 1)
        for m in msgs
    )


def test_over_a_udpin_link_the_land_goes_to_the_vehicle_heard():
    """PX4's offboard link: perchd listens (udpin) and answers the address PX4 sent from."""
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255)
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(2.0)
    px4 = mavutil.mavlink.MAVLink(None, 1, 1)
    vehicle.sendto(
        px4.heartbeat_encode(2, 12, 0, 0, 4).pack(px4), ("127.0.0.1", conn.port.getsockname()[1])
    )
    assert conn.recv_match(type="HEARTBEAT", blocking=True, timeout=2.0) is not None
    sentinel = Sentinel(Connection(conn), (1, 1), (4, 6))
    sentinel.flying(True)
    sentinel._sock.close()
    parser = mavutil.mavlink.MAVLink(None)
    msgs = [parser.parse_char(vehicle.recv(512)) for _ in range(LAND_REPEATS)]
    conn.close()
    assert all(m.command == 176 and (m.param2, m.param3) == (4, 6) for m in msgs)


def test_a_brake_that_fails_still_ends_in_land(monkeypatch):
    """The brake is the sentinel's first act, LAND its duty: an error in the one must not
    cost the other."""
    import signal

    from perchd.drivers.mavlink import sentinel
    from perchd.drivers.mavlink.brake import brake_for

    def broken(*_: object) -> None:
        raise RuntimeError("a brake that cannot be flown")

    monkeypatch.setattr(sentinel, "fly_brake", broken)
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(2.0)
    link = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    ours.send(b"F")
    ours.send(b"B" + brake_for((1.0, 0.0, 0.0), 0.0, 0.4, time.monotonic()).pack())
    ours.close()
    dest = f"127.0.0.1:{vehicle.getsockname()[1]}"
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGABRT)}
    try:
        argv = [
            str(theirs.detach()),
            str(link.fileno()),
            dest,
            "255",
            "190",
            "1",
            "1",
            "4",
            "6",
            "-",
        ]
        assert sentinel.main(argv) == 0
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
    parser = mavutil.mavlink.MAVLink(None)
    msgs = [parser.parse_char(vehicle.recv(512)) for _ in range(LAND_REPEATS)]
    link.close()
    vehicle.close()
    assert all(m.command == 176 and (m.param2, m.param3) == (4, 6) for m in msgs)


class HeardLink:
    """The follow phase's view of a vehicle heard just now, armed, in a pilot's mode: the
    link's state the sentinel reads (a socket for its select)."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.fd = self.sock.fileno()
        self.mode, self.armed, self.heard_s = 3 << 16, True, time.monotonic()

    def poll(self) -> None:
        self.heard_s = time.monotonic()


class LiveRelay:
    alive = True


def test_the_relay_ends_relay_max_s_after_the_death_whatever_the_vehicle_does():
    """A vehicle still armed RELAY_MAX_S after the death is someone else's: the relay ends."""
    link = HeardLink()
    try:
        start = time.monotonic()
        assert (
            follow_landing(link, LiveRelay(), 6 << 16, start - RELAY_MAX_S + 0.3)
            == f"{RELAY_MAX_S:g} s after the death"
        )
        assert 0.25 <= time.monotonic() - start <= 1.0
    finally:
        link.sock.close()
