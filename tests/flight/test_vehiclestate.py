"""What a flight learns of its vehicle is kept in the vehicle's profile (flight/profile.py,
flight/vehiclestate.py): the hover thrust, the next flight's guess, and the lag and drag
identified, to be seen; an unwritable or malformed profile is one warning or no memory,
never a failed flight."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

from perchd.flight.config import FlightConfig, VehicleConfig
from perchd.flight.lagid import LagModel
from perchd.flight.profile import SCHEMA
from perchd.flight.vehiclestate import VehicleStore, file_stem, profile_path

MODEL = LagModel(0.13, 0.25, -0.2, 0.01, 400, 1.0, time_constant_s=0.02)


def flown(hover_n: float | None = None, model: LagModel | None = None) -> SimpleNamespace:
    """What remember_flight reads of a FlightResult."""
    return SimpleNamespace(hover_n=hover_n, lag_model=model)


def fly(store: VehicleStore, hover_n: float | None = None, model: LagModel | None = None):
    """One flight's visit: read, then what it learned kept."""
    cfg, visit = store.with_learned_guess(FlightConfig())
    return cfg, store.remember_flight(cfg, flown(hover_n, model), visit)


def test_a_learned_hover_is_the_next_flights_guess_and_counts_its_flights(tmp_path):
    store = VehicleStore(tmp_path / "state" / "lab-1.json", "lab-1", print)
    _, first = fly(store, 0.327, MODEL)
    assert first.read is None and first.written
    assert first.describe() == f"vehicle profile: {store.path} (none yet; written)"
    cfg, second = fly(store, 0.331)
    assert cfg.vehicle.hover_thrust_n == pytest.approx(0.327, abs=1e-12)
    assert "read: hover 0.3270 N from 1 flight, lag 0.130 s" in second.describe()
    doc = json.loads(store.path.read_text())
    assert doc["schema"] == SCHEMA and doc["vehicle"] == "lab-1"
    assert doc["hover"]["thrust_n"] == 0.331 and doc["hover"]["flights"] == 2
    assert doc["response"] == {
        "lag_s": 0.13,
        "time_constant_s": 0.02,
        "drag_per_s": 0.25,
        "flights": 1,
    }
    other = VehicleStore(tmp_path / "state" / "lab-2.json", "lab-2", print)
    assert other.with_learned_guess(FlightConfig())[0] == FlightConfig()


def test_a_configured_hover_overrides_the_profile(tmp_path):
    store = VehicleStore(tmp_path / "v.json", "v", print)
    fly(store, 0.327)
    given = FlightConfig(vehicle=VehicleConfig(hover_thrust_n=0.3))
    assert store.with_learned_guess(given)[0].vehicle.hover_thrust_n == 0.3


def test_nothing_learned_is_nothing_written_and_said_so(tmp_path):
    store = VehicleStore(tmp_path / "v.json", "v", print)
    _, visit = fly(store)
    assert not store.path.exists() and visit.describe().endswith("not written: nothing learned)")


def test_an_unwritable_profile_is_one_warning_not_a_crash(tmp_path):
    (tmp_path / "file").write_text("")
    said: list[str] = []
    store = VehicleStore(tmp_path / "file" / "v.json", "v", said.append)
    cfg, visit = fly(store, 0.327)
    assert len(said) == 1 and "not written" in said[0] and "\n" not in said[0]
    assert cfg == FlightConfig() and not visit.written and "not written" in visit.describe()


@pytest.mark.parametrize(
    "hover",
    [
        {"thrust_n": "x", "ratio": 1.0, "mass_kg": 0.03, "flights": 1},
        {"thrust_n": 0.3, "ratio": 10**400, "mass_kg": 0.03, "flights": 1},
        {"thrust_n": 0.3, "ratio": 50.0, "mass_kg": 0.03, "flights": 1},
        {"thrust_n": 0.3, "ratio": 1.0, "mass_kg": 0.03, "flights": 0},
        {"thrust_n": 0.3, "ratio": 1.0, "mass_kg": 0.03, "flights": True},
        {"thrust_n": 0.3, "ratio": float("nan"), "mass_kg": 0.03, "flights": 1},
        {"ratio": 1.0},
        [],
    ],
)
def test_a_malformed_hover_is_no_memory(tmp_path, hover):
    path = tmp_path / "v.json"
    path.write_text(json.dumps({"schema": SCHEMA, "vehicle": "v", "hover": hover}))
    store = VehicleStore(path, "v", print)
    assert store.read().hover is None
    assert store.with_learned_guess(FlightConfig())[0] == FlightConfig()


def test_a_name_that_is_not_a_plain_file_name_stays_in_the_directory(tmp_path):
    """A driver URI names the vehicle when --vehicle does not: its '/' and '?' never lead
    out of the directory, and two URIs alike but for those characters never share a file."""
    a = profile_path("sim://?draught=-2.9,0.3", tmp_path)
    b = profile_path("sim:/?draught=-2.9,0.3", tmp_path)
    assert a.parent == b.parent == tmp_path and a != b
    assert profile_path("lab-1", tmp_path) == tmp_path / "lab-1.json"
    assert file_stem("..") != ".." and "/" not in file_stem("../../etc/passwd")


def test_forget_removes_a_profile_and_nothing_else(tmp_path):
    store = VehicleStore(tmp_path / "v.json", "v", print)
    fly(store, 0.327)
    assert store.forget() and not store.path.exists() and not store.forget()
