"""Issue 13 B: the learned hover is kept per vehicle; an unwritable store is one warning."""

from __future__ import annotations

from perchd.flight.config import FlightConfig
from perchd.flight.vehiclestate import VehicleStore


def test_a_learned_hover_is_the_next_flights_guess(tmp_path):
    store = VehicleStore(tmp_path / "state" / "vehicles.json", print)
    store.remember("udp://x", 0.327, FlightConfig())
    cfg = store.with_learned_guess("udp://x", FlightConfig())
    assert abs(cfg.vehicle.hover_thrust_n - 0.327) < 1e-9
    assert store.with_learned_guess("udp://other", FlightConfig()).vehicle.hover_thrust_n is None


def test_an_unwritable_store_is_one_warning_not_a_crash(tmp_path):
    (tmp_path / "file").write_text("")
    said: list[str] = []
    store = VehicleStore(tmp_path / "file" / "vehicles.json", said.append)
    store.remember("udp://x", 0.327, FlightConfig())
    assert len(said) == 1 and "not kept" in said[0] and "\n" not in said[0]
    assert store.with_learned_guess("udp://x", FlightConfig()) == FlightConfig()
