"""`perchd fly` (docs/contracts.md §2): a whole simulated perch from the command line."""

from __future__ import annotations

import dataclasses
import io
import json

import pytest
from simflight import PLANS, Sim, case1

from perchd.cli import main
from perchd.commands.fly import StatusLine, summary_text
from perchd.core.errors import UriError
from perchd.core.types import Phase
from perchd.flight.config import FlightConfig
from perchd.flight.run import TickStatus
from perchd.logs.flightlog import read_log
from perchd.session import open_links


def plan_file(tmp_path, strategy="ipts"):
    import perchd.tau as tau

    if not hasattr(tau, "load_plan"):
        pytest.skip("perchd.tau has no load_plan yet")
    shipped = PLANS / ("case1-ipts-n3.json" if strategy == "ipts" else "case1-ctdts.json")
    if shipped.exists():
        return shipped
    path = tmp_path / "plan.json"
    tau.save_plan(case1(strategy), path)
    return path


def test_perchd_fly_sim_performs_a_whole_perch_and_prints_the_contract_json(tmp_path, capsys):
    log = tmp_path / "f.jsonl"
    code = main(
        [
            "fly",
            str(plan_file(tmp_path)),
            "--driver",
            "sim://",
            "--mocap",
            "sim://",
            "--log",
            str(log),
            "--json",
        ]
    )
    out, err = capsys.readouterr()
    res = json.loads(out)
    assert code == 0 and res["outcome"] == "CONTACT"
    for key in ("contact_speed", "perch_time", "plan_duration", "v_contact_plan", "log"):
        assert key in res
    assert res["contact_speed"] == pytest.approx(res["v_hold_mps"], abs=0.05)
    assert res["perch_time"] == pytest.approx(res["plan_duration"], rel=0.05)
    assert res["log"] == str(log) and read_log(log).complete
    assert "stage1" in err and "tau" in err  # the live status line


def test_perchd_fly_without_log_writes_into_flightlogs_and_prints_a_summary(
    tmp_path, capsys, monkeypatch
):
    plan = plan_file(tmp_path).resolve()
    monkeypatch.chdir(tmp_path)
    assert main(["fly", str(plan), "--driver", "sim://", "--mocap", "sim://"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("outcome: CONTACT")
    assert "contact speed:" in out and "perch time:" in out
    assert len(list((tmp_path / "flightlogs").glob("*.jsonl"))) == 1


def test_a_surface_given_on_the_command_line_moves_the_simulated_wall_too():
    cfg = FlightConfig()
    cfg = dataclasses.replace(
        cfg, surface=dataclasses.replace(cfg.surface, point=(2.0, 1.0, 0.0), normal=(0.0, 1.0, 0.0))
    )
    links = open_links("sim://", "sim://", cfg.surface)
    links.close()
    assert links.world.params.surface_point == (2.0, 1.0, 0.0)
    assert links.world.start == pytest.approx((2.0, -3.5, 1.0))


def test_sim_on_one_side_only_is_refused_with_one_line():
    with pytest.raises(UriError, match="sim:// flies only with sim:// on both"):
        open_links("sim://", "natnet://10.0.0.5")


def test_the_status_line_shows_phase_x_xdot_and_tau_against_its_reference():
    stream = io.StringIO()
    line = StatusLine(stream)
    line(TickStatus(0.0, Phase.STAGE1, -2.5, 1.4, -1.786, -1.75))
    line(TickStatus(0.1, Phase.STAGE1, -2.4, 1.4, -1.7, -1.7))  # within 0.5 s: not repeated
    text = stream.getvalue()
    assert text.count("\n") == 1
    assert "stage1" in text and "-2.500" in text and "+1.400" in text
    assert "tau  -1.786 / ref  -1.750" in text


def test_the_summary_reports_errors_against_the_plan(tmp_path):
    res = Sim().fly(case1("ipts"), tmp_path / "f.jsonl")
    text = summary_text(res)
    assert text.splitlines()[0] == "outcome: CONTACT (contact with the surface): " + res.detail
    assert f"{res.contact_speed - res.v_contact_plan:+.3f} m/s" in text


def test_a_push_met_in_earlier_flights_never_reaches_the_next(tmp_path, capsys):
    """Two flights of one vehicle through a draught, then a clean one, touch as a fresh
    vehicle's clean flight does: only the vehicle's own properties are kept (its hover), not
    the air a flight met (a draught)."""
    plan, state = plan_file(tmp_path), tmp_path / "lab-1.json"

    def fly(driver: str, state_file, name: str, i: int) -> dict:
        assert (
            main(
                [
                    "fly",
                    str(plan),
                    "--driver",
                    driver,
                    "--mocap",
                    "sim://?noise=0.001",
                    "--log",
                    str(tmp_path / f"f{i}.jsonl"),
                    "--state",
                    str(state_file),
                    "--vehicle",
                    name,
                    "--json",
                ]
            )
            == 0
        )
        return json.loads(capsys.readouterr().out)

    for i in range(2):
        fly("sim://?draught=-2.9,0.3", state, "lab-1", i)
    clean = fly("sim://", state, "lab-1", 2)
    fresh = fly("sim://", tmp_path / "fresh.json", "fresh", 3)
    assert clean["vehicle_profile"]["read"]["hover"]["flights"] == 2
    assert fresh["vehicle_profile"]["read"] is None
    assert clean["true_contact_speed"] == pytest.approx(fresh["true_contact_speed"], abs=0.005)
    kept = json.loads(state.read_text())
    assert set(kept) == {"schema", "vehicle", "hover", "response"}
    assert kept["hover"]["flights"] == kept["response"]["flights"] == 3


def test_the_summary_names_the_vehicle_profile_each_time(tmp_path, capsys):
    plan, state = plan_file(tmp_path), tmp_path / "v.json"
    for i, read in enumerate(("none yet", "read: hover ")):
        assert (
            main(
                [
                    "fly",
                    str(plan),
                    "--driver",
                    "sim://",
                    "--mocap",
                    "sim://",
                    "--log",
                    str(tmp_path / f"f{i}.jsonl"),
                    "--state",
                    str(state),
                ]
            )
            == 0
        )
        line = capsys.readouterr().out.splitlines()[-1]
        assert line.startswith(f"vehicle profile: {state} ({read}") and line.endswith("; written)")
