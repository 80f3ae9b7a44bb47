"""In perchd's own sim: the hold learns the hover thrust (and the approach waits
for it), the approach's speed integral meets v0 at the trigger despite drag, and the thrust
saturates at the driver's ceiling."""

from __future__ import annotations

import pytest
from caseplans import case1_ipts as case1
from simflight import NOISY, Sim

import perchd.flight.hover
import perchd.flight.supervisor
from perchd.core.types import EndReason
from perchd.core.vehicle import CRAZYFLIE_THRUST_MAX_N
from perchd.drivers.thrust import CF_UNITS_MAX, CrazyflieThrust
from perchd.flight.config import FlightConfig, HoverConfig
from perchd.flight.run import bind_vehicle
from perchd.logs.flightlog import read_log


def _events(log, kind: str) -> list:
    return [e for e in read_log(log).events if e.kind == kind]


def test_the_hold_learns_a_heavier_vehicles_hover_thrust_and_perches(tmp_path):
    true_hover = 0.0336 * 9.81  # 12 % heavier than the config's 30 g; no hover given
    res = Sim(NOISY + "&mass=0.0336").fly(case1(), tmp_path / "f.jsonl")
    assert res.outcome is EndReason.CONTACT, res.detail
    assert res.hover_n == pytest.approx(true_hover, rel=0.02)
    learned = _events(tmp_path / "f.jsonl", "hover-learned")
    assert len(learned) == 1 and learned[0].values["hover_n"] == res.hover_n
    assert _events(tmp_path / "f.jsonl", "hover-wait")  # the wait is said, not silent


def test_a_take_off_from_the_floor_learns_the_hover_too(tmp_path):
    res = Sim(NOISY + "&mass=0.026&start=-4.5,0,0").fly(case1(), tmp_path / "f.jsonl")
    assert res.outcome is EndReason.CONTACT, res.detail
    assert res.hover_n == pytest.approx(0.026 * 9.81, rel=0.02)


def test_a_hover_that_never_settles_on_a_vehicle_holding_its_height_flies_the_estimate(
    tmp_path, monkeypatch
):
    """An autopilot's height loop keeps the thrust moving: after [hover] timeout_s the
    vehicle holding its height flies on the estimate it has, and the log says so."""
    monkeypatch.setattr(perchd.flight.hover, "REL_TOL", 0.0)
    cfg = FlightConfig(hover=HoverConfig(timeout_s=1.0))
    res = Sim(NOISY).fly(case1(), tmp_path / "f.jsonl", cfg)
    assert res.outcome is EndReason.CONTACT, res.detail
    assert res.trigger is not None and res.hover_n is not None
    assert res.hover_n == pytest.approx(0.030 * 9.81, rel=0.02)
    unsettled = _events(tmp_path / "f.jsonl", "hover-unsettled")
    assert len(unsettled) == 1 and "hover thrust unsettled after" in unsettled[0].detail


def test_a_hover_that_never_settles_off_its_height_ends_the_flight_with_a_named_reason(
    tmp_path, monkeypatch
):
    monkeypatch.setattr(perchd.flight.hover, "REL_TOL", 0.0)
    monkeypatch.setattr(perchd.flight.supervisor, "Z_TOL_M", 0.0)  # no height is held
    cfg = FlightConfig(hover=HoverConfig(timeout_s=1.0))
    res = Sim(NOISY).fly(case1(), tmp_path / "f.jsonl", cfg)
    assert res.outcome is EndReason.HOVER_UNLEARNED
    assert "hover thrust unsettled after" in res.detail and "off its hold height" in res.detail
    assert res.failsafe_sent
    assert res.trigger is None and res.hover_n is None
    assert not _events(tmp_path / "f.jsonl", "hover-unsettled")


def test_a_learned_hover_far_from_the_weight_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(perchd.flight.supervisor, "RATIO", (0.6, 1.05))
    res = Sim(NOISY + "&mass=0.0336").fly(case1(), tmp_path / "f.jsonl")
    assert res.outcome is EndReason.HOVER_UNLEARNED
    assert "x the weight of vehicle.mass_kg = 0.03 kg" in res.detail


def test_an_unsettled_hover_far_from_the_weight_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(perchd.flight.hover, "REL_TOL", 0.0)
    monkeypatch.setattr(perchd.flight.supervisor, "RATIO", (0.6, 1.05))
    cfg = FlightConfig(hover=HoverConfig(timeout_s=1.0))
    res = Sim(NOISY + "&mass=0.0336").fly(case1(), tmp_path / "f.jsonl", cfg)
    assert res.outcome is EndReason.HOVER_UNLEARNED
    assert "x the weight of vehicle.mass_kg = 0.03 kg" in res.detail
    assert res.trigger is None


@pytest.mark.parametrize("drag", [0.0, 0.3])
def test_the_approach_meets_v0_at_the_trigger_despite_drag(tmp_path, drag):
    res = Sim(NOISY + f"&drag={drag}").fly(case1(), tmp_path / "f.jsonl")
    assert res.trigger is not None, res.detail
    # 1 mm of noise scatters the trigger speed +-0.03 m/s over seeds; the approach's lead
    # into the plan's first acceleration adds ~+0.005.
    assert abs(res.trigger.v - case1().v0) < 0.04


def test_the_default_thrust_cap_is_the_crazyflie_firmware_ceiling():
    assert CRAZYFLIE_THRUST_MAX_N == pytest.approx(
        CrazyflieThrust().newtons(CF_UNITS_MAX), abs=1e-3
    )


def test_the_flight_saturates_at_the_drivers_ceiling(tmp_path):
    sim = Sim(NOISY)
    plant_max = sim.world.plant.params.thrust_max_n
    assert plant_max < FlightConfig().vehicle.thrust_max_n
    assert bind_vehicle(sim.driver, FlightConfig()).vehicle.thrust_max_n == plant_max
    res = sim.fly(case1(), tmp_path / "f.jsonl")
    assert res.outcome is EndReason.CONTACT
    header = read_log(tmp_path / "f.jsonl").header
    assert header["config"]["vehicle"]["thrust_max_n"] == plant_max
    assert max(r.thrust for r in read_log(tmp_path / "f.jsonl").rows) <= plant_max
