"""Every URI scheme refuses unknown parameters and lists its parameters in one
table (perchd.core.uriparams.PARAMS), which docs/contracts.md §7 and `perchd fly --help` show."""

import subprocess
import sys
from pathlib import Path

import pytest

from perchd.core.clock import ManualClock
from perchd.core.errors import UriError
from perchd.core.runtime import Runtime
from perchd.core.uri import parse_uri
from perchd.core.uriparams import PARAMS, SIM, check_params
from perchd.drivers.base import open_driver
from perchd.mocap.base import open_source
from perchd.sim.plant import PlantParams
from perchd.sim.world import MocapParams, world_params_from_uri

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    "opener, uri",
    [
        (open_driver, "sim://?latncy=0.02"),
        (open_source, "sim://?noize=0.01"),
        (open_driver, "zmq://127.0.0.1:5999?vehical=cf1"),
        (open_driver, "mavlink:udpout:127.0.0.1:14550?mass=1&hovr=0.4"),
        (open_source, "zmq://127.0.0.1:5999?body=cf1&bdy=x"),
    ],
)
def test_a_misspelt_parameter_is_refused_naming_it(opener, uri):
    with pytest.raises(UriError, match="unknown parameter"):
        opener(uri, Runtime(ManualClock(0.0)))


@pytest.mark.parametrize("uri", ["radio://0/80/2M?extpos=1", "udp://127.0.0.1:19850?mas=0.03"])
def test_crazyflie_parameters_are_checked(uri):
    with pytest.raises(UriError, match="unknown parameter"):
        check_params("driver", parse_uri(uri))


def test_world_params_refuse_unknown_keys_too():
    with pytest.raises(UriError, match="'latncy'"):
        world_params_from_uri(parse_uri("sim://?latncy=0.02"))


def test_the_sim_defaults_listed_are_the_code_defaults():
    listed = {name: default for name, _, default, _ in SIM}
    p, m = PlantParams(), MocapParams()
    for key, value in (
        ("latency", p.latency_s),
        ("attitude_tau", p.attitude_tau_s),
        ("motor_tau", p.motor_tau_s),
        ("mass", p.mass_kg),
        ("mocap_rate", m.rate_hz),
        ("mocap_latency", m.latency_s),
        ("noise", m.noise_m),
    ):
        assert float(listed[key]) == value, key


def test_every_key_is_in_the_contract_and_the_help():
    contract = (ROOT / "docs" / "contracts.md").read_text()
    helptext = subprocess.run(
        [sys.executable, "-m", "perchd", "fly", "--help"], cwd=ROOT, capture_output=True, text=True
    ).stdout
    for params in PARAMS.values():
        for name, *_ in params:
            assert f"`{name}`" in contract and name in helptext, name
    assert "simulated clock" in helptext
