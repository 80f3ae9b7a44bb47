"""perchd.toml: versioned, every key documented, unknown keys and bad values name the key."""

import dataclasses
import math
import re
from pathlib import Path

import pytest
from svc import perchd

from perchd.core.errors import ConfigError
from perchd.flight.config import FlightConfig, TriggerPolicy
from perchd.service.config import ServiceConfig, config_from_dict, load_config

EXAMPLE = Path(__file__).resolve().parents[2] / "systemd" / "perchd.toml"


def leaves(obj, prefix=""):
    """Every scalar field of a nested dataclass as 'section.key'."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            yield from leaves(value, f"{prefix}{f.name}.")
        else:
            yield prefix + f.name


def test_the_example_documents_every_key_with_its_default():
    text = EXAMPLE.read_text()
    documented = set(re.findall(r"^#? ?(\w+) = ", text, re.M))
    wanted = (
        {k.rsplit(".", 1)[-1] for k in leaves(FlightConfig())}
        | set(f.name for f in dataclasses.fields(ServiceConfig))
        | {"version"}
    )
    wanted = {k[:-4] + "_deg" if k.endswith("_rad") else k for k in wanted}
    assert wanted - documented == set()
    cfg = load_config(EXAMPLE)
    assert cfg.service == ServiceConfig()
    for key in leaves(FlightConfig()):
        got, default = cfg.flight, FlightConfig()
        for part in key.split("."):
            got, default = getattr(got, part), getattr(default, part)
        assert got == (
            pytest.approx(default, rel=1e-6) if isinstance(default, float) else default
        ), key


def test_values_map_onto_flight_config_with_degrees_converted():
    cfg = config_from_dict(
        {
            "version": 1,
            "flight": {"rate_hz": 200, "tilt_limit_deg": 20},
            "safety": {"tilt_max_deg": 30.0},
            "trigger": {"policy": "robust"},
            "lateral": {"y": {"kp": 2.0}},
            "surface": {"point": [1, 2, 0]},
            "service": {"mocap": "natnet://10.0.0.2", "body": "cf7"},
        }
    )
    f = cfg.flight
    assert f.rate_hz == 200.0 and f.tilt_limit_rad == pytest.approx(math.radians(20))
    assert f.safety.tilt_max_rad == pytest.approx(math.radians(30))
    assert f.trigger.policy is TriggerPolicy.ROBUST
    assert f.lateral.y.kp == 2.0 and f.lateral.y.ki == FlightConfig().lateral.y.ki
    assert f.surface.point == (1.0, 2.0, 0.0)
    assert cfg.service.mocap_uri() == "natnet://10.0.0.2?body=cf7"


@pytest.mark.parametrize(
    "doc, message",
    [
        ({"safety": {"tilt_max_deg": "x"}}, "[safety] tilt_max_deg: expected a number, got 'x'"),
        ({"flight": {"rate_hz": 1000}}, "[flight] rate_hz = 1000 Hz: outside its range 20..500 Hz"),
        ({"limits": {}}, "unknown table or key 'limits'"),
        ({"service": {"drver": "sim://"}}, "[service] drver: unknown key"),
        ({"lateral": {"y": {"kq": 1}}}, "[lateral.y] kq: unknown key"),
        (
            {"trigger": {"policy": "maybe"}},
            "[trigger] policy: expected 'robust' or 'replan' or 'refuse'",
        ),
        ({"surface": {"normal": [1, 0]}}, "[surface] normal: expected a list of 3 numbers"),
        ({"safety": {"overrun_streak": 10}}, "[safety] overrun_streak: unknown key"),
        ({"tau_gains": {"feedforward": 1}}, "[tau_gains] feedforward: expected true or false"),
        ({"service": {"socket": 3}}, "[service] socket: expected a string, got 3"),
        (
            {"flight": {"tilt_limit_deg": 20, "tilt_limit_rad": 0.3}},
            "[flight] tilt_limit_deg and tilt_limit_rad: give one of them, not both",
        ),
        (
            {"safety": {"tilt_max_rad": 0.5, "tilt_max_deg": 30}},
            "[safety] tilt_max_deg and tilt_max_rad: give one of them, not both",
        ),
    ],
)
def test_a_bad_key_or_value_is_one_error_naming_it(doc, message):
    with pytest.raises(ConfigError) as err:
        config_from_dict({"version": 1, **doc})
    assert message in str(err.value) and str(err.value).startswith("perchd.toml: ")


def test_the_version_is_required():
    with pytest.raises(ConfigError, match=r"version: expected 1, got None \(missing\)"):
        config_from_dict({})
    with pytest.raises(ConfigError, match="version: expected 1, got 2"):
        config_from_dict({"version": 2})


def test_serve_with_a_bad_config_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "perchd.toml"
    bad.write_text('version = 1\n[safety]\ntilt_max_deg = "x"\n')
    done = perchd("serve", "--config", str(bad), "--socket", str(tmp_path / "s"))
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "perchd serve: perchd.toml: [safety] tilt_max_deg: expected a number, got 'x'"
    ]
    assert not (tmp_path / "s").exists()


def test_fly_reads_the_flight_part_of_the_same_file(tmp_path):
    cfg = tmp_path / "perchd.toml"
    cfg.write_text("version = 1\n[flight]\nrate_hz = 5\n")
    done = perchd(
        "fly",
        "plans/case1-ipts-n3.json",
        "--driver",
        "sim://",
        "--mocap",
        "sim://",
        "--config",
        str(cfg),
        cwd=EXAMPLE.parents[1],
    )
    assert (
        done.returncode == 2
        and "[flight] rate_hz = 5 Hz: outside its range 20..500 Hz" in done.stderr
    )


@pytest.mark.parametrize(
    "surface, message",
    [
        (
            {"point": [math.inf, 0.0, 0.0]},
            "[surface] point[0] = inf: not a finite number (range -1000..1000 m)",
        ),
        ({"normal": [1.0, math.nan, 0.0]}, "[surface] normal[1] = nan: not a finite number"),
        (
            {"point": [0.0, 1e300, 0.0]},
            "[surface] point[1] = 1e+300 m: outside its range -1000..1000 m",
        ),
    ],
)
def test_a_service_surface_is_held_to_the_same_geometry_rule_as_fly_flags(surface, message):
    """`perchd fly --surface` refused these; the service's [surface] table flew them (found
    by the config fuzzer: an infinite point loaded)."""
    with pytest.raises(ConfigError, match=re.escape(message)):
        config_from_dict({"version": 1, "surface": surface})


@pytest.mark.parametrize("vehicle", ["a/b", "../x", "..", ".hidden", "a\0b", "a\\b", "", "x" * 65])
def test_a_vehicle_name_that_would_lead_a_log_out_of_log_dir_is_refused(vehicle):
    # the service names each flight's log after its vehicle: "a/b" would write beside it
    with pytest.raises(ConfigError, match=r"\[service\] vehicle: .* is not a plain name"):
        config_from_dict({"version": 1, "service": {"vehicle": vehicle}})


@pytest.mark.parametrize("value", [10**400, -(10**400), True, math.inf, math.nan])
def test_a_number_beyond_a_float_or_not_a_number_is_one_config_error(value):
    """Beyond a float or not a number: the loader's type check; inf and NaN: the range
    check, which names the range too."""
    why = (
        r": expected a number"
        if not isinstance(value, float)
        else r" = (inf|nan): not a finite number \(range 0.001..50 kg\)"
    )
    with pytest.raises(ConfigError, match=r"\[vehicle\] mass_kg" + why):
        config_from_dict({"version": 1, "vehicle": {"mass_kg": value}})
    with pytest.raises(ConfigError):
        config_from_dict({"version": 1, "surface": {"point": [value, 0.0, 0.0]}})


def test_an_integer_beyond_pythons_digit_limit_is_one_config_error(tmp_path):
    path = tmp_path / "perchd.toml"
    path.write_text("version = 1\n[vehicle]\nmass_kg = " + "9" * 5000 + "\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(path)


def test_a_hex_integer_of_more_digits_than_python_writes_is_one_config_error(tmp_path):
    # found by benchmarks/fuzz.py: the error message's repr() of it raised ValueError
    path = tmp_path / "perchd.toml"
    path.write_text("version = 1\n[vehicle]\nmass_kg = 0x" + "f" * 4000 + "\n")
    with pytest.raises(ConfigError, match="mass_kg: expected a number, got a value too long"):
        load_config(path)


def test_a_version_or_table_too_long_to_show_is_one_config_error(tmp_path):
    path = tmp_path / "perchd.toml"
    for text in ("version = 0x" + "f" * 4000, "version = 1\nvehicle = [0x" + "f" * 4000 + "]"):
        path.write_text(text + "\n")
        with pytest.raises(ConfigError, match="too long to show"):
            load_config(path)
