"""What one flight learns about its vehicle, kept for the next: a small JSON file,
`{"schema": "perchd.vehicles/1", "vehicles": {KEY: {"hover_ratio": R, "hover_n": N,
"mass_kg": M, "stage2_departure_mps2": D, "stage2_flights": K}}}`, keyed by the vehicle
(`perchd fly`: the driver URI; the service: its vehicle name and driver URI).

The hover is kept as a ratio to the configured weight (hover_n / (mass_kg * g)): with the
drivers' thrust calibrated by the flight's mass (Driver.bind_mass) that ratio is what the
vehicle carries over if the configured mass changes. The stage-2 departure is the running
mean of the flights' stage-1 push beyond the approach's bias (LagIdGains.stage2_prior_mps2)
over the last K of them, K at most MEMORY_FLIGHTS. Reading or writing never fails a flight:
a missing, unreadable or malformed file or field is no memory, an unwritable file one
warning line.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from perchd.flight.config import FlightConfig

SCHEMA = "perchd.vehicles/1"
MEMORY_FLIGHTS = 10
"""The stage-2 departure is the mean of at most this many flights: a vehicle that changes
(a new propeller, a payload) is followed within about as many."""


def default_path() -> Path:
    """$XDG_STATE_HOME/perchd/vehicles.json (default ~/.local/state/perchd/vehicles.json)."""
    base = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    return Path(base) / "perchd" / "vehicles.json"


@dataclass(frozen=True)
class VehicleStore:
    """path: the JSON file; warn: where the one warning line goes."""

    path: Path
    warn: Callable[[str], None]

    def _read(self) -> dict:
        try:
            doc = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return {}
        ok = isinstance(doc, dict) and doc.get("schema") == SCHEMA \
            and isinstance(doc.get("vehicles"), dict)
        return doc["vehicles"] if ok else {}

    def _record(self, key: str) -> dict:
        rec = self._read().get(key)
        return rec if isinstance(rec, dict) else {}

    def hover_ratio(self, key: str) -> float | None:
        ratio = self._record(key).get("hover_ratio")
        return float(ratio) if _number(ratio) and 0.1 < ratio < 10 else None

    def stage2_departure(self, key: str) -> tuple[float, int] | None:
        """(the mean departure [m/s^2], how many flights) or None."""
        rec = self._record(key)
        mean, n = rec.get("stage2_departure_mps2"), rec.get("stage2_flights")
        ok = _number(mean) and abs(mean) < 5.0 and isinstance(n, int) and n >= 1
        return (float(mean), min(n, MEMORY_FLIGHTS)) if ok else None

    def with_learned_guess(self, key: str, cfg: FlightConfig) -> FlightConfig:
        """cfg with what earlier flights learned: the hover as its initial guess, unless the
        config gives one (vehicle.hover_thrust_n overrides the memory), and the stage-2
        departure as its prior, unless the config gives one (lag_id.stage2_prior_mps2)."""
        ratio, departure = self.hover_ratio(key), self.stage2_departure(key)
        if ratio is not None and cfg.vehicle.hover_thrust_n is None:
            v = cfg.vehicle
            hover = min(ratio * v.mass_kg * v.g, v.thrust_max_n)
            cfg = replace(cfg, vehicle=replace(v, hover_thrust_n=hover))
        if departure is not None and cfg.lag_id.stage2_prior_mps2 is None:
            cfg = replace(cfg, lag_id=replace(cfg.lag_id, stage2_prior_mps2=departure[0],
                                              stage2_prior_flights=departure[1]))
        return cfg

    def remember(self, key: str, cfg: FlightConfig, hover_n: float | None = None,
                 departure_mps2: float | None = None) -> None:
        """Keep what this flight learned (None: nothing of that kind) beside the rest."""
        if hover_n is None and departure_mps2 is None:
            return
        vehicles = self._read()
        rec = self._record(key)
        if hover_n is not None:
            v = cfg.vehicle
            rec.update(hover_ratio=hover_n / (v.mass_kg * v.g), hover_n=hover_n,
                       mass_kg=v.mass_kg)
        if departure_mps2 is not None:
            mean, n = self.stage2_departure(key) or (0.0, 0)
            k = min(n + 1, MEMORY_FLIGHTS)
            rec.update(stage2_departure_mps2=mean + (departure_mps2 - mean) / k,
                       stage2_flights=k)
        vehicles[key] = rec
        self._write(vehicles, hover_n, departure_mps2)

    def _write(self, vehicles: dict, hover_n: float | None,
               departure_mps2: float | None) -> None:
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(json.dumps({"schema": SCHEMA, "vehicles": vehicles}, indent=1))
            os.replace(tmp, self.path)
        except OSError as err:
            learned = [f"hover {hover_n:.4f} N" if hover_n is not None else "",
                       f"stage-2 departure {departure_mps2:+.3f} m/s^2"
                       if departure_mps2 is not None else ""]
            self.warn(f"warning: learned {' and '.join(x for x in learned if x)} not kept: "
                      f"{self.path}: {err.strerror or err}")


def _number(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
