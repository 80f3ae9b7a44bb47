"""The hard envelope (perchd.core.envelope, docs/safety.md "Hard envelope"): take-off
height, ceiling and surface inside the geofence or refused at start naming the key, its
value and the bound; a reference that would leave the ceiling ends GEOFENCE before it; a
failsafe high above the floor descends before it cuts the motors."""

from __future__ import annotations

import dataclasses

import pytest
from simflight import PLANS

from perchd.cli import main
from perchd.core.envelope import (
    CEILING_ABOVE_FLOOR_M,
    FAILSAFE_DESCENT_MPS,
    FAILSAFE_DROP_MAX_M,
    MARGIN_M,
    TAKEOFF_HEIGHT_MAX_M,
)
from perchd.core.errors import ConfigError
from perchd.core.types import EndReason
from perchd.flight.config import ApproachConfig, FlightConfig, SafetyConfig
from perchd.session import open_session
from perchd.tau import load_plan

PLAN = PLANS / "case1-ipts-n3.json"


def fly_with_config(tmp_path, capsys, toml: str) -> tuple[int, str]:
    cfg = tmp_path / "flight.toml"
    cfg.write_text(f"version = 1\n{toml}\n")
    code = main(
        [
            "fly",
            str(PLAN),
            "--driver",
            "sim://",
            "--mocap",
            "sim://",
            "--config",
            str(cfg),
            "--log",
            str(tmp_path / "f.jsonl"),
        ]
    )
    return code, capsys.readouterr().err.strip()


def test_a_take_off_height_of_100_m_is_refused_naming_key_value_and_bound(tmp_path, capsys):
    code, err = fly_with_config(tmp_path, capsys, "[approach]\ntakeoff_height_m = 100")
    assert code == 2 and len(err.splitlines()) == 1
    assert (
        f"[approach] takeoff_height_m = 100 m: outside its range 0..{TAKEOFF_HEIGHT_MAX_M:g} m"
        in err
    )
    assert not (tmp_path / "f.jsonl").exists()
    code, err = fly_with_config(tmp_path, capsys, "[approach]\ntakeoff_height_m = 3.5")
    top = SafetyConfig().ceiling_m - MARGIN_M
    assert code == 2 and "[approach] takeoff_height_m" in err and "= 3.5 " in err
    assert f"above {top:g} by {3.5 - top:g}" in err


def test_no_ceiling_lifts_the_take_off_height_past_its_constant():
    floor = SafetyConfig().floor_m
    high = SafetyConfig(ceiling_m=floor + CEILING_ABOVE_FLOOR_M)
    with pytest.raises(ConfigError, match=f"outside its range 0..{TAKEOFF_HEIGHT_MAX_M:g} m"):
        FlightConfig(
            safety=high, approach=ApproachConfig(takeoff_height_m=TAKEOFF_HEIGHT_MAX_M + 1)
        )
    with pytest.raises(ConfigError, match=r"\[safety\] ceiling_m = 50 is above"):
        FlightConfig(safety=SafetyConfig(ceiling_m=50.0))


@pytest.mark.parametrize(
    "key, value, why",
    [("x_max_m", -0.5, "outside its range 0..100 m"), ("x_min_m", -0.1, "surface, X = 0, inside")],
)
def test_a_geofence_that_leaves_the_surface_outside_is_refused(tmp_path, capsys, key, value, why):
    code, err = fly_with_config(tmp_path, capsys, f"[safety]\n{key} = {value}")
    assert code == 2 and len(err.splitlines()) == 1
    assert f"[safety] {key}" in err and f"= {value:g}" in err and why in err


def high_flight(tmp_path, start_z: float, cfg: FlightConfig = FlightConfig()):
    session = open_session(f"sim://?start=-4.5,0,{start_z}")
    world = session.world
    res = session.fly(load_plan(PLAN), tmp_path / "f.jsonl", cfg)
    return world, res


def after_failsafe(world, seconds: float, step: float = 0.02) -> list[tuple[float, float]]:
    """(true height [m], thrust [N]) every `step` of simulated time after the flight."""
    out, t = [], world.clock.now()
    for _ in range(int(seconds / step)):
        t += step
        world.clock.sleep_until(t)
        world.advance()
        out.append((world.plant.p[2], world.plant.thrust))
    return out


def test_a_start_whose_hold_would_leave_the_ceiling_ends_geofence_before_it(tmp_path):
    ceiling = SafetyConfig().ceiling_m
    start = ceiling - MARGIN_M / 2  # inside the fence, but the hold's reference is not
    world, res = high_flight(tmp_path, start)
    assert res.outcome is EndReason.GEOFENCE and "start height" in res.detail
    assert res.trigger is None and world.failsafes == [EndReason.GEOFENCE]
    heights = [z for z, _ in after_failsafe(world, 8.0)]
    assert max(heights) <= start + 1e-6 < ceiling


def test_a_failsafe_high_above_the_floor_descends_before_it_cuts(tmp_path):
    start = 2.5
    cfg = FlightConfig(safety=dataclasses.replace(SafetyConfig(), timeout_s=1.0))
    world, res = high_flight(tmp_path, start, cfg)
    assert res.outcome is EndReason.TIMEOUT
    t0 = world.clock.now()
    trace = after_failsafe(world, 6.0)
    stop = world.sent[-1]
    assert stop.thrust == 0.0 and all(sp.thrust > 0 for sp in world.sent[-10:-1])
    cut = int((stop.t - t0) / 0.02)  # the sample at the motors-off command
    powered = [z for z, _ in trace[:cut]]
    assert powered[0] > FAILSAFE_DROP_MAX_M + 0.5  # it was high when the failsafe came
    assert all(b <= a + 1e-4 for a, b in zip(powered, powered[1:]))  # down, never up
    assert trace[cut][0] == pytest.approx(FAILSAFE_DROP_MAX_M, abs=0.05)  # cut at the bound
    descent_s = stop.t - t0
    assert descent_s == pytest.approx(
        (powered[0] - FAILSAFE_DROP_MAX_M) / FAILSAFE_DESCENT_MPS, rel=0.25
    )


def test_a_failsafe_low_above_the_floor_cuts_at_once(tmp_path):
    world, res = high_flight(
        tmp_path, 1.0, FlightConfig(safety=dataclasses.replace(SafetyConfig(), timeout_s=1.0))
    )
    assert res.outcome is EndReason.TIMEOUT
    assert world.sent[-1].thrust == 0.0
