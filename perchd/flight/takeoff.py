"""The take-off's height reference: what the TAKEOFF phase asks the height loop for.

A vehicle on the ground may not leave it when its thrust first lifts: an autopilot's land
detector and motor spool-up hold it (ArduCopter SITL sits ~0.7 s at 1.1 x its hover thrust,
then surges; docs/safety.md "Ground take-off"). A reference that climbs meanwhile, and a
height integral that grows against the ground, are released all at once and overshoot. So:
- until the measured height is LIFTOFF_M above the start, the reference is the start plus
  LEAD_M (a constant push of kp x LEAD_M above the hover thrust) and does not move; the
  supervisor keeps the height integral at zero. Only a vehicle still on the ground after
  GROUND_WAIT_S, longer than any spool-up and land detector seen, is pushed harder: the lead
  grows at LEAD_GROWTH_MPS to LEAD_MAX_M, for a hover thrust guessed too low;
- from then on it is a smooth profile (accelerate, climb at the take-off speed, decelerate
  to stop at the hold height), with its velocity and acceleration fed forward, so the height
  loop's own dynamics are not excited by the reference's corners (its damping is ~0.2);
- it never runs further ahead of the measured height than the lead it lifted off with: a
  vehicle that lags or sticks again cannot wind the reference up.
Measured state only: no driver tells the supervisor that the vehicle is airborne.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

LIFTOFF_M = 0.03
"""[m] measured height above the start that counts as off the ground: above mocap noise
(~1 mm), below what a vehicle crawling on its landing gear reaches before it is free."""
LEAD_M = 0.2
"""[m] how far the reference runs ahead of the measured height; on the ground it asks for
kp x LEAD_M (1.09 m/s^2 with the default height gain, 11 % of g) above the hover thrust."""
GROUND_WAIT_S = 1.5
"""[s] on the ground with the LEAD_M push before the lead grows: ArduCopter SITL leaves
after ~0.7 s at 1.1 x its hover thrust; a vehicle still down is heavier than its guess."""
LEAD_GROWTH_MPS = 0.1
"""[m/s] growth of the lead after GROUND_WAIT_S: 0.55 m/s^2 (5.6 % of g) more push a
second, so a vehicle that then leaves carries little more than it needed."""
LEAD_MAX_M = 0.6
"""[m] the most lead: kp x 0.6 m is a third of g above the guess; a vehicle that needs more
is beyond what the hover learner accepts anyway (flight/hover.py's RATIO)."""
ACCEL_MPS2 = 0.5
"""[m/s^2] the profile's acceleration and deceleration: with its feed-forward the loop
follows it; the deceleration ends the climb at the hold height at rest."""


@dataclass(frozen=True, slots=True)
class HeightRef:
    """z [m] (perching frame), vz [m/s], az [m/s^2]: the height reference of one tick."""

    z: float
    vz: float
    az: float


class TakeoffProfile:
    """z0 [m]: the measured start height; z1 [m]: the hold height; speed [m/s]: the climb
    rate (ApproachConfig.takeoff_speed_mps). `step` once per TAKEOFF tick."""

    def __init__(self, z0: float, z1: float, speed: float) -> None:
        self.z0, self.z1, self.speed = z0, z1, speed
        self.lifted = False
        self.lead = LEAD_M  # [m] now; frozen at lift-off
        self._ground_s = 0.0  # [s] on the ground so far
        self._z = min(z0 + LEAD_M, z1)
        self._v = 0.0

    @property
    def done(self) -> bool:
        """The reference has come to rest at the hold height."""
        return self.lifted and self._z >= self.z1 and self._v == 0.0

    def step(self, dt: float, z: float) -> HeightRef:
        """The reference for a tick dt [s] after the last, given the measured height z [m]."""
        if not self.lifted and z - self.z0 < LIFTOFF_M:
            self._ground_s += dt
            late = max(0.0, self._ground_s - GROUND_WAIT_S)
            self.lead = min(LEAD_M + LEAD_GROWTH_MPS * late, LEAD_MAX_M)
            self._z = min(self.z0 + self.lead, self.z1)
            return HeightRef(self._z, 0.0, 0.0)
        self.lifted = True
        v0 = self._v
        stop = math.sqrt(2.0 * ACCEL_MPS2 * max(self.z1 - self._z, 0.0))
        self._v = max(0.0, min(v0 + ACCEL_MPS2 * dt, self.speed, stop))
        self._z = min(self._z + 0.5 * (v0 + self._v) * dt, self.z1, z + self.lead)
        if self._z >= self.z1:
            self._v = 0.0
        az = (self._v - v0) / dt if dt > 0 else 0.0
        # the last tick's stop is a step of the discrete profile, not an acceleration to fly
        return HeightRef(self._z, self._v, min(max(az, -ACCEL_MPS2), ACCEL_MPS2))
