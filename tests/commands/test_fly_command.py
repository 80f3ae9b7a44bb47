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
    code = main(["fly", str(plan_file(tmp_path)), "--driver", "sim://", "--mocap", "sim://",
                 "--log", str(log), "--json"])
    out, err = capsys.readouterr()
    res = json.loads(out)
    assert code == 0 and res["outcome"] == "CONTACT"
    for key in ("contact_speed", "perch_time", "plan_duration", "v_contact_plan", "log"):
        assert key in res
    assert res["contact_speed"] == pytest.approx(res["v_contact_plan"], abs=0.05)
    assert res["perch_time"] == pytest.approx(res["plan_duration"], rel=0.05)
    assert res["log"] == str(log) and read_log(log).complete
    assert "stage1" in err and "tau" in err  # the live status line


def test_perchd_fly_without_log_writes_into_flightlogs_and_prints_a_summary(tmp_path, capsys,
                                                                            monkeypatch):
    plan = plan_file(tmp_path).resolve()
    monkeypatch.chdir(tmp_path)
    assert main(["fly", str(plan), "--driver", "sim://", "--mocap", "sim://"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("outcome: CONTACT")
    assert "contact speed:" in out and "perch time:" in out
    assert len(list((tmp_path / "flightlogs").glob("*.jsonl"))) == 1


def test_a_surface_given_on_the_command_line_moves_the_simulated_wall_too():
    cfg = FlightConfig()
    cfg = dataclasses.replace(cfg, surface=dataclasses.replace(cfg.surface, point=(2.0, 1.0, 0.0),
                                                               normal=(0.0, 1.0, 0.0)))
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


def test_the_next_flight_of_a_vehicle_pools_stage_1s_push_with_the_last(tmp_path, capsys):
    """--state keeps per vehicle (--vehicle, else the driver URI) the mean of stage 1's push
    beyond the approach's bias; the next flight's stage 2 pools its own with it
    (docs/errata.md §10). The two flights' URIs differ (another seed), as a harness's
    ephemeral port does; the name is what keys the memory."""
    state, flown = tmp_path / "vehicles.json", []
    for seed in range(2):
        log = tmp_path / f"f{seed}.jsonl"
        driver, mocap = "sim://?draught=-2.9,0.2", f"sim://?noise=0.001&seed={seed}"
        assert main(["fly", str(plan_file(tmp_path)), "--driver", driver, "--mocap", mocap,
                     "--log", str(log), "--state", str(state), "--vehicle", "lab-1",
                     "--json"]) == 0
        res = json.loads(capsys.readouterr().out)
        refit = next(e for e in read_log(log).events if e.kind == "bias-refit").values
        assert refit["departure_mps2"] == res["stage2_departure_mps2"]
        flown.append((res["stage2_departure_mps2"], refit))
    (first, _), (second, refit) = flown
    assert refit["prior_flights"] == 1
    assert refit["pooled_mps2"] == pytest.approx((first + second) / 2, abs=1e-12)
    kept = json.loads(state.read_text())["vehicles"]
    assert list(kept) == ["lab-1"] and kept["lab-1"]["stage2_flights"] == 2
    assert kept["lab-1"]["stage2_departure_mps2"] == pytest.approx((first + second) / 2,
                                                                   abs=1e-12)
