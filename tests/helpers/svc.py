"""Helpers for the service tests: a notify socket standing in for systemd, `perchd serve`
and `perchd sim` as child processes, and a config file writer."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

from announced import start_announced
from stale import HARNESS_SAFETY

PLANS = Path(__file__).resolve().parents[2] / "plans"
PLAN = PLANS / "case1-ipts-n3.json"


class NotifyListener:
    """An AF_UNIX datagram socket playing systemd's NOTIFY_SOCKET; collects the messages."""

    def __init__(self, path: Path | None = None, abstract: str | None = None) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        if abstract:
            self.sock.bind("\0" + abstract)
            self.address = "@" + abstract
        else:
            self.sock.bind(str(path))
            self.address = str(path)
        self.messages: list[str] = []

    def wait_for(self, field: str, timeout: float = 10.0) -> str:
        """The first message (from now on, or already seen) holding the line `field`."""
        deadline = time.monotonic() + timeout
        while True:
            for m in self.messages:
                if field in m.split("\n"):
                    return m
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"no {field} within {timeout} s; got {self.messages}")
            self.sock.settimeout(left)
            try:
                self.messages.append(self.sock.recv(4096).decode())
            except TimeoutError:
                pass

    def count(self, field: str) -> int:
        return sum(field in m.split("\n") for m in self.messages)

    def drain(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            self.sock.settimeout(left)
            try:
                self.messages.append(self.sock.recv(4096).decode())
            except TimeoutError:
                return

    def close(self) -> None:
        self.sock.close()


def write_config(tmp: Path, tables: str = "", **service: str) -> Path:
    """perchd.toml for `perchd serve` under tmp: its [service] table, then `tables`, with
    HARNESS_SAFETY (stale.py) unless they hold a [safety] table of their own."""
    lines = [
        "version = 1",
        "" if "[safety]" in tables else HARNESS_SAFETY,  # before [service]: tests append to it
        "[service]",
        f'socket = "{tmp / "control.sock"}"',
        f'log_dir = "{tmp / "logs"}"',
        f'plan_dir = "{PLANS}"',
        *(f'{k} = "{v}"' for k, v in service.items()),
    ]
    path = tmp / "perchd.toml"
    path.write_text("\n".join(lines) + "\n" + tables)
    return path


def perchd(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "perchd", *args], capture_output=True, text=True, timeout=30, **kw
    )


def ctl(sock: Path, *args: str) -> dict:
    done = perchd("ctl", "--socket", str(sock), "--json", *args)
    assert done.stdout, done.stderr
    return json.loads(done.stdout)


ACTIVATE = (
    "import os, sys; os.dup2(int(sys.argv[1]), 3); "
    "os.environ['LISTEN_PID'] = str(os.getpid()); os.execvp(sys.argv[2], sys.argv[2:])"
)
"""What systemd does between fork and exec for socket activation: the socket at fd 3 and
LISTEN_PID set to the pid that exec keeps (sd_listen_fds(3))."""


class Serve:
    """`perchd serve` under a test notify socket; .sock is its control socket. With
    `listen`, started as systemd's socket activation starts it: that socket at fd 3."""

    def __init__(
        self,
        tmp: Path,
        notify: NotifyListener,
        *extra: str,
        tables: str = "",
        listen: socket.socket | None = None,
        prefix: tuple[str, ...] = (),
        **service: str,
    ) -> None:
        """prefix: a command the service runs under (prlimit, setpriv)."""
        self.config = write_config(tmp, tables, **service)
        self.sock = tmp / "control.sock"
        env = {**os.environ, "NOTIFY_SOCKET": notify.address, "WATCHDOG_USEC": "2000000"}
        cmd = [
            *prefix,
            sys.executable,
            "-m",
            "perchd",
            "serve",
            "--config",
            str(self.config),
            *extra,
        ]
        fds: tuple[int, ...] = ()
        if listen is not None:
            fds = (listen.fileno(),)
            cmd = [sys.executable, "-c", ACTIVATE, str(listen.fileno()), *cmd]
            env.update(LISTEN_FDS="1", LISTEN_FDNAMES="control")
        self.proc = subprocess.Popen(
            cmd, env=env, pass_fds=fds, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )

    def wait_phase(self, phases: set[str], timeout: float = 10.0) -> dict:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            st = ctl(self.sock, "status")
            if st.get("phase") in phases:
                return st
            time.sleep(0.05)
        raise AssertionError(f"never reached {phases}; last status {st}")

    def stop(self, timeout: float = 15.0) -> tuple[int, str]:
        try:
            _, err = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        return self.proc.returncode, err

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


class SimProcess:
    """`perchd sim` in its own process (real clock); .mocap and .driver URIs to fly it."""

    def __init__(self) -> None:
        self.proc, self.mocap, self.driver = start_announced(
            "sim",
            "--pose-out",
            "natnet://127.0.0.1:0",
            "--setpoint-in",
            "zmq://127.0.0.1:0",
            "--json",
        )

    def summary(self) -> dict:
        self.proc.terminate()
        out, _ = self.proc.communicate(timeout=10)
        return json.loads(out)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()
