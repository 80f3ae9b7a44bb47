"""`perchd serve` on sim:// as a child process, talked to over its real control socket."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path


class Service:
    """`perchd serve` on sim:// with its own (empty) plan_dir, run with umask 0."""

    def __init__(self, tmp: Path, extra: str = "") -> None:
        self.tmp, self.plans = tmp, tmp / "plans"
        self.plans.mkdir(exist_ok=True)
        self.sock = tmp / "control.sock"
        self.config = tmp / "perchd.toml"
        self.write_config(extra)
        self.log = tmp / "serve.stderr"
        with open(self.log, "wb") as log:  # a file, not a pipe nobody drains
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "perchd", "serve", "--config", str(self.config)],
                stdout=subprocess.DEVNULL,
                stderr=log,
                preexec_fn=lambda: os.umask(0),
            )  # 0660 must not rely on the umask
        deadline = time.monotonic() + 20
        while not self.sock.exists():
            assert self.proc.poll() is None and time.monotonic() < deadline, "serve did not start"
            time.sleep(0.05)

    def talk(self, payload: bytes, replies: int) -> list[dict]:
        with socket.socket(socket.AF_UNIX) as c:
            c.settimeout(5)
            c.connect(str(self.sock))
            c.sendall(payload)
            buf = b""
            while buf.count(b"\n") < replies:
                chunk = c.recv(65536)
                if not chunk:
                    break
                buf += chunk
        return [json.loads(x) for x in buf.splitlines()]

    def write_config(self, extra: str = "") -> None:
        self.config.write_text(
            f'version = 1\n[service]\nsocket = "{self.sock}"\n'
            f'plan_dir = "{self.plans}"\nlog_dir = "{self.tmp / "logs"}"\n{extra}'
        )

    def reload(self, extra: str) -> None:
        """New [service] lines, applied by SIGHUP; returns once the service has reloaded."""
        self.write_config(extra)
        self.proc.send_signal(signal.SIGHUP)
        time.sleep(0.5)
        assert self.talk(b'{"cmd": "status"}\n', 1)[0]["ok"] is True

    def stderr(self) -> str:
        return self.log.read_text()

    def stop(self) -> str:
        """SIGTERM; the service's stderr. It must exit 0."""
        self.proc.terminate()
        self.proc.wait(timeout=10)
        assert self.proc.returncode == 0, self.stderr()
        return self.stderr()
