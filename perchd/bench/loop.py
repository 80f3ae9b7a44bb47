"""The control loop's figures, each as min/median/p99/max; `perchd bench loop`.

1. A 500 Hz FixedRateLoop on the real clock for S seconds whose tick is the agent's own work
   (estimator + supervisor + controller) on a synthetic perch: start lateness (start -
   deadline), period deviation (start_k - start_k-1 - period), overruns, missed deadlines,
   and the agent compute inside that loop.
2. The agent compute back to back (hot caches), the figure a simulated flight sees.
3. Over real ZMQ sockets on loopback, per loop mode (mocap-synchronous with 100 Hz mocap;
   fixed 100 Hz with 120 Hz mocap): this process is the rig, a SimWorld on the real clock
   publishing its poses (perchd.mocap.zmq) and taking setpoints on a SUB socket; the agent is
   `perchd fly --driver zmq://... --mocap zmq://...` in its own process. Latency is a
   setpoint's arrival at the rig minus the publication of the pose its pose_seq names (the
   first setpoint per pose), so it includes both socket hops; the agent's own view (arrival
   to driver.send) and its CPU load (process CPU / wall time over the flight loop, all its
   threads) come from its `--json` loop summary. Perches are flown back to back until S
   seconds have passed; one still flying then (and at least MIN_FLIGHT_S after its first
   setpoint) is stopped with SIGINT. The same rig and sockets with the agent replaced by an
   echo (each pose's seq sent straight back as a setpoint: `python -m perchd.bench.loop echo`)
   give the sockets' own share, so what the agent adds is the difference.
4. The machine's own wake-up tail: the 500 Hz loop with an empty tick (at most 20 s).
The load average before and after is printed: figures from a busy machine say so.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from perchd.bench.cpuload import cpu_hogs
from perchd.core.clock import MonotonicClock
from perchd.core.runtime import Runtime
from perchd.core.types import LinkHealth, Phase, Pose, Setpoint
from perchd.drivers.base import open_driver
from perchd.drivers.zmq import parse_setpoint_message
from perchd.flight.config import FlightConfig, VehicleConfig
from perchd.flight.endrules import Conditions
from perchd.flight.estimator import Estimator, EstimatorConfig
from perchd.flight.frame import PerchFrame
from perchd.flight.loop import NO_SEQ, FixedRateLoop, LoopStats, spread
from perchd.flight.supervisor import Supervisor
from perchd.mocap.base import open_source
from perchd.mocap.zmq import ZmqPosePublisher
from perchd.sim.receiver import bind_setpoint_socket
from perchd.sim.world import MocapParams, SimWorld, WorldParams
from perchd.tau import plan_ipts, save_plan
from perchd.tau.cases import CASES
from perchd.tau.plan import Plan

LOOP_HZ = 500.0
RIG_HZ = 100.0
MIN_FLIGHT_S = 1.0
"""[s] a flight is never interrupted sooner than this after its first setpoint."""


def stats_us(values_s: list[float]) -> dict[str, float]:
    """min/median/p99/max [us] of values [s]."""
    lo, med, p99, hi = spread(values_s)
    return {"min_us": 1e6 * lo, "median_us": 1e6 * med, "p99_us": 1e6 * p99, "max_us": 1e6 * hi}


# ------------------------------------------------------------------ the agent's own work


class SyntheticAgent:
    """Estimator + supervisor + controller fed poses of a synthetic perch (accelerate to the
    plan's trigger state, then coast): one call is one tick; a flight that ends restarts."""

    def __init__(self, plan: Plan, rate_hz: float) -> None:
        self.plan, self.cfg = plan, FlightConfig(rate_hz=rate_hz)
        self.frame = PerchFrame.from_surface(self.cfg.surface.point, self.cfg.surface.normal)
        self.ok = LinkHealth(True)
        self.period = 1.0 / rate_hz
        self.compute: list[float] = []
        self.est: Estimator
        self.sup: Supervisor
        self.k = 0
        self._restart()

    def _restart(self) -> None:
        self.est = Estimator(EstimatorConfig(), self.frame)
        self.sup = Supervisor(self.plan, self.cfg, self.frame)
        self.k = 0

    def _x(self, t: float) -> float:
        """[m] the approach reaches (x0, v0) at t = 2 s with constant acceleration."""
        x0, v0, t_trig = self.plan.x0, self.plan.v0, 2.0
        if t < t_trig:
            return x0 - v0 * t_trig / 2 + v0 / (2 * t_trig) * t * t
        return x0 + v0 * (t - t_trig)

    def tick(self, k: int = 0, t_now: float = 0.0) -> bool:
        t = self.k * self.period
        pose = Pose(
            "cf1", self.k + 1, t - 0.004, (self._x(t), 0.0, 1.0), (0.0, 0.0, 0.0, 1.0), True, 0.004
        )
        w0 = time.perf_counter()
        self.est.offer(pose)
        rep = self.sup.tick(
            t,
            self.est.state(t),
            Conditions(self.ok, mocap_period_s=self.est.mocap_period, arrival_age_s=0.004),
        )
        self.compute.append(time.perf_counter() - w0)
        self.k += 1
        if rep.finished or self.k * self.period > 6.0:
            self._restart()
        return True


def fixed_rate_figures(plan: Plan, seconds: float, rate_hz: float = LOOP_HZ) -> dict[str, Any]:
    """The loop at rate_hz on the real clock for `seconds`, ticking the synthetic agent."""
    agent = SyntheticAgent(plan, rate_hz)
    loop = FixedRateLoop(MonotonicClock(), rate_hz)
    starts: list[float] = []
    end = time.monotonic() + seconds
    steal = StealMeter()

    def tick(k: int, t: float) -> bool:
        starts.append(t)
        agent.tick()
        return t < end

    stats = loop.run(tick)
    period = 1.0 / rate_hz
    deviation = [abs(b - a - period) for a, b in zip(starts, starts[1:])]
    return {
        "rate_hz": rate_hz,
        "seconds": stats.wall_s,
        "ticks": len(stats.jitter),
        "overruns": stats.overruns,
        "overruns_per_min": per_minute(stats),
        "missed": stats.missed,
        "steal_ms": steal.ms(),
        "gc_collections": stats.gc_collections,
        "lateness": stats_us(stats.jitter),
        "period_deviation": stats_us(deviation),
        "agent_compute": stats_us(agent.compute),
        "tick_compute": stats_us(stats.compute),
        "cpu_fraction": stats.cpu_s / stats.wall_s,
    }


def per_minute(stats: LoopStats) -> float:
    """Overruns per minute of the run."""
    return 60.0 * stats.overruns / stats.wall_s if stats.wall_s > 0 else 0.0


class StealMeter:
    """[ms] CPU time the hypervisor gave other guests while this machine's vCPUs wanted to run
    (/proc/stat "steal", summed over CPUs) since it was made: on a VM, a wake-up that comes
    milliseconds late with no other runnable program is the vCPU descheduled by the host."""

    def __init__(self) -> None:
        self.start = self.read()

    @staticmethod
    def read() -> int:
        try:
            with open("/proc/stat") as f:
                return int(f.readline().split()[8])
        except (OSError, IndexError, ValueError):
            return 0

    def ms(self) -> float:
        return (self.read() - self.start) * 1000.0 / os.sysconf("SC_CLK_TCK")


def idle_loop_figures(seconds: float) -> dict[str, Any]:
    """The 500 Hz loop with nothing to do: what the machine's scheduler alone costs."""
    loop = FixedRateLoop(MonotonicClock(), LOOP_HZ)
    end = time.monotonic() + seconds
    steal = StealMeter()
    stats = loop.run(lambda k, t: t < end)
    return {
        "seconds": stats.wall_s,
        "ticks": len(stats.jitter),
        "overruns": stats.overruns,
        "overruns_per_min": per_minute(stats),
        "missed": stats.missed,
        "steal_ms": steal.ms(),
        "lateness": stats_us(stats.jitter),
    }


def hot_compute(plan: Plan, ticks: int = 5000) -> dict[str, Any]:
    """The agent's tick back to back (what an in-process simulated flight measures)."""
    agent = SyntheticAgent(plan, RIG_HZ)
    for _ in range(ticks):
        agent.tick()
    return {"ticks": ticks, **stats_us(agent.compute)}


# ------------------------------------------------------------------ ZMQ rig and agent process


@dataclass
class Flight:
    """What the rig saw of one agent flight: latencies [s], and the agent's JSON result."""

    latency: list[float] = field(default_factory=list)
    result: dict[str, Any] = field(default_factory=dict)


class Rig:
    """A simulated vehicle on the real clock behind real ZMQ sockets: poses out on an XPUB
    (ZmqPosePublisher), setpoints in on a bound SUB; one thread, so nothing waits for a GIL
    between a setpoint's arrival and its timestamp."""

    def __init__(self, mocap_hz: float) -> None:
        self.mocap_hz = mocap_hz
        self.pub = ZmqPosePublisher("tcp://127.0.0.1:0")
        self.sub, port = bind_setpoint_socket("127.0.0.1", 0, "loop benchmark rig")
        self.driver_uri = f"zmq://127.0.0.1:{port}?vehicle=cf1&wait=10"
        self.mocap_uri = self.pub.uri("cf1")

    def close(self) -> None:
        self.sub.close(0)
        self.pub.close()

    def _world(self):
        return SimWorld(WorldParams(mocap=MocapParams(rate_hz=self.mocap_hz)), MonotonicClock())

    def fly(self, agent: subprocess.Popen, stop_at: float) -> Flight:
        """Serve one agent process until it exits (SIGINT at `stop_at` [monotonic s])."""
        world, flight = self._world(), Flight()
        sent: dict[int, float] = {}
        answered: set[int] = set()
        last_seq, interrupted, first = -1, False, None
        while agent.poll() is None:
            pose = world.latest_pose()
            if pose is not None and pose.seq != last_seq:
                sent[pose.seq], last_seq = time.monotonic(), pose.seq
                self.pub.publish(pose)
            now = time.monotonic()
            if first is not None and now >= max(stop_at, first + MIN_FLIGHT_S) and not interrupted:
                agent.send_signal(signal.SIGINT)
                interrupted = True
            wait_s = max(0.0, min(world.next_arrival() - world.clock.now(), 0.05))
            if not self.sub.poll(math.ceil(wait_s * 1e3)):  # whole ms: never a busy spin
                continue
            while self.sub.poll(0):
                topic, body = self.sub.recv_multipart()[:2]
                arrival = time.monotonic()
                if topic == b"stop":
                    world.command(Setpoint.stop(world.clock.now()))
                    continue
                _, _, sp = parse_setpoint_message(body)
                first = arrival if first is None else first
                if sp.pose_seq in sent and sp.pose_seq not in answered:
                    answered.add(sp.pose_seq)
                    flight.latency.append(arrival - sent[sp.pose_seq])
                world.command(sp)
        out = agent.stdout.read()
        flight.result = json.loads(out) if out.strip() else {}
        return flight


def _agent(
    plan_file: Path, rig: Rig, sync: str, rate_hz: float, tmp: Path, n: int, realtime: int = 0
) -> subprocess.Popen:
    if sync == "echo":
        cmd = [sys.executable, "-m", "perchd.bench.loop", "echo", rig.mocap_uri, rig.driver_uri]
        return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    config = tmp / f"{sync}.toml"
    config.write_text(f'version = 1\n[flight]\nsync = "{sync}"\nrate_hz = {rate_hz}\n')
    cmd = [
        sys.executable,
        "-m",
        "perchd",
        "fly",
        str(plan_file),
        "--driver",
        rig.driver_uri,
        "--mocap",
        rig.mocap_uri,
        "--config",
        str(config),
        "--json",
        "--log",
        str(tmp / f"{sync}-{n}.jsonl"),
        *([f"--realtime={realtime}"] * (realtime > 0)),
    ]
    return subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )


def zmq_mode_figures(
    plan_file: Path, sync: str, seconds: float, tmp: Path, realtime: int = 0
) -> dict[str, Any]:
    """Fly perches back to back over ZMQ in one loop mode for `seconds` (at least one);
    realtime: the agent's `perchd fly --realtime` priority (0: none)."""
    mocap_hz = 120.0 if sync == "fixed" else RIG_HZ
    rig = Rig(mocap_hz)
    flights: list[Flight] = []
    end = time.monotonic() + seconds
    try:
        while not flights or time.monotonic() < end:
            agent = _agent(plan_file, rig, sync, RIG_HZ, tmp, len(flights), realtime)
            try:
                flights.append(rig.fly(agent, end))
            finally:
                if agent.poll() is None:
                    agent.kill()
                    agent.wait()
    finally:
        rig.close()
    loops = [f.result["loop"] for f in flights if f.result]
    return {
        "sync": sync,
        "rate_hz": RIG_HZ,
        "mocap_hz": mocap_hz,
        "flights": len(flights),
        "outcomes": [f.result.get("outcome") for f in flights],
        "setpoints_matched": sum(len(f.latency) for f in flights),
        "latency_sockets": stats_us([x for f in flights for x in f.latency]),
        "latency_agent": _loop_us(loops, "latency"),
        "tick_compute": _loop_us(loops, "compute"),
        "agent_compute": _loop_us(loops, "agent"),
        "jitter": _loop_us(loops, "jitter"),
        "overruns": sum(lp["overruns"] for lp in loops),
        "gc_collections": sum(lp.get("gc_collections", 0) for lp in loops),
        "cpu_fraction": _weighted_cpu(loops),
    }


def echo(mocap_uri: str, driver_uri: str) -> None:
    """Send each pose's seq straight back as a hover setpoint until SIGINT (no agent work)."""
    # A shell's background job starts with SIGINT ignored, and Python then leaves it so:
    # the rig's SIGINT would never end the echo.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    rt = Runtime.real()
    source, driver = open_source(mocap_uri, rt), open_driver(driver_uri, rt)
    hover = VehicleConfig().mass_kg * VehicleConfig().g
    source.start()
    driver.connect()
    seq = NO_SEQ
    try:
        while True:
            pose = source.wait(seq, 0.1)
            if pose is not None:
                seq = pose.seq
                driver.send(Setpoint(pose.t, 0.0, 0.0, 0.0, hover, seq, Phase.HOLD))
    except KeyboardInterrupt:
        pass
    finally:
        driver.close()
        source.close()


def _loop_us(loops: list[dict], name: str) -> dict[str, float]:
    """The agent's own min/median/p99/max [us] of `name`: min and max over its flights,
    median and p99 of the longest flight (most ticks)."""
    if not loops:
        return {"min_us": 0.0, "median_us": 0.0, "p99_us": 0.0, "max_us": 0.0}
    main = max(loops, key=lambda lp: lp["ticks"])
    return {
        "min_us": 1e6 * min(lp[f"{name}_min_s"] for lp in loops),
        "median_us": 1e6 * main[f"{name}_median_s"],
        "p99_us": 1e6 * main[f"{name}_p99_s"],
        "max_us": 1e6 * max(lp[f"{name}_max_s"] for lp in loops),
    }


def _weighted_cpu(loops: list[dict]) -> float:
    wall = sum(lp["wall_s"] for lp in loops)
    return sum(lp["cpu_fraction"] * lp["wall_s"] for lp in loops) / wall if wall else 0.0


@contextlib.contextmanager
def bench_plan() -> Iterator[tuple[Plan, Path, Path]]:
    """The paper's case-1 IPTS order-3 plan, its file, and a scratch folder for the flights."""
    case = CASES[0]
    plan = plan_ipts(case.x0, case.v0, case.tau_s, case.v_contact, case.v_max, case.a_max, 3)
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        plan_file = tmp / "case1-ipts-n3.json"
        save_plan(plan, plan_file)
        yield plan, plan_file, tmp


def measure(seconds: float, realtime: int = 0) -> dict[str, Any]:
    with bench_plan() as (plan, plan_file, tmp):
        load = os.getloadavg()[0]
        return {
            "seconds": seconds,
            "load_before": load,
            "agent_compute_hot": hot_compute(plan),
            "fixed_500hz": fixed_rate_figures(plan, seconds),
            "fixed_100hz": fixed_rate_figures(plan, seconds, 100.0),
            "zmq_mocap": zmq_mode_figures(plan_file, "mocap", seconds, tmp, realtime),
            "zmq_fixed": zmq_mode_figures(plan_file, "fixed", seconds, tmp, realtime),
            "zmq_echo": zmq_mode_figures(plan_file, "echo", min(seconds, 20.0), tmp),
            "idle_500hz": idle_loop_figures(min(seconds, 20.0)),
            "load_after": os.getloadavg()[0],
        }


def load_figures(
    plan: Plan, plan_file: Path, seconds: float, tmp: Path, realtime: int
) -> dict[str, Any]:
    """What load changes: overruns at 100 and 500 Hz, and the default (mocap-synchronous)
    loop's pose-to-setpoint latency over ZMQ."""
    return {
        "fixed_100hz": fixed_rate_figures(plan, seconds, 100.0),
        "fixed_500hz": fixed_rate_figures(plan, seconds, LOOP_HZ),
        "zmq_mocap": zmq_mode_figures(plan_file, "mocap", seconds, tmp, realtime),
    }


def measure_under_load(seconds: float, hogs: int, realtime: int = 0) -> dict[str, Any]:
    """load_figures without load, then with `hogs` CPU-bound processes beside them."""
    with bench_plan() as (plan, plan_file, tmp):
        out: dict[str, Any] = {
            "seconds": seconds,
            "hogs": hogs,
            "realtime": realtime,
            "load_before": os.getloadavg()[0],
        }
        for name in ("idle", "loaded"):  # each run's flight logs in a folder of its own
            (tmp / name).mkdir()
        out["idle"] = load_figures(plan, plan_file, seconds, tmp / "idle", realtime)
        with cpu_hogs(hogs):
            out["loaded"] = load_figures(plan, plan_file, seconds, tmp / "loaded", realtime)
            out["load_during"] = os.getloadavg()[0]
        return out


# ------------------------------------------------------------------ report

TARGETS = {
    "lateness": "p99 <= 500",
    "period_deviation": "p99 <= 500",
    "agent": "median <= 50",
    "latency_mocap": "p99 <= 1000",
    "latency_fixed": "<= 10000 (one period)",
}


def rows(fig: dict[str, Any]) -> list[tuple[str, dict[str, float], str]]:
    """(figure, min/median/p99/max [us], target) in the order they are printed."""
    f5, zm, zf = fig["fixed_500hz"], fig["zmq_mocap"], fig["zmq_fixed"]
    return [
        ("500 Hz loop: start lateness", f5["lateness"], TARGETS["lateness"]),
        ("500 Hz loop: period deviation", f5["period_deviation"], TARGETS["period_deviation"]),
        ("agent compute, back to back", fig["agent_compute_hot"], TARGETS["agent"]),
        ("agent compute in the 500 Hz loop", f5["agent_compute"], TARGETS["agent"]),
        ("agent compute, ZMQ fixed 100 Hz", zf["agent_compute"], TARGETS["agent"]),
        ("whole tick, ZMQ fixed 100 Hz", zf["tick_compute"], ""),
        ("latency mocap-sync, sockets", zm["latency_sockets"], TARGETS["latency_mocap"]),
        ("latency mocap-sync, in agent", zm["latency_agent"], ""),
        ("latency fixed 100 Hz, sockets", zf["latency_sockets"], TARGETS["latency_fixed"]),
        ("latency fixed 100 Hz, in agent", zf["latency_agent"], ""),
        ("latency floor: echo, sockets", fig["zmq_echo"]["latency_sockets"], ""),
        ("500 Hz loop, empty tick: lateness", fig["idle_500hz"]["lateness"], ""),
    ]


def text(fig: dict[str, Any]) -> str:
    f5, zm, zf = fig["fixed_500hz"], fig["zmq_mocap"], fig["zmq_fixed"]
    out = [
        f"load average {fig['load_before']:.2f} before, {fig['load_after']:.2f} after "
        f"({os.cpu_count()} cores; targets are for an idle machine)",
        f"{'figure [us]':36} {'min':>8} {'median':>8} {'p99':>8} {'max':>8}   target",
    ]
    for name, s, target in rows(fig):
        out.append(
            f"{name:36} {s['min_us']:8.1f} {s['median_us']:8.1f} {s['p99_us']:8.1f} "
            f"{s['max_us']:8.1f}   {target}"
        )
    for f in (f5, fig["fixed_100hz"]):
        out.append(overrun_line(f) + f", CPU {100 * f['cpu_fraction']:.1f} % of a core")
    idle = fig["idle_500hz"]
    out.append(
        f"500 Hz loop with an empty tick: {idle['ticks']} ticks in {idle['seconds']:.1f} "
        f"s, {idle['overruns']} overruns ({idle['overruns_per_min']:.1f} per minute; the "
        f"machine's own wake-up tail; hypervisor steal {idle['steal_ms']:.0f} ms)"
    )
    for z in (zm, zf):
        out.append(
            f"ZMQ {z['sync']:5} {z['rate_hz']:g} Hz loop, {z['mocap_hz']:g} Hz mocap: "
            f"{z['flights']} flight(s) {', '.join(map(str, z['outcomes']))}; "
            f"{z['setpoints_matched']} poses matched; {z['overruns']} overruns; agent "
            f"CPU {100 * z['cpu_fraction']:.1f} % of a core (target <= 10 %)"
        )
    return "\n".join(out)


def overrun_line(f: dict[str, Any]) -> str:
    return (
        f"{f['rate_hz']:g} Hz loop: {f['ticks']} ticks in {f['seconds']:.1f} s, "
        f"{f['overruns']} overruns ({f['overruns_per_min']:.1f} per minute, target 0), "
        f"{f['missed']} missed deadlines, hypervisor steal {f['steal_ms']:.0f} ms, "
        f"{f['gc_collections']} garbage collections"
    )


def load_text(fig: dict[str, Any]) -> str:
    """Each figure without load beside the same figure with the hogs running."""
    rt = f"SCHED_FIFO {fig['realtime']} (bench and agent)" if fig["realtime"] else "none"
    idle, busy = fig["idle"], fig["loaded"]
    out = [
        f"{fig['hogs']} CPU-bound processes beside the loaded run; {os.cpu_count()} cores; "
        f"load average {fig['load_before']:.2f} before, {fig['load_during']:.2f} loaded; "
        f"--realtime: {rt}",
        f"{'figure':44} {'no load':>16} {'loaded':>16}",
    ]

    def row(name: str, get) -> None:
        out.append(f"{name:44} {get(idle):>16} {get(busy):>16}")

    for key in ("fixed_100hz", "fixed_500hz"):
        hz = idle[key]["rate_hz"]
        row(
            f"{hz:g} Hz loop: overruns (per minute)",
            lambda f, k=key: f"{f[k]['overruns']} ({f[k]['overruns_per_min']:.1f})",
        )
        row(
            f"{hz:g} Hz loop: lateness p50 / p99 [us]",
            lambda f, k=key: (
                f"{f[k]['lateness']['median_us']:.0f} / {f[k]['lateness']['p99_us']:.0f}"
            ),
        )
    for name, key in (("in agent", "latency_agent"), ("sockets", "latency_sockets")):
        row(
            f"pose->setpoint, mocap-sync, {name} p50 / p99 [us]",
            lambda f, k=key: (
                f"{f['zmq_mocap'][k]['median_us']:.0f} / {f['zmq_mocap'][k]['p99_us']:.0f}"
            ),
        )
    row(
        "ZMQ flights: agent overruns / poses matched",
        lambda f: f"{f['zmq_mocap']['overruns']} / {f['zmq_mocap']['setpoints_matched']}",
    )
    return "\n".join(out)


if __name__ == "__main__":  # the echo agent: python -m perchd.bench.loop echo MOCAP DRIVER
    if sys.argv[1:2] != ["echo"] or len(sys.argv) != 4:
        sys.exit("usage: python -m perchd.bench.loop echo MOCAP_URI DRIVER_URI")
    echo(sys.argv[2], sys.argv[3])
