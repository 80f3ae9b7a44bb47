"""The vehicle family: a distribution of simulated vehicles nobody tuned the controller for.

Every parameter is drawn independently from its range (the mass log-uniformly, since 25 g
and 3 kg are both ordinary vehicles), each vehicle from its own generator seeded by
(family seed, index), so vehicle i is the same whatever n is drawn. `lab_config` is the
flight config a lab would write for one of them knowing only its scale and its motors:
its mass and thrust limits, nothing of its dynamics.

The controller works in accelerations (its gains are m/s^2 per unit of error, its thrust
the commanded acceleration times the configured mass), so a 3 kg vehicle flies the same
world geometry, plans and speeds as a 25 g one: what differs is its response, not its size.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from perchd.core.vehicle import CRAZYFLIE_THRUST_MAX_N, CRAZYFLIE_THRUST_MIN_N
from perchd.flight.config import FlightConfig
from perchd.sim.plant import PlantParams
from perchd.sim.world import MocapParams

LAB_THRUST_MIN_SHARE = CRAZYFLIE_THRUST_MIN_N / CRAZYFLIE_THRUST_MAX_N
"""thrust_min_n as a share of the vehicle's full thrust: the Crazyflie's own (about 13 %),
the one floor perchd's defaults already fly with."""


@dataclass(frozen=True)
class Span:
    """lo..hi of one parameter, in the unit of the field it draws; log: log-uniform."""

    lo: float
    hi: float
    log: bool = False

    def draw(self, rng: np.random.Generator) -> float:
        if self.log:
            return float(math.exp(rng.uniform(math.log(self.lo), math.log(self.hi))))
        return float(rng.uniform(self.lo, self.hi))

    def holds(self, value: float) -> bool:
        return self.lo <= value <= self.hi


@dataclass(frozen=True)
class Family:
    """The ranges. mass_kg [kg]; thrust_to_weight: full collective thrust over weight;
    attitude_tau_s, motor_tau_s [s] first-order time constants; latency_s [s] command
    delay; drag_per_s [1/s] linear, qdrag_per_m [1/m] quadratic drag; mocap_rate_hz [Hz],
    mocap_latency_s [s], mocap_noise_m [m] std per axis; draught_mps2 [m/s^2] a push along
    the approach (> 0: towards the wall) from draught_reach_m [m] before the wall on."""

    mass_kg: Span = Span(0.025, 3.0, log=True)
    thrust_to_weight: Span = Span(1.6, 2.5)
    attitude_tau_s: Span = Span(0.03, 0.25)
    latency_s: Span = Span(0.0, 0.10)
    motor_tau_s: Span = Span(0.01, 0.08)
    drag_per_s: Span = Span(0.0, 1.2)
    qdrag_per_m: Span = Span(0.0, 0.4)
    mocap_rate_hz: Span = Span(60.0, 360.0)
    mocap_latency_s: Span = Span(0.0, 0.015)
    mocap_noise_m: Span = Span(0.0, 0.001)
    draught_mps2: Span = Span(-0.3, 0.3)
    draught_reach_m: Span = Span(0.2, 1.0)


FAMILY = Family()


@dataclass(frozen=True)
class FamilyVehicle:
    """One member: its index in the sample, seed (its draws and its mocap noise), the
    plant flown and the mocap that measures it. The wall is the default world's (x = 0,
    approached along +X), so the draught starts at world x = -draught_reach_m."""

    index: int
    seed: int
    plant: PlantParams
    mocap: MocapParams

    @property
    def thrust_to_weight(self) -> float:
        return self.plant.thrust_max_n / (self.plant.mass_kg * self.plant.g)

    @property
    def draught_reach_m(self) -> float:
        return -self.plant.draught_x_m


def vehicle(index: int, seed: int, family: Family = FAMILY) -> FamilyVehicle:
    """Member `index` of the family drawn with `seed`: the same for any sample size."""
    rng = np.random.default_rng([seed, index])
    d = {f.name: getattr(family, f.name).draw(rng) for f in dataclasses.fields(family)}
    plant = PlantParams(
        mass_kg=d["mass_kg"],
        attitude_tau_s=d["attitude_tau_s"],
        motor_tau_s=d["motor_tau_s"],
        latency_s=d["latency_s"],
        drag_per_s=d["drag_per_s"],
        qdrag_per_m=d["qdrag_per_m"],
        draught_x_m=-d["draught_reach_m"],
        draught_mps2=d["draught_mps2"],
    )
    plant = dataclasses.replace(plant, thrust_max_n=d["thrust_to_weight"] * d["mass_kg"] * plant.g)
    mocap = MocapParams(d["mocap_rate_hz"], d["mocap_latency_s"], d["mocap_noise_m"])
    return FamilyVehicle(index, int(rng.integers(0, 2**31)), plant, mocap)


def sample(n: int, seed: int, family: Family = FAMILY) -> list[FamilyVehicle]:
    """n members, indices 0..n-1, deterministic per seed."""
    if n < 0:
        raise ValueError(f"n = {n}: a sample is at least empty")
    return [vehicle(i, seed, family) for i in range(n)]


def lab_config(member: FamilyVehicle, base: FlightConfig) -> FlightConfig:
    """The base config with the member's mass and thrust limits (full thrust its real one,
    the floor LAB_THRUST_MIN_SHARE of it, the hover guessed from the mass: a first flight
    remembers none); every gain, limit and timing is the base's."""
    full = member.plant.thrust_max_n
    v = dataclasses.replace(
        base.vehicle,
        mass_kg=member.plant.mass_kg,
        thrust_max_n=full,
        thrust_min_n=LAB_THRUST_MIN_SHARE * full,
        hover_thrust_n=None,
    )
    return dataclasses.replace(base, vehicle=v)
