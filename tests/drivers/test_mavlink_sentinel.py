"""The MAVLink sentinel (drivers/mavsentinel.py): an agent killed while it flies the vehicle
has it in LAND within a tenth of a second, over the very link it flew on; a normal end, a
vehicle not yet taken and one handed back say nothing."""

from __future__ import annotations

import socket
import subprocess
import sys
import textwrap
import threading
import time

import pytest
from mavlink_double import ARDUPILOT, PX4, VehicleDouble, connected
from perchd.drivers.mavsentinel import LAND_REPEATS, Sentinel, agent_died_flying
from pymavlink import mavutil

LAND = {ARDUPILOT: 9, PX4: (4 << 16) | (6 << 24)}  # the double's custom_mode for LAND


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


def agent(uri: str, engage: bool) -> subprocess.Popen:
    """A process that connects perchd's driver to `uri` (engaging it when asked), says
    "ready" and then streams a pitched setpoint at 100 Hz until it is killed."""
    code = textwrap.dedent(f"""
        import time
        from perchd.core.runtime import Runtime
        from perchd.core.types import Phase, Setpoint
        from perchd.drivers.base import open_driver
        d = open_driver({uri!r} + "?mass=0.5", Runtime.real())
        d.connect()
        if {engage}:
            d.engage()
        print("ready", flush=True)
        while True:
            d.send(Setpoint(0.0, 0.0, 0.2, 0.0, 5.0, 1, Phase.STAGE1))
            time.sleep(0.01)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True,
                            stderr=subprocess.DEVNULL)
    assert proc.stdout.readline().strip() == "ready"
    return proc


def modes_after_kill(vehicle: VehicleDouble, engage: bool = True) -> list[tuple[float, int]]:
    """(seconds after the SIGKILL, custom mode) of every mode the vehicle was switched to."""
    proc = agent(vehicle.uri, engage)
    time.sleep(0.3)
    killed = time.monotonic()
    proc.kill()
    proc.wait()
    time.sleep(LAND_REPEATS * 0.1 + 0.5)
    return [(t - killed, mode) for t, mode in vehicle.modes if t > killed]


@pytest.mark.parametrize("autopilot", [ARDUPILOT, PX4], ids=["ardupilot", "px4"])
def test_a_killed_agent_has_the_vehicle_landing_within_a_tenth_of_a_second(airborne,
                                                                          autopilot):
    """Before, the vehicle flew the last pitched setpoint for GUID_TIMEOUT / COM_OF_LOSS_T
    and only then took its own failsafe."""
    after = modes_after_kill(airborne(autopilot))
    assert after, "nothing was commanded after the kill"
    assert after[0][0] < 0.1
    assert {mode for _, mode in after} == {LAND[autopilot]}
    assert len(after) == LAND_REPEATS  # repeated: a datagram may be lost


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


def died_flying(*messages: bytes) -> bool:
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    for msg in messages:
        ours.send(msg)
    ours.close()
    return agent_died_flying(theirs)


def test_the_sentinel_acts_only_on_a_death_while_flying():
    assert died_flying(b"F")
    assert died_flying(b"D", b"F")
    assert not died_flying()
    assert not died_flying(b"F", b"D")  # LAND taken, or the pilot's mode: not ours
    assert not died_flying(b"F", b"R")


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
    sentinel = Sentinel(conn, (1, 1), (9, 0))
    sentinel.flying(True)
    sentinel._sock.close()  # the driver's end gone without a release, as on SIGKILL
    thread.join(5.0)
    conn.close()
    parser = mavutil.mavlink.MAVLink(None)
    msgs = [m for m in (parser.parse_buffer(b"".join(got)) or [])]
    assert len(msgs) == LAND_REPEATS
    assert all(m.get_type() == "COMMAND_LONG" and m.command == 176 and m.param2 == 9
               and (m.target_system, m.target_component) == (1, 1) for m in msgs)


def test_over_a_udpin_link_the_land_goes_to_the_vehicle_heard():
    """PX4's offboard link: perchd listens (udpin) and answers the address PX4 sent from."""
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255)
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(2.0)
    px4 = mavutil.mavlink.MAVLink(None, 1, 1)
    vehicle.sendto(px4.heartbeat_encode(2, 12, 0, 0, 4).pack(px4),
                   ("127.0.0.1", conn.port.getsockname()[1]))
    assert conn.recv_match(type="HEARTBEAT", blocking=True, timeout=2.0) is not None
    sentinel = Sentinel(conn, (1, 1), (4, 6))
    sentinel.flying(True)
    sentinel._sock.close()
    parser = mavutil.mavlink.MAVLink(None)
    msgs = [parser.parse_char(vehicle.recv(512)) for _ in range(LAND_REPEATS)]
    conn.close()
    assert all(m.command == 176 and (m.param2, m.param3) == (4, 6) for m in msgs)
