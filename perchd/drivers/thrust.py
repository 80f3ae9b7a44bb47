"""Thrust models: collective thrust [N] to the units a vehicle's attitude interface takes.

perchd's Setpoint carries thrust in newtons; vehicles want a command. Each model is a frozen
dataclass with its constants and their sources, and maps both ways so tests can re-derive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from perchd.core.vehicle import CRAZYFLIE_HOVER_UNITS, CRAZYFLIE_MASS_KG, G_M_S2

G = G_M_S2
"""[m/s^2] gravity used for hover calibrations (docs/errata.md §8)."""

CF_UNITS_MAX = 60000
"""Largest thrust command: the firmware clamps RPYT thrust at 60000 (MAX_THRUST in
crtp_commander_rpyt.c), so anything above would be asked for and not flown (docs/firmware.md)."""


@dataclass(frozen=True, slots=True)
class CrazyflieThrust:
    """Crazyflie 2.0 thrust command u in 0..65535 <-> collective thrust [N].

    Shape: static thrust of one CF2.0 motor and propeller as identified by J. Foerster,
    "System Identification of the Crazyflie 2.0 Nano Quadrocopter" (ETH Zurich, 2015):
        f(u) = A u^2 + B u + C   [N per motor], four motors.
    Calibration: the curve is scaled by a single factor so that the vehicle's weight
    mass_kg * G maps exactly to hover_units. The default, 36000 units for 30 g at
    9.81 m/s^2, is the paper's hover figure (docs/errata.md §8: about 36000 for a 27-30 g CF2.0)
    at the mass perchd's controller and simulator use (VehicleConfig, PlantParams: a
    CF2.0 with markers); the unscaled curve gives 36000 <-> 26.6 g, so the default
    factor is 1.1262 (a 30 g vehicle's motors run ~6 % harder than the bare curve says).
    Set mass/hover per vehicle (driver URI ?mass=KG&hover=UNITS) after a hover test.
    """

    hover_units: float = CRAZYFLIE_HOVER_UNITS
    mass_kg: float = CRAZYFLIE_MASS_KG

    A = 2.130295e-11
    """[N / unit^2] per motor."""
    B = 1.032633e-6
    """[N / unit] per motor."""
    C = 5.484560e-4
    """[N] per motor."""

    def __post_init__(self) -> None:
        if not 1000 <= self.hover_units <= 60000:
            raise ValueError(f"hover thrust {self.hover_units} units is outside 1000..60000")
        if not 0.010 <= self.mass_kg <= 0.100:
            raise ValueError(f"Crazyflie mass {self.mass_kg} kg is outside 0.010..0.100 kg")

    @property
    def scale(self) -> float:
        """Dimensionless factor applied to the identified curve."""
        return self.mass_kg * G / (4.0 * self._motor(self.hover_units))

    def _motor(self, u: float) -> float:
        return self.A * u * u + self.B * u + self.C

    def newtons(self, units: float) -> float:
        """[N] collective thrust a command gives (0 N at 0 units: motors off)."""
        if units <= 0:
            return 0.0
        return 4.0 * self.scale * self._motor(units)

    def units(self, newtons: float) -> int:
        """Command for a collective thrust [N], rounded and clamped to 0..CF_UNITS_MAX.

        Zero or negative thrust is 0 (motors off; also the value that unlocks thrust)."""
        if newtons <= 0 or math.isnan(newtons):
            return 0
        per_motor = newtons / (4.0 * self.scale)
        disc = self.B * self.B - 4.0 * self.A * (self.C - per_motor)
        u = (-self.B + math.sqrt(max(disc, 0.0))) / (2.0 * self.A)
        return int(min(max(round(u), 0), CF_UNITS_MAX))


@dataclass(frozen=True, slots=True)
class NormalisedThrust:
    """Collective thrust [N] <-> the normalised 0..1 thrust of MAVLink SET_ATTITUDE_TARGET.

    Both ArduPilot (GUID_OPTIONS bit 3, "thrust as thrust") and PX4 take thrust as a
    fraction of maximum that their own thrust curve linearises (MOT_THST_EXPO,
    THR_MDL_FAC), so the model is linear through hover:
        fraction = hover_fraction * newtons / (mass_kg * G)
    hover_fraction is the autopilot's learnt hover thrust (ArduPilot MOT_THST_HOVER,
    PX4 MPC_THR_HOVER); the driver reads it from the vehicle unless the URI gives it.
    """

    mass_kg: float
    hover_fraction: float

    def __post_init__(self) -> None:
        if not 0.0 < self.mass_kg <= 50.0:
            raise ValueError(f"vehicle mass {self.mass_kg} kg is outside (0, 50] kg")
        if not 0.05 <= self.hover_fraction <= 0.95:
            raise ValueError(f"hover thrust fraction {self.hover_fraction} is outside 0.05..0.95")

    def fraction(self, newtons: float) -> float:
        """Normalised thrust in 0..1 (clamped; NaN and negative thrust give 0)."""
        if not newtons > 0:
            return 0.0
        return min(self.hover_fraction * newtons / (self.mass_kg * G), 1.0)

    def newtons(self, fraction: float) -> float:
        return fraction * self.mass_kg * G / self.hover_fraction
