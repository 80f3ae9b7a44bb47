"""`perchd sim firmware` as the opt-in firmware tests start and stop it."""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from announced import start_announced

ROOT = Path(__file__).parents[2]
"""The repository: a firmware test's perchd processes run from it."""
PLAN = ROOT / "plans" / "case1-ipts-n3.json"


"""The plan every firmware flight perches on (paper case 1, IPTS order 3)."""
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
"""The environment of those processes."""


def start_harness(*args: str, env: dict | None = None) -> tuple[subprocess.Popen, str, str]:
    """Start `perchd sim firmware ARGS --json`; its process and the announced URIs."""
    return start_announced("sim", "firmware", *args, "--json", env=env)


def start_placed(
    *args: str, env: dict | None = None
) -> tuple[subprocess.Popen, str, str, list[str]]:
    """`perchd sim firmware ARGS --json` for a vehicle whose harness places the surface
    itself (PX4: ahead along its heading, said on stderr before the ready line): its
    process, mocap and driver URIs, and the `--surface ... --normal ...` options for
    `perchd fly` (none when the harness said nothing)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "perchd", "sim", "firmware", *args, "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    surface: list[str] = []
    for line in proc.stderr:
        if found := re.search(r"surface (\S+ \S+ \S+) normal (\S+ \S+ \S+)", line):
            surface = ["--surface", *found.group(1).split(), "--normal", *found.group(2).split()]
        if found := re.search(r"ready: mocap (\S+) driver (\S+)", line):
            return proc, found.group(1), found.group(2), surface
    proc.kill()
    raise RuntimeError(
        f"perchd sim firmware {' '.join(args[:2])} did not start: {proc.stderr.read()}"
    )


def log_rows(log: Path) -> list[dict]:
    """The flight log's rows (docs/contracts.md, flight log), from complete lines only: a
    flight still flying may be half-way through writing its last one."""
    text = log.read_text() if log.exists() else ""
    return [
        json.loads(line)["row"]
        for line in text[: text.rfind("\n") + 1].splitlines()
        if line.startswith('{"row"')
    ]


def lag_event(log: Path) -> dict:
    """The flight's lag-identified (or -unidentified) event (first_event)."""
    return first_event(log, "lag-")


def first_event(log: Path, kind: str) -> dict:
    """The log's first event whose kind starts with `kind`, as {"kind": ..., **values}
    (docs/contracts.md, flight log); {} without one."""
    if not log.exists():
        return {}
    for line in log.read_text().splitlines():
        if f'"kind":"{kind}' in line:
            ev = json.loads(line)["event"]
            return {"kind": ev["kind"], **ev["values"]}
    return {}


def stop_harness(proc: subprocess.Popen, timeout_s: float = 20.0) -> dict:
    """SIGTERM, then its JSON summary (killed if it does not stop in time)."""
    proc.send_signal(signal.SIGTERM)
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
    return json.loads(out)


class YawWatch:
    """The mocap's true yaw [rad] by pose time, collected while `perchd fly` runs."""

    def __init__(self, mocap: str) -> None:
        from perchd.core.runtime import Runtime
        from perchd.mocap.base import open_source

        self.src = open_source(mocap, Runtime.real())
        self.src.start()
        self.samples: list[tuple[float, float]] = []
        self.positions: list[tuple[float, tuple[float, float, float]]] = []  # (t, p)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from perchd.sim.firmware.harness import yaw_of

        seq = 0
        while not self._stop.is_set():
            pose = self.src.wait(seq, 0.2)
            if pose is not None:
                seq = pose.seq
                self.samples.append((pose.t, yaw_of(pose.q)))
                self.positions.append((time.monotonic(), pose.p))

    def between(self, t0: float, t1: float) -> list[float]:
        return [y for t, y in self.samples if t0 <= t <= t1]

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        self.src.close()


def flight_window(log: Path) -> tuple[float, float]:
    """[s] monotonic times of the flight's first and last control ticks (perchd fly's clock);
    an empty window when the flight ticked none."""
    ticks = (
        [
            json.loads(line)["row"]["t"]
            for line in log.read_text().splitlines()
            if line.startswith('{"row"')
        ]
        if log.exists()
        else []
    )
    return (ticks[0], ticks[-1]) if ticks else (0.0, -1.0)


def heading_error(yaws: list[float], heading: float) -> float:
    """[rad] largest |yaw - heading|."""
    return max(abs(math.remainder(y - heading, math.tau)) for y in yaws)


def kill_at_speed(
    fly: subprocess.Popen, log: Path, speed_mps: float, timeout_s: float
) -> float | None:
    """SIGKILL `perchd fly` once its flight log shows the approach at speed_mps toward the
    wall: time.monotonic() of the kill. None when the flight ended or never got there
    within timeout_s (it is killed then all the same)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and fly.poll() is None:
        if any(r["phase"] == "approach" and r["xdot"] >= speed_mps for r in log_rows(log)[-3:]):
            fly.send_signal(signal.SIGKILL)
            killed = time.monotonic()
            fly.wait()
            return killed
        time.sleep(0.02)
    fly.kill()
    fly.wait()
    return None


def surface_normal(surface: list[str]) -> tuple[float, float, float]:
    """The unit normal of `perchd fly`'s --normal option (its default, 1 0 0, without one)."""
    if "--normal" not in surface:
        return (1.0, 0.0, 0.0)
    n = [float(c) for c in surface[surface.index("--normal") + 1 :][:3]]
    size = math.sqrt(sum(c * c for c in n))
    return (n[0] / size, n[1] / size, n[2] / size)


def after_kill(
    positions: list[tuple[float, tuple[float, float, float]]],
    killed: float,
    normal: tuple[float, float, float],
) -> dict:
    """From the mocap's positions [(time.monotonic() s, p m)] (YawWatch.positions): how far
    the vehicle went on toward the wall after the kill (the largest displacement along the
    normal), its speed along the normal over the 0.2 s before it, and its height after."""

    def along(a, b) -> float:
        return sum((b[i] - a[i]) * normal[i] for i in range(3))

    at_kill = min(positions, key=lambda s: abs(s[0] - killed))[1]
    before = min(positions, key=lambda s: abs(s[0] - (killed - 0.2)))[1]
    after = [(t - killed, along(at_kill, p), p[2]) for t, p in positions if t >= killed]
    return {
        "further_toward_wall_m": max(d for _, d, _ in after),
        "speed_at_kill_mps": along(before, at_kill) / 0.2,
        "toward_wall_m_by_0_25_s": [round(d, 3) for _, d, _ in after][::25][:16],
        "height_at_kill_m": at_kill[2],
        "final_height_m": after[-1][2],
    }
