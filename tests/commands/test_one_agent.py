"""Two `perchd fly` at one simulator: the second is refused before it sends anything, in one
line naming the first (pid and command), exit 2 (docs/safety.md "One vehicle, one agent")."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from svc import PLAN, SimProcess

from perchd.drivers.targetlock import COMMAND_CHARS, lock_path, read_holder

pytestmark = pytest.mark.slow


def test_a_second_fly_at_the_same_vehicle_is_refused_naming_the_first(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    sim = SimProcess()
    fly = [sys.executable, "-m", "perchd", "fly", str(PLAN), "--driver", sim.driver,
           "--mocap", sim.mocap]
    first = subprocess.Popen([*fly, "--log", str(tmp_path / "first.jsonl")],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        lock = lock_path(sim.driver)
        deadline = time.monotonic() + 20
        while not (lock.exists() and read_holder(lock).pid == first.pid):
            assert first.poll() is None and time.monotonic() < deadline, "the first never connected"
            time.sleep(0.05)
        second = subprocess.run([*fly, "--log", str(tmp_path / "second.jsonl")],
                                capture_output=True, text=True, timeout=60, check=False)
        assert second.returncode == 2 and second.stdout == ""
        command = " ".join([*fly, "--log", str(tmp_path / "first.jsonl")])[:COMMAND_CHARS]
        assert second.stderr == (f"perchd fly: {sim.driver}: the vehicle is in use by another "
                                 f"perchd, pid {first.pid} ({command}); stop that one first "
                                 f"(lock {lock})\n")
        assert not (tmp_path / "second.jsonl").exists()
        first.send_signal(signal.SIGINT)
        assert first.wait(30) == 130
        assert sim.summary()["foreign"] == 0  # nothing of the second reached the wire
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
        sim.kill()
    assert os.path.exists(lock)  # the file stays; its flock went with the process
