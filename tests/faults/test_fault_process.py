"""Process faults: signals to a real `perchd fly` mid-flight, a loop starved of CPU, and
clocks that jump.

`perchd fly` with sim:// on both links runs on a simulated clock (a flight takes a fraction
of a second), so the signal tests fly in real time the way tests/service does: against
`perchd sim` in its own process (zmq:// driver, natnet:// mocap on loopback).
"""

from __future__ import annotations

import ast
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from faultsim import TICK, fly, injected, report
from lateness import assert_lasted
from stale import harness_config
from svc import PLAN, SimProcess

from perchd.core.types import EndReason
from perchd.logs.flightlog import read_log

ROOT = Path(__file__).resolve().parents[2]
LEVEL_S = 0.5
"""[s] perchd sim's default watchdog level (Crazyflie firmware: COMMANDER_WDT_TIMEOUT_STABILIZE)."""
CUT_S = 2.0
"""[s] perchd sim's default watchdog cut (Crazyflie firmware: COMMANDER_WDT_TIMEOUT_SHUTDOWN)."""
FALL_S = 0.7
"""[s] a vehicle at 1 m with its motors cut is on the floor within this (0.45 s free fall)."""


pytestmark = pytest.mark.solo  # real-time bounds: see tests/conftest.py


@pytest.fixture
def sim():
    s = SimProcess()
    yield s
    s.kill()


class Fly:
    """`perchd fly` against a `perchd sim` process, in real time, with the harness's stale
    limit (stale.py); `harness=False`: the default limit, for a test of that limit."""

    def __init__(self, sim: SimProcess, log: Path, preexec=None, harness: bool = True) -> None:
        self.log = log
        config = ["--config", str(harness_config(log.parent))] if harness else []
        self.proc = subprocess.Popen(
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
                *config,
                "--log",
                str(log),
                "--json",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=preexec,
        )

    def wait_phase(self, phase: str) -> None:
        """Read the status lines on stderr (one per 0.5 s) until one names `phase`."""
        for line in self.proc.stderr:
            if f" {phase} " in line:
                return
        raise AssertionError(f"perchd fly ended before {phase}: {self.proc.wait()}")

    def finish(self) -> tuple[int, dict | None]:
        out, self.err = self.proc.communicate(timeout=20)
        return self.proc.returncode, json.loads(out) if out.strip() else None

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_mid_flight_ends_it_on_the_next_tick_with_the_failsafe(sig, sim, tmp_path):
    flight = Fly(sim, tmp_path / "f.jsonl")
    try:
        flight.wait_phase("approach")
        sent = time.monotonic()
        flight.proc.send_signal(sig)
        code, out = flight.finish()
    finally:
        flight.kill()
    injected(sig.name, real_time=True)
    assert code == 128 + sig and out["outcome"] == "SIGNAL" and out["failsafe_sent"] is True
    assert f"interrupted by {sig.name}" in flight.err
    log = read_log(out["log"])
    assert log.complete and log.end["outcome"] == "SIGNAL"
    after = [r for r in log.rows if r.t >= sent]
    assert 1 <= len(after) <= 2 and after[-1].end == "SIGNAL"  # the next tick (or the one after)
    assert sim.summary()["stops"] >= 1  # the vehicle heard the stop
    report(
        f"process: {sig.name} to perchd fly",
        "signal handler -> abort flag, read every tick",
        f"SIGNAL, failsafe, log closed, exit {128 + sig}",
        "stop published (motors off)",
        [log.rows[-1].t - sent],
    )


def test_sigkill_mid_flight_leaves_a_readable_log_and_the_vehicle_s_watchdog_lands_it(
    sim, tmp_path
):
    flight = Fly(sim, tmp_path / "f.jsonl")
    try:
        flight.wait_phase("approach")
        killed = time.monotonic()
        flight.proc.kill()
        flight.proc.communicate(timeout=10)
    finally:
        flight.kill()
    injected("SIGKILL", real_time=True)
    log = read_log(tmp_path / "f.jsonl")
    assert not log.complete and log.end is None  # cut short, and says so
    assert [r.k for r in log.rows] == sorted({r.k for r in log.rows})
    assert any(r.phase == "approach" for r in log.rows)
    assert log.rows[-1].t > killed - 0.1 - 2 * TICK  # at most the last 100 ms lost
    time.sleep(max(0.0, killed + CUT_S + FALL_S - time.monotonic()))
    summary = sim.summary()
    assert summary["stops"] == 0  # nothing could be sent: the vehicle's own watchdog acts
    wd = summary["watchdog"]
    # silences [s] after the last setpoint heard, timed by the sim process between its
    # messages: a late wakeup only lengthens them (lateness.py)
    assert len(wd["levelled_after_s"]) == 1 and len(wd["cut_after_s"]) == 1
    assert_lasted(wd["levelled_after_s"][0], LEVEL_S)
    assert_lasted(wd["cut_after_s"][0], CUT_S)
    assert wd["locked"] and summary["vehicle"]["thrust_n"] < 1e-3  # motors off
    assert summary["contact"] or summary["vehicle"]["z_m"] == 0.0  # down: floor (or perched)
    report(
        "process: SIGKILL to perchd fly",
        "none possible in-process",
        "none; log readable up to the kill (flushed per row)",
        "no stop; the vehicle's setpoint "
        f"watchdog (perchd sim as Crazyflie firmware) levels it "
        f"{1e3 * wd['levelled_after_s'][0]:.0f} ms and cuts the motors "
        f"{1e3 * wd['cut_after_s'][0]:.0f} ms after the last setpoint",
    )


def ended(log: Path) -> bool:
    try:
        return read_log(log).end is not None
    except (OSError, ValueError):
        return False


@pytest.mark.own_stale_limit  # the stale rule is one of the two ends under test
@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two CPUs to pin apart")
def test_a_loop_starved_of_cpu_ends_in_a_named_abort_with_the_failsafe(sim, tmp_path):
    """perchd fly (nice 19) shares one CPU with two busy processes (nice 0); perchd sim keeps
    the other CPU, so the vehicle and its mocap run on while the agent starves: the default
    stale limit, a stream that keeps its rate."""
    cpus = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(sim.proc.pid, {cpus[1]})

    def starved():
        os.sched_setaffinity(0, {cpus[0]})
        os.nice(19)

    flight = Fly(sim, tmp_path / "f.jsonl", preexec=starved, harness=False)
    hogs = []
    try:
        flight.wait_phase("approach")
        busy = f"import os; os.sched_setaffinity(0, {{{cpus[0]}}})\nwhile True: pass"
        hogs = [subprocess.Popen([sys.executable, "-c", busy]) for _ in range(2)]
        hogged = time.monotonic()
        while not ended(flight.log) and time.monotonic() < hogged + 20:
            time.sleep(0.05)  # then let it finish its report at full speed
        for h in hogs:
            h.kill()
        code, out = flight.finish()
    finally:
        for h in hogs:
            h.kill()
            h.wait()
        flight.kill()
    injected("CPU starvation", real_time=True)
    assert code == 1
    reason = EndReason[out["outcome"]]
    assert reason in (EndReason.DEADLINE_OVERRUN, EndReason.STALE_MOCAP)
    assert out["failsafe_sent"] is True
    log = read_log(out["log"])
    assert log.complete and log.end["outcome"] == reason.name
    assert sim.summary()["stops"] >= 1
    report(
        "process: loop starved of CPU (nice 19 beside 2 busy processes on one CPU)",
        "10 missed deadlines in a row, or stale mocap, whichever first",
        f"{reason.name} here, failsafe, log closed",
        "stop published (motors off)",
        [log.rows[-1].t - hogged],
    )


@pytest.mark.slow
def test_a_busy_process_beside_the_loop_does_not_stop_a_perch(sim, tmp_path):
    """Ordinary contention (one busy process, same priority, no pinning) is ridden out."""
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        code, out = Fly(sim, tmp_path / "f.jsonl").finish()
    finally:
        hog.kill()
        hog.wait()
    injected("CPU contention", real_time=True)
    assert code == 0 and out["outcome"] == "CONTACT", out and out["detail"]
    loop = out["loop"]
    report(
        "process: one busy process beside the loop",
        "-",
        f"flown ({loop['overruns']} overruns, max streak {loop['max_streak']})",
        f"perches ({out['contact_speed']:.3f} m/s estimated)",
    )


# --- clocks --------------------------------------------------------------------------------
def wall_clock_calls(root: Path) -> list[str]:
    """Every time.time / datetime.now / time.gmtime... call in perchd/ and drivers/."""
    wall = {
        ("time", "time"),
        ("time", "time_ns"),
        ("datetime", "now"),
        ("datetime", "utcnow"),
        ("time", "localtime"),
        ("time", "gmtime"),
    }
    found = []
    for path in [*(root / "perchd").rglob("*.py"), *(root / "drivers").rglob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text())):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and (node.value.id, node.attr) in wall
            ):
                found.append(f"{path.relative_to(root)}:{node.lineno} {node.value.id}.{node.attr}")
    return found


def test_no_flight_code_reads_the_wall_clock():
    assert wall_clock_calls(ROOT) == []


def test_wall_clock_steps_change_nothing_in_a_flight(tmp_path, monkeypatch):
    nominal = fly(tmp_path, name="nominal")
    steps = iter(range(10**9))
    monkeypatch.setattr(time, "time", lambda: 1.7e9 + 86400.0 * (-1) ** next(steps) * 365)
    monkeypatch.setattr(time, "time_ns", lambda: int(time.time() * 1e9))
    stepped = fly(tmp_path, name="stepped")
    injected("wall clock steps")
    assert [(r.t, r.x, r.thrust) for r in stepped.log.rows] == [
        (r.t, r.x, r.thrust) for r in nominal.log.rows
    ]
    report(
        "clock: wall clock steps +-1 year on every read",
        "not read by any flight code (AST scan + identical flight)",
        "none",
        "perches exactly as without",
    )


@pytest.mark.parametrize("jump, phase", [(0.05, "stage1"), (0.2, "stage1"), (1.0, "approach")])
def test_a_monotonic_clock_jump_skips_the_missed_ticks_and_flies_on(jump, phase, tmp_path):
    """The process stalls for `jump` seconds (the clock leaps forward within one tick): the
    loop does not run the missed ticks back to back, it resumes on its grid."""
    at = []

    def on_tick(sim):
        def stall(st):
            if st.phase.value == phase and not at:
                at.append(sim.runtime.clock.now())
                sim.runtime.clock.advance(jump)

        return stall

    f = fly(tmp_path, on_tick=on_tick)
    injected("monotonic clock jump")
    assert f.res.outcome is EndReason.CONTACT
    assert f.res.loop.missed == round(jump / TICK) - 1 or f.res.loop.missed == round(jump / TICK)
    assert f.res.loop.max_streak == 1
    ts = [r.t for r in f.log.rows]
    gap = max(b - a for a, b in zip(ts, ts[1:]))
    assert gap == pytest.approx(jump, abs=1e-6)  # the next tick is the first deadline after it
    report(
        f"clock: monotonic clock leaps {1000 * jump:.0f} ms ({phase})",
        "one overrun",
        f"{f.res.loop.missed} missed ticks skipped, loop back on its grid",
        f"perches ({f.res.true_contact_speed:.3f} m/s)",
    )
