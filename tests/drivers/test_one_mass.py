"""The flight config's vehicle is the one mass. Drivers take it (bind_mass)
before they connect; a URI mass= that disagrees is refused, in one line naming both."""

from __future__ import annotations

import pytest

from perchd.core.errors import ConfigError
from perchd.core.runtime import Runtime
from perchd.drivers.base import open_driver
from perchd.drivers.thrust import CF_UNITS_MAX, CrazyflieThrust
from perchd.flight.config import FlightConfig, VehicleConfig
from perchd.flight.run import bind_vehicle
from perchd.session import open_links


def _cf(query: str = ""):
    pytest.importorskip("cflib")
    return open_driver(f"udp://127.0.0.1:9{query}", Runtime.real())


def test_the_crazyflie_thrust_model_takes_the_flights_mass():
    drv = _cf("?hover=38780")
    drv.bind_mass(0.0282)
    assert drv.model == CrazyflieThrust(hover_units=38780, mass_kg=0.0282)
    assert drv.model.units(0.0282 * 9.81) == 38780


def test_a_crazyflie_uri_mass_that_disagrees_is_refused_naming_both():
    with pytest.raises(ConfigError) as err:
        bind_vehicle(_cf("?mass=0.0282"), FlightConfig())
    msg = str(err.value)
    assert "mass=0.0282 kg" in msg and "vehicle.mass_kg = 0.03 kg" in msg and "\n" not in msg


def test_a_uri_mass_that_agrees_is_accepted():
    cfg = FlightConfig(vehicle=VehicleConfig(mass_kg=0.0282))
    assert bind_vehicle(_cf("?mass=0.0282"), cfg).vehicle.mass_kg == 0.0282


def test_the_mismatch_is_refused_before_the_driver_connects():
    pytest.importorskip("cflib")
    # Nothing listens on the port: a connect would fail with LinkError after its wait.
    with pytest.raises(ConfigError, match="disagrees"):
        open_links(
            "udp://127.0.0.1:9?mass=0.0282&wait=5", "zmq://127.0.0.1:9?body=cf1", mass_kg=0.030
        )


def test_a_mavlink_uri_mass_that_disagrees_is_refused():
    pytest.importorskip("pymavlink")
    drv = open_driver("mavlink:udpout:127.0.0.1:14550?mass=3.0", Runtime.real())
    with pytest.raises(ConfigError, match=r"mass=3 kg .* vehicle.mass_kg = 0.03 kg"):
        bind_vehicle(drv, FlightConfig())


def test_a_mavlink_driver_takes_its_mass_from_the_flight():
    pytest.importorskip("pymavlink")
    drv = open_driver("mavlink:udpout:127.0.0.1:14550", Runtime.real())
    drv.bind_mass(3.0)
    assert drv.mass_kg == 3.0


def test_the_crazyflie_ceiling_caps_the_flights_thrust():
    drv = _cf("?hover=50000")  # a weak vehicle: 60000 units are little above its hover
    cfg = bind_vehicle(drv, FlightConfig())
    ceiling = CrazyflieThrust(hover_units=50000, mass_kg=0.030).newtons(CF_UNITS_MAX)
    assert cfg.vehicle.thrust_max_n == pytest.approx(ceiling) and ceiling < 0.5


def test_a_mavlink_driver_never_given_a_mass_refuses_to_connect():
    pytest.importorskip("pymavlink")
    drv = open_driver("mavlink:udpout:127.0.0.1:9?wait=0.3", Runtime.real())
    with pytest.raises(ConfigError, match="vehicle mass is unknown"):
        drv.connect()
