"""Plan libraries: a warm replan from the grid is the cold global optimum, fast enough for
the trigger tick; files are checked node by node; the supervisor replans from one."""

from __future__ import annotations

import json
import random
import subprocess
import sys
from pathlib import Path

import pytest

from perchd.core.errors import ConfigError, PlanError
from perchd.tau import load_plan, plan_ipts
from perchd.tau.library import library_from_json, library_to_json, load_library

ROOT = Path(__file__).resolve().parents[2]
LIBRARY = ROOT / "plans" / "libraries" / "case1-ipts-n3.json"
CASE1 = dict(tau_s=-0.5, v_contact=(0.7, 1.0), v_max=2.5, a_max=1.4)


@pytest.fixture(scope="module")
def lib():
    return load_library(LIBRARY)


def test_the_committed_library_covers_the_case1_trigger_with_a_plan_at_every_node(lib):
    assert lib.x0s[0] < -3.0 < lib.x0s[-1] and lib.v0s[0] < 1.5 < lib.v0s[-1]
    assert all(node is not None for row in lib.nodes for node in row)


def test_a_warm_replan_matches_a_cold_global_solve_to_1e_4_s(lib):
    rng = random.Random(7)
    for _ in range(6):
        x0 = rng.uniform(lib.x0s[0], lib.x0s[-1])
        v0 = rng.uniform(lib.v0s[0], lib.v0s[-1])
        warm = lib.replan(x0, v0)
        cold = plan_ipts(
            x0, v0, CASE1["tau_s"], CASE1["v_contact"], CASE1["v_max"], CASE1["a_max"], 3
        )
        assert warm.duration == pytest.approx(cold.duration, abs=1e-4)
        assert (warm.x0, warm.v0, warm.k[0]) == (x0, v0, v0 / x0)
        assert warm.peaks.a <= 1.4 * (1 + 1e-9) and warm.peaks.v <= 2.5


def test_at_a_grid_node_the_replan_is_the_stored_plan(lib):
    node = lib.nodes[2][3]
    plan = lib.replan(lib.x0s[2], lib.v0s[3])
    assert plan.t_switch == pytest.approx(node.t_switch, abs=1e-9)


@pytest.mark.parametrize(
    "x0, v0, message",
    [
        (-3.5, 1.5, "x0 = -3.5 m is outside the library's grid -3.3..-2.7 m by 0.2 m"),
        (-3.0, 1.75, "v0 = 1.75 m/s is outside the library's grid 1.3..1.7 m/s by 0.05 m/s"),
    ],
)
def test_a_state_outside_the_grid_is_refused_naming_the_axis_and_by_how_much(lib, x0, v0, message):
    with pytest.raises(PlanError, match=message.replace(".", r"\.")):
        lib.replan(x0, v0)


def test_a_saved_library_loads_back_equal(lib):
    assert library_from_json(json.loads(json.dumps(library_to_json(lib)))) == lib


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d.update(schema="perchd.plan/1"), "schema must be 'perchd.planlib/1'"),
        (
            lambda d: d["nodes"][1][2]["k"].__setitem__(0, -0.4),
            r"nodes\[1\]\[2\]: k_0 must be v0/x0",
        ),
        (lambda d: d["nodes"][0][0]["k"].__setitem__(2, 0.5), r"nodes\[0\]\[0\]: tau\(t_switch\)"),
        (lambda d: d["nodes"][3].pop(), r"nodes\[3\] must be a list of 9"),
        (lambda d: d.update(x0=[-3.0, -3.1] + d["x0"][2:]), "x0 must list at least 2 increasing"),
        (lambda d: d["limits"].update(a_max="fast"), "limits.a_max must be a finite number"),
    ],
)
def test_a_tampered_library_is_refused_naming_the_field(edit, message):
    doc = json.loads(LIBRARY.read_text())
    edit(doc)
    with pytest.raises(PlanError, match=message):
        library_from_json(doc)


def test_perchd_plan_library_builds_a_file_the_replan_reads(tmp_path):
    out = tmp_path / "lib.json"
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "perchd",
            "plan",
            "library",
            "--x0",
            "-3.1",
            "-2.9",
            "--v0",
            "1.45",
            "1.55",
            "--nodes",
            "2",
            "2",
            "--tau-s",
            "-0.5",
            "--v-contact",
            "0.7",
            "1.0",
            "--v-max",
            "2.5",
            "--a-max",
            "1.4",
            "--out",
            str(out),
            "--json",
        ],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["plans"] == 4
    plan = load_library(out).replan(-3.0, 1.5)
    assert plan.duration == pytest.approx(
        load_plan(ROOT / "plans" / "case1-ipts-n3.json").duration, abs=1e-4
    )


def test_perchd_plan_library_with_an_empty_range_is_one_line_and_exit_2(tmp_path):
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "perchd",
            "plan",
            "library",
            "--x0",
            "-2",
            "-3",
            "--v0",
            "1",
            "2",
            "--tau-s",
            "-0.5",
            "--v-contact",
            "0.7",
            "1.0",
            "--out",
            str(tmp_path / "l.json"),
        ],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 2
    assert run.stderr.strip().splitlines() == [
        "perchd plan: library x0 grid needs LO < HI and at least 2 nodes, got -2..-3 with 11"
    ]


def test_the_supervisor_replans_from_the_library_at_the_measured_trigger(tmp_path):
    from simflight import NOISY, Sim

    from perchd.core.types import EndReason
    from perchd.flight.config import FlightConfig, TriggerConfig, TriggerPolicy

    plan = load_plan(ROOT / "plans" / "case1-ipts-n3.json")
    cfg = FlightConfig(trigger=TriggerConfig(TriggerPolicy.REPLAN, library=str(LIBRARY)))
    res = Sim(NOISY).fly(plan, tmp_path / "f.jsonl", cfg)
    assert res.outcome is EndReason.CONTACT
    assert res.trigger.action.startswith("replan (library): retargeted")
    assert (res.trigger.plan_x0, res.trigger.plan_v0) == (res.trigger.x, res.trigger.v)
    cold = plan_ipts(res.trigger.x, res.trigger.v, -0.5, (0.7, 1.0), 2.5, 1.4, 3)
    assert res.plan_duration == pytest.approx(cold.duration, abs=1e-4)


def test_a_library_for_another_plan_or_policy_is_refused_before_flying():
    from perchd.flight.config import FlightConfig, TriggerConfig, TriggerPolicy
    from perchd.flight.frame import PerchFrame
    from perchd.flight.supervisor import Supervisor

    frame = PerchFrame.from_surface((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    cfg = FlightConfig(trigger=TriggerConfig(TriggerPolicy.REPLAN, library=str(LIBRARY)))
    with pytest.raises(ConfigError, match="holds IPTS order 3 plans, the plan is ctdts"):
        Supervisor(load_plan(ROOT / "plans" / "case1-ctdts.json"), cfg, frame)
    with pytest.raises(ConfigError, match="used by policy 'replan' only, not 'refuse'"):
        FlightConfig(trigger=TriggerConfig(library=str(LIBRARY)))


@pytest.mark.parametrize(
    "order, a_max, message",
    [
        (12, 1.4, "order must be 1..9, got 12"),
        (3, 0.2, "no node of the grid has a plan; at x0 = -3.3 m, v0 = 1.3 m/s: no order-3 IPTS"),
    ],
)
def test_a_library_with_no_plan_to_hold_is_refused_not_written_empty(order, a_max, message):
    from perchd.tau.library import build_library

    with pytest.raises(PlanError, match=message):
        build_library((-3.3, -2.7), (1.3, 1.7), (2, 2), -0.5, (0.7, 1.0), 2.5, a_max, order)


def test_retarget_with_a_library_is_the_warm_replan_and_equals_the_cold_one(lib):
    from perchd.tau import retarget

    base = load_plan(ROOT / "plans" / "case1-ipts-n3.json")
    warm = retarget(base, -3.1, 1.55, library=lib)
    cold = retarget(base, -3.1, 1.55)
    assert (warm.x0, warm.v0) == (-3.1, 1.55)
    assert warm.duration == pytest.approx(cold.duration, abs=1e-4)


def test_retarget_refuses_a_library_made_for_another_plan(lib):
    from perchd.tau import retarget

    with pytest.raises(PlanError, match="library cannot retarget.*order 3.*order 5"):
        retarget(load_plan(ROOT / "plans" / "case1-ipts-n5.json"), -3.0, 1.5, library=lib)
