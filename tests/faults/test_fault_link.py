"""Link faults: the driver's peer stops answering, answers slowly, goes away and comes back.

Simulated time (the loopback driver's fault switch) for detection-time sweeps; real drivers
on loopback sockets in real time (cflib's udp:// link to the CRTP responder and the MAVLink
double, through a delaying/pausing UDP relay; ZMQ to a subscriber) for what the drivers'
own health rules do. A lost link ends the flight LOST_LINK within 3 ticks of the driver
declaring it, with one failsafe; a link that comes back never gets thrust again."""

from __future__ import annotations

import threading
import time

import pytest
import zmq
from aborts import TRIGGER_T, assert_failsafe_and_closed_log
from caseplans import case1_ipts
from faultsim import TICK, fly, injected, report
from rigs import MASS, CrazyflieRig, MavlinkRig, ZmqRig, bridge
from udp_relay import UdpRelay

from perchd.core.runtime import Runtime
from perchd.core.types import EndReason
from perchd.drivers.base import open_driver
from perchd.flight.run import FlightAbort
from perchd.flight.run import fly as fly_real
from perchd.logs.flightlog import read_log
from perchd.mocap.base import open_source

PING_S = 0.02
"""[s] the crazyflie driver's echo period: its 'last heard' is at most this old when the
peer falls silent (drivers/crazyflie.PING_S)."""


# --- simulated time: the loopback driver's switch -------------------------------------------
class CutAfterTick:
    """An on_tick hook: right after the first tick at or past t0 [s] the link dies (so it is
    dead from the next tick on); it comes back `back_s` [s] later."""

    def __init__(self, t0: float, back_s: float = 0.05) -> None:
        self.t0, self.back_s = t0, back_s
        self.cut_at: float | None = None

    def __call__(self, sim):
        def on_tick(st):
            now = sim.runtime.clock.now()
            if self.cut_at is None and now >= self.t0 - 1e-9:
                self.cut_at = now
                sim.world.faults.link_ok = False
                sim.world.faults.at.append(
                    (now + self.back_s, lambda w: setattr(w.faults, "link_ok", True))
                )

        return on_tick


def test_a_cut_link_ends_the_flight_on_the_next_tick_in_every_phase(tmp_path):
    delays = []
    for at in (0.3, 1.5, TRIGGER_T + 0.2, 3.0, 4.2):
        cut = CutAfterTick(at)
        f = fly(tmp_path, on_tick=cut)
        injected("link cut")
        assert_failsafe_and_closed_log(f.sim, f.res, EndReason.LOST_LINK)
        assert f.end_t - cut.cut_at == pytest.approx(TICK)  # the very next tick
        delays.append(f.end_t - cut.cut_at)
    report(
        "link: loopback link cut (fault switch)",
        "driver health not ok, read at the start of every tick",
        "LOST_LINK, failsafe",
        "motors off (stop setpoint)",
        delays,
    )


def test_a_link_that_comes_back_after_the_abort_gets_no_thrust(tmp_path):
    f = fly(tmp_path, on_tick=CutAfterTick(3.0, back_s=0.03))
    injected("link cut", "link back")
    assert f.res.outcome is EndReason.LOST_LINK
    f.sim.world.advance(f.end_t + 0.5)
    assert f.sim.world.faults.link_ok  # it did come back
    fail = f.sim.world.sent.index(next(s for s in f.sim.world.sent if s.phase.value == "abort"))
    assert all(s.thrust == 0.0 for s in f.sim.world.sent[fail:])
    assert f.sim.world.plant.thrust < 0.01  # the motors spun down and stayed down
    report(
        "link: loopback link back after the abort",
        "-",
        "failsafe is latched: the driver sends nothing more",
        "motors stay off",
    )


@pytest.mark.parametrize("latency", [0.05, 0.1])
def test_a_slow_link_up_to_100_ms_still_perches_inside_the_contact_window(latency, tmp_path):
    f = fly(tmp_path, uri=f"sim://?latency={latency}")
    injected("slow link")
    assert f.res.outcome is EndReason.CONTACT
    assert 0.7 - 0.02 <= f.res.true_contact_speed <= 1.0 + 0.02
    report(
        f"link: commands {1000 * latency:.0f} ms late (loopback)",
        "none needed",
        "flown (the setpoints lead by ff_lead_s)",
        f"perches ({f.res.true_contact_speed:.3f} m/s)",
    )


def test_a_link_200_ms_slow_is_a_lost_link_before_it_flies(tmp_path):
    f = fly(tmp_path, uri="sim://?latency=0.2")
    report(
        "link: commands 200 ms late (loopback)",
        "echo round trip > link_rtt_max_s (0.25 s)",
        f"{f.res.outcome.name}, failsafe",
        "motors off before the approach",
    )
    assert f.res.outcome is EndReason.LOST_LINK and f.res.failsafe_sent
    assert "link too slow: round trip 400 ms > 250 ms" in f.res.detail
    assert f.res.trigger is None  # never reached the trigger: the slow link was seen at once


# --- real drivers, real time ----------------------------------------------------------------
# Each flight below is judged in real time (a pose every period, a link within its timeout):
# `solo`, it runs with the CPU to itself (tests/conftest.py).
class RealFlight:
    """fly() in real time against a real driver; the peer's commands drive a simulated world
    whose mocap the agent reads (tests/drivers/test_lost_link_flight.bridge)."""

    def __init__(self, rig, uri: str) -> None:
        self.rig = rig
        self.runtime = Runtime.real()
        self.source = open_source("sim://", self.runtime)
        self.world = self.runtime.sim
        self.driver = open_driver(uri, self.runtime)
        self.abort = FlightAbort()
        self.marks: dict[str, float] = {}
        self._stop = threading.Event()

    def at_setpoint(self, n: int, name: str, fn) -> None:
        """Run fn once n setpoints have reached the world; remember when (monotonic)."""

        def wait():
            while len(self.world.sent) < n and not self._stop.is_set():
                time.sleep(0.001)
            fn()
            self.marks[name] = time.monotonic()

        threading.Thread(target=wait, daemon=True).start()

    def fly(self, tmp_path, abort_after_s: float | None = None, close: bool = True):
        if abort_after_s is not None:
            self.at_setpoint(int(abort_after_s * 100), "abort", self.abort.request)
        threading.Thread(
            target=bridge, args=(self.rig, self.world, self._stop), daemon=True
        ).start()
        try:
            self.driver.connect()
            self.source.start()
            return fly_real(
                case1_ipts(),
                self.driver,
                self.source,
                self.runtime.clock,
                tmp_path / "f.jsonl",
                abort=self.abort,
                world=self.world,
            )
        finally:
            self._stop.set()
            if close:
                self.close()

    def close(self) -> None:
        self.source.close()
        self.driver.close()


def crazyflie(timeout: float, relay_delay: float | None = None):
    rig = CrazyflieRig()
    relay = None if relay_delay is None else UdpRelay(rig.peer.port, relay_delay)
    port = rig.peer.port if relay is None else relay.port
    return rig, relay, f"udp://127.0.0.1:{port}?timeout={timeout}"


def mavlink(timeout: float, relay_delay: float | None = None):
    rig = MavlinkRig()
    relay = None if relay_delay is None else UdpRelay(rig.peer.port, relay_delay)
    port = rig.peer.port if relay is None else relay.port
    return rig, relay, f"mavlink:udpout:127.0.0.1:{port}?mass={MASS}&timeout={timeout}"


def closing(rig, relay):
    if relay is not None:
        relay.close()
    rig.close()


@pytest.mark.solo
@pytest.mark.parametrize("make", [crazyflie, mavlink], ids=["crazyflie-udp", "mavlink"])
def test_a_peer_that_stops_answering_is_lost_link_within_3_ticks_of_the_timeout(make, tmp_path):
    timeout = 0.1
    rig, relay, uri = make(timeout)
    flight = RealFlight(rig, uri)
    flight.at_setpoint(30, "mute", rig.peer.mute)
    try:
        res = flight.fly(tmp_path)
    finally:
        closing(rig, relay)
    injected("peer mute", real_time=True)
    assert res.outcome is EndReason.LOST_LINK and res.failsafe_sent
    assert flight.driver.failsafe_reasons == [EndReason.LOST_LINK]
    rows, mute = read_log(res.log).rows, flight.marks["mute"]
    assert rows[-1].end == "LOST_LINK"
    assert rows[-1].t > mute + timeout - PING_S - 2 * TICK  # not before the silence rule
    assert len([r for r in rows if r.t > mute + timeout]) <= 3  # and then within 3 ticks
    assert rig.stopped()
    report(
        f"link: {make.__name__} peer stops answering",
        f"silent > timeout (URI timeout=, here {timeout:g} s)",
        "LOST_LINK, failsafe",
        "stop sent (Crazyflie: stop setpoint; MAVLink: LAND)",
        [rows[-1].t - mute],
    )


def fly_slowed(make, delay_s: float, tmp_path, what: str):
    """A real-time flight through a relay delaying every datagram delay_s each way; the
    operator aborts it after 1-2 s if nothing else ends it first."""
    rig, relay, uri = make(timeout=0.5, relay_delay=delay_s)
    flight = RealFlight(rig, uri)
    try:
        res = flight.fly(tmp_path, abort_after_s=1.0 if delay_s < 0.12 else 2.0)
    finally:
        closing(rig, relay)
    injected(what, real_time=True)
    return rig, relay, res


@pytest.mark.solo
@pytest.mark.parametrize("make", [crazyflie, mavlink], ids=["crazyflie-udp", "mavlink"])
def test_a_slow_peer_within_the_round_trip_limit_is_not_a_lost_link(make, tmp_path):
    rig, relay, res = fly_slowed(make, 0.1, tmp_path, "slow peer")
    assert res.outcome is EndReason.OPERATOR_ABORT  # flown until the operator stopped it
    assert relay.forwarded["down"] > 20 and relay.forwarded["up"] > 50
    assert rig.commanded() is not None  # the vehicle got the (late) setpoints
    report(
        f"link: {make.__name__} peer answers 100 ms late each way",
        "none: a 200 ms round trip is inside link_rtt_max_s (0.25 s)",
        "flown",
        "flies on",
    )


@pytest.mark.solo
def test_a_crazyflie_link_slower_than_the_round_trip_limit_is_lost_link(tmp_path):
    _, _, res = fly_slowed(crazyflie, 0.15, tmp_path, "slow crazyflie link")
    assert res.outcome is EndReason.LOST_LINK and res.failsafe_sent
    assert "link too slow: round trip" in res.detail and "> 250 ms" in res.detail
    report(
        "link: crazyflie echo 150 ms late each way",
        "echo round trip (median of 10) > link_rtt_max_s 0.25 s",
        "LOST_LINK, failsafe",
        "stop sent (and repeated)",
    )


def thrust_after(rig, since: float) -> list[float]:
    """[N or normalised] thrust the vehicle received after `since` (monotonic)."""
    if isinstance(rig, CrazyflieRig):
        return [s.thrust for s in rig.peer.setpoints() if s.t > since]
    return [t.thrust for t in rig.peer.targets if t.t > since]


TIMEOUT_S = 0.3
"""[s] the drivers' silence timeout in the outage tests: ten times the 30 ms blip, so a
loaded machine cannot stretch the blip into a loss."""


def outage_then_back(make, tmp_path, blip: bool = True):
    """A 30 ms outage (with blip), later one that lasts, and the link back 0.3 s after the
    abort, the driver still open. Returns (rig, result, marks, ended)."""
    rig, relay, uri = make(timeout=TIMEOUT_S, relay_delay=0.0)
    flight = RealFlight(rig, uri)
    if blip:
        short = lambda: (relay.pause(), threading.Timer(0.03, relay.resume).start())  # noqa
        flight.at_setpoint(30, "pause1", short)
    flight.at_setpoint(60, "pause2", relay.pause)
    try:
        res = flight.fly(tmp_path, close=False)
        ended = time.monotonic()
        time.sleep(0.1)  # what was sent while the link was down is lost, not late
        flight.marks["resume"] = time.monotonic()
        relay.resume()
        time.sleep(0.3)
    finally:
        flight.close()
        closing(rig, relay)
    injected("link blip", "link outage", "link back", real_time=True)
    return rig, res, flight.marks, ended


@pytest.mark.solo
@pytest.mark.parametrize("make", [crazyflie, mavlink], ids=["crazyflie-udp", "mavlink"])
def test_a_short_outage_is_ridden_out_and_a_long_one_is_lost_link_for_good(make, tmp_path):
    rig, res, marks, ended = outage_then_back(make, tmp_path)
    assert res.outcome is EndReason.LOST_LINK and res.failsafe_sent
    rows = read_log(res.log).rows
    assert rows[-1].t > marks["pause2"]  # the first, short outage was flown through
    assert all(t == 0 for t in thrust_after(rig, ended))  # back, and no thrust
    report(f"link: {make.__name__} outage of 30 ms (< timeout)", "-", "flown", "flies on")
    report(
        f"link: {make.__name__} outage longer than the timeout, then back",
        f"silent > timeout ({TIMEOUT_S:g} s)",
        "LOST_LINK, failsafe latched",
        "no thrust after the link returns",
        [rows[-1].t - marks["pause2"]],
    )


def stops_heard(rig) -> list[float]:
    """[s] time.monotonic() of each stop the vehicle heard (stop setpoint, LAND mode)."""
    if isinstance(rig, CrazyflieRig):
        return [d.t for d in rig.peer.stops()]
    return [t for t, mode in rig.peer.modes if mode == 9]  # ARDUPILOT_LAND


@pytest.mark.solo
@pytest.mark.parametrize("make", [crazyflie, mavlink], ids=["crazyflie-udp", "mavlink"])
def test_a_failsafe_sent_into_a_dead_link_reaches_the_vehicle_when_it_returns(make, tmp_path):
    rig, res, marks, ended = outage_then_back(make, tmp_path, blip=False)
    assert res.outcome is EndReason.LOST_LINK and res.failsafe_sent
    heard = stops_heard(rig)
    assert heard and min(heard) > marks["resume"]  # the first stop went into the dead link
    first = min(heard) - marks["resume"]
    assert rig.stopped()
    assert all(t == 0 for t in thrust_after(rig, ended))  # and thrust never came back
    repeat = {
        "crazyflie": "stop every 20 ms for 3 s",
        "mavlink": "LAND every 0.25 s until the heartbeat shows it taken, 10 s at most",
    }[make.__name__]
    report(
        f"link: {make.__name__} failsafe sent while the link is down, link back",
        "-",
        f"LOST_LINK, failsafe repeated by the driver ({repeat})",
        f"stop/LAND heard {1e3 * first:.0f} ms after the link is back",
    )


@pytest.mark.solo
def test_a_zmq_subscriber_that_returns_on_the_same_port_gets_no_setpoint(tmp_path):
    rig = ZmqRig()
    flight = RealFlight(rig, rig.uri)
    flight.at_setpoint(30, "die", rig.peer.die)
    try:
        res = flight.fly(tmp_path, close=False)
        back = zmq.Context.instance().socket(zmq.SUB)
        back.setsockopt(zmq.LINGER, 0)
        back.bind(f"tcp://127.0.0.1:{rig.peer.port}")
        back.setsockopt(zmq.SUBSCRIBE, b"")
        got = back.poll(300)
        back.close(0)
    finally:
        flight.close()
        rig.peer.close()
    injected("subscriber gone", "subscriber back", real_time=True)
    assert res.outcome is EndReason.LOST_LINK and res.failsafe_sent
    assert len([r for r in read_log(res.log).rows if r.t > flight.marks["die"]]) <= 3
    assert not got  # the driver, still open, sends nothing after its failsafe
    report(
        "link: zmq subscriber gone, then back on the same port",
        "XPUB sees the unsubscription",
        "LOST_LINK, failsafe",
        "stop published; nothing after",
    )
