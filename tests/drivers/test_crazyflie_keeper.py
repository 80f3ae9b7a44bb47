"""The Crazyflie link keeper (drivers/cflink.py): an agent that dies mid-approach gets a
descent and a stop from the keeper (here without the mocap: its open-loop sink), over cflib's real udp:// link to the CRTP
responder; a keeper that dies is a named lost link (docs/safety.md, "When the agent dies")."""

from __future__ import annotations

import math
import os
import signal
import socket
import statistics
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from crtp_responder import CrtpResponder
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from lateness import assert_lasted
from ticks import level

from perchd.core.runtime import Runtime
from perchd.core.types import EndReason
from perchd.drivers import cflink, cfsink
from perchd.drivers.base import open_driver
from perchd.drivers.crazyflie import KEEPER_START_S
from perchd.drivers.mavlink.brake import BRAKE_ACCEL_MPS2
from perchd.drivers.thrust import CrazyflieThrust

pytest.importorskip("cflib")

ROOT = Path(__file__).parents[2]
HOVER_N = 0.030 * 9.81  # the default thrust model's vehicle
PITCH, THRUST_N = 0.2, 1.15 * HOVER_N  # mid-approach: tilted, more than the weight
AGENT = textwrap.dedent(f"""
    import math, sys, time
    from perchd.drivers.base import open_driver
    from perchd.core.runtime import Runtime
    from perchd.core.types import Phase, Pose, Setpoint
    cf = open_driver(sys.argv[1], Runtime.real())
    speed = float(sys.argv[2]) if len(sys.argv) > 2 else None
    yaw = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
    q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    cf.connect()
    print(cf._keeper.pid, flush=True)
    k = 0
    while True:  # 100 Hz, as the loop streams
        if speed is not None:  # mocap along world X, the body yawed by yaw [rad]
            now = time.monotonic()
            cf.observe_pose(Pose("cf", k, now, (speed * now, 0.0, 1.0), q))
        cf.send(Setpoint(k * 0.01, 0.0, {PITCH}, 0.0, {THRUST_N}, k, Phase.STAGE1))
        if k == 30:
            print("streaming", flush=True)
        k += 1
        time.sleep(0.01)
""")


@pytest.fixture
def responder():
    r = CrtpResponder()
    yield r
    r.close()


def start_agent(uri: str, *speed: str) -> tuple[subprocess.Popen, int]:
    """A process that owns a driver and streams a tilted stage-1 setpoint (with a `speed`
    [m/s], mocap moving along world X beside it); its keeper's pid."""
    agent = subprocess.Popen(
        [sys.executable, "-c", AGENT, uri, *speed],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    keeper_pid = int(agent.stdout.readline())
    assert agent.stdout.readline().strip() == "streaming"
    return agent, keeper_pid


def gone(pid: int) -> bool:
    """Exited: no such process, or a zombie waiting for whoever inherited it."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def check_descent_then_stop(
    responder: CrtpResponder, t_dead: float, keeper_pid: int, height_m: float | None = None
) -> None:
    """Without the mocap (none bound): the open-loop sink, level, its kick below the hover,
    then hover less the margin (below the hold, above the kick), stopped by its bound."""
    hold = CrazyflieThrust().units(THRUST_N * math.cos(PITCH))
    last = CrazyflieThrust().units(THRUST_N)
    bound = cfsink.KICK_S + (
        cfsink.OPEN_UNKNOWN_S
        if height_m is None
        else height_m / cfsink.OPEN_SINK_MPS + cfsink.OPEN_SPARE_S
    )
    assert responder.wait_for(lambda: responder.stops(), timeout=bound + 1.5)
    stop_t = responder.stops()[0].t
    after = [s for s in responder.setpoints() if t_dead < s.t < stop_t]
    tail = [s for s in after if (s.roll_deg, s.wire_pitch_deg) == (0.0, 0.0)]
    assert after and after[-1] in tail  # levelled, at the latest by the keeper's first tick
    thrusts = [s.thrust for s in tail]
    assert all(0 < t <= hold < last for t in thrusts)  # never the tilted thrust, level
    kick = thrusts.index(min(thrusts))
    # the push: KICK_FRACTION of the hover the keeper learned (between the model's and the hold)
    assert CrazyflieThrust().units(cfsink.KICK_FRACTION * HOVER_N) - 1 <= thrusts[kick]
    assert thrusts[kick] <= CrazyflieThrust().units(cfsink.KICK_FRACTION * THRUST_N) + 1
    assert thrusts[kick:] == sorted(thrusts[kick:])  # ... then back up ...
    sink = thrusts[-1]  # ... to hover less the margin: a held sink, not a fall
    assert CrazyflieThrust().units(HOVER_N * (1 - 2 * cfsink.SINK_MARGIN)) < sink < hold
    assert bound - 0.1 <= stop_t - t_dead <= bound + cflink.SILENT_S + 0.3  # at the bound
    assert not [s for s in responder.setpoints() if s.t > stop_t]  # nothing re-arms
    deadline = time.monotonic() + 2.0
    while not gone(keeper_pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert gone(keeper_pid)  # no orphan: it exits after the stop


def test_sigkill_of_the_agent_gets_a_level_descent_then_the_stop(responder):
    agent, keeper_pid = start_agent(responder.uri)
    agent.kill()  # SIGKILL
    t_dead = time.monotonic()
    agent.wait()
    check_descent_then_stop(responder, t_dead, keeper_pid)
    print(f"\nstop {responder.stops()[0].t - t_dead:.3f} s after SIGKILL")


def expected_lean(yaw_deg: float) -> tuple[float, float]:
    """[rad] (roll, pitch) on cflib's wire that decelerates a body yawed yaw_deg (world
    Z up) flying along world +X at BRAKE_ACCEL_MPS2: the acceleration wanted is along world
    -X; split into the body's forward and right, nose up (positive on the wire) brakes
    forward, right side down (positive roll) pushes right."""
    yaw = math.radians(yaw_deg)
    forward = -BRAKE_ACCEL_MPS2 * math.cos(yaw)
    right = -BRAKE_ACCEL_MPS2 * math.sin(yaw)  # world -X seen from a body facing +Y: left
    pitch = math.atan2(-forward, 9.81)
    return math.atan2(right * math.cos(pitch), 9.81), pitch


@pytest.mark.parametrize("yaw_deg", [0.0, 90.0, -150.0])
def test_an_agent_killed_at_speed_has_the_keeper_brake_before_the_descent(responder, yaw_deg):
    """At 0.9 m/s along world X the keeper first leans the vehicle against it at
    BRAKE_ACCEL_MPS2 for 0.3 s (0.9 / 3): facing along X, nose up on the wire and level in
    roll; facing +Y, a roll to its left; facing back and aside, both. Its thrust is the
    descent's, tilt-compensated through the thrust model; then it descends level and
    stops, as without a brake and as soon."""
    agent, keeper_pid = start_agent(responder.uri, "0.9", str(math.radians(yaw_deg)))
    time.sleep(0.3)
    agent.kill()
    t_dead = time.monotonic()
    agent.wait()
    check_descent_then_stop(responder, t_dead, keeper_pid, height_m=1.0)
    (roll, pitch), model = expected_lean(yaw_deg), CrazyflieThrust()
    lean = [
        s
        for s in responder.setpoints()  # the agent's own last ones pitch the other way
        if s.t > t_dead
        and abs(s.wire_pitch_deg - math.degrees(pitch)) < 0.01
        and abs(s.roll_deg - math.degrees(roll)) < 0.01
    ]
    assert len(lean) >= 8
    assert_lasted(lean[-1].t - t_dead, 0.3, early_s=0.08)
    hold_n = THRUST_N * math.cos(PITCH)
    hold = model.units(hold_n)
    factor = model.units(hold_n / (math.cos(roll) * math.cos(pitch))) / hold
    thrusts = [s.thrust for s in lean]  # the descent's kick, tilt-compensated
    assert thrusts[0] <= int(hold * factor)  # never above the hold
    # the kick: KICK_FRACTION of the hover the keeper learned (the model's .. the hold's)
    kick = [int(model.units(cfsink.KICK_FRACTION * n) * factor) for n in (HOVER_N, hold_n)]
    assert kick[0] - 1 <= min(thrusts) <= kick[1] + 1


def test_a_hung_agent_is_a_dead_agent_after_the_keepers_silence_limit(responder):
    agent, keeper_pid = start_agent(responder.uri)
    try:
        agent.send_signal(signal.SIGSTOP)
        t_hung = time.monotonic()
        check_descent_then_stop(responder, t_hung, keeper_pid)
        assert responder.stops()[0].t - t_hung >= cflink.SILENT_S + cfsink.OPEN_UNKNOWN_S
    finally:
        agent.kill()
        agent.wait()


def test_a_dead_keeper_is_a_named_lost_link(responder):
    with open_driver(responder.uri, Runtime.real()) as cf:
        cf.send(level(HOVER_N))
        assert cf.health().ok
        os.kill(cf._keeper.pid, signal.SIGKILL)
        assert responder.wait_for(lambda: not cf.health().ok)
        assert "link keeper exited" in cf.health().detail


CONNECT_THEN_DIE = textwrap.dedent(f"""
    import os, sys, time
    from perchd.core import childproc
    from perchd.core.errors import LinkError
    from perchd.core.runtime import Runtime
    from perchd.core.types import Phase, Setpoint
    from perchd.drivers.base import open_driver

    start = childproc.start
    def start_and_tell(*args):  # the keeper's pid, which a failed connect forgets
        proc = start(*args)
        print(proc.pid, flush=True)
        return proc
    childproc.start = start_and_tell
    cf = open_driver(sys.argv[1], Runtime.real())
    try:
        cf.connect()
    except LinkError:
        sys.exit(3)  # as `perchd fly` after its one line
    for k in range(int(sys.argv[2])):  # 100 Hz of level hover thrust
        cf.send(Setpoint(k * 0.01, 0.0, 0.0, 0.0, {HOVER_N}, k, Phase.STAGE1))
        time.sleep(0.01)
    os._exit(0)  # dies holding the link, as a killed agent does
""")
KEEPER_EXIT_S = 1.0
"""[s] a keeper with nothing to land is gone this soon after its agent (its open-loop
descent alone lasts KICK_S + OPEN_UNKNOWN_S)."""


def connect_then_die(uri: str, ticks: int = 0) -> tuple[subprocess.Popen, int]:
    """An agent that connects to `uri`, sends `ticks` level hover setpoints and dies
    without a close; its keeper's pid. stdout and stderr are pipes the keeper shares."""
    agent = subprocess.Popen(
        [sys.executable, "-c", CONNECT_THEN_DIE, uri, str(ticks)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    return agent, int(agent.stdout.readline())


def wait_gone(pid: int, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while not gone(pid) and time.monotonic() < deadline:
        time.sleep(0.02)
    return gone(pid)


@pytest.mark.solo  # a real-time bound: see tests/conftest.py
@pytest.mark.parametrize("peer", ["refused", "silent"])
def test_a_keeper_whose_link_never_reached_a_vehicle_exits_silently(peer, responder):
    """The connect's echo never came back (a UDP port nobody bound: refused; a vehicle
    that never answers: silent): the agent's connect fails, and its keeper, which only ever
    sent zero-thrust keep-alives, has nothing to land. It says nothing (a user error is
    the agent's one line) and exits at once: no descent, no stop."""
    if peer == "refused":
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            uri = f"udp://127.0.0.1:{s.getsockname()[1]}?wait=0.3"
    else:
        responder.mute()
        uri = f"{responder.uri}?wait=0.3"
    agent, keeper_pid = connect_then_die(uri)
    assert agent.wait(timeout=KEEPER_START_S + 5) == 3  # the connect failed
    assert wait_gone(keeper_pid, KEEPER_EXIT_S)
    _, err = agent.communicate(timeout=5)
    assert err == ""
    assert not responder.stops()
    assert all(s.thrust == 0 for s in responder.setpoints())


@pytest.mark.parametrize("ticks", [0, 30])
def test_a_keeper_that_reached_the_vehicle_still_lands_it_when_the_agent_dies(ticks, responder):
    """The echo came back, so the vehicle is there: at the agent's death the keeper flies
    its descent and stops the motors, and says so. Connected only (zero thrust so far):
    at once; after 0.3 s of hover thrust: the open-loop sink to its bound."""
    agent, keeper_pid = connect_then_die(responder.uri, ticks)
    assert agent.wait(timeout=KEEPER_START_S + 5) == 0  # connected, then died
    t_dead = time.monotonic()
    bound = 0.0 if ticks == 0 else cfsink.KICK_S + cfsink.OPEN_UNKNOWN_S
    assert responder.wait_for(lambda: responder.stops(), timeout=bound + 1.5)
    assert responder.stops()[0].t - t_dead >= bound - 0.1
    if ticks:
        descent = [s for s in responder.setpoints() if t_dead < s.t < responder.stops()[0].t]
        assert descent and all(s.thrust > 0 for s in descent)
    assert wait_gone(keeper_pid, 2.0)
    _, err = agent.communicate(timeout=5)
    assert err.splitlines() == ["perchd cflink: descent over (open loop): motors stopped"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGABRT])
def test_the_keeper_outlives_signals_sent_to_the_whole_group(responder, sig):
    """Ctrl-C, a service stop (SIGTERM) and systemd's watchdog (SIGABRT) reach the whole
    process group: the agent's handler, or the keeper's own descent, needs the keeper alive."""
    with open_driver(responder.uri, Runtime.real()) as cf:
        time.sleep(0.5)  # its handlers are set before it reports the link open
        os.kill(cf._keeper.pid, sig)
        time.sleep(0.1)
        assert cf.health().ok


def test_a_flight_after_a_failsafe_on_the_same_link_is_flown_again(responder):
    """perchd serve keeps the link across flights: the stop latches until the next flight's
    engage, which unlocks the thrust with a zero setpoint before anything else."""
    with open_driver(responder.uri, Runtime.real()) as cf:
        cf.failsafe(EndReason.GEOFENCE)
        assert responder.wait_for(lambda: responder.stops())
        cf.send(level(HOVER_N))  # the ended flight's late tick: never flown
        time.sleep(0.3)
        assert not [s for s in responder.setpoints() if s.t > responder.stops()[0].t]
        cf.engage()
        cf.send(level(HOVER_N))
        assert responder.wait_for(
            lambda: [
                s for s in responder.setpoints() if s.t > responder.stops()[-1].t and s.thrust > 0
            ]
        )
        after = [s.thrust for s in responder.setpoints() if s.t > responder.stops()[-1].t]
    assert after[0] == 0 and max(after) > 0  # the zero-thrust unlock first


class Vertical:
    """A Crazyflie's height under the keeper's level thrust, for the descent: the true
    weight `hover_error` off the thrust model's, the motors' 25 ms lag, linear drag
    0.25 /s, a floor at z = 0 that stops it; mocap poses at 100 Hz with 1 mm of noise."""

    def __init__(self, z_m: float, vz_mps: float, hover_error: float, seed: int = 1) -> None:
        import random

        self.model = CrazyflieThrust()
        self.z, self.vz, self.thrust_n = z_m, vz_mps, self.model.newtons(self.model.hover_units)
        self.weight_n = self.thrust_n * (1.0 + hover_error)
        self.rng, self.t, self.seq = random.Random(seed), 0.0, 0
        self.touchdown_mps: float | None = None
        self.z_max = z_m

    def step(self, units: int, dt: float = 0.001) -> None:
        self.thrust_n += (self.model.newtons(units) - self.thrust_n) * dt / 0.025
        az = 9.81 * (self.thrust_n - self.weight_n) / self.weight_n - 0.25 * self.vz
        self.vz += az * dt
        self.z += self.vz * dt
        self.t += dt
        self.z_max = max(self.z_max, self.z)
        if self.z <= 0.0:
            if self.touchdown_mps is None:
                self.touchdown_mps = -self.vz
            self.z, self.vz = 0.0, max(0.0, self.vz)

    def pose(self):
        from perchd.core.types import Pose

        self.seq += 1
        return Pose(
            "cf",
            self.seq,
            self.t,
            (0.0, 0.0, self.z + self.rng.gauss(0, 0.001)),
            (0.0, 0.0, 0.0, 1.0),
        )


def fly_down(
    plant: Vertical, mocap_until_s: float = 99.0, mocap: bool = True, hold_units: int | None = None
) -> tuple[list[float], float | None]:
    """The keeper's descent against `plant` at its 20 ms ticks, mocap poses every 10 ms until
    mocap_until_s [s]: the true sink at each tick, and when the motors were cut."""
    hover = cfsink.Hover(plant.model, plant.model.newtons(plant.model.hover_units))
    hold = hold_units or plant.model.hover_units
    descent = cflink.Descent(
        0.0,
        cfsink.OpenSink(0.0, hold, hover, plant.z, -plant.vz),  # what the driver last sent
        cfsink.ClosedSink(0.0, hover) if mocap else None,
    )
    sinks, units = [], hold
    for tick in range(int(cflink.DESCENT_MAX_S / cflink.PING_S) + 1):
        now = tick * cflink.PING_S
        if descent.closed is not None and now < mocap_until_s:
            for _ in range(2):
                descent.closed.observe(plant.pose(), plant.t)
        cmd = descent.command(now)
        if cmd is None:
            return sinks, now
        units = cmd[3]
        for _ in range(20):
            plant.step(units)
        sinks.append(-plant.vz)
    return sinks, None


@pytest.mark.parametrize("hover_error", [0.0, -0.05, 0.05])
@pytest.mark.parametrize("vz0", [0.0, 0.8, -1.0])  # hovering, climbing (take-off), sinking
def test_the_closed_loop_holds_the_sink_and_cuts_at_touchdown(hover_error, vz0):
    """From 1 m on the mocap, the hover estimate 5 % either way off: the sink settles at
    SINK_MPS, slows to SINK_LOW_MPS near the floor, touches at no more than that and no
    faster than it was going; the motors are cut once it rests, well before the bound."""
    plant = Vertical(1.0, vz0, hover_error)
    sinks, cut = fly_down(plant)
    mid = [s for h, s in enumerate(sinks) if 1.0 <= h * cflink.PING_S <= 1.4]
    assert plant.touchdown_mps is not None and cut is not None
    assert plant.touchdown_mps <= cfsink.SINK_LOW_MPS + 0.15
    assert plant.z_max - 1.0 <= climb_bound_m(vz0)  # no climb of its own
    assert max(sinks) <= max(-vz0, cfsink.SINK_MPS) + 0.3  # a climb stopped overshoots a little
    if mid and plant.z > 0.4:
        assert statistics.mean(mid) == pytest.approx(cfsink.SINK_MPS, abs=0.08)
    assert cut < cflink.DESCENT_MAX_S - 5.0


def climb_bound_m(vz0: float) -> float:
    """[m] the most a climb met at the death may carry the vehicle up: its stopping distance
    at the keeper's brake, plus the climb over the motors' lag and one tick."""
    climb = max(0.0, vz0)
    return climb**2 / (2.0 * cfsink.BRAKE_MPS2) + climb * (0.025 + cflink.PING_S) + 0.002


@settings(max_examples=60, deadline=None)
@given(
    vz0=st.floats(-1.2, 1.2),
    hover_error=st.floats(-0.015, 0.015),
    hold_share=st.floats(0.9, 1.2),
    z0=st.floats(0.3, 2.0),
    mocap=st.booleans(),
)
def test_whatever_the_motion_at_the_death_no_climb_and_a_soft_touch(
    vz0, hover_error, hold_share, z0, mocap
):
    """Climbing, hovering or sinking at the death, with the last command's thrust anywhere
    from 0.9 to 1.2 x hover (a take-off climbs above it) and the hover estimate within the
    hold's 1.5 %: the vehicle rises no further than its climb carries it and touches the
    floor before the motors are cut. On the mocap at no more than the sink it holds (from
    low heights the low sink is not reached in time); open loop, from up to 1 m (its stated reach), at no more than 1.0 m/s or the
    sink it already had."""
    plant = Vertical(z0, vz0, hover_error)
    if not mocap:
        assume(z0 + climb_bound_m(vz0) <= 1.0)
    hold = plant.model.units(plant.model.newtons(plant.model.hover_units) * hold_share)
    _, cut = fly_down(plant, mocap=mocap, hold_units=hold)
    assert plant.z_max - z0 <= climb_bound_m(vz0)
    assert plant.touchdown_mps is not None and cut is not None
    soft = cfsink.SINK_MPS if mocap else 1.0
    assert plant.touchdown_mps <= max(soft, -vz0)


def test_the_closed_loop_sink_is_held_mid_descent():
    plant = Vertical(2.0, 0.0, 0.05)
    sinks, _ = fly_down(plant)
    held = sinks[int(1.0 / cflink.PING_S) : int(2.5 / cflink.PING_S)]
    assert statistics.mean(held) == pytest.approx(cfsink.SINK_MPS, abs=0.08)
    assert max(held) - min(held) < 0.15


@pytest.mark.parametrize("hover_error", [0.0, -0.015, 0.015])
def test_without_the_mocap_the_open_loop_touches_softly(hover_error):
    """No mocap at all: the kick, then hover less the margin: from 1 m at no more than
    1.0 m/s with the hover estimate 1.5 % either way off (the hold thrusts mean), then the stop at the bound."""
    plant = Vertical(1.0, 0.0, hover_error)
    _, cut = fly_down(plant, mocap=False)
    assert plant.touchdown_mps is not None and plant.touchdown_mps <= 1.0
    assert plant.z_max - 1.0 < 0.005 and cut is not None


def test_a_mocap_lost_mid_descent_goes_on_open_loop_from_what_it_learned():
    """The mocap stops 1.2 s in (~0.5 m down): the open loop takes the learned hover and
    the height last seen; a 6 % hover error is then taken up and the touch stays soft."""
    plant = Vertical(1.2, 0.0, 0.06)
    sinks, cut = fly_down(plant, mocap_until_s=1.2)
    assert plant.touchdown_mps is not None and plant.touchdown_mps <= 1.0
    assert cut is not None
