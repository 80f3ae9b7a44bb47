"""`perchd plan`: figures out, and every bad input as one line with exit code 2."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

PLANS = Path(__file__).resolve().parents[2] / "plans"


def perchd(*args):
    return subprocess.run([sys.executable, "-m", "perchd", *args], capture_output=True, text=True)


def test_plan_check_json_holds_the_contract_fields():
    out = perchd("plan", "check", str(PLANS / "case1-ipts-n3.json"), "--json")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    for key in (
        "strategy",
        "duration",
        "t_switch",
        "v_contact",
        "v_peak",
        "a_peak",
        "bound",
        "ratio",
        "feasible",
    ):
        assert key in doc
    assert doc["ratio"] == pytest.approx(doc["duration"] / doc["bound"])
    assert doc["feasible"] is True


def test_plan_check_verifies_a_plan_library_node_by_node(tmp_path):
    lib = PLANS / "libraries" / "case1-ipts-n3.json"
    out = perchd("plan", "check", str(lib), "--json")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert doc["schema"] == "perchd.planlib/1" and doc["feasible"] is True
    assert doc["plans"] == doc["nodes"] == 63
    tight = json.loads(lib.read_text())
    tight["limits"]["a_max"] = 0.9  # the plans were made for 1.4 m/s^2
    (tmp_path / "tight.json").write_text(json.dumps(tight))
    out = perchd("plan", "check", str(tmp_path / "tight.json"))
    assert out.returncode == 1 and "NOT feasible: nodes[" in out.stdout and "a_max" in out.stdout
    out = perchd("plan", "check", str(lib), "--plot", str(tmp_path / "l.png"))
    assert out.returncode == 2 and "is a plan library" in out.stderr
    assert out.stderr.count("\n") == 1 and not (tmp_path / "l.png").exists()


def test_plan_ipts_writes_a_file_that_checks(tmp_path):
    out = perchd(
        "plan",
        "ipts",
        "--x0",
        "-3",
        "--v0",
        "1.5",
        "--tau-s",
        "-0.5",
        "--v-contact",
        "0.7",
        "1.0",
        "--v-max",
        "2.5",
        "--a-max",
        "1.4",
        "--order",
        "3",
        "--out",
        str(tmp_path / "p.json"),
    )
    assert out.returncode == 0, out.stderr
    assert "2.014" in out.stdout
    assert perchd("plan", "check", str(tmp_path / "p.json")).returncode == 0


def test_plan_check_draws_the_four_panels(tmp_path):
    out = perchd(
        "plan", "check", str(PLANS / "case1-ctdts.json"), "--plot", str(tmp_path / "f.png")
    )
    assert out.returncode == 0 and (tmp_path / "f.png").stat().st_size > 10_000


BAD = [
    (["ctds", "--x0", "-3", "--v0", "1.5", "--c", "0.7"], "infinite"),
    (["ctds", "--x0", "-3", "--v0", "1.5", "--c", "-0.1"], "never arrives"),
    (["ctds", "--x0", "3", "--v0", "1.5"], "x0 must be a negative"),
    (
        [
            "ctdts",
            "--x0",
            "-3",
            "--v0",
            "1.5",
            "--tau-s",
            "-0.5",
            "--v-contact",
            "1.0",
            "--a-max",
            "0.4",
        ],
        r"a_max = 0.4 m/s\^2 by 0.05",
    ),
    (
        ["ctdts", "--x0", "-3", "--v0", "1.5", "--tau-s", "-0.5", "--v-contact", "2.0"],
        "only decelerate",
    ),
    (["ctdts", "--x0", "-3", "--v0", "1.5", "--tau-s", "-3", "--v-contact", "1.0"], "tau_s"),
    (
        [
            "ipts",
            "--x0",
            "-3",
            "--v0",
            "1.5",
            "--tau-s",
            "-0.5",
            "--v-contact",
            "0.7",
            "1.0",
            "--v-max",
            "2.5",
            "--a-max",
            "0.2",
        ],
        "a_max = 0.2",
    ),
    (
        [
            "ipts",
            "--x0",
            "-3",
            "--v0",
            "1.5",
            "--tau-s",
            "-0.5",
            "--v-contact",
            "0.7",
            "1.0",
            "--order",
            "10",
        ],
        "order must be 1..9",
    ),
    (["check", "/nonexistent/plan.json"], "cannot read"),
    (["ipts", "--x0", "-3"], "required"),
]


@pytest.mark.parametrize("args, message", BAD, ids=[" ".join(a[:2]) + m for a, m in BAD])
def test_bad_input_is_one_line_and_exit_2(args, message):
    import re

    out = perchd("plan", *args)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    line = out.stderr.strip().splitlines()[-1]
    assert re.search(message, line), out.stderr
    assert len([ln for ln in out.stderr.strip().splitlines() if not ln.startswith("usage")]) == 1


def _edited(edit):
    doc = json.loads((PLANS / "case1-ipts-n3.json").read_text())
    edit(doc)
    return json.dumps(doc)


BAD_FILES = [
    ("{oops", "not JSON"),
    ("[1, 2]", "one JSON object"),
    (_edited(lambda d: d.update(schema="perchd.plan/2")), "schema"),
    (_edited(lambda d: d.update(duration=1.9)), "duration: file says 1.9"),
    (_edited(lambda d: d["stage1"]["k"].__setitem__(2, -0.3)), "t_switch"),
    (_edited(lambda d: d["peaks"].update(a=1.0)), "peaks.a"),
    (_edited(lambda d: d.pop("limits")), "limits"),
]


@pytest.mark.parametrize("text, message", BAD_FILES, ids=[m for _, m in BAD_FILES])
def test_a_bad_plan_file_is_one_line_naming_the_field_and_exit_2(tmp_path, text, message):
    path = tmp_path / "bad.json"
    path.write_text(text)
    out = perchd("plan", "check", str(path), "--json")
    assert (out.returncode, out.stdout) == (2, "")
    assert out.stderr.count("\n") == 1 and message in out.stderr, out.stderr
