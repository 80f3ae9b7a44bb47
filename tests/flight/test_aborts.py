"""Every end the simulator can provoke is named, sends the driver's failsafe once, stops the
vehicle's motors and leaves a closed log that says why."""

from __future__ import annotations

import dataclasses
import math
import re

import pytest
from aborts import TRIGGER_T, assert_failsafe_and_closed_log, fly, safety
from simflight import Sim, case1

from perchd.core.types import EndReason, Phase
from perchd.flight.config import (
    FlightConfig,
    TriggerConfig,
    TriggerPolicy,
)
from perchd.flight.endrules import OVERRUN_STREAK
from perchd.flight.run import FlightAbort
from perchd.logs.flightlog import read_log


def test_a_mocap_outage_ends_the_flight_as_stale_mocap_within_three_periods_and_a_tick(tmp_path):
    outage = (3.0, 9.0)
    sim, res = fly(tmp_path, setup=lambda s: s.world.faults.mocap_outages.append(outage))
    assert_failsafe_and_closed_log(sim, res, EndReason.STALE_MOCAP)
    end = read_log(res.log).rows[-1].t
    # the last pose was measured just before 3.0 s and arrived 4 ms later
    assert 3.0 + 3 / 120 < end <= 3.0 + 4 / 120 + 0.004 + 0.01 + 1e-9


def test_no_pose_at_all_ends_as_stale_mocap(tmp_path):
    sim, res = fly(tmp_path, setup=lambda s: s.world.faults.mocap_outages.append((0.0, 99.0)))
    assert_failsafe_and_closed_log(sim, res, EndReason.STALE_MOCAP)
    assert res.trigger is None


def test_crossing_the_geofence_ceiling_ends_the_flight(tmp_path):
    def lift(world):
        world.plant.v[2] += 2.0

    sim, res = fly(
        tmp_path,
        safety(ceiling_m=1.4, speed_max_mps=10.0),
        setup=lambda s: s.world.faults.at.append((TRIGGER_T + 0.5, lift)),
    )
    assert_failsafe_and_closed_log(sim, res, EndReason.GEOFENCE)
    assert "above the ceiling 1.4 m" in res.detail
    rows = read_log(res.log).rows
    assert rows[-2].z <= 1.4 < rows[-1].z  # the first tick above it ends the flight


def test_a_gust_that_pushes_the_vehicle_off_its_line_is_a_geofence_end(tmp_path):
    def gust(world):
        world.plant.v[1] += 3.0

    sim, res = fly(
        tmp_path,
        safety(speed_max_mps=10.0),
        setup=lambda s: s.world.faults.at.append((TRIGGER_T + 0.5, gust)),
    )
    assert_failsafe_and_closed_log(sim, res, EndReason.GEOFENCE)
    assert "off the approach line" in res.detail


def test_a_knock_that_tilts_the_vehicle_past_the_limit_ends_the_flight(tmp_path):
    def knock(world):
        world.plant.att[0] = math.radians(70.0)

    sim, res = fly(tmp_path, setup=lambda s: s.world.faults.at.append((TRIGGER_T + 0.3, knock)))
    assert_failsafe_and_closed_log(sim, res, EndReason.TILT_LIMIT)
    assert "tilt" in res.detail


def test_an_operator_abort_from_another_thread_ends_the_flight_on_the_next_tick(tmp_path):
    abort = FlightAbort()

    def on_tick(sim):
        return lambda st: abort.request() if st.phase is Phase.STAGE1 else None

    sim, res = fly(tmp_path, abort=abort, on_tick=on_tick)
    assert_failsafe_and_closed_log(sim, res, EndReason.OPERATOR_ABORT)
    rows = read_log(res.log).rows
    assert rows[-2].phase == "stage1"  # one tick after the request


def test_a_signal_is_its_own_reason(tmp_path):
    abort = FlightAbort()
    abort.request(EndReason.SIGNAL)
    abort.request(EndReason.OPERATOR_ABORT)  # the first request wins
    sim, res = fly(tmp_path, abort=abort)
    assert_failsafe_and_closed_log(sim, res, EndReason.SIGNAL)


def test_a_cut_link_is_a_lost_link_end(tmp_path):
    def cut(world):
        world.faults.link_ok = False

    sim, res = fly(tmp_path, setup=lambda s: s.world.faults.at.append((TRIGGER_T + 0.2, cut)))
    assert res.outcome is EndReason.LOST_LINK and res.failsafe_sent
    assert read_log(res.log).end["outcome"] == "LOST_LINK"


def test_going_too_fast_is_a_speed_limit_end(tmp_path):
    def shove(world):  # above the plan's own peak speed, which the limit must allow
        world.plant.v[0] += 2.6

    sim, res = fly(
        tmp_path, safety(speed_max_mps=2.5), setup=lambda s: s.world.faults.at.append((0.3, shove))
    )
    assert_failsafe_and_closed_log(sim, res, EndReason.SPEED_LIMIT)
    assert res.trigger is None  # shoved in the hold, before the approach


def test_a_vehicle_stopped_by_a_headwind_diverges_from_its_tau_reference(tmp_path):
    def headwind(world):
        world.plant.v[0] = -0.5

    sim, res = fly(tmp_path, setup=lambda s: s.world.faults.at.append((TRIGGER_T + 0.5, headwind)))
    assert_failsafe_and_closed_log(sim, res, EndReason.TAU_DIVERGENCE)


def test_a_loop_that_keeps_missing_its_deadlines_ends_the_flight(tmp_path):
    def on_tick(sim):  # every stage-1 tick takes 15 ms of a 10 ms period
        return lambda st: sim.runtime.clock.advance(0.015) if st.phase is Phase.STAGE1 else None

    sim, res = fly(tmp_path, on_tick=on_tick)
    assert_failsafe_and_closed_log(sim, res, EndReason.DEADLINE_OVERRUN)
    assert res.loop.max_streak >= OVERRUN_STREAK


def test_a_flight_that_takes_too_long_times_out(tmp_path):
    sim, res = fly(tmp_path, safety(timeout_s=1.0))
    assert_failsafe_and_closed_log(sim, res, EndReason.TIMEOUT)


def test_the_timeout_says_how_long_it_flew_beside_the_limit_it_passed(tmp_path):
    """Not "0.5 s > 0.5 s": the time flown to the millisecond, and the limit's key."""
    _, res = fly(tmp_path, safety(timeout_s=0.5))
    flown = float(re.search(r"flying (\d+\.\d{3}) s", res.detail).group(1))
    assert res.outcome is EndReason.TIMEOUT and flown > 0.5
    assert res.detail.endswith("longer than [safety] timeout_s = 0.5 s")


def test_a_trigger_state_outside_the_tolerance_is_refused_not_flown(tmp_path):
    cfg = FlightConfig(trigger=TriggerConfig(TriggerPolicy.REFUSE, x_tol_m=1e-4, v_tol_mps=1e-4))
    sim, res = fly(tmp_path, cfg)
    assert_failsafe_and_closed_log(sim, res, EndReason.TRIGGER_REFUSED)
    assert "differ from the plan's x0 = -3" in res.detail and res.trigger is None


def test_a_robust_policy_refuses_a_plan_without_a_robust_box(tmp_path):
    cfg = FlightConfig(trigger=TriggerConfig(TriggerPolicy.ROBUST))
    sim, res = fly(tmp_path, cfg)
    assert res.outcome is EndReason.TRIGGER_REFUSED and "no robust box" in res.detail


def test_a_start_too_close_to_reach_the_trigger_speed_is_refused(tmp_path):
    sim = Sim("sim://?start=-3.2,0,1")
    res = sim.fly(case1("ipts"), tmp_path / "f.jsonl")
    assert res.outcome is EndReason.TRIGGER_REFUSED and "approach limit" in res.detail
    assert sim.world.failsafes == [EndReason.TRIGGER_REFUSED]


def test_an_exception_in_the_loop_still_sends_the_failsafe_and_closes_the_log(tmp_path):
    def on_tick(sim):
        def boom(st):
            if st.phase is Phase.STAGE1:
                raise RuntimeError("display crashed")

        return boom

    sim = Sim()
    with pytest.raises(RuntimeError, match="display crashed"):
        sim.fly(case1("ipts"), tmp_path / "f.jsonl", on_tick=on_tick(sim))
    assert sim.world.failsafes == [EndReason.SOFTWARE_ERROR]
    log = read_log(tmp_path / "f.jsonl")
    assert log.complete and log.end["outcome"] == "SOFTWARE_ERROR"


def test_a_wall_nearer_than_configured_stops_the_vehicle_short_and_the_plan_completes(
    tmp_path, monkeypatch
):
    from perchd.flight import endrules
    from perchd.flight.config import SurfaceConfig

    monkeypatch.setattr(endrules, "TAU_ERROR_HOLD_S", 100.0)
    cfg = dataclasses.replace(FlightConfig(), surface=SurfaceConfig(point=(0.5, 0.0, 0.0)))

    def noisy(sim):  # real mocap sees a perched body jitter; bit-still reads as a frozen tracker
        wp = sim.world.params
        sim.world.params = dataclasses.replace(
            wp, mocap=dataclasses.replace(wp.mocap, noise_m=1e-4)
        )

    sim, res = fly(tmp_path, cfg, setup=noisy)
    assert sim.world.contact is not None  # it hit the real wall, 0.5 m before the configured one
    assert_failsafe_and_closed_log(sim, res, EndReason.PLAN_COMPLETE)
    assert "X = -0.49" in res.detail or "X = -0.50" in res.detail
