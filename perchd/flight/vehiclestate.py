"""What one flight learns about its vehicle, kept for the next: a small JSON file,
`{"schema": "perchd.vehicles/1", "vehicles": {KEY: {"hover_ratio": R, "hover_n": N,
"mass_kg": M, "stage2_departure_mps2": D, "stage2_flights": K}}}`, keyed by the vehicle
(`perchd fly`: --vehicle NAME, else the driver URI; the service: its vehicle name and
driver URI).

The hover is kept as a ratio to the configured weight (hover_n / (mass_kg * g)): with the
drivers' thrust calibrated by the flight's mass (Driver.bind_mass) that ratio is what the
vehicle carries over if the configured mass changes. The stage-2 departure is stage 1's
push beyond the approach's bias (LagIdGains.stage2_prior_mps2), from flights that touched
the surface: the mean of the first MEMORY_FLIGHTS, then an exponential mean weighing each
new flight 1/MEMORY_FLIGHTS. Reading or writing never fails a flight: a missing,
unreadable or malformed file or field is no memory, an unwritable file or a push beyond
STAGE2_PRIOR_MAX_MPS2 one warning line.

The file is read by core/safefile.py's bounded regular-file rule and written by its
write_atomic. Only a state file of perchd's own is ever replaced: anything else at the path
(a plan, a FIFO, /dev/zero, a file of another schema) is left as it is, refused before a
flight by check() and warned about after one.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from perchd.core.errors import PerchdError
from perchd.core.safefile import OutputError, read_regular, write_text
from perchd.core.types import EndReason
from perchd.flight.config import STAGE2_PRIOR_MAX_MPS2, FlightConfig

if TYPE_CHECKING:
    from perchd.flight.run import FlightResult

SCHEMA = "perchd.vehicles/1"
MEMORY_FLIGHTS = 10
"""The stage-2 departure stands for at most this many flights: a vehicle that changes (a new
propeller, a payload) is followed within about as many."""


def default_path() -> Path:
    """$XDG_STATE_HOME/perchd/vehicles.json (default ~/.local/state/perchd/vehicles.json)."""
    base = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    return Path(base) / "perchd" / "vehicles.json"


@dataclass(frozen=True)
class VehicleStore:
    """path: the JSON file; warn: where the one warning line goes."""

    path: Path
    warn: Callable[[str], None]

    def check(self) -> None:
        """OutputError (one line, before anything flies) unless the path is missing or a
        state file of perchd's own: a flight must never replace what is there."""
        try:
            os.lstat(self.path)
        except (FileNotFoundError, NotADirectoryError):
            return
        except (OSError, ValueError) as err:  # too long, a NUL byte, no permission
            why = err.strerror if isinstance(err, OSError) else err
            raise OutputError(f"--state {self.path}: cannot read ({why})") from None
        if self._load() is None:
            raise OutputError(f"--state {self.path}: not a perchd vehicle state file "
                              f"(schema {SCHEMA}); give another path")

    def _load(self) -> dict | None:
        """The vehicles of the state file; {} when there is none, None when the path holds
        something else (unreadable, not a regular file, not JSON, another schema)."""
        if not os.path.lexists(self.path):
            return {}
        try:
            doc = json.loads(read_regular(self.path, "", PerchdError))
        except (PerchdError, ValueError, RecursionError):
            return None
        ok = isinstance(doc, dict) and doc.get("schema") == SCHEMA \
            and isinstance(doc.get("vehicles"), dict)
        return doc["vehicles"] if ok else None

    def _read(self) -> dict:
        return self._load() or {}

    def _record(self, key: str, vehicles: dict | None = None) -> dict:
        rec = (self._read() if vehicles is None else vehicles).get(key)
        return rec if isinstance(rec, dict) else {}

    def hover_ratio(self, key: str, vehicles: dict | None = None) -> float | None:
        ratio = self._record(key, vehicles).get("hover_ratio")
        return float(ratio) if _number(ratio) and 0.1 < ratio < 10 else None

    def stage2_departure(self, key: str, vehicles: dict | None = None
                         ) -> tuple[float, int] | None:
        """(the mean departure [m/s^2], how many flights it stands for) or None."""
        rec = self._record(key, vehicles)
        mean, n = rec.get("stage2_departure_mps2"), rec.get("stage2_flights")
        ok = (_number(mean) and abs(mean) <= STAGE2_PRIOR_MAX_MPS2
              and isinstance(n, int) and not isinstance(n, bool) and n >= 1)
        return (float(mean), min(n, MEMORY_FLIGHTS)) if ok else None

    def with_learned_guess(self, key: str, cfg: FlightConfig) -> FlightConfig:
        """cfg with what earlier flights learned: the hover as its initial guess, unless the
        config gives one (vehicle.hover_thrust_n overrides the memory), and the stage-2
        departure as its prior, unless the config gives one (lag_id.stage2_prior_mps2)."""
        vehicles = self._read()
        ratio, departure = self.hover_ratio(key, vehicles), self.stage2_departure(key, vehicles)
        if ratio is not None and cfg.vehicle.hover_thrust_n is None:
            v = cfg.vehicle
            hover = min(ratio * v.mass_kg * v.g, v.thrust_max_n)
            cfg = replace(cfg, vehicle=replace(v, hover_thrust_n=hover))
        if departure is not None and cfg.lag_id.stage2_prior_mps2 is None:
            cfg = replace(cfg, lag_id=replace(cfg.lag_id, stage2_prior_mps2=departure[0],
                                              stage2_prior_flights=departure[1]))
        return cfg

    def remember_flight(self, key: str, cfg: FlightConfig, res: FlightResult) -> None:
        """Keep what a flight learned: its hover, and its stage-1 push if it touched (an
        aborted flight's stage 1 may have met what ended it)."""
        touched = res.outcome is EndReason.CONTACT
        self.remember(key, cfg, res.hover_n, res.stage2_departure_mps2 if touched else None)

    def remember(self, key: str, cfg: FlightConfig, hover_n: float | None = None,
                 departure_mps2: float | None = None) -> None:
        """Keep what this flight learned (None: nothing of that kind) beside the rest."""
        if departure_mps2 is not None and abs(departure_mps2) > STAGE2_PRIOR_MAX_MPS2:
            self.warn(f"warning: stage 1's push {departure_mps2:+.3f} m/s^2 beyond the "
                      f"approach's not kept: beyond +-{STAGE2_PRIOR_MAX_MPS2:g} m/s^2 it met "
                      "something passing, not the vehicle")
            departure_mps2 = None
        if hover_n is None and departure_mps2 is None:
            return
        vehicles = self._read()
        rec = self._record(key, vehicles)
        if hover_n is not None:
            v = cfg.vehicle
            rec.update(hover_ratio=hover_n / (v.mass_kg * v.g), hover_n=hover_n,
                       mass_kg=v.mass_kg)
        if departure_mps2 is not None:
            mean, n = self.stage2_departure(key, vehicles) or (0.0, 0)
            k = min(n + 1, MEMORY_FLIGHTS)
            rec.update(stage2_departure_mps2=mean + (departure_mps2 - mean) / k,
                       stage2_flights=k)
        vehicles[key] = rec
        self._write(vehicles, hover_n, departure_mps2)

    def _write(self, vehicles: dict, hover_n: float | None,
               departure_mps2: float | None) -> None:
        try:
            if self._load() is None:
                raise OutputError(f"{self.path}: not a perchd vehicle state file; left as it is")
            self.path.parent.mkdir(parents=True, exist_ok=True)
            write_text(self.path, json.dumps({"schema": SCHEMA, "vehicles": vehicles},
                                             indent=1), "--state", force=True)
        except OSError as err:
            learned = [f"hover {hover_n:.4f} N" if hover_n is not None else "",
                       f"stage-2 departure {departure_mps2:+.3f} m/s^2"
                       if departure_mps2 is not None else ""]
            why = err if isinstance(err, PerchdError) else f"{self.path}: {err.strerror or err}"
            self.warn(f"warning: learned {' and '.join(x for x in learned if x)} not kept: {why}")


def _number(x: object) -> bool:
    """A finite JSON number (not a bool; an integer too large for a float is none)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:
        return False
