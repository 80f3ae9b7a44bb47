"""The flight hands every pose it uses to drivers that want it (Crazyflie yaw and extpose)."""

from __future__ import annotations

from simflight import Sim, case1

from perchd.core.types import EndReason


def test_a_driver_with_observe_pose_sees_the_poses_the_flight_flew_on(tmp_path):
    sim = Sim()
    seen = []
    sim.driver.observe_pose = seen.append  # the loopback driver has no hook of its own
    res = sim.fly(case1("ipts"), tmp_path / "f.jsonl")
    assert res.outcome is EndReason.CONTACT
    seqs = [p.seq for p in seen]
    assert len(set(seqs)) > 100 and seqs == sorted(seqs)
    assert max(p.p[0] for p in seen) > -0.05  # the poses run up to the wall at X = 0
