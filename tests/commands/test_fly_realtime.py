"""`perchd fly --realtime[=PRIO] [--cpu N]`: the agent under SCHED_FIFO with its memory
locked, or, where the system does not permit it, one line saying what is missing and no
flight (docs/contracts.md §6)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from simflight import PLANS

from perchd.logs.flightlog import read_log

ROOT = Path(__file__).resolve().parents[2]
PLAN = PLANS / "case1-ipts-n3.json"
ROOT_USER = os.geteuid() == 0


def without_rt(argv: list[str]) -> list[str]:
    """argv run with RLIMIT_RTPRIO 0 and, as root, without CAP_SYS_NICE."""
    if shutil.which("prlimit") is None or (ROOT_USER and shutil.which("setpriv") is None):
        pytest.skip("needs util-linux prlimit and setpriv")
    drop = ["setpriv", "--inh-caps=-sys_nice", "--bounding-set=-sys_nice"] if ROOT_USER else []
    return ["prlimit", "--rtprio=0", *drop, *argv]


def perchd(*args: str, prefix=lambda a: a) -> subprocess.CompletedProcess:
    argv = prefix([sys.executable, "-m", "perchd", *args])
    return subprocess.run(
        argv,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )


def fly_args(log: Path, *extra: str) -> tuple[str, ...]:
    return (
        "fly",
        str(PLAN),
        "--driver",
        "sim://",
        "--mocap",
        "sim://",
        "--log",
        str(log),
        "--json",
        *extra,
    )


def test_refused_without_cap_sys_nice_and_rtprio_0_in_one_line_and_nothing_flown(tmp_path):
    log = tmp_path / "f.jsonl"
    out = perchd(*fly_args(log, "--realtime=50"), prefix=without_rt)
    assert out.returncode == 2, out.stderr
    assert out.stdout == ""
    lines = out.stderr.splitlines()
    assert len(lines) == 1, out.stderr
    assert lines[0].startswith("perchd fly: SCHED_FIFO priority 50 refused")
    assert "CAP_SYS_NICE" in lines[0] and "RLIMIT_RTPRIO 0" in lines[0]
    assert "LimitRTPRIO=50" in lines[0]  # what the unit needs
    assert not log.exists()


@pytest.mark.skipif(not ROOT_USER, reason="granted only with CAP_SYS_NICE (root here)")
def test_granted_when_permitted_the_flight_flies_under_fifo_pinned(tmp_path):
    log = tmp_path / "f.jsonl"
    out = perchd(*fly_args(log, "--realtime=1", "--cpu", "0"))
    assert out.returncode == 0, out.stderr
    header = read_log(log).header
    assert header["scheduling"] == "SCHED_FIFO priority 1, memory locked, pinned to CPU 0"


@pytest.mark.parametrize(
    "args, message",
    [
        (("--realtime=100",), "realtime priority 100 is outside 0..99"),
        (("--cpu", "1"), "--cpu 1: only with --realtime"),
        (("--realtime=5", "--cpu", "4096"), "CPU 4096 is not one this process may run on"),
    ],
)
def test_bad_values_are_one_line_and_nothing_flown(tmp_path, args, message):
    log = tmp_path / "f.jsonl"
    out = perchd(*fly_args(log, *args))
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1 and message in out.stderr, out.stderr
    assert not log.exists()
