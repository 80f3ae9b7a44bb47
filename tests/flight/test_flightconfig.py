"""Flight configuration: frozen SI defaults, and one clear error per bad field."""

from __future__ import annotations

import dataclasses
import math

import pytest

from perchd.core.errors import ConfigError
from perchd.flight.config import FlightConfig, LagIdGains, SurfaceConfig, VehicleConfig


def test_defaults_are_a_30_g_crazyflie_at_100_hz_with_25_degree_tilt():
    cfg = FlightConfig()
    assert cfg.vehicle.mass_kg == 0.030 and cfg.rate_hz == 100.0
    assert math.degrees(cfg.tilt_limit_rad) == pytest.approx(25.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.rate_hz = 200.0


@pytest.mark.parametrize("kwargs,message", [
    ({"rate_hz": 600.0}, "rate_hz = 600 is above 500 by 100"),
    ({"tilt_limit_rad": 0.0}, "tilt_limit_rad = 0 is below 0.01 by 0.01"),
    ({"vehicle": VehicleConfig(thrust_max_n=0.2)}, "vehicle.thrust_max_n = 0.2 is below 0.2943"),
    ({"surface": SurfaceConfig(normal=(0.0, 0.0, 1.0))}, "surface.normal .* must point more sideways"),
    ({"lag_id": LagIdGains(lag_step_s=0.0)}, "lag_id.lag_step_s = 0 is below 0.005 by 0.005"),
    ({"lag_id": LagIdGains(time_constant_max_s=-1.0)},
     "lag_id.time_constant_max_s = -1 is below 0 by 1"),
    ({"lag_id": LagIdGains(stage2_prior_mps2=-0.1, stage2_prior_flights=101)},
     "lag_id.stage2_prior_flights = 101 is above 100 by 1"),
    ({"lag_id": LagIdGains(stage2_prior_mps2=0.6, stage2_prior_flights=3)},
     "lag_id.stage2_prior_mps2 = 0.6 is above 0.5 by 0.1"),
    ({"lag_id": LagIdGains(stage2_prior_mps2=-0.1)},
     "lag_id.stage2_prior_mps2 and lag_id.stage2_prior_flights go together"),
    ({"lag_id": LagIdGains(stage2_prior_flights=3)},
     "lag_id.stage2_prior_mps2 and lag_id.stage2_prior_flights go together"),
])
def test_a_field_out_of_range_is_one_error_naming_it_and_by_how_much(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        FlightConfig(**kwargs)
