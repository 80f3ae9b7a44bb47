"""A campaign writes its table as flights finish; SIGINT/SIGTERM stop it with
the summary of what finished, exit 130 / 143 (docs/contracts.md §6)."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PLAN = ROOT / "plans" / "case1-ipts-n3.json"


def rows(table: Path) -> list[dict]:
    with open(table, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
@pytest.mark.parametrize("jobs", ["1", "2"])
def test_an_interrupted_campaign_keeps_what_finished(tmp_path, sig, code, jobs):
    table = tmp_path / "t.csv"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "perchd",
            "sim",
            "--campaign",
            str(PLAN),
            "--flights",
            "400",
            "--jobs",
            jobs,
            "--table",
            str(table),
            "--json",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env=env,
    )
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and (not table.exists() or len(rows(table)) < 2):
        time.sleep(0.1)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=90)
    assert proc.returncode == code, err
    done = json.loads(out)
    assert done["interrupted"] == sig.name and done["planned"] == 400
    kept = rows(table)
    assert 2 <= len(kept) == done["flights"] < 400
    assert f"interrupted by {sig.name}" in err and "Traceback" not in err
