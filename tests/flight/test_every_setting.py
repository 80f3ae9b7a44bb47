"""Every setting has a unit and a range declared beside it (flight/bounds.py), and a value
outside it, of the wrong sign, NaN or infinite, stops `perchd fly --config` at exit 2 with
one line naming the key, before any link opens. Generated from the declarations: a numeric
setting added without a range fails here."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from simflight import PLANS

from perchd.cli import main
from perchd.flight.bounds import Leaf, leaves, table
from perchd.flight.config import FlightConfig

PLAN = PLANS / "case1-ipts-n3.json"
LEAVES = leaves(FlightConfig)
NUMERIC = [leaf for leaf in LEAVES if leaf.numeric]


def test_every_numeric_setting_declares_a_finite_range_holding_its_default():
    defaults = FlightConfig()
    assert 0 < len(NUMERIC) <= len(LEAVES) <= 50  # the settings are few by design
    for leaf in NUMERIC:
        b = leaf.bound
        assert b is not None, f"{leaf.key} has no declared range (bounds.setting)"
        assert math.isfinite(b.lo) and math.isfinite(b.hi) and b.lo < b.hi, leaf.key
        value = leaf.value(defaults)
        for x in value if isinstance(value, tuple) else (() if value is None else (value,)):
            assert b.lo <= x <= b.hi, leaf.key


def bad_values(leaf: Leaf) -> list[float]:
    """Above the range, below it, the wrong sign where the range has one; NaN and the
    infinities for a float."""
    b, integer = leaf.bound, leaf.tp is int
    out = [b.hi + max(1.0, abs(b.hi)), b.lo - max(1.0, abs(b.lo))]
    if b.lo >= 0:
        out.append(-max(1.0, b.hi / 2))
    elif b.hi <= 0:
        out.append(max(1.0, -b.lo / 2))
    if integer:
        return [int(x) for x in out]
    return out + [math.nan, math.inf, -math.inf]


def toml(leaf: Leaf, value: float) -> str:
    """A config file setting leaf (every number of a tuple) to value."""
    section, key = ".".join(leaf.path[:-1]) or "flight", leaf.path[-1]
    text = repr(value) if isinstance(value, int) else _toml_float(value)
    if "tuple" in str(leaf.tp):
        text = f"[{text}, {text}, {text}]"
    return f"version = 1\n[{section}]\n{key} = {text}\n"


def _toml_float(x: float) -> str:
    return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf") if math.isinf(x) else repr(x)


CASES = [(leaf, v) for leaf in NUMERIC for v in bad_values(leaf)]


@pytest.mark.parametrize("leaf,value", CASES, ids=[f"{leaf.key}={v}" for leaf, v in CASES])
def test_a_setting_outside_its_range_stops_perchd_fly_naming_it(tmp_path, capsys, leaf, value):
    config = tmp_path / "bad.toml"
    config.write_text(toml(leaf, value))
    log = tmp_path / "f.jsonl"
    code = main(
        [
            "fly",
            str(PLAN),
            "--driver",
            "sim://",
            "--mocap",
            "sim://",
            "--config",
            str(config),
            "--log",
            str(log),
            "--state",
            str(tmp_path / "v.json"),
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert leaf.key in err, err
    assert not log.exists()


@pytest.mark.parametrize(
    "command",
    [
        ["serve", "--socket", "{tmp}/control.sock"],
        ["sim", "--campaign", str(PLANS / "robust-n3-table2-box.json"), "--flights", "1"],
    ],
)
def test_serve_and_a_campaign_refuse_a_wrong_sign_gain_before_anything_opens(
    tmp_path, capsys, command
):
    config = tmp_path / "bad.toml"
    config.write_text("version = 1\n[tau_gains]\nkp_fast = -50\n")
    args = [a.replace("{tmp}", str(tmp_path)) for a in command]
    code = main([*args, "--config", str(config)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.endswith(
        "bad.toml: [tau_gains] kp_fast = -50 m/s^2: outside its range 0..200 m/s^2"
    ), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_the_settings_table_in_the_contracts_is_the_declarations():
    """docs/contracts.md §8: regenerate it with perchd.flight.bounds.table when a setting
    changes."""
    text = (Path(__file__).parents[2] / "docs" / "contracts.md").read_text()
    documented = text.split("<!-- settings: generated -->\n")[1].split("\n<!-- settings: end")[0]
    assert documented.splitlines() == table(FlightConfig)
    assert len(documented.splitlines()) == len(LEAVES) + 2
