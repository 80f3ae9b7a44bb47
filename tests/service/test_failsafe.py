"""`perchd failsafe` (the units' ExecStopPost=) against real links on loopback: the MAVLink
vehicle double, `perchd sim` over ZMQ, and cflib's udp:// to the CRTP responder."""

import os
import socket
import subprocess
import sys
import threading

import pytest
from crtp_responder import CrtpResponder
from mavlink_double import ARDUPILOT, PX4, VehicleDouble
from svc import SimProcess, perchd

GUIDED_NOGPS, LAND, LOITER = 20, 9, 5  # ArduPilot custom modes
PX4_OFFBOARD, PX4_AUTO_LAND = 6 << 16, (4 << 16) | (6 << 24)


def failsafe(*args: str, **env: str) -> subprocess.CompletedProcess:
    return perchd("failsafe", "--timeout", "3", *args, env={**os.environ, **env})


@pytest.fixture
def double(request):
    autopilot, mode = request.param
    d = VehicleDouble(autopilot, airborne=True)
    d.switch_mode_by_pilot(mode)  # as the service left it
    yield d
    d.die()


def set_modes(d: VehicleDouble) -> list[int]:
    return [m for _, m in d.modes]


@pytest.mark.parametrize(
    "double, land",
    [((ARDUPILOT, GUIDED_NOGPS), LAND), ((PX4, PX4_OFFBOARD), PX4_AUTO_LAND)],
    indirect=["double"],
    ids=["ardupilot", "px4"],
)
def test_mavlink_in_perchds_mode_is_landed(double, land):
    done = failsafe(
        "--driver", double.uri, SERVICE_RESULT="signal", EXIT_CODE="killed", EXIT_STATUS="KILL"
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("\n") == 1 and "LAND commanded" in done.stdout
    assert "(SERVICE_RESULT=signal, EXIT_CODE=killed, EXIT_STATUS=KILL)" in done.stdout
    assert set_modes(double) == [land] and double.custom_mode == land


@pytest.mark.parametrize("double", [(ARDUPILOT, LOITER)], indirect=True)
def test_mavlink_in_a_mode_the_pilot_chose_is_left_alone(double):
    done = failsafe("--driver", double.uri)
    assert done.returncode == 0 and "left to the pilot" in done.stdout
    assert set_modes(double) == [] and double.custom_mode == LOITER


def test_a_disarmed_mavlink_vehicle_needs_nothing():
    d = VehicleDouble(ARDUPILOT)
    try:
        done = failsafe("--driver", d.uri)
    finally:
        d.die()
    assert done.returncode == 0 and "disarmed; nothing to do" in done.stdout
    assert not [c for _, c, _ in d.commands if c == 176]


def test_no_vehicle_is_one_line_and_exit_1_within_the_timeout_unless_the_stop_was_clean():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:  # a port nobody answers on
        s.bind(("127.0.0.1", 0))
        uri = f"mavlink:udpout:127.0.0.1:{s.getsockname()[1]}"
        failed = failsafe("--driver", uri, SERVICE_RESULT="exit-code")
        clean = failsafe("--driver", uri, SERVICE_RESULT="success")
    assert failed.returncode == 1 and failed.stderr.count("\n") == 1
    assert (
        "no heartbeat from the vehicle" in failed.stderr
        and "SERVICE_RESULT=exit-code" in failed.stderr
    )
    assert clean.returncode == 0 and "stopped cleanly after its own failsafe" in clean.stdout


@pytest.mark.slow
def test_zmq_publishes_the_stop_to_the_simulator_using_the_services_config(tmp_path):
    sim = SimProcess()
    try:
        config = tmp_path / "perchd.toml"
        config.write_text(f'version = 1\n[service]\ndriver = "{sim.driver}"\n')
        done = failsafe("--config", str(config))
        summary = sim.summary()
    finally:
        sim.kill()
    assert done.returncode == 0, done.stderr
    assert done.stdout == f"perchd failsafe: {sim.driver}: stop published (end reason SIGNAL)\n"
    assert summary["stops"] == 1


def test_the_in_process_simulator_needs_nothing():
    done = failsafe("--driver", "sim://")
    assert done.returncode == 0 and "nothing to do" in done.stdout


@pytest.fixture
def responder():
    r = CrtpResponder()
    yield r
    r.close()


def test_crazyflie_without_a_keeper_gets_the_stop_setpoint(responder):
    done = failsafe("--driver", responder.uri + "?hover=38790")
    assert done.returncode == 0, done.stderr
    assert "no link keeper left; stop setpoint sent 3 times" in done.stdout
    assert len(responder.stops()) == 3 and responder.setpoints() == []


def test_crazyflie_whose_keeper_still_holds_the_link_is_left_to_it(responder):
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    keeper = subprocess.Popen(
        [sys.executable, "-m", "perchd.drivers.cflink", str(theirs.fileno()), responder.uri, "3.0"],
        pass_fds=(theirs.fileno(),),
    )
    theirs.close()
    agent = threading.Event()  # set: the agent has gone quiet

    def alive() -> None:  # the driver's alive message; without it the keeper lands at once
        while not agent.wait(0.02):
            ours.send(b"A")

    threading.Thread(target=alive, daemon=True).start()  # from the start, as the driver's
    try:
        ours.settimeout(15)
        assert ours.recv(64)[:1] == b"R"  # the keeper has the link open
        done = failsafe("--driver", responder.uri)
        stops = len(responder.stops())
        assert keeper.poll() is None  # it held the link throughout
    finally:
        agent.set()
        keeper.wait(10)  # silent agent: the keeper's own descent, stop and exit
        ours.close()
    assert done.returncode == 0, done.stderr
    assert f"the link keeper (pid {keeper.pid}) still holds the link" in done.stdout
    assert stops == 0  # nothing of the failsafe's own on the link
