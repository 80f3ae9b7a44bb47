"""Outputs never destroy data, and write errors are reported. An existing
file is overwritten only with --force; no directory is made but the default log directory."""

import json
import os
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PLAN = ROOT / "plans" / "case1-ipts-n3.json"
IPTS = [
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
]
SIM = ["--driver", "sim://", "--mocap", "sim://"]


def perchd(*args, cwd=ROOT):
    return subprocess.run(
        [sys.executable, "-m", "perchd", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
    )


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


@pytest.mark.parametrize(
    "where, says", [("missing/o.json", "does not exist"), (".", "is a directory")]
)
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
    assert "does not exist" in one_line(
        perchd("log", "plot", log, "--out", tmp_path / "m" / "x.png")
    )
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
        perchd("sim", "--campaign", PLAN, "--flights", 1, "--logs", tmp_path / "nope")
    )


def test_negative_exponent_values_parse(tmp_path):
    done = perchd(
        "plan",
        "ipts",
        "--x0",
        "-3e0",
        "--v0",
        "1.5",
        "--tau-s",
        "-5e-1",
        "--v-contact",
        "0.7",
        "1.0",
        "--v-max",
        "2.5",
        "--a-max",
        "1.4",
    )
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("x0", ["-1e308", "-inf", "nan"])
def test_absurd_numbers_are_one_line_without_a_warning(x0):
    line = one_line(perchd(*IPTS[:2], f"--x0={x0}", *IPTS[4:]))
    assert line.startswith("perchd plan: --x0") and "finite number in -1000..1000 m" in line


# --- the one rule for every file (core/safefile.py): nothing destroyed, one line --------------

ROOT_USER = os.geteuid() == 0
LONG = "n" * 300  # over NAME_MAX (255): ENAMETOOLONG


def limited(fsize_bytes):
    """A subprocess preexec: files this process writes stop at fsize_bytes (EFBIG, as a full
    disk's ENOSPC; Python ignores SIGXFSZ, so the write fails rather than the process)."""
    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (fsize_bytes, fsize_bytes))


def perchd_limited(fsize_bytes, *args, cwd=ROOT):
    return subprocess.run(
        [sys.executable, "-m", "perchd", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
        preexec_fn=limited(fsize_bytes),
    )


def read_only(tmp_path):
    """A directory nobody may write, root included (perchd run without CAP_DAC_OVERRIDE)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    if not ROOT_USER:
        return ro, []
    if shutil.which("setpriv") is None:
        pytest.skip("needs util-linux setpriv to drop root's CAP_DAC_OVERRIDE")
    caps = "-dac_override,-dac_read_search"
    return ro, ["setpriv", f"--inh-caps={caps}", f"--bounding-set={caps}"]


def test_state_onto_the_plan_is_refused_and_the_plan_kept(tmp_path):
    plan = tmp_path / "P.json"
    shutil.copy(PLAN, plan)
    line = one_line(perchd("fly", plan, *SIM, "--log", tmp_path / "f.jsonl", "--state", plan))
    assert "--state" in line and "not a perchd vehicle profile" in line
    assert plan.read_bytes() == PLAN.read_bytes() and not (tmp_path / "f.jsonl").exists()


def test_state_of_another_program_is_never_replaced(tmp_path):
    state = tmp_path / "vehicles.json"
    state.write_text('{"schema": "someone.else/1", "vehicles": {}}')
    one_line(perchd("fly", PLAN, *SIM, "--log", tmp_path / "f.jsonl", "--state", state))
    assert state.read_text() == '{"schema": "someone.else/1", "vehicles": {}}'


@pytest.mark.parametrize("kind", ["fifo", "/dev/zero", "dir"])
def test_state_that_is_not_a_regular_file_is_one_line_at_once(tmp_path, kind):
    state = {"fifo": tmp_path / "s", "/dev/zero": Path("/dev/zero"), "dir": tmp_path}[kind]
    if kind == "fifo":
        os.mkfifo(state)
    line = one_line(perchd("fly", PLAN, *SIM, "--log", tmp_path / "f.jsonl", "--state", state))
    assert "--state" in line and not (tmp_path / "f.jsonl").exists()


def test_log_onto_a_fifo_or_a_device_is_one_line_even_with_force(tmp_path):
    fifo = tmp_path / "f.jsonl"
    os.mkfifo(fifo)
    for log in (fifo, "/dev/null"):
        line = one_line(perchd("fly", PLAN, *SIM, "--log", log, "--force"))
        assert "not a regular file" in line and "--log" in line


def test_log_onto_the_config_or_the_state_is_refused(tmp_path):
    state = tmp_path / "s.json"
    assert (
        perchd(
            "fly", PLAN, *SIM, "--log", tmp_path / "a.jsonl", "--state", state, "--json"
        ).returncode
        == 0
    )
    before = state.read_bytes()
    assert "is the input" in one_line(
        perchd("fly", PLAN, *SIM, "--log", state, "--state", state, "--force")
    )
    assert state.read_bytes() == before


def test_log_force_keeps_the_old_log_until_the_new_one_is_whole(tmp_path):
    log = tmp_path / "f.jsonl"
    log.write_text("old")
    out = perchd_limited(
        100_000,
        "fly",
        PLAN,
        *SIM,
        "--log",
        log,
        "--force",
        "--json",
        "--state",
        tmp_path / "s.json",
    )
    assert out.returncode == 1 and json.loads(out.stdout)["log_lost"]
    assert log.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".part")] == []


def test_a_full_disk_mid_flight_ends_in_the_failsafe_with_its_summary_and_json(tmp_path):
    log = tmp_path / "f.jsonl"
    out = perchd_limited(
        100_000, "fly", PLAN, *SIM, "--log", log, "--json", "--state", tmp_path / "s.json"
    )
    assert out.returncode == 1, out.stderr
    assert "Traceback" not in out.stderr
    res = json.loads(out.stdout)
    assert res["outcome"] == "SOFTWARE_ERROR" and res["failsafe_sent"] is True
    assert "File too large" in res["log_lost"] and "log was lost" in res["detail"]
    summary = perchd("log", "summary", log)  # what was written before the loss still reads
    assert summary.returncode == 0 and "INCOMPLETE" in summary.stdout
    text = perchd_limited(
        100_000, "fly", PLAN, *SIM, "--log", tmp_path / "g.jsonl", "--state", tmp_path / "s.json"
    )
    assert "outcome: SOFTWARE_ERROR" in text.stdout and "LOST" in text.stdout


def test_a_full_disk_for_a_plan_leaves_no_file_and_the_old_one_whole(tmp_path):
    out = tmp_path / "p.json"
    assert "cannot write (File too large)" in one_line(perchd_limited(100, *IPTS, "--out", out))
    assert list(tmp_path.iterdir()) == []
    out.write_text("keep")
    one_line(perchd_limited(100, *IPTS, "--out", out, "--force"))
    assert out.read_text() == "keep" and list(tmp_path.iterdir()) == [out]


def test_dev_full_as_an_output_is_one_line():
    assert "not a regular file (a character device)" in one_line(
        perchd(*IPTS, "--out", "/dev/full", "--force")
    )


def test_a_read_only_directory_is_one_line(tmp_path):
    ro, drop = read_only(tmp_path)
    out = subprocess.run(
        [*drop, sys.executable, "-m", "perchd", *IPTS, "--out", str(ro / "p.json")],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )
    assert "Permission denied" in one_line(out) and list(ro.iterdir()) == []
    fly = subprocess.run(
        [
            *drop,
            sys.executable,
            "-m",
            "perchd",
            "fly",
            str(PLAN),
            *SIM,
            "--log",
            str(ro / "f.jsonl"),
            "--state",
            str(tmp_path / "s.json"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )
    assert "--log" in one_line(fly) and list(ro.iterdir()) == []


@pytest.mark.parametrize(
    "argv",
    [
        ["plan", "check", f"/tmp/{LONG}.json"],
        [*IPTS, "--out", f"/tmp/{LONG}.json"],
        ["fly", str(PLAN), *SIM, "--log", f"/tmp/{LONG}.jsonl"],
        ["fly", str(PLAN), *SIM, "--log", "/tmp/nope.jsonl", "--state", f"/tmp/{LONG}"],
        ["log", "summary", f"/tmp/{LONG}.jsonl"],
    ],
)
def test_a_path_too_long_is_one_line(argv):
    assert "File name too long" in one_line(perchd(*argv))
