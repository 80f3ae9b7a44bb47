"""The hard envelope: bounds no setting can lift (docs/safety.md "Hard envelope").

The flight config validates against these (perchd.flight.config.validate) and the
simulated vehicle's failsafe descends by them; a config may narrow the envelope, never
widen it.
"""

from __future__ import annotations

CEILING_ABOVE_FLOOR_M = 10.0
"""[m] the highest geofence ceiling, above its floor: no flying room perches higher."""
TAKEOFF_HEIGHT_MAX_M = 5.0
"""[m] the highest take-off height (world): 100 is centimetres typed as metres."""
MARGIN_M = 0.2
"""[m] every height reference stays this far inside the geofence's floor and ceiling."""
FAILSAFE_DROP_MAX_M = 1.5
"""[m] the highest a failsafe cuts the motors from; above, it descends to this first."""
FAILSAFE_DESCENT_MPS = 0.5
"""[m/s] the failsafe's descent rate down to FAILSAFE_DROP_MAX_M."""
