"""Non-finite or absurd flight geometry is refused before the flight, naming
the flag (a NaN surface used to start a flight that ended STALE_MOCAP)."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PLAN = ROOT / "plans" / "case1-ipts-n3.json"


def perchd(*args):
    return subprocess.run(
        [sys.executable, "-m", "perchd", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )


@pytest.mark.parametrize(
    "flag, values, says",
    [
        ("--surface", ["nan", "0", "0"], "--surface nan"),
        ("--surface", ["1e300", "0", "0"], "--surface 1e+300"),
        ("--surface", ["0", "-2e3", "0"], "-1000..1000 m"),
        ("--normal", ["0", "0", "0"], "non-zero"),
        ("--normal", ["inf", "0", "0"], "--normal inf"),
    ],
)
def test_fly_refuses_bad_geometry_before_flying(tmp_path, flag, values, says):
    done = perchd(
        "fly",
        PLAN,
        "--driver",
        "sim://",
        "--mocap",
        "sim://",
        flag,
        *values,
        "--log",
        tmp_path / "f.jsonl",
    )
    assert done.returncode == 2, done.stderr
    assert says in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "f.jsonl").exists()


def test_sim_refuses_bad_geometry():
    done = perchd("sim", "--campaign", PLAN, "--flights", "1", "--surface", "nan", "0", "0")
    assert done.returncode == 2 and "--surface nan" in done.stderr
