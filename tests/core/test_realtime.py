"""perchd.core.realtime.apply puts every thread of the process under SCHED_FIFO, locks its
memory and pins it; refused, it leaves nothing changed and names what is missing."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from perchd.core.errors import ConfigError
from perchd.core.realtime import RealtimeConfig

ROOT = Path(__file__).resolve().parents[2]
PROBE = """
import json, os, threading
from perchd.core.realtime import RealtimeConfig, RealtimeRefused, apply
stop = threading.Event()
early = threading.Thread(target=stop.wait); early.start()   # a thread from before apply
try:
    apply(RealtimeConfig({prio}, cpu={cpu}))
    error = None
except RealtimeRefused as err:
    error = str(err)
late = threading.Thread(target=stop.wait); late.start()     # and one started after
tids = [int(t) for t in os.listdir("/proc/self/task")]
locked = [l for l in open("/proc/self/status") if l.startswith("VmLck")][0].split()[1]
print(json.dumps({{"error": error, "locked_kb": int(locked),
                  "policies": [os.sched_getscheduler(t) for t in tids],
                  "cpus": [sorted(os.sched_getaffinity(t)) for t in tids]}}))
stop.set()
"""


def probe(prio: int, cpu: int = -1, prefix: tuple[str, ...] = ()) -> dict:
    out = subprocess.run(
        [*prefix, sys.executable, "-c", PROBE.format(prio=prio, cpu=cpu)],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    return json.loads(out.stdout)


@pytest.mark.skipif(os.geteuid() != 0, reason="granted only with CAP_SYS_NICE (root here)")
def test_granted_every_thread_before_and_after_is_fifo_pinned_and_memory_locked():
    got = probe(10, cpu=0)
    assert got["error"] is None
    assert len(got["policies"]) == 3 and set(got["policies"]) == {os.SCHED_FIFO}
    assert got["cpus"] == [[0]] * 3
    assert got["locked_kb"] > 0


def test_refused_leaves_the_pin_and_the_lock_undone():
    if shutil.which("prlimit") is None or shutil.which("setpriv") is None:
        pytest.skip("needs util-linux prlimit and setpriv")
    drop = (
        ("setpriv", "--inh-caps=-sys_nice", "--bounding-set=-sys_nice") if os.geteuid() == 0 else ()
    )
    got = probe(10, cpu=0, prefix=("prlimit", "--rtprio=0", *drop))
    assert got["error"].startswith("SCHED_FIFO priority 10 refused")
    assert set(got["policies"]) == {os.SCHED_OTHER}
    assert got["cpus"] == [sorted(os.sched_getaffinity(0))] * 3
    assert got["locked_kb"] == 0


def test_off_by_default_and_priorities_outside_1_to_99_refused():
    assert not RealtimeConfig().enabled
    assert (
        RealtimeConfig(50, 1).describe() == "SCHED_FIFO priority 50, memory locked, pinned to CPU 1"
    )
    for bad in ({"priority": -1}, {"priority": 100}, {"cpu": -2}):
        with pytest.raises(ConfigError):
            RealtimeConfig(**bad)


@pytest.mark.skipif(os.geteuid() != 0, reason="granted only with CAP_SYS_NICE (root here)")
@pytest.mark.parametrize("prio, policy, child_prio", [(50, "FIFO", 49), (1, "OTHER", 0)])
def test_a_child_such_as_the_planner_worker_runs_just_below_the_loop(prio, policy, child_prio):
    """At the loop's own priority a CPU-bound solve would hold its CPU while the loop waits."""
    code = f"""
import json, os, subprocess, sys
from perchd.core.realtime import RealtimeConfig, apply, below_loop
apply(RealtimeConfig({prio}, lock_memory=False))
child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(5)"])
below_loop(child.pid)
print(json.dumps([os.sched_getscheduler(child.pid), os.sched_getparam(child.pid).sched_priority]))
child.kill()
"""
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert json.loads(out.stdout) == [getattr(os, f"SCHED_{policy}"), child_prio]


@pytest.mark.skipif(os.geteuid() != 0, reason="granted only with CAP_SYS_NICE (root here)")
def test_a_helper_process_such_as_the_live_view_leaves_the_inherited_fifo():
    """A niceness means nothing under SCHED_FIFO: the view would compete with the loop."""
    code = """
import json, os, subprocess, sys
from perchd.core.realtime import RealtimeConfig, apply
apply(RealtimeConfig(20, lock_memory=False))
probe = "import os; from perchd.core.realtime import leave_realtime; a = os.sched_getscheduler(0); leave_realtime(); print(a, os.sched_getscheduler(0))"
print(json.dumps(subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.split()))
"""
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert json.loads(out.stdout) == [str(os.SCHED_FIFO), str(os.SCHED_OTHER)]
