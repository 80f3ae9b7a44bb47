"""Faults in combination: stacks of tolerable faults, a fatal fault inside such a stack, and
two fatal faults on the same tick (the first end rule in the supervisor's order names the
end, and the failsafe goes out once)."""

from __future__ import annotations

import math

import pytest
from aborts import assert_failsafe_and_closed_log, safety
from faultsim import FIXED, PERIOD, TICK, fly, report
from simflight import NOISY, Sim, case1

from perchd.core.types import EndReason, Phase
from perchd.flight.run import FlightAbort
from perchd.logs.flightlog import read_log
from perchd.sim.faults import Corrupt, Late, Outliers, RateDrop, Reorder, Repeat, Stop

TOLERABLE = (Repeat(times=2), Outliers(every=10), Corrupt(3.52, 3.53))
"""Each alone is flown through (test_fault_mocap); together, with 1 mm noise and 20 ms of
command latency, they still are."""


def test_a_stack_of_tolerable_faults_on_a_noisy_late_link_still_perches(tmp_path):
    f = fly(tmp_path, *TOLERABLE, uri=NOISY)
    assert f.res.outcome is EndReason.CONTACT and not f.res.failsafe_sent
    assert 0.7 - 0.03 <= f.res.true_contact_speed <= 1.0 + 0.03
    report(
        "combo: duplicates + an outlier every 10th frame + a NaN frame, 1 mm noise, 20 ms latency",
        "per frame",
        "frames ignored",
        f"perches ({f.res.true_contact_speed:.3f} m/s)",
    )


def test_frames_stopping_inside_that_stack_are_still_stale_within_3_periods_and_a_tick(tmp_path):
    delays = []
    for onset in (3.0, 3.003, 4.2):
        f = fly(tmp_path, *TOLERABLE, Stop(onset), uri=NOISY)
        assert_failsafe_and_closed_log(f.sim, f.res, EndReason.STALE_MOCAP)
        assert 3 * PERIOD < f.age_of_last_fused <= 3 * PERIOD + TICK + 1e-9
        delays.append(f.age_of_last_fused)
    report(
        "combo: frames stop inside the stack above",
        "> 3 frame periods without a usable frame",
        "STALE_MOCAP, failsafe",
        "motors off",
        delays,
    )


@pytest.mark.parametrize(
    "name, faults",
    [
        ("pairs out of order + an outlier every 10th frame", (Reorder(), Outliers(every=10))),
        ("50 % rate + an outlier every 10th frame", (RateDrop(keep_every=2), Outliers(every=10))),
        ("an outlier every 10th + NaN every 17th frame", (Outliers(every=10), Corrupt(every=17))),
        ("10 ms late + an outlier every 10th frame", (Late(3.0, 3.3, 0.010), Outliers(every=10))),
    ],
    ids=lambda v: v if isinstance(v, str) else "",
)
def test_two_tolerable_faults_that_starve_the_estimator_together_end_stale(name, faults, tmp_path):
    """Alone each is flown through; together they can leave more than 3 frame periods
    without a usable frame (an outlier where the only frame for 2 periods was): stale,
    never flown blind."""
    f = fly(tmp_path, *faults)
    assert_failsafe_and_closed_log(f.sim, f.res, EndReason.STALE_MOCAP)
    assert 3 * PERIOD < f.age_of_last_fused <= 3 * PERIOD + TICK + 1e-9
    report(
        f"combo: {name}",
        "> 3 frame periods without a usable frame (frame age as stamped)",
        "STALE_MOCAP, failsafe",
        "motors off",
        [f.age_of_last_fused],
    )


def cut_link_at(t):
    return lambda s: s.world.faults.at.append((t, lambda w: setattr(w.faults, "link_ok", False)))


def knock_at(t):
    return lambda s: s.world.faults.at.append((t, lambda w: w.plant.att.__setitem__(0, 1.2)))


@pytest.mark.parametrize(
    "name, faults, setups, first",
    [
        # the world applies a cut during a tick's pose read; health is read at the next tick
        ("stale mocap + lost link", (Stop(3.0),), (cut_link_at(3.015),), EndReason.STALE_MOCAP),
        ("lost link + tilt", (), (cut_link_at(3.0), knock_at(3.0)), EndReason.LOST_LINK),
        ("NaN frames + lost link", (Corrupt(3.0),), (cut_link_at(3.0),), EndReason.LOST_LINK),
    ],
    ids=lambda v: v if isinstance(v, str) else "",
)
def test_two_fatal_faults_end_once_with_the_first_rule_that_sees_one(
    name, faults, setups, first, tmp_path
):
    f = fly(tmp_path, *faults, setup=lambda s: [fn(s) for fn in setups])
    assert_failsafe_and_closed_log(f.sim, f.res, first)
    assert f.sim.driver.failsafe_reasons == [first]
    if first is EndReason.STALE_MOCAP:  # both faults were there on the end tick
        assert not f.sim.world.faults.link_ok and f.end_t == pytest.approx(3.03)
    report(
        f"combo: {name}", "the supervisor's rule order", f"{first.name}, one failsafe", "motors off"
    )


def test_a_signal_and_stale_mocap_on_the_same_tick_end_as_signal(tmp_path):
    abort = FlightAbort()
    sim = Sim()
    sim.world.faults.mocap.append(Stop(3.0))

    def on_tick(st):  # the signal lands just before the tick on which mocap turns stale
        if st.t >= 3.02 - 1e-9:
            abort.request(EndReason.SIGNAL)

    res = sim.fly(case1("ipts"), tmp_path / "f.jsonl", FIXED, abort=abort, on_tick=on_tick)
    assert_failsafe_and_closed_log(sim, res, EndReason.SIGNAL)
    assert read_log(res.log).rows[-1].t == pytest.approx(3.03)  # stale from this tick too


def test_an_overrun_streak_during_mocap_trouble_still_names_the_overrun(tmp_path):
    def slow(sim):
        return lambda st: sim.runtime.clock.advance(0.012) if st.phase is Phase.STAGE1 else None

    # Overrunning ticks come 20 ms apart, so one rejected outlier between two of them ages the
    # newest pose past the default 3 mocap periods (25 ms): stale mocap would rightly win
    # whenever an outlier lands there. Give the stale rule room for that one frame (40 ms),
    # so what is tested is the overrun streak amid duplicated and outlying frames.
    f = fly(tmp_path, Repeat(), Outliers(every=10), cfg=safety(stale_timeout_s=0.04), on_tick=slow)
    assert_failsafe_and_closed_log(f.sim, f.res, EndReason.DEADLINE_OVERRUN)
    report(
        "combo: overrun streak + duplicated and outlying frames",
        "10 consecutive overruns",
        "DEADLINE_OVERRUN, failsafe",
        "motors off",
    )


def test_no_combination_leaves_a_non_finite_setpoint(tmp_path):
    f = fly(tmp_path, Corrupt(every=3), Corrupt(value=math.inf, every=5), Reorder(), uri=NOISY)
    assert all(
        math.isfinite(v) for s in f.sim.world.sent for v in (s.roll, s.pitch, s.yaw, s.thrust)
    )
    assert f.res.outcome in (EndReason.CONTACT, EndReason.STALE_MOCAP)
