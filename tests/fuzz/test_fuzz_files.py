"""The three file readers under fuzzing, from the file on disk: the plan reader (load_plan),
the config reader (load_flight_config) and the flight log reader (read_log). Whatever the
bytes (real files mutated, numbers replaced by 1e999, 400 or 5000 digits, NaN, booleans,
garbage), each returns or raises one PerchdError; nothing else escapes, and nothing hangs
(each read is bounded and non-blocking)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from logseed import log_seed
from mutate import mutated_bytes, spliced_numbers

from perchd.core.errors import PerchdError
from perchd.logs.flightlog import read_log
from perchd.service.config import load_flight_config
from perchd.tau.planfile import load_plan

ROOT = Path(__file__).resolve().parents[2]
PLANS = [p.read_bytes() for p in sorted((ROOT / "plans").glob("*.json"))]
CONFIGS = [
    (ROOT / "systemd" / "perchd.toml").read_bytes(),
    b"version = 1\n[vehicle]\nmass_kg = 0.034\n[surface]\npoint = [0.0, 0.0, 1.5]\n",
]
EXAMPLES = settings(
    max_examples=300,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> list[bytes]:
    return [log_seed(tmp_path_factory.mktemp("seed") / "f.jsonl")]


def verdict(reader, path: Path, data: bytes) -> str:
    path.write_bytes(data)
    try:
        reader(path)
    except PerchdError as err:
        assert str(err) and "\n" not in str(err)
        return "refused"
    return "read"


def anything(seeds: list[bytes]):
    return st.one_of(mutated_bytes(seeds), spliced_numbers(seeds), st.binary(max_size=300))


@EXAMPLES
@given(data=anything(PLANS))
def test_the_plan_reader_reads_or_refuses_in_one_line(tmp_path, data):
    event(verdict(load_plan, tmp_path / "p.json", data))


@EXAMPLES
@given(data=anything(CONFIGS))
def test_the_config_reader_reads_or_refuses_in_one_line(tmp_path, data):
    event(verdict(load_flight_config, tmp_path / "perchd.toml", data))


@EXAMPLES
@given(pick=st.data())
def test_the_log_reader_reads_or_refuses_in_one_line(tmp_path, logs, pick):
    event(verdict(read_log, tmp_path / "f.jsonl", pick.draw(anything(logs))))
