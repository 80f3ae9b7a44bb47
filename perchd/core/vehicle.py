"""The default vehicle's constants, in one place: a Crazyflie 2.0 carrying mocap markers.

The controller's VehicleConfig, the simulator's PlantParams and the Crazyflie driver's
thrust model all start from these, so a default flight never has two masses.
"""

from __future__ import annotations

G_M_S2 = 9.81
"""[m/s^2] gravity, the value the paper's hover figure assumes (docs/errata.md §8)."""

CRAZYFLIE_MASS_KG = 0.030
"""[kg] a Crazyflie 2.0 with battery and mocap markers."""

CRAZYFLIE_HOVER_UNITS = 36000.0
"""[0..65535 thrust units] what holds a 27-30 g Crazyflie 2.0 in the air (docs/errata.md §8)."""

CRAZYFLIE_THRUST_MIN_N = 0.08
"""[N] least collective thrust while flying (the paper clamps at 10000 units, ~0.07 N)."""

CRAZYFLIE_THRUST_MAX_N = 0.627
"""[N] most collective thrust perchd asks of a Crazyflie 2.0: what the firmware's RPYT clamp
(60000 units, drivers/thrust.py CF_UNITS_MAX) gives in the default thrust model (30 g hover at
36000 units); a test re-derives it. A flight takes the smaller of this and its driver's own
ceiling (Driver.thrust_ceiling_n, for the calibration flown)."""
