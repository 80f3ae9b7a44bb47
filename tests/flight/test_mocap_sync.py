"""In mocap-synchronous mode each pose's arrival releases a tick: the setpoint is computed
from that very pose at once, no pose is ticked on twice, and a silent mocap still ends the
flight. (Behaviour on simulated time and on real loopback sockets; speed lives in
`perchd bench loop`.)"""

from __future__ import annotations

import json
import threading
import time

import pytest
import zmq
from simflight import Sim, case1

from perchd.core.clock import ManualClock, MonotonicClock
from perchd.core.errors import ConfigError
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Phase, Pose, Setpoint
from perchd.flight.config import FlightConfig, LoopSync
from perchd.flight.loop import FixedRateLoop, MocapSyncLoop, make_loop
from perchd.logs.flightlog import read_log
from perchd.mocap.base import open_source
from perchd.service.config import config_from_dict

MOCAP = FlightConfig(sync=LoopSync.MOCAP, rate_hz=120.0)  # the simulator's mocap runs at 120 Hz


def sim_source(uri: str = "sim://"):
    rt = Runtime(ManualClock(0.0))
    source = open_source(uri, rt)
    source.start()
    return rt, source


def test_each_tick_starts_at_the_arrival_of_a_new_pose_and_uses_it():
    rt, source = sim_source()  # 120 Hz frames, 4 ms mocap latency
    loop = MocapSyncLoop(rt.clock, 120.0, source)
    seen = []
    loop.run(lambda k, t: seen.append((k, t, source.latest())) or k < 59)
    assert [k for k, _, _ in seen] == list(range(60))
    assert [p.seq for _, _, p in seen] == list(range(1, 61))
    for _, t, pose in seen:
        assert t == pytest.approx(pose.t + pose.latency, abs=1e-12)  # released by its arrival
    s = loop.summary()
    assert (s.sync, s.ticks, s.overruns, s.missed, s.jitter_max_s) == ("mocap", 60, 0, 0, 0.0)


def test_a_tick_longer_than_a_frame_skips_to_the_newest_pose_and_counts_the_skipped():
    rt, source = sim_source()
    loop = MocapSyncLoop(rt.clock, 120.0, source)
    seqs = []

    def tick(k, t):
        seqs.append(source.latest().seq)
        if k == 3:
            rt.clock.advance(2.5 / 120)  # 2.5 frames of work
        return k < 8

    s = loop.run(tick).summary("mocap")
    assert seqs[:5] == [1, 2, 3, 4, 6]  # frames 5 and 6 arrived during tick 3
    assert s.overruns == 1 and s.missed == 1 and s.max_streak == 1


def test_without_poses_it_still_ticks_every_one_and_a_half_periods():
    rt, source = sim_source()
    rt.sim.faults.mocap_outages.append((0.0, 1.0))
    loop = MocapSyncLoop(rt.clock, 100.0, source)
    times = []
    loop.run(lambda k, t: times.append(t) or k < 4)
    assert times == pytest.approx([0.015 * (k + 1) for k in range(5)])
    assert source.latest() is None


class HeldSource:
    """Pose 1; then a wait held 3 s (a hung call, as sim://?stall= makes) that times out
    while frames 2-301 arrive; then one frame at a time."""

    def __init__(self, clock: ManualClock) -> None:
        self.clock, self.newest, self.waits = clock, 0, 0

    def wait(self, after_seq: int, timeout: float) -> Pose | None:
        self.waits += 1
        if self.waits == 2:
            self.clock.advance(3.0)
            self.newest = 301
            return None
        self.newest += 1
        return self.latest()

    def latest(self) -> Pose | None:
        t = self.clock.now()
        return Pose("b", self.newest, t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def test_frames_that_arrive_while_a_wait_is_held_are_counted_missed():
    """The tick after a held wait reads frame 301: 2-300 were skipped (before, a timed-out
    wait took the newest number without counting them: CI once saw 3 missed for 300)."""
    clock = ManualClock(0.0)
    loop = MocapSyncLoop(clock, 100.0, HeldSource(clock))
    assert loop.run(lambda k, t: k < 3).summary("mocap").missed == 299


def test_make_loop_builds_the_mode_the_config_names():
    rt, source = sim_source()
    assert isinstance(make_loop("fixed", rt.clock, 100.0, source), FixedRateLoop)
    assert isinstance(make_loop("mocap", rt.clock, 100.0, source), MocapSyncLoop)
    with pytest.raises(ValueError, match="neither"):
        make_loop("spin", rt.clock, 100.0, source)


@pytest.mark.parametrize("strategy", ["ipts", "ctdts"])
def test_a_mocap_synchronous_perch_ticks_once_per_pose_and_reaches_contact(tmp_path, strategy):
    sim = Sim("sim://?latency=0.02&noise=0.001")
    plan = case1(strategy)
    res = sim.fly(plan, tmp_path / "f.jsonl", MOCAP)
    assert res.outcome is EndReason.CONTACT and not res.failsafe_sent
    assert res.true_contact_speed == pytest.approx(res.v_hold_mps, abs=0.05)
    assert res.true_perch_time == pytest.approx(plan.duration, rel=0.05)
    rows = read_log(res.log).rows
    seqs = [r.pose_seq for r in rows]
    # a tick per pose, in order: each fused on its tick, or held for the next frame (the
    # contact's stop, off the track) and fused with it (perchd/flight/estimator.py)
    assert len(rows) == seqs[-1] and seqs[0] == 1
    steps = [b - a for a, b in zip(seqs, seqs[1:], strict=False)]
    assert set(steps) <= {0, 1, 2} and steps.count(0) == steps.count(2)
    assert all(steps[i + 1] == 2 for i, step in enumerate(steps) if step == 0)
    first = sim.world.t0 + sim.world.params.mocap.latency_s
    assert [r.t for r in rows[:3]] == pytest.approx([first + k / 120 for k in range(3)])
    assert res.loop.sync == "mocap" and res.loop.missed == 0 and res.loop.overruns == 0
    assert res.loop.latency_max_s == 0.0  # simulated time stands still while it computes


def test_in_fixed_rate_mode_a_pose_waits_less_than_one_period(tmp_path):
    res = Sim().fly(case1("ipts"), tmp_path / "f.jsonl", FlightConfig(sync=LoopSync.FIXED))
    assert res.loop.sync == "fixed"
    assert 0.0 < res.loop.latency_median_s < res.loop.latency_max_s < 1 / 100


def test_mocap_silent_mid_flight_ends_stale_with_the_failsafe(tmp_path):
    sim = Sim()
    sim.world.faults.mocap_outages.append((1.0, 9.0))
    res = sim.fly(case1("ipts"), tmp_path / "f.jsonl", MOCAP)
    assert res.outcome is EndReason.STALE_MOCAP and res.failsafe_sent
    rows = read_log(res.log).rows
    assert rows[-1].t == pytest.approx(1.0 + 0.004 + 3 / 120, abs=2 * 1.5 / 120)


def test_the_config_file_selects_the_mode_and_refuses_others():
    doc = {"version": 1, "flight": {"sync": "mocap", "rate_hz": 120.0}}
    assert config_from_dict(doc).flight.sync is LoopSync.MOCAP
    assert config_from_dict({"version": 1}).flight.sync is LoopSync.MOCAP  # the default
    fixed = config_from_dict({"version": 1, "flight": {"sync": "fixed"}})
    assert fixed.flight.sync is LoopSync.FIXED
    with pytest.raises(ConfigError, match=r"\[flight\] sync: expected 'fixed' or 'mocap'"):
        config_from_dict({"version": 1, "flight": {"sync": "free"}})


def test_over_real_zmq_sockets_each_published_pose_releases_one_setpoint():
    """Publisher -> zmq:// source -> MocapSyncLoop -> zmq driver -> subscriber: the setpoints'
    pose_seq are exactly the poses published, each once."""
    from perchd.drivers.zmq import ZmqSetpointDriver
    from perchd.mocap.zmq import ZmqPosePublisher

    rt = Runtime(MonotonicClock())
    sub = zmq.Context.instance().socket(zmq.SUB)
    sub.setsockopt(zmq.LINGER, 0)
    sub.setsockopt(zmq.SUBSCRIBE, b"setpoint")
    sub.bind("tcp://127.0.0.1:*")
    port = sub.getsockopt(zmq.LAST_ENDPOINT).decode().rsplit(":", 1)[1]
    got, listening = [], threading.Event()
    listening.set()

    def receive():  # a bound socket handles its peers only while someone polls it
        while listening.is_set():
            if sub.poll(5):
                got.append(json.loads(sub.recv_multipart()[1])["pose_seq"])

    receiver = threading.Thread(target=receive)
    receiver.start()
    pub = ZmqPosePublisher("tcp://127.0.0.1:0")
    source = open_source(pub.uri("cf1"), rt)
    driver = ZmqSetpointDriver(
        "zmq://test", f"tcp://127.0.0.1:{port}", rt, "cf1", bind=False, wait=2.0
    )
    source.start()
    driver.connect()
    n = 40

    def publish():  # the next pose once the last one's setpoint is back: none is skipped
        for seq in range(1, n + 1):
            pub.publish(Pose("cf1", seq, time.monotonic(), (-3.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0)))
            deadline = time.monotonic() + 2.0
            while len(got) < seq and time.monotonic() < deadline:
                time.sleep(0.001)

    def tick(k, t):
        pose = source.latest()
        driver.send(Setpoint(t, 0.0, 0.0, 0.0, 0.3, pose.seq, Phase.HOLD))
        return pose.seq < n

    try:
        assert pub.wait_for_subscriber(2.0)
        sender = threading.Thread(target=publish)
        sender.start()
        loop = MocapSyncLoop(rt.clock, 100.0, source, timeout_periods=100.0)  # no timeouts
        loop.run(tick)
        sender.join()
        deadline = time.monotonic() + 2.0
        while len(got) < n and time.monotonic() < deadline:
            time.sleep(0.01)
        assert got == list(range(1, n + 1))
        assert loop.summary().ticks == n
    finally:
        driver.close()
        source.close()
        pub.close()
        listening.clear()
        receiver.join()
        sub.close()


def test_by_default_the_loop_is_mocap_synchronous_and_a_dropout_keeps_setpoints_flowing(tmp_path):
    """The default loop ticks on each frame; when the frames stop it still ticks every 1.5
    periods, so a driver never goes quiet long enough for its own keep-alive (100 ms on the
    Crazyflie keeper and MAVLink) to stand in, and stale mocap ends the flight on time."""
    from perchd.drivers import cflink
    from perchd.drivers.mavlink import setpoints

    sim = Sim()
    sim.world.faults.mocap_outages.append((2.0, 9.0))
    res = sim.fly(case1("ipts"), tmp_path / "f.jsonl")  # FlightConfig()
    assert res.loop.sync == "mocap" and res.outcome is EndReason.STALE_MOCAP
    rows = read_log(res.log).rows
    last_pose = rows[-1].t - rows[-1].age + 0.004  # the newest frame's arrival (4 ms latency)
    assert 3 / 120 < rows[-1].t - last_pose <= 3 / 120 + 1.5 / 100 + 1e-9
    times = [r.t for r in rows]
    gaps = [b - a for a, b in zip(times, times[1:])]
    assert max(gaps) <= 1.5 / 100 + 1e-9 < min(cflink.KEEPALIVE_S, setpoints.KEEPALIVE_S)
    assert len(sim.world.sent) >= len(rows) - 1  # every tick but the failsafe one sent
