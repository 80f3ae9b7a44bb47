"""What one flight learns about its vehicle, kept for the next: a small JSON file,
`{"schema": "perchd.vehicles/1", "vehicles": {KEY: {"hover_ratio": R, "hover_n": N,
"mass_kg": M}}}`, keyed by the vehicle (`perchd fly`: the driver URI; the service: its
vehicle name and driver URI).

The hover is kept as a ratio to the configured weight (hover_n / (mass_kg * g)): with the
drivers' thrust calibrated by the flight's mass (Driver.bind_mass) that ratio is what the
vehicle carries over if the configured mass changes. Reading or writing never fails a flight:
a missing, unreadable or malformed file is no memory, an unwritable one is one warning line.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from perchd.flight.config import FlightConfig

SCHEMA = "perchd.vehicles/1"


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

    def hover_ratio(self, key: str) -> float | None:
        rec = self._read().get(key)
        ratio = rec.get("hover_ratio") if isinstance(rec, dict) else None
        return float(ratio) if isinstance(ratio, (int, float)) and 0.1 < ratio < 10 else None

    def with_learned_guess(self, key: str, cfg: FlightConfig) -> FlightConfig:
        """cfg with the hover an earlier flight learned as its initial guess, unless the
        config gives one (vehicle.hover_thrust_n overrides the memory)."""
        ratio = self.hover_ratio(key)
        if ratio is None or cfg.vehicle.hover_thrust_n is not None:
            return cfg
        v = cfg.vehicle
        hover = min(ratio * v.mass_kg * v.g, v.thrust_max_n)
        return replace(cfg, vehicle=replace(v, hover_thrust_n=hover))

    def remember(self, key: str, hover_n: float, cfg: FlightConfig) -> None:
        v = cfg.vehicle
        vehicles = self._read()
        vehicles[key] = {"hover_ratio": hover_n / (v.mass_kg * v.g), "hover_n": hover_n,
                         "mass_kg": v.mass_kg}
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(json.dumps({"schema": SCHEMA, "vehicles": vehicles}, indent=1))
            os.replace(tmp, self.path)
        except OSError as err:
            self.warn(f"warning: learned hover {hover_n:.4f} N not kept: {self.path}: "
                      f"{err.strerror or err}")
