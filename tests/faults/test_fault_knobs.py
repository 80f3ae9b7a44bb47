"""The frame faults (perchd/sim/faults.py) do to a frame stream what their names say, and the
world delivers what comes out by arrival time: checked on frames directly, so the flights
that use them test perchd, not the knobs."""

from __future__ import annotations

import math

from perchd.core.clock import ManualClock
from perchd.core.types import Pose
from perchd.sim.faults import (
    Corrupt,
    Freeze,
    Invalid,
    Late,
    Outliers,
    RateDrop,
    Reorder,
    Repeat,
    Stop,
    shape,
)
from perchd.sim.world import SimWorld, WorldParams

P = 0.01


def frames(n: int = 10) -> list[Pose]:
    return [Pose("cf1", k + 1, k * P, (float(k), 0.0, 1.0), (0.0, 0.0, 0.0, 1.0)) for k in range(n)]


def run(*faults) -> list[tuple[float, Pose]]:
    return [out for pose in frames() for out in shape(faults, pose.t + 0.004, pose)]


def test_stop_drops_the_frames_measured_in_its_window_only():
    assert [p.seq for _, p in run(Stop(0.03, 0.06))] == [1, 2, 3, 7, 8, 9, 10]


def test_late_delays_arrival_but_not_the_stamp_or_stated_latency():
    out = run(Late(0.0, 0.02, 0.05))
    assert [round(a - p.t, 6) for a, p in out[:3]] == [0.054, 0.054, 0.004]
    assert all(p.latency == 0.0 for _, p in out)


def test_reorder_makes_each_even_frame_arrive_after_its_successor():
    out = sorted(run(Reorder(delay_s=0.015)), key=lambda item: item[0])
    assert [p.seq for _, p in out][:4] == [1, 3, 2, 5]


def test_repeat_sends_copies_with_the_same_seq_and_stamp():
    out = run(Repeat(times=3))
    assert len(out) == 30 and {p.seq for _, p in out[:3]} == {1}


def test_freeze_resends_the_last_frame_before_it_with_fresh_seqs():
    held = run(Freeze(0.05))
    assert [p.p[0] for _, p in held][5:] == [4.0] * 5
    assert [p.seq for _, p in held][5:] == [6, 7, 8, 9, 10]
    assert {p.t for _, p in held[5:]} == {0.04}
    fresh = run(Freeze(0.05, restamp=True))
    assert [p.t for _, p in fresh][5:] == [k * P for k in range(5, 10)]


def test_outliers_jump_every_nth_frame():
    out = run(Outliers(every=5, jump_m=0.5))
    assert [p.p[0] - (p.seq - 1) for _, p in out] == [0.0] * 4 + [0.5] + [0.0] * 4 + [0.5]


def test_invalid_frames_are_flagged_and_carry_no_position():
    out = run(Invalid(0.05))
    assert [p.valid for _, p in out] == [True] * 5 + [False] * 5
    assert out[-1][1].p == (0.0, 0.0, 0.0)


def test_rate_drop_keeps_one_frame_in_five():
    assert [p.seq for _, p in run(RateDrop(keep_every=5))] == [5, 10]


def test_corrupt_fills_every_coordinate():
    out = run(Corrupt(every=2))
    assert all(math.isnan(c) for c in (*out[1][1].p, *out[1][1].q))
    assert out[0][1].p == (0.0, 0.0, 1.0)


def test_the_world_delivers_by_arrival_so_a_late_frame_can_replace_a_newer_one():
    clock = ManualClock()
    world = SimWorld(WorldParams(), clock)
    world.faults.mocap.append(Reorder(delay_s=1.5 / 120))
    seen = []
    for _ in range(40):
        clock.advance(0.001)
        pose = world.latest_pose()
        if pose is not None and (not seen or pose.seq != seen[-1]):
            seen.append(pose.seq)
    assert seen[:4] == [1, 3, 2, 5]  # frame 2 arrived after frame 3
