"""Outputs never destroy data, and write errors are reported. An existing
file is overwritten only with --force; no directory is made but the default log directory."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PLAN = ROOT / "plans" / "case1-ipts-n3.json"
IPTS = ["plan", "ipts", "--x0", "-3", "--v0", "1.5", "--tau-s", "-0.5", "--v-contact", "0.7",
        "1.0", "--v-max", "2.5", "--a-max", "1.4"]
SIM = ["--driver", "sim://", "--mocap", "sim://"]


def perchd(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "perchd", *map(str, args)], capture_output=True,
                          text=True, timeout=120, cwd=cwd)


def one_line(out, code=2):
    assert out.returncode == code, out.stderr
    assert "Traceback" not in out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    return lines[0]


def test_fly_log_onto_the_plan_is_refused_even_with_force(tmp_path):
    plan = tmp_path / "P.json"
    shutil.copy(PLAN, plan)
    for force in ([], ["--force"]):
        line = one_line(perchd("fly", plan, *SIM, "--log", plan, *force))
        assert "--log" in line and str(plan) in line
    assert plan.read_bytes() == PLAN.read_bytes()


def test_fly_log_into_a_missing_directory_makes_none(tmp_path):
    line = one_line(perchd("fly", PLAN, *SIM, "--log", tmp_path / "no" / "x.jsonl"))
    assert "does not exist" in line and "--log" in line
    assert not (tmp_path / "no").exists()


def test_fly_log_onto_a_directory_is_one_line(tmp_path):
    assert "is a directory" in one_line(perchd("fly", PLAN, *SIM, "--log", tmp_path))


def test_fly_log_exists_needs_force(tmp_path):
    log = tmp_path / "f.jsonl"
    log.write_text("keep")
    assert "--force" in one_line(perchd("fly", PLAN, *SIM, "--log", log))
    assert log.read_text() == "keep"
    assert perchd("fly", PLAN, *SIM, "--log", log, "--force", "--json").returncode == 0


def test_plan_out_is_never_overwritten_without_force(tmp_path):
    out = tmp_path / "p.json"
    out.write_text("keep")
    assert "exists (pass --force" in one_line(perchd(*IPTS, "--out", out))
    assert out.read_text() == "keep"
    done = perchd(*IPTS, "--out", out, "--force")
    assert done.returncode == 0 and f"wrote {out}" in done.stderr
    assert perchd("plan", "check", out).returncode == 0


@pytest.mark.parametrize("where, says", [("missing/o.json", "does not exist"),
                                         (".", "is a directory")])
def test_plan_out_bad_places_are_one_line(tmp_path, where, says):
    assert says in one_line(perchd(*IPTS, "--out", tmp_path / where))
    assert not (tmp_path / "missing").exists()


def test_plan_check_plot_into_a_missing_directory_is_one_line(tmp_path):
    line = one_line(perchd("plan", "check", PLAN, "--plot", tmp_path / "m" / "p.png"))
    assert "--plot" in line and "does not exist" in line


def test_plan_check_plot_of_an_unknown_format_is_one_line(tmp_path):
    assert "--plot" in one_line(perchd("plan", "check", PLAN, "--plot", tmp_path / "p.xyz"))


def test_log_plot_out_is_checked(tmp_path):
    log = tmp_path / "f.jsonl"
    assert perchd("fly", PLAN, *SIM, "--log", log, "--json").returncode == 0
    assert "does not exist" in one_line(perchd("log", "plot", log, "--out", tmp_path / "m" / "x.png"))
    png = tmp_path / "f.png"
    png.write_text("keep")
    assert "--force" in one_line(perchd("log", "plot", log))
    assert png.read_text() == "keep"
    assert "is the input" in one_line(perchd("log", "plot", log, "--out", log, "--force"))


def test_campaign_table_is_checked(tmp_path):
    table = tmp_path / "t.csv"
    table.write_text("keep")
    line = one_line(perchd("sim", "--campaign", PLAN, "--flights", 1, "--table", table))
    assert "--table" in line and "--force" in line
    assert table.read_text() == "keep"
    assert "not an existing directory" in one_line(
        perchd("sim", "--campaign", PLAN, "--flights", 1, "--logs", tmp_path / "nope"))


def test_negative_exponent_values_parse(tmp_path):
    done = perchd("plan", "ipts", "--x0", "-3e0", "--v0", "1.5", "--tau-s", "-5e-1",
                  "--v-contact", "0.7", "1.0", "--v-max", "2.5", "--a-max", "1.4")
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("x0", ["-1e308", "-inf", "nan"])
def test_absurd_numbers_are_one_line_without_a_warning(x0):
    line = one_line(perchd(*IPTS[:2], f"--x0={x0}", *IPTS[4:]))
    assert line.startswith("perchd plan: --x0") and "finite number in -1000..1000 m" in line
