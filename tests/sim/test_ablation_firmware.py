"""benchmarks/ablation_firmware.py: a variant's TOML, appended to a firmware's flight config,
loads as the variant's own config; the figures count what they say. No firmware is flown
here (the benchmark measures; docs/controller.md has its table)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from perchd.flight.config import FlightConfig, TriggerPolicy
from perchd.service.config import load_flight_config

ROOT = Path(__file__).resolve().parents[2]


sys.path.insert(0, str(ROOT / "benchmarks"))
import ablation_firmware as fwablation  # noqa: E402

_load = fwablation.bench_module
ablation, firmware = _load("ablation"), _load("firmware")
CONFIG_ONLY = [v for v in ablation.VARIANTS if v.changes and not v.patches]


@pytest.mark.parametrize("variant", CONFIG_ONLY, ids=lambda v: v.name)
@pytest.mark.parametrize("fw", firmware.FIRMWARES, ids=lambda f: f.name)
def test_a_variants_toml_on_a_firmwares_config_is_the_variant(variant, fw, tmp_path):
    path = tmp_path / "flight.toml"
    base_text = fw.config or "version = 1\n"
    path.write_text(base_text)
    base = load_flight_config(path)
    path.write_text(base_text + variant.config_toml())
    assert load_flight_config(path) == variant.apply(base)


def test_the_figures_count_the_window_the_time_and_the_endings():
    plan = {"duration": 2.1, "limits": {"v_contact": [0.7, 1.0]}}
    flights = [
        {"outcome": "CONTACT", "contact_speed": 0.95, "perch_time": 2.02, "plan_duration": 2.0},
        {"outcome": "CONTACT", "contact_speed": 1.01, "perch_time": 1.94, "plan_duration": 2.0},
        {"outcome": "SPEED_LIMIT", "contact_speed": None, "perch_time": None},
    ]
    s = fwablation.figures(flights, plan)
    assert s["in_window"] == 1 and s["unstable"] == 1 and s["within_2pct"] == 1
    assert s["contact"] == [pytest.approx(0.98), 0.95, 1.01]
    assert s["perch_pct"] == pytest.approx(-1.0) and s["perch_pct_maxabs"] == pytest.approx(3.0)
    line = fwablation.row("hover", "cf2", s, s)
    assert line.startswith("| hover | cf2 | 1/3 | 0.980 [0.950..1.010] | -1.00 (3.00) | 1/3 | 1 |")


def test_a_variant_with_a_module_constant_is_not_flown(capsys, monkeypatch):
    monkeypatch.delenv("PERCHD_CF2", raising=False)
    assert fwablation.main(["--only", "cf2", "--layers", "qdrag", "--flights", "1"]) == 0
    err = capsys.readouterr().err
    assert "qdrag: not flown (it sets a module constant" in err
    assert "cf2: skipped (PERCHD_CF2 is not set)" in err


@pytest.mark.parametrize("fw", firmware.FIRMWARES, ids=lambda f: f.name)
def test_every_firmware_flight_replans_at_the_trigger_as_a_campaign_does(fw, tmp_path):
    """benchmarks/firmware.py gives each firmware's config the family's trigger
    (benchmarks/family.py base_config), whatever [trigger] table the config has."""
    path = tmp_path / "flight.toml"
    path.write_text(firmware.with_trigger(fw.config or "version = 1\n"))
    trigger = load_flight_config(path).trigger
    campaign = _load("family").base_config(firmware.PLAN, ablation.load_plan(firmware.PLAN))
    assert (trigger.policy, trigger.library) == (
        campaign.trigger.policy,
        str(firmware.LIBRARY),
    )
    assert Path(trigger.library).exists()
    assert campaign.trigger.library == str(firmware.LIBRARY)


@pytest.mark.parametrize("fw", firmware.FIRMWARES, ids=lambda f: f.name)
def test_as_made_a_firmware_flight_keeps_the_triggers_default(fw, tmp_path):
    """--as-made: the firmware's own config, its trigger the default (refuse past v_tol)."""
    policies = {}
    for replan in (True, False):
        firmware.fly_argv(fw, tmp_path, "zmq://x", "udp://x", ["0", "0", "0"], replan=replan)
        policies[replan] = load_flight_config(tmp_path / "flight.toml").trigger.policy
    assert policies == {True: TriggerPolicy.REPLAN, False: FlightConfig().trigger.policy}
    assert FlightConfig().trigger.policy is TriggerPolicy.REFUSE


def test_a_flights_perch_time_is_measured_against_the_plan_it_flew():
    flight = {"perch_time": 2.04, "plan_duration": 2.0}
    assert firmware.perch_error_pct(flight) == pytest.approx(2.0)
