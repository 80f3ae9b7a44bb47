"""Flight configuration: frozen SI defaults, and one clear error per bad field."""

from __future__ import annotations

import dataclasses
import math

import pytest

from perchd.core.errors import ConfigError
from perchd.flight.config import (
    FlightConfig,
    SafetyConfig,
    SurfaceConfig,
    TauGains,
    TriggerConfig,
    VehicleConfig,
)


def test_defaults_are_a_30_g_crazyflie_at_100_hz_with_25_degree_tilt():
    cfg = FlightConfig()
    assert cfg.vehicle.mass_kg == 0.030 and cfg.rate_hz == 100.0
    assert math.degrees(cfg.tilt_limit_rad) == pytest.approx(25.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.rate_hz = 200.0


@pytest.mark.parametrize(
    "kwargs,message",
    [
        ({"rate_hz": 600.0}, r"\[flight\] rate_hz = 600 Hz: outside its range 20..500 Hz"),
        (
            {"tilt_limit_rad": 0.0},
            r"\[flight\] tilt_limit_rad = 0 rad \(0 deg\): outside its range",
        ),
        (
            {"vehicle": VehicleConfig(thrust_max_n=0.2)},
            r"\[vehicle\] thrust_max_n = 0.2 N must lift \[vehicle\] mass_kg = 0.03 kg: more than "
            r"its weight 0.2943 N",
        ),
        (
            {"vehicle": VehicleConfig(thrust_min_n=0.7)},
            r"\[vehicle\] thrust_min_n = 0.7 N must be below \[vehicle\] thrust_max_n = 0.627 N",
        ),
        (
            {"vehicle": VehicleConfig(hover_thrust_n=0.7)},
            r"\[vehicle\] hover_thrust_n = 0.7 N must be at most \[vehicle\] thrust_max_n",
        ),
        ({"idle_thrust_n": 0.7}, r"\[flight\] idle_thrust_n = 0.7 N must be at most"),
        (
            {"surface": SurfaceConfig(normal=(0.0, 0.0, 1.0))},
            r"\[surface\] normal .* must point more sideways",
        ),
        ({"tau_gains": TauGains(kp_fast=-50.0)}, r"\[tau_gains\] kp_fast = -50 m/s\^2: outside"),
        (
            {"safety": SafetyConfig(timeout_s=-1.0)},
            r"\[safety\] timeout_s = -1 s: outside its range",
        ),
        (
            {"trigger": TriggerConfig(library="lib.json")},
            r"\[trigger\] library is used by policy 'replan'",
        ),
    ],
)
def test_a_setting_out_of_range_or_a_broken_rule_is_one_error_naming_it(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        FlightConfig(**kwargs)
