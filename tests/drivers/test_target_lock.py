"""One vehicle, one agent on this machine: the driver-target lock (drivers/targetlock.py),
held by real processes, taken over from dead ones, released by close."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest
from zmq_subscriber import SetpointSubscriber

from perchd.core.errors import LinkError
from perchd.core.runtime import Runtime
from perchd.drivers.base import open_driver
from perchd.drivers.targetlock import (
    COMMAND_CHARS,
    TargetBusy,
    hold_target,
    lock_path,
    read_holder,
    target_of,
)

URI = "zmq://127.0.0.1:5999?vehicle=cf1"
HOLD = (
    "import sys, time; from perchd.drivers.targetlock import hold_target; "
    "hold_target(sys.argv[1]); print('held', flush=True); time.sleep(60)"
)


@pytest.fixture(autouse=True)
def lock_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    return tmp_path / "perchd-locks"


@pytest.fixture
def holder():
    """Another process holding URI's lock."""
    proc = subprocess.Popen([sys.executable, "-c", HOLD, URI], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline() == "held\n"
    yield proc
    proc.kill()
    proc.wait()


def takes(uri: str) -> subprocess.CompletedProcess:
    """Whether another process can take the lock now."""
    code = "import sys; from perchd.drivers.targetlock import hold_target; hold_target(sys.argv[1])"
    return subprocess.run(
        [sys.executable, "-c", code, uri], capture_output=True, text=True, timeout=30, check=False
    )


def test_the_target_is_the_uri_without_its_options():
    assert target_of("zmq://LocalHost:5556?vehicle=cf2&wait=1") == "zmq://127.0.0.1:5556"
    assert target_of("mavlink:udpin:0.0.0.0:14550?arm=1") == "mavlink:udpin:0.0.0.0:14550"
    assert target_of("radio://0/80/2M/E7E7E7E7E7?hover=30000") == "radio://0/80/2M/E7E7E7E7E7"
    assert lock_path("zmq://localhost:5556") == lock_path("zmq://127.0.0.1:5556?wait=2")
    assert lock_path("zmq://127.0.0.1:5556") != lock_path("zmq://127.0.0.1:5557")


def test_a_held_vehicle_is_refused_naming_the_holder_and_taken_once_it_dies(holder, lock_dir):
    with pytest.raises(TargetBusy) as err:
        hold_target(URI)
    command = f"{sys.executable} -c {HOLD} {URI}"[:COMMAND_CHARS]
    assert str(err.value) == (
        f"{URI}: the vehicle is in use by another perchd, pid {holder.pid} "
        f"({command}); stop that one first (lock {lock_path(URI)})"
    )
    assert err.value.exit_code == 2
    holder.send_signal(signal.SIGKILL)  # no chance to clean up: the kernel drops the flock
    holder.wait()
    lock = hold_target(URI)
    try:
        assert read_holder(lock.path).pid == os.getpid()
    finally:
        lock.release()


def test_close_releases_and_a_failed_connect_holds_nothing(lock_dir):
    sub = SetpointSubscriber()
    try:
        drv = open_driver(sub.uri, Runtime.real())
        drv.connect()
        assert takes(sub.uri).returncode == 1  # held by this process
        drv.close()
        assert takes(sub.uri).returncode == 0
    finally:
        sub.close()
    lonely = open_driver("zmq://127.0.0.1:9?wait=0.1", Runtime.real())
    with pytest.raises(LinkError, match="no subscriber"):
        lonely.connect()
    assert takes("zmq://127.0.0.1:9").returncode == 0


def test_a_driver_refused_by_the_lock_sends_nothing(holder):
    drv = open_driver(URI, Runtime.real())
    with pytest.raises(TargetBusy, match=f"pid {holder.pid} "):
        drv.connect()
    drv.close()  # nothing to close, nothing released that it did not hold
    assert takes(URI).returncode == 1


def test_one_process_may_hold_its_own_target_twice():
    first, second = hold_target(URI), hold_target(URI)
    first.release()
    assert takes(URI).returncode == 1
    second.release()
    assert takes(URI).returncode == 0
