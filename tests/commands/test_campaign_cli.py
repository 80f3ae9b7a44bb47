"""`perchd sim --campaign`: the command a user runs, its progress, table, summary and errors."""

from __future__ import annotations

import csv
import io
import json
import statistics
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
from terminal import run_on_terminal

from perchd.console.progress import Progress

PLANS = Path(__file__).parents[2] / "plans"
BOX = str(PLANS / "robust-n3-table2-box.json")


def perchd(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "perchd", "sim", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=cwd,
    )


def read_table(path: Path) -> list[dict]:
    """The rows: of the default .parquet (with pyarrow), else of a CSV table."""
    if path.suffix == ".parquet":
        return pytest.importorskip("pyarrow.parquet").read_table(path).to_pylist()
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_a_grid_campaign_writes_its_table_and_prints_one_json_summary(tmp_path):
    table = tmp_path / "out.csv"
    done = perchd(
        "--campaign",
        BOX,
        "--grid",
        "2",
        "2",
        "--latency",
        "0.02",
        "--noise",
        "0.001",
        "--gust",
        "0.2",
        "--seed",
        "1",
        "--table",
        str(table),
        "--json",
    )
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    rows = read_table(table)
    assert len(rows) == out["flights"] == 4 and out["table"] == str(table)
    assert out["outcomes"] == {"CONTACT": 4} and out["in_window"] == 4
    assert {r["latency_s"] for r in rows} == {"0.02"} and {r["noise_m"] for r in rows} == {"0.001"}
    assert sorted({float(r["x0_aim"]) for r in rows}) == pytest.approx([-3.84, -3.77])  # box - 4 cm
    speeds = [float(r["contact_speed"]) for r in rows]
    assert out["contact_speed"]["median"] == pytest.approx(statistics.median(speeds), abs=1e-6)
    assert out["contact_speed"]["min"] == pytest.approx(min(speeds), abs=1e-6)
    errors = [float(r["perch_error_s"]) for r in rows]
    assert out["perch_error_s"]["max"] == pytest.approx(max(errors), abs=1e-6)
    assert out["policy"] == "robust" and out["spread"]["gust_mps"] == 0.2
    assert "perchd sim: 4/4 flights (CONTACT 4)" in done.stderr  # progress lines: not a tty


def test_the_text_summary_counts_outcomes_and_gives_speed_and_perch_time_figures(tmp_path):
    (tmp_path / "campaigns").mkdir()
    done = perchd(
        "--campaign", BOX, "--flights", "3", "--x0", "-3.95", "-3.8", "--seed", "2", cwd=tmp_path
    )
    made = (tmp_path / "campaigns").glob("*-robust-n3-table2-box.*")
    rows = read_table(next(p for p in made if p.suffix in (".parquet", ".csv")))
    refused = sum(r["outcome"] == "TRIGGER_REFUSED" for r in rows)
    contacts = [float(r["contact_speed"]) for r in rows if r["contact_speed"]]
    assert refused >= 1 and refused + len(contacts) == 3  # aims below -3.88 m leave the box
    assert done.returncode == 1  # not every flight perched inside its window
    lines = done.stdout.splitlines()
    assert lines[0].startswith("flights: 3 in ") and f"TRIGGER_REFUSED {refused}" in lines[0]
    assert lines[1] == f"contact inside the plan's window: {len(contacts)} of 3"
    if contacts:
        assert f"{statistics.median(contacts):.3f}" in lines[2]
    assert lines[3].startswith("perch time - plan: ") and lines[3].endswith("%)")
    assert lines[-1].startswith("table: campaigns/")


@pytest.mark.parametrize(
    "args, message",
    [
        ((), "--pose-out and --setpoint-in are required (or --campaign P.json"),
        (("--pose-out", "zmq://127.0.0.1:0"), "--pose-out and --setpoint-in are required"),
        (
            ("--campaign", BOX, "--pose-out", "zmq://127.0.0.1:0", "--exit-on-stop"),
            "--pose-out, --exit-on-stop: for a live simulator, not a --campaign",
        ),
        (
            (
                "--pose-out",
                "zmq://127.0.0.1:0",
                "--setpoint-in",
                "zmq://127.0.0.1:0",
                "--flights",
                "3",
            ),
            "--flights: only with --campaign P.json",
        ),
        (("--campaign", BOX, "--x0", "-3", "-3.5"), "--x0 -3 -3.5: LO must not exceed HI (by 0.5)"),
        (("--campaign", BOX, "--latency", "2"), "--latency 2 s is outside 0..1 s"),
        (("--campaign", BOX, "--flights", "0"), "--flights 0: at least 1"),
        (("--campaign", BOX, "--jobs", "0"), "--jobs 0: at least 1"),
        (("--campaign", "/nonexistent/plan.json"), "/nonexistent/plan.json"),
        (("--campaign", BOX, "--flights", "2", "--grid", "2", "2"), "not allowed with argument"),
    ],
)
def test_bad_options_are_one_line_and_exit_2(args, message, tmp_path):
    done = perchd(*args, cwd=tmp_path)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and message in done.stderr, done.stderr
    assert not (tmp_path / "campaigns").exists()


class Terminal(io.StringIO):
    """What the progress bar writes to when stderr is a terminal."""

    def isatty(self) -> bool:
        return True


def rows(*outcomes: str):
    return [SimpleNamespace(outcome=o) for o in outcomes]


def test_on_a_terminal_the_bar_is_rewritten_in_place_and_ends_the_line():
    term = Terminal()
    bar = Progress(4, "flights", "sim", term)
    for row in rows("CONTACT", "CONTACT", "GEOFENCE", "CONTACT"):
        bar(row.outcome)
    bar.close()
    text = term.getvalue()
    assert text.count("\r") == 4 and text.endswith("\n") and text.count("\n") == 1
    assert text.count("\x1b[K") == 4  # each bar clears what a longer one left
    last = text.split("\r")[-1]
    assert last.startswith("[" + "#" * 30 + "] 4/4 flights (CONTACT 3, GEOFENCE 1)")
    assert text.split("\r")[2].startswith("[" + "#" * 15 + "." * 15 + "] 2/4")


def test_elsewhere_a_line_comes_at_every_tenth_of_the_campaign():
    out = io.StringIO()
    bar = Progress(25, "flights", "sim", out)
    for row in rows(*["CONTACT"] * 25):
        bar(row.outcome)
    bar.close()
    lines = out.getvalue().splitlines()
    assert [line.split()[2] for line in lines] == [
        f"{n}/25" for n in (2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 25)
    ]
    assert "\r" not in out.getvalue()


def test_the_command_draws_the_bar_when_stderr_is_a_real_terminal(tmp_path):
    code, out, seen = run_on_terminal(
        "sim", "--campaign", BOX, "--flights", "3", "--table", str(tmp_path / "t.csv")
    )
    bars = seen.split("\r")
    assert code == 0 and out.startswith("flights: 3 in ")
    assert [b.split("] ")[1].split()[0] for b in bars[1:4]] == ["1/3", "2/3", "3/3"]
    assert "perchd sim:" not in seen  # no line-per-tenth form on a terminal
