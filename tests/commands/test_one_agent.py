"""A `perchd fly` at a simulator another agent is connected to is refused before it sends
anything, in one line naming the first (pid and command), exit 2 (docs/safety.md "One
vehicle, one agent")."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest
from svc import PLAN, SimProcess

from perchd.drivers.targetlock import COMMAND_CHARS, lock_path, read_holder

pytestmark = pytest.mark.slow


HOLD = (
    "import sys, time; from perchd.core.runtime import Runtime; "
    "from perchd.drivers.base import open_driver; "
    "open_driver(sys.argv[1], Runtime.real()).connect(); print('connected', flush=True); "
    "time.sleep(60)"
)
"""The first agent: a process with its zmq:// driver connected to the simulator, as `perchd fly`
holds it from connect to the end of its flight."""


def test_a_second_fly_at_the_same_vehicle_is_refused_naming_the_first(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    sim = SimProcess()
    first = subprocess.Popen(
        [sys.executable, "-c", HOLD, sim.driver], stdout=subprocess.PIPE, text=True
    )
    try:
        assert first.stdout.readline() == "connected\n"
        lock = lock_path(sim.driver)
        second = subprocess.run(
            [
                sys.executable,
                "-m",
                "perchd",
                "fly",
                str(PLAN),
                "--driver",
                sim.driver,
                "--mocap",
                sim.mocap,
                "--log",
                str(tmp_path / "second.jsonl"),
            ],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert second.returncode == 2 and second.stdout == ""
        command = f"{sys.executable} -c {HOLD} {sim.driver}"[:COMMAND_CHARS].strip()
        assert second.stderr == (
            f"perchd fly: {sim.driver}: the vehicle is in use by another "
            f"perchd, pid {first.pid} ({command}); stop that one first "
            f"(lock {lock})\n"
        )
        assert not (tmp_path / "second.jsonl").exists()
        first.send_signal(signal.SIGKILL)  # however the holder ends, the lock goes with it
        assert first.wait(30) == -signal.SIGKILL
        assert read_holder(lock).pid == first.pid  # the file stays: only its name tag
        assert sim.summary()["foreign"] == 0  # nothing of the second reached the wire
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
        sim.kill()
