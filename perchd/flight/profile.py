"""A vehicle's profile: what flights learned of the vehicle itself, as readable JSON.

    {"schema": "perchd.vehicle/1", "vehicle": NAME,
     "hover": {"thrust_n": N, "ratio": R, "mass_kg": M, "flights": K},
     "response": {"lag_s": L, "time_constant_s": T, "drag_per_s": D, "flights": K}}

hover: the latest hover thrust a hold learned [N], as a ratio R to the weight configured
then (mass_kg [kg] times g): with the drivers' thrust calibrated by the flight's mass
(Driver.bind_mass) the ratio is what carries over if the configured mass changes; the next
flight's hover guess. response: the latest lag [s] (time_constant_s [s] of it first-order)
and drag [1/s] the approach identified (flight/lagid.py), kept to be seen: every flight
identifies its own. flights: how many flights taught each. A push met in a flight (stage 1's
bias, a draught, the wall's air) is the air's, not the vehicle's: never kept.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, replace
from typing import Any

from perchd.flight.config import VehicleConfig
from perchd.flight.lagid import LagModel

SCHEMA = "perchd.vehicle/1"
HOVER_RATIO_RANGE = (0.1, 10.0)
"""A kept hover ratio outside this is no memory (a corrupted or hand-broken file)."""


@dataclass(frozen=True)
class Hover:
    """thrust_n [N] learned at mass_kg [kg]; ratio: thrust_n / (mass_kg g); flights: count."""

    thrust_n: float
    ratio: float
    mass_kg: float
    flights: int


@dataclass(frozen=True)
class Response:
    """lag_s [s] (time_constant_s [s] of it first-order), drag_per_s [1/s]; flights: count."""

    lag_s: float
    time_constant_s: float
    drag_per_s: float
    flights: int


@dataclass(frozen=True)
class VehicleProfile:
    """name: the vehicle's name (`perchd fly --vehicle`); hover, response: None until a
    flight learned them."""

    name: str
    hover: Hover | None = None
    response: Response | None = None

    def hover_guess_n(self, v: VehicleConfig) -> float | None:
        """[N] the kept ratio at this flight's weight (at most thrust_max_n), or None."""
        if self.hover is None:
            return None
        return min(self.hover.ratio * v.mass_kg * v.g, v.thrust_max_n)

    def learned(
        self, v: VehicleConfig, hover_n: float | None, model: LagModel | None
    ) -> VehicleProfile:
        """This profile with one more flight's hover [N] and identified response (None:
        not learned)."""
        out = self
        if hover_n is not None:
            count = self.hover.flights if self.hover else 0
            out = replace(
                out, hover=Hover(hover_n, hover_n / (v.mass_kg * v.g), v.mass_kg, count + 1)
            )
        if model is not None:
            count = self.response.flights if self.response else 0
            out = replace(
                out,
                response=Response(model.lag_s, model.time_constant_s, model.drag_per_s, count + 1),
            )
        return out

    def describe(self) -> str:
        """One line: what is known, e.g. 'hover 0.2950 N from 4 flights, lag 0.130 s'."""
        parts = []
        if self.hover:
            parts.append(f"hover {self.hover.thrust_n:.4f} N from {_flights(self.hover.flights)}")
        if self.response:
            r = self.response
            parts.append(
                f"lag {r.lag_s:.3f} s, drag {r.drag_per_s:.3f} 1/s from {_flights(r.flights)}"
            )
        return ", ".join(parts) or "nothing learned yet"

    def to_doc(self) -> dict[str, Any]:
        """The JSON document (the module docstring's format)."""
        doc: dict[str, Any] = {"schema": SCHEMA, "vehicle": self.name}
        if self.hover:
            doc["hover"] = vars(self.hover).copy()
        if self.response:
            doc["response"] = vars(self.response).copy()
        return doc


def is_profile(doc: Any) -> bool:
    """A document of this schema (its fields may still be malformed: from_doc drops them)."""
    return isinstance(doc, dict) and doc.get("schema") == SCHEMA


def from_doc(doc: dict[str, Any], name: str) -> VehicleProfile:
    """The profile of a document of this schema; a malformed part is no memory."""
    hover = _part(Hover, doc.get("hover"))
    if hover is not None and not HOVER_RATIO_RANGE[0] < hover.ratio < HOVER_RATIO_RANGE[1]:
        hover = None
    return VehicleProfile(name, hover, _part(Response, doc.get("response")))


def _part(cls: type, raw: Any) -> Any:
    """cls from a JSON object whose fields are finite numbers (flights a positive
    integer), or None."""
    if not isinstance(raw, dict):
        return None
    names = [f.name for f in dataclasses.fields(cls)]
    if set(raw) != set(names):
        return None
    ok = all(_count(raw[k]) if k == "flights" else _number(raw[k]) for k in names)
    if not ok:
        return None
    return cls(**{k: raw[k] if k == "flights" else float(raw[k]) for k in names})


def _count(x: object) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and 0 < x < 1 << 31


def _number(x: object) -> bool:
    """A finite JSON number (not a bool; an integer too large for a float is none)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def _flights(n: int) -> str:
    return f"{n} flight{'s' if n != 1 else ''}"
