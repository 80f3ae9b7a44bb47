"""Limits: tilt, speed, geofence (x, lateral, floor) and the deadline-overrun streak, each
provoked by a disturbance of the simulated vehicle at a known time, and the time to the abort
measured. Every end leaves the failsafe sent and a closed, readable log."""

from __future__ import annotations

import dataclasses
import math

import pytest
from aborts import TRIGGER_T, assert_failsafe_and_closed_log, safety
from faultsim import PERIOD, TICK, fly, injected, report

from perchd.core.types import EndReason, Phase
from perchd.flight.config import FlightConfig
from perchd.flight.endrules import OVERRUN_STREAK

LATENCY = 0.004
"""[s] the simulated mocap's latency."""
SEEN = PERIOD + LATENCY + TICK
"""[s] longest time from a change of the vehicle to the tick that sees it in a frame."""


def knock(roll_deg):
    def fn(world):
        world.plant.att[0] = math.radians(roll_deg)

    return fn


def push(axis, speed):
    def fn(world):
        world.plant.v[axis] = speed

    return fn


EVERY_PHASE = (0.3, TRIGGER_T + 0.3, 4.2)
"""[s] hold, stage 1, stage 2."""


def weaken(fraction):
    def fn(world):
        p = world.plant.params
        world.plant.params = dataclasses.replace(p, thrust_max_n=fraction * p.mass_kg * p.g)

    return fn


LIMITS = {
    # name: (config, disturbance, onsets [s], reason, words in the detail, detection bound [s])
    "tilt > 45 deg (knock to 60 deg)": (
        FlightConfig(),
        knock(60.0),
        EVERY_PHASE,
        EndReason.TILT_LIMIT,
        "tilt",
        SEEN,
    ),
    "speed > 3.5 m/s (shove to 4 m/s)": (
        FlightConfig(),
        push(0, 4.0),
        EVERY_PHASE,
        EndReason.SPEED_LIMIT,
        "m/s >",
        SEEN + 0.05,
    ),
    "geofence X < x_min (blown back at 1 m/s)": (
        safety(x_min_m=-4.6),
        push(0, -1.0),
        (0.3,),
        EndReason.GEOFENCE,
        "outside",
        None,
    ),
    "geofence floor (motors weaken to 75 % of the weight)": (
        FlightConfig(),
        weaken(0.75),
        (0.3, 1.0),
        EndReason.GEOFENCE,
        "below the floor",
        None,
    ),
}


@pytest.mark.parametrize("name", LIMITS)
def test_a_limit_crossed_by_a_disturbance_ends_the_flight_with_the_failsafe(name, tmp_path):
    cfg, fn, onsets, reason, words, bound = LIMITS[name]
    delays = []
    for at in onsets:
        f = fly(tmp_path, cfg=cfg, setup=lambda s: s.world.faults.at.append((at, fn)))
        injected(name)
        assert_failsafe_and_closed_log(f.sim, f.res, reason)
        assert words in f.res.detail and f.sim.world.contact is None
        if bound is not None:
            assert 0.0 < f.end_t - at <= bound + 1e-9
        delays.append(f.end_t - at)
    report(
        f"limit: {name}",
        "checked every tick on the estimated state",
        f"{reason.name}, failsafe",
        "motors off (stop setpoint)",
        delays,
    )


def test_the_geofence_holds_within_a_tick_of_travel(tmp_path):
    """The fence is checked every tick on the estimated state, so the vehicle is at most a
    tick of travel plus the filter's lag past it: blown back at 1 m/s, within 2 cm."""
    f = fly(
        tmp_path,
        cfg=safety(x_min_m=-4.6),
        setup=lambda s: s.world.faults.at.append((0.3, push(0, -1.0))),
    )
    injected("geofence")
    true_x = f.sim.world.gap(f.sim.world.plant.p)
    assert -4.6 - 0.02 <= true_x <= -4.6 + 0.02


def stall_ticks(n: int, each_s: float = 0.015):
    """An on_tick hook: n consecutive stage-1 ticks each take each_s [s] of a 10 ms period."""

    def hook(sim):
        done = []

        def on_tick(st):
            if st.phase is Phase.STAGE1 and len(done) < n:
                done.append(sim.runtime.clock.now())
                sim.runtime.clock.advance(each_s)

        hook.first = done
        return on_tick

    return hook


def test_an_overrun_streak_one_short_of_the_limit_is_flown_through(tmp_path):
    streak = OVERRUN_STREAK
    f = fly(tmp_path, on_tick=stall_ticks(streak - 1))
    injected("overrun streak")
    assert f.res.outcome is EndReason.CONTACT and f.res.loop.max_streak == streak - 1


def test_the_overrun_streak_aborts_on_its_tenth_missed_deadline(tmp_path):
    streak = OVERRUN_STREAK
    hook = stall_ticks(10 * streak)
    f = fly(tmp_path, on_tick=hook)
    injected("overrun streak")
    assert_failsafe_and_closed_log(f.sim, f.res, EndReason.DEADLINE_OVERRUN)
    assert f.res.loop.max_streak == streak
    first = hook.first[0]
    overran = [r for r in f.log.rows if r.t >= first]
    assert len(overran) == streak + 1  # 10 slow ticks, the 11th sees the streak and ends
    report(
        "limit: deadline overrun streak (10 ticks of 15 ms in a 10 ms period)",
        f"{streak} consecutive overruns",
        "DEADLINE_OVERRUN, failsafe",
        "motors off (stop setpoint)",
        [f.end_t - first],
    )


def test_no_limit_is_crossed_by_a_nominal_flight(tmp_path):
    """The limits have margin: the nominal perch, noisy and late, trips none of them."""
    f = fly(tmp_path, uri="sim://?latency=0.02&noise=0.001")
    assert f.res.outcome is EndReason.CONTACT and not f.res.failsafe_sent


def test_tight_limits_still_name_their_reason_not_a_crash(tmp_path):
    f = fly(tmp_path, cfg=safety(tilt_max_rad=math.radians(5.0)))
    injected("tight tilt limit")
    assert_failsafe_and_closed_log(f.sim, f.res, EndReason.TILT_LIMIT)
