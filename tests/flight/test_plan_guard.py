"""A plan is verified before it flies (perchd.flight.planguard): its figures re-derived, its
limits met, and inside the vehicle's speed, tilt and geofence; refused in one line, exit 2,
before any link opens, by `perchd fly`, a campaign, the service and flight.run.fly."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import pytest
from simflight import PLANS

import perchd.commands.fly as fly_command
from perchd.cli import main
from perchd.core.errors import PlanError
from perchd.flight.config import FlightConfig, SafetyConfig
from perchd.flight.planguard import check_flight_plan
from perchd.session import open_session
from perchd.tau import load_plan

SHIPPED = PLANS / "case1-ipts-n3.json"
G = 9.81


def edited(tmp_path, edit) -> str:
    doc = json.loads(SHIPPED.read_text())
    edit(doc)
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(doc))
    return str(path)


def set_limit(key, value):
    return lambda doc: doc["limits"].__setitem__(key, value)


def set_peak_v(doc):
    doc["peaks"]["v"] *= 1.1


@pytest.fixture
def no_links(monkeypatch):
    """Fail the test if `perchd fly` gets as far as opening a link."""

    def refuse(*_a, **_k):
        raise AssertionError("a link was opened for a plan that should be refused")

    monkeypatch.setattr(fly_command, "open_links", refuse)


def fly_refusal(capsys, plan: str, *extra: str) -> str:
    code = main(["fly", plan, "--driver", "sim://", "--mocap", "sim://", *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    return err


@pytest.mark.parametrize(
    "edit, field",
    [
        (set_limit("v_contact", [3, 4]), "v_contact [3, 4]"),
        (set_limit("a_max", 0.1), "a_max = 0.1"),
        (set_peak_v, "peaks.v"),
    ],
)
def test_perchd_fly_refuses_an_edited_plan_before_any_link(tmp_path, capsys, no_links, edit, field):
    err = fly_refusal(capsys, edited(tmp_path, edit))
    assert field in err


def test_the_infeasible_plan_is_refused_by_how_much_plan_check_says(tmp_path, capsys, no_links):
    path = edited(tmp_path, set_limit("a_max", 0.1))
    peak = json.loads(SHIPPED.read_text())["peaks"]["a"]
    err = fly_refusal(capsys, path)
    assert f"by {peak - 0.1:.4f} m/s^2" in err
    assert main(["plan", "check", path]) == 1  # the same verdict from `perchd plan check`


def config_with(tmp_path, text: str) -> str:
    path = tmp_path / "flight.toml"
    path.write_text(f"version = 1\n{text}\n")
    return str(path)


def test_a_plan_faster_than_the_vehicles_speed_limit_is_refused(tmp_path, capsys, no_links):
    peak = json.loads(SHIPPED.read_text())["peaks"]["v"]
    cfg = config_with(tmp_path, "[safety]\nspeed_max_mps = 1.5")
    err = fly_refusal(capsys, str(SHIPPED), "--config", cfg)
    assert "speed_max_mps = 1.5" in err and f"by {peak - 1.5:.4g} m/s" in err


def test_a_plan_needing_more_tilt_than_the_setpoints_allow_is_refused():
    plan = load_plan(SHIPPED)
    need = math.degrees(math.atan(plan.peaks.a / G))
    cfg = FlightConfig(tilt_limit_rad=math.radians(need - 1.0))
    with pytest.raises(PlanError, match=r"tilt_limit_rad .* by 1\.0 deg"):
        check_flight_plan(plan, cfg)
    check_flight_plan(plan, FlightConfig(tilt_limit_rad=math.radians(need + 0.5)))


def test_a_trigger_point_outside_the_geofence_is_refused():
    plan = load_plan(SHIPPED)  # x0 = -3 m
    with pytest.raises(PlanError, match=r"x_min_m = -2.5 m by 0.5 m"):
        check_flight_plan(plan, FlightConfig(safety=SafetyConfig(x_min_m=-2.5)))


def test_fly_itself_refuses_an_edited_plan_before_it_engages(tmp_path):
    plan = load_plan(SHIPPED)
    bad = dataclasses.replace(plan, limits=dataclasses.replace(plan.limits, v_contact=(3.0, 4.0)))
    session = open_session()
    with pytest.raises(PlanError, match="v_contact"):
        session.fly(bad, tmp_path / "f.jsonl")
    assert all(sp.thrust == 0.0 for sp in session.world.sent)  # its close's motors-off only
    assert session.world.failsafes == [] and not (tmp_path / "f.jsonl").exists()


def test_a_campaign_refuses_an_edited_plan_before_its_table(tmp_path):
    path = edited(tmp_path, set_limit("v_contact", [3, 4]))
    table = tmp_path / "t.csv"
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "perchd",
            "sim",
            "--campaign",
            path,
            "--flights",
            "2",
            "--table",
            str(table),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert run.returncode == 2 and "v_contact [3, 4]" in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1 and not table.exists()


def test_the_service_refuses_an_edited_plan_and_ctl_exits_2(tmp_path):
    from served import Service

    svc = Service(tmp_path)
    try:
        plan = svc.plans / "edited.json"
        plan.write_text(open(edited(tmp_path, set_limit("a_max", 0.1))).read())
        reply = svc.talk(json.dumps({"cmd": "fly", "plan": str(plan)}).encode() + b"\n", 1)[0]
        assert reply["ok"] is False and reply["refused"] == "plan" and "a_max" in reply["error"]
        ctl = subprocess.run(
            [sys.executable, "-m", "perchd", "ctl", "fly", str(plan), "--socket", str(svc.sock)],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert ctl.returncode == 2 and "a_max" in ctl.stderr
        status = svc.talk(b'{"cmd": "status"}\n', 1)[0]
        assert status["state"] == "idle"
    finally:
        svc.stop()
