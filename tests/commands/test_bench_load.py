"""`perchd bench loop|planner --load N`: N CPU-bound processes run beside the loaded half of
the measurement and are gone afterwards, however the run ends (Ctrl-C included); the figures
without and with load come from the same run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sigint_child import popen_handling_sigint

from perchd.bench.cpuload import cpu_hogs

ROOT = Path(__file__).resolve().parents[2]


pytestmark = pytest.mark.solo  # real-time bounds: see tests/conftest.py


def children(pid: int) -> set[int]:
    """Child pids of `pid` (every thread's children, /proc/PID/task/TID/children)."""
    out: set[int] = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{tid}/children") as f:
            out |= {int(c) for c in f.read().split()}
    return out


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(") ")[1][0] != "Z"
    except FileNotFoundError:
        return False


def test_the_hogs_spin_inside_the_block_and_are_gone_after_it():
    with cpu_hogs(2) as procs:
        pids = [p.pid for p in procs]
        time.sleep(0.3)
        assert all(alive(p) for p in pids)
        cpu = [int(open(f"/proc/{p}/stat").read().split(") ")[1].split()[11]) for p in pids]
        assert min(cpu) > 0  # utime ticks: they really run
    assert not any(alive(p) for p in pids)


def test_an_exception_inside_the_block_still_stops_them():
    with pytest.raises(KeyboardInterrupt):
        with cpu_hogs(2) as procs:
            pids = [p.pid for p in procs]
            raise KeyboardInterrupt
    assert not any(alive(p) for p in pids)


def perchd_bench(*args: str) -> subprocess.Popen:
    """`perchd bench ARGS`, SIGINT handled in it whatever this process inherited."""
    return popen_handling_sigint(
        [sys.executable, "-m", "perchd", "bench", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )


@pytest.mark.slow
def test_ctrl_c_during_the_loaded_run_stops_every_hog():
    bench = perchd_bench(
        "planner", "--orders", "3", "--repeat", "20", "--replans", "5", "--load", "2"
    )
    try:
        deadline, hogs = time.monotonic() + 120, set()
        while len(hogs) < 2 and time.monotonic() < deadline and bench.poll() is None:
            time.sleep(0.1)
            hogs = children(bench.pid)
        assert len(hogs) == 2, "the loaded run never started"
        bench.send_signal(signal.SIGINT)
        _, err = bench.communicate(timeout=30)
    finally:
        if bench.poll() is None:
            bench.kill()
    assert bench.returncode == 130 and "interrupted" in err
    time.sleep(0.2)
    assert not any(alive(p) for p in hogs)


@pytest.mark.slow
def test_planner_load_json_has_idle_and_loaded_medians_of_the_same_rows():
    bench = perchd_bench(
        "planner", "--orders", "3", "--repeat", "2", "--replans", "5", "--load", "1", "--json"
    )
    out, err = bench.communicate(timeout=120)
    assert bench.returncode == 0, err
    fig = json.loads(out)
    assert fig["hogs"] == 1 and len(fig["rows"]) == 4
    for r in fig["rows"]:
        assert r["loaded_median_ms"] > 0 and r["ratio_loaded"] == pytest.approx(
            r["loaded_median_ms"] / r["median_ms"]
        )


@pytest.mark.parametrize("args", [("loop", "--load", "-1"), ("planner", "--load", "65")])
def test_a_load_out_of_range_is_one_line_and_exit_2(args):
    bench = perchd_bench(*args)
    _, err = bench.communicate(timeout=60)
    assert bench.returncode == 2 and err.count("\n") == 1 and "--load" in err


@pytest.mark.slow
def test_loop_load_json_flies_both_halves_and_counts_overruns_at_100_and_500_hz():
    bench = perchd_bench("loop", "--seconds", "0.5", "--load", "1", "--json")
    out, err = bench.communicate(timeout=180)
    assert bench.returncode == 0, err
    fig = json.loads(out)
    assert fig["hogs"] == 1 and fig["realtime"] == 0
    for half in ("idle", "loaded"):
        f = fig[half]
        assert (f["fixed_100hz"]["rate_hz"], f["fixed_500hz"]["rate_hz"]) == (100.0, 500.0)
        assert f["zmq_mocap"]["outcomes"] and set(f["zmq_mocap"]["outcomes"]) <= {
            "SIGNAL",
            "CONTACT",
        }
        assert f["zmq_mocap"]["setpoints_matched"] >= 25
