"""What `perchd fly --foxglove` costs the control loop: real-time perches of the case-1 IPTS
plan against `perchd sim` in its own process (zmq:// driver, natnet:// mocap on loopback),
flown alternately without the live view and with it, a Foxglove WebSocket client subscribed
to every channel (tests/helpers/foxglove_client.py). Per mode, the median over flights of
each flight's `--json` loop summary: the agent's tick cost (estimator, supervisor, controller),
the whole tick's compute (with the driver send and the log write), the start jitter, the
overruns, and the process's CPU share; with the view, the messages the client received.

Run: python benchmarks/foxglove.py [--flights N] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "helpers"))

from foxglove_client import serving_url, watch  # noqa: E402
from stale import harness_config  # noqa: E402
from svc import PLAN, SimProcess  # noqa: E402

FIGURES = (
    ("agent_median_s", 1e6, "agent tick median [us]"),
    ("agent_p99_s", 1e6, "agent tick p99 [us]"),
    ("compute_median_s", 1e6, "whole tick median [us]"),
    ("compute_p99_s", 1e6, "whole tick p99 [us]"),
    ("jitter_p99_s", 1e6, "start jitter p99 [us]"),
    ("overruns", 1, "overruns per flight"),
    ("cpu_fraction", 100, "agent process CPU [%]"),
)


def fly(sim: SimProcess, log: Path, view: bool) -> tuple[dict, int]:
    """One perch: (its --json loop summary, messages a subscribed client received)."""
    extra = ["--foxglove", "127.0.0.1:0"] if view else []
    proc = subprocess.Popen(
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
            "--config",
            str(harness_config(log.parent)),
            "--log",
            str(log),
            "--force",
            "--json",
            *extra,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    got: list = []
    if view:
        url = serving_url(proc)
        client = threading.Thread(target=lambda: got.extend(watch(url)[1]), daemon=True)
        client.start()
    out, _ = proc.communicate(timeout=60)
    if view:
        client.join(10)
    return json.loads(out)["loop"], len(got)


def measure(flights: int) -> dict:
    load = os.getloadavg()
    runs: dict[str, list] = {"off": [], "on": []}
    received = []
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["XDG_STATE_HOME"] = tmp  # learned hover thrusts stay out of the home
        for i in range(flights):
            for mode in ("off", "on"):  # alternated: a load change hits both alike
                sim = SimProcess()
                try:
                    loop, n = fly(sim, Path(tmp) / f"{mode}-{i}.jsonl", mode == "on")
                finally:
                    sim.kill()
                runs[mode].append(loop)
                if mode == "on":
                    received.append(n)
    return {
        "flights": flights,
        "load_before": load,
        "load_after": os.getloadavg(),
        "messages_received_median": statistics.median(received),
        **{
            mode: {
                key: statistics.median(r[key] for r in loops) * scale for key, scale, _ in FIGURES
            }
            for mode, loops in runs.items()
        },
    }


def text(fig: dict) -> str:
    lines = [
        f"{fig['flights']} real-time perches per mode; load average before "
        f"{fig['load_before'][0]:.2f}, after {fig['load_after'][0]:.2f}",
        f"{'median over flights':<26} {'no view':>10} {'--foxglove':>11}",
    ]
    for key, _, label in FIGURES:
        lines.append(f"{label:<26} {fig['off'][key]:>10.1f} {fig['on'][key]:>11.1f}")
    lines.append(
        f"messages received by the subscribed client per flight: "
        f"{fig['messages_received_median']:.0f}"
    )
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=5, help="perches per mode (default 5)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    fig = measure(args.flights)
    print(json.dumps(fig) if args.json else text(fig))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
