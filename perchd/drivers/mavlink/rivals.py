"""Another GCS or companion computer steering the vehicle, noticed at connect: one that sends
attitude or position targets on the link, or a vehicle armed in its offboard mode already
(docs/safety.md "One vehicle, one agent"). The driver then refuses, naming it, before it
sends anything that steers."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from perchd.drivers.mavlink.dialect import Dialect
from perchd.drivers.mavlink.link import SOURCE
from perchd.drivers.mavlink.vehicle import GCS_OR_COMPANION, VehicleView
from perchd.drivers.targetlock import TargetBusy

STEERING = frozenset(
    {"SET_ATTITUDE_TARGET", "SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT"}
)
KINDS = {6: "GCS", 18: "companion"}  # MAV_TYPE of a heartbeat from GCS_OR_COMPANION


@dataclass
class RivalWatch:
    """Fed every message the link receives; (system, component) of each other sender of
    steering targets, and what its heartbeat says it is."""

    steering: dict[tuple[int, int], str] = field(default_factory=dict)  # source -> message
    kinds: dict[tuple[int, int], str] = field(default_factory=dict)  # source -> GCS/companion

    def on_message(self, msg: Any) -> None:
        kind, source = msg.get_type(), (msg.get_srcSystem(), msg.get_srcComponent())
        if source == SOURCE:
            return
        if kind in STEERING:
            self.steering.setdefault(source, kind)
        elif kind == "HEARTBEAT" and msg.type in GCS_OR_COMPANION:
            self.kinds[source] = KINDS[msg.type]

    def check(self, uri: str, vehicle: VehicleView, dialect: Dialect, ours: bool) -> None:
        """TargetBusy if another sender steers the vehicle; or if it is armed in the offboard
        mode already and not by this process (`ours`: it holds the vehicle's lock already,
        a service replacing its links)."""
        if self.steering:
            (system, component), message = next(iter(self.steering.items()))
            what = self.kinds.get((system, component), "GCS or companion")
            raise TargetBusy(
                f"{uri}: another {what} (system {system}, component {component}) "
                f"is steering the vehicle ({message}); stop it first"
            )
        if vehicle.armed and vehicle.mode == dialect.flight.custom and not ours:
            raise TargetBusy(
                f"{uri}: the vehicle is armed in its offboard mode already (custom "
                f"mode {vehicle.mode}): another GCS or companion flies it; stop it "
                "first"
            )
