"""What a flight learns of its vehicle is kept for the next (flight/vehiclestate.py): the hover
thrust, and stage 1's push beyond the approach's bias (docs/firmware.md, "Each vehicle's own
mean"); an unwritable or malformed store is one warning or no memory, never a failed flight."""

from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace

import pytest

from perchd.core.types import EndReason
from perchd.flight.config import FlightConfig, LagIdGains
from perchd.flight.vehiclestate import MEMORY_FLIGHTS, VehicleStore


def test_a_learned_hover_is_the_next_flights_guess(tmp_path):
    store = VehicleStore(tmp_path / "state" / "vehicles.json", print)
    store.remember("udp://x", FlightConfig(), 0.327)
    cfg = store.with_learned_guess("udp://x", FlightConfig())
    assert abs(cfg.vehicle.hover_thrust_n - 0.327) < 1e-9
    assert store.with_learned_guess("udp://other", FlightConfig()).vehicle.hover_thrust_n is None


def test_an_unwritable_store_is_one_warning_not_a_crash(tmp_path):
    (tmp_path / "file").write_text("")
    said: list[str] = []
    store = VehicleStore(tmp_path / "file" / "vehicles.json", said.append)
    store.remember("udp://x", FlightConfig(), 0.327)
    assert len(said) == 1 and "not kept" in said[0] and "\n" not in said[0]
    assert store.with_learned_guess("udp://x", FlightConfig()) == FlightConfig()


def test_the_stage_2_departure_is_the_mean_of_the_flights_and_the_next_ones_prior(tmp_path):
    store = VehicleStore(tmp_path / "vehicles.json", print)
    for d in (-0.10, -0.13, -0.12):
        store.remember("tcp:5762", FlightConfig(), departure_mps2=d)
    mean, n = store.stage2_departure("tcp:5762")
    assert n == 3 and mean == pytest.approx(-0.35 / 3, abs=1e-12)
    lag = store.with_learned_guess("tcp:5762", FlightConfig()).lag_id
    assert (lag.stage2_prior_mps2, lag.stage2_prior_flights) == (pytest.approx(mean), 3)
    given = dataclasses.replace(FlightConfig(), lag_id=LagIdGains(
        stage2_prior_mps2=0.0, stage2_prior_flights=5))
    assert store.with_learned_guess("tcp:5762", given).lag_id.stage2_prior_mps2 == 0.0


def test_a_vehicle_that_changes_is_followed_within_about_ten_flights(tmp_path):
    """The mean of the first MEMORY_FLIGHTS flights, then each new one weighs a tenth (an
    exponential mean): ten flights at -0.1 after ten at 0 leave 1 - 0.9^10 of the change."""
    store = VehicleStore(tmp_path / "vehicles.json", print)
    for d in [0.0] * 10 + [-0.1] * 10:
        store.remember("udp://x", FlightConfig(), departure_mps2=d)
    mean, n = store.stage2_departure("udp://x")
    assert n == MEMORY_FLIGHTS == 10
    assert mean == pytest.approx(-0.1 * (1 - 0.9 ** 10), abs=1e-12)


def test_the_hover_and_the_departure_are_kept_beside_each_other(tmp_path):
    store = VehicleStore(tmp_path / "vehicles.json", print)
    store.remember("udp://x", FlightConfig(), departure_mps2=-0.05)
    store.remember("udp://x", FlightConfig(), hover_n=0.327)
    before = store.path.read_text()
    store.remember("udp://x", FlightConfig())  # nothing learned: nothing written
    assert store.path.read_text() == before
    assert store.hover_ratio("udp://x") == pytest.approx(0.327 / (0.03 * 9.81))
    assert store.stage2_departure("udp://x") == (pytest.approx(-0.05), 1)


@pytest.mark.parametrize("rec", [{"stage2_departure_mps2": "x", "stage2_flights": 2},
                                 {"stage2_departure_mps2": -0.1, "stage2_flights": 0},
                                 {"stage2_departure_mps2": -0.1, "stage2_flights": True},
                                 {"stage2_departure_mps2": float("nan"), "stage2_flights": 1},
                                 {"stage2_departure_mps2": 0.6, "stage2_flights": 3},
                                 {"stage2_departure_mps2": 10 ** 400, "stage2_flights": 3},
                                 {"hover_ratio": 10 ** 400},
                                 {"stage2_departure_mps2": -0.1}, []])
def test_a_malformed_departure_is_no_memory(tmp_path, rec):
    path = tmp_path / "vehicles.json"
    path.write_text(json.dumps({"schema": "perchd.vehicles/1", "vehicles": {"k": rec}}))
    store = VehicleStore(path, print)
    assert store.stage2_departure("k") is None and store.hover_ratio("k") is None
    assert store.with_learned_guess("k", FlightConfig()) == FlightConfig()


def test_a_count_beyond_the_memory_reads_as_its_cap(tmp_path):
    path = tmp_path / "vehicles.json"
    path.write_text(json.dumps({"schema": "perchd.vehicles/1", "vehicles": {
        "k": {"stage2_departure_mps2": -0.1, "stage2_flights": 250}}}))
    assert VehicleStore(path, print).stage2_departure("k") == (-0.1, MEMORY_FLIGHTS)


def test_a_push_beyond_a_steady_ones_bound_is_not_kept_and_said_once(tmp_path):
    """A flight whose stage 1 showed 0.8 m/s^2 beyond its approach met something passing
    (a gust, a wall effect), not the vehicle: it would weigh on ten flights after it."""
    said: list[str] = []
    store = VehicleStore(tmp_path / "vehicles.json", said.append)
    store.remember("k", FlightConfig(), departure_mps2=-0.1)
    store.remember("k", FlightConfig(), departure_mps2=0.8)
    assert store.stage2_departure("k") == (pytest.approx(-0.1), 1)
    assert len(said) == 1 and "0.8" in said[0] and "not kept" in said[0]


def test_only_a_flight_that_touched_teaches_the_push(tmp_path):
    store = VehicleStore(tmp_path / "vehicles.json", print)
    for outcome, d in ((EndReason.STALE_MOCAP, -0.3), (EndReason.CONTACT, -0.1)):
        store.remember_flight("k", FlightConfig(), flown(outcome, d))
    assert store.stage2_departure("k") == (pytest.approx(-0.1), 1)


def flown(outcome: EndReason, departure: float) -> SimpleNamespace:
    """What remember_flight reads of a FlightResult."""
    return SimpleNamespace(outcome=outcome, hover_n=None, stage2_departure_mps2=departure)
