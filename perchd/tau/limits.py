"""Limits a plan must respect, SI."""

from __future__ import annotations

import math
from dataclasses import dataclass

from perchd.core.errors import PlanError


@dataclass(frozen=True)
class Limits:
    """v_contact: [m/s] (V_l, V_u) allowed contact speeds.  v_max: [m/s] peak closing speed.
    a_max: [m/s^2] peak |acceleration| along X.  None means unconstrained."""

    v_contact: tuple[float, float]
    v_max: float | None = None
    a_max: float | None = None

    def __post_init__(self) -> None:
        lo, hi = self.v_contact
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi):
            raise PlanError(f"limits.v_contact must be 0 <= V_l <= V_u, got [{lo:g}, {hi:g}]")
        for name in ("v_max", "a_max"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise PlanError(f"limits.{name} must be a positive number, got {value!r}")

    def to_json(self) -> dict[str, object]:
        return {"v_contact": list(self.v_contact), "v_max": self.v_max, "a_max": self.a_max}
