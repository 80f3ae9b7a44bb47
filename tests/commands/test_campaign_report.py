"""`perchd sim report TABLE`: a campaign's table read back, its summary and figures; and a
CSV table resumed by the same command (no Dask or pyarrow needed)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

PLAN = str(Path(__file__).parents[2] / "plans" / "robust-n3-table2-box.json")


def perchd(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "perchd", "sim", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=180,
    )


def test_a_csv_campaign_is_resumed_and_reported_with_its_figures(tmp_path):
    table = tmp_path / "t.csv"
    fly = ("--campaign", PLAN, "--flights", "3", "--seed", "4", "--table", table, "--json")
    first = perchd(*fly)
    assert first.returncode == 0, first.stderr
    again = json.loads(perchd(*fly).stdout)
    assert (again["resumed"], again["flown"], again["flights"]) == (3, 0, 3)

    plots = tmp_path / "plots"
    plots.mkdir()
    done = perchd("report", table, "--plots", plots, "--worst", "2", "--json")
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out["flights"] == 3 and out["complete"] is True and len(out["worst"]) == 2
    assert sorted(p.name for p in plots.iterdir()) == [
        "contact-speed.png",
        "outcomes.png",
        "perch-error.png",
        "worst.png",
    ]
    median = json.loads(first.stdout)["contact_speed"]["median"]
    assert out["contact_speed"]["median"] == pytest.approx(median, rel=1e-6)  # CSV: 7 digits


def test_a_file_that_is_no_table_is_one_line_exit_2(tmp_path):
    bad = tmp_path / "x.csv"
    bad.write_text("a,b\n1,2\n")
    done = perchd("report", bad)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "not a campaign table" in done.stderr
