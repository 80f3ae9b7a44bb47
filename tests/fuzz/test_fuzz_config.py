"""perchd.toml under fuzzing: any bytes in the file or any value under any key gives either a
valid Config or one ConfigError naming the problem; never another exception."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from mutate import mutated_bytes, mutated_document

from perchd.core.errors import ConfigError
from perchd.service.config import Config, config_from_dict, load_config

EXAMPLE = Path(__file__).resolve().parents[2] / "systemd" / "perchd.toml"
SMALL = b'version = 1\n[service]\nvehicle = "cf2"\n[flight]\nrate_hz = 200\n[safety]\ntilt_max_deg = 30\n'
TEXTS = [EXAMPLE.read_bytes(), SMALL]
DOC = tomllib.loads(EXAMPLE.read_text())
FAST = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])


def check(config: Config) -> None:
    """What a loaded config promises: every number finite, the service fields strings."""

    def numbers(obj):
        for value in vars(obj).values():
            if isinstance(value, float):
                yield value
            elif hasattr(value, "__dataclass_fields__"):
                yield from numbers(value)
            elif isinstance(value, tuple):
                yield from (v for v in value if isinstance(v, float))

    assert all(math.isfinite(v) for v in numbers(config.flight))
    assert all(isinstance(getattr(config.service, k), str) for k in ("vehicle", "driver", "socket"))


@FAST
@given(mutated_document(DOC).filter(lambda d: isinstance(d, dict)))
def test_any_value_under_any_key_is_a_config_or_one_config_error(doc):
    try:
        config = config_from_dict(doc)
    except ConfigError as err:
        assert str(err).startswith("perchd.toml: ")
        event("refused")
        return
    check(config)
    event("loaded")


@FAST
@given(st.one_of(mutated_bytes(TEXTS), st.binary(max_size=300)))
def test_any_bytes_in_the_file_are_a_config_or_one_config_error(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("cfg") / "perchd.toml"
    path.write_bytes(data)
    try:
        check(load_config(path))
        event("loaded")
    except ConfigError as err:
        assert str(err) and "\n" not in str(err)  # one line
        event("refused")


def test_deeply_nested_toml_is_one_config_error(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("version = 1\nx = " + "[" * 5000)
    try:
        load_config(path)
    except ConfigError as err:
        assert str(err) == "deep.toml: not valid TOML: nested too deeply"
    else:
        raise AssertionError("a deeply nested config loaded")


def test_a_flight_key_that_is_not_a_table_is_one_config_error():
    # found by the mutation test above: `flight = true` raised TypeError, `flight = [""]` ValueError
    for value in (True, [""], 3):
        try:
            config_from_dict({"version": 1, "flight": value})
        except ConfigError as err:
            assert str(err) == f"perchd.toml: [flight] must be a table, got {value!r}"
        else:
            raise AssertionError(f"flight = {value!r} loaded")
